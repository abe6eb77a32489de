// Enclosure: points inside closed solids, from boundary particles alone.
#include <gtest/gtest.h>

#include "rime/sph/enclosure.h"

namespace rime::sph {
namespace {

// The six faces of the cube [0, a]³ sampled at spacing s, with normals pointing out (sign = +1)
// or in (sign = −1); `open_top` leaves the face z = a out.
void CubeSurface(double a, double s, double sign, bool open_top, std::vector<Vec3d>& x, std::vector<Vec3d>& n) {
  const int m = int(std::round(a / s));
  for (int i = 0; i <= m; ++i)
    for (int j = 0; j <= m; ++j) {
      const double u = i * s, v = j * s;
      const Vec3d face[6][2] = {{{u, v, 0}, {0, 0, -1}}, {{u, v, a}, {0, 0, 1}},  {{u, 0, v}, {0, -1, 0}},
                                {{u, a, v}, {0, 1, 0}},  {{0, u, v}, {-1, 0, 0}}, {{a, u, v}, {1, 0, 0}}};
      for (int f = 0; f < 6; ++f) {
        if (open_top && f == 1) continue;
        x.push_back(face[f][0]);
        n.push_back(face[f][1] * sign);
      }
    }
}

TEST(Enclosure, ClosedSolidEnclosesItsInterior) {
  std::vector<Vec3d> x, n;
  CubeSurface(0.3, 0.01, +1, false, x, n);
  const Enclosure e(x, n, 0.02);
  EXPECT_GT(e.enclosed_cells(), 0);
  EXPECT_TRUE(e.Inside({0.15, 0.15, 0.15}));
  EXPECT_TRUE(e.Inside({0.05, 0.25, 0.1}));
  EXPECT_FALSE(e.Inside({0.5, 0.15, 0.15}));
  EXPECT_FALSE(e.Inside({-0.1, -0.1, -0.1}));
  // Without normals a closed surface is taken for a solid.
  EXPECT_TRUE(Enclosure(x, {}, 0.02).Inside({0.15, 0.15, 0.15}));
}

TEST(Enclosure, OpenContainerAndSealedTankHoldWater) {
  std::vector<Vec3d> x, n;
  CubeSurface(0.3, 0.01, -1, true, x, n);
  EXPECT_FALSE(Enclosure(x, n, 0.02).Inside({0.15, 0.15, 0.15})) << "an open container";
  EXPECT_FALSE(Enclosure(x, {}, 0.02).Inside({0.15, 0.15, 0.15})) << "an open container, no normals";
  x.clear(), n.clear();
  CubeSurface(0.3, 0.01, -1, false, x, n);
  const Enclosure tank(x, n, 0.02);
  EXPECT_FALSE(tank.Inside({0.15, 0.15, 0.15})) << "a sealed tank faces inward: its inside is for water";
  EXPECT_EQ(tank.enclosed_cells(), 0);
}

TEST(Enclosure, CoarsensBeyondTheCellBudgetAndStillEncloses) {
  std::vector<Vec3d> x, n;
  CubeSurface(1.0, 0.01, +1, false, x, n);
  const Enclosure e(x, n, 0.01, 20'000);  // 100³ cells wanted, at most 20k allowed
  EXPECT_TRUE(e.Inside({0.5, 0.5, 0.5}));
  EXPECT_FALSE(e.Inside({1.5, 0.5, 0.5}));
}

}  // namespace
}  // namespace rime::sph
