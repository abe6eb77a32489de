#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>

#include "rime/clean/ice_metrics.h"
#include "rime/clean/procedural.h"

namespace rime::clean {
namespace {

using namespace procedural;

constexpr double kSpacing = 0.02;  // d_p
const Vec3d kGravity{0, 0, -9.81};

/// A frame of solid particles (phase 1, object 0) on the square z = 0 of side `side`, spaced d_p/2,
/// with a water film where `wet(x)`; ice particles (phase 2) are added by the caller.
struct FrameBuilder {
  std::vector<Vec3f> x;
  std::vector<std::uint8_t> phase;
  std::vector<float> film;
  std::vector<std::uint32_t> object;

  void Solid(const Vec3d& p, bool wet) {
    x.push_back(Vec3f(p)), phase.push_back(1), film.push_back(wet ? 0.5f : 0.0f), object.push_back(0);
  }
  void Ice(const Vec3d& p) { x.push_back(Vec3f(p)), phase.push_back(2), film.push_back(0), object.push_back(0); }
  void Plate(double side, const std::function<bool(const Vec3d&)>& wet) {
    const int n = int(std::round(side / (kSpacing / 2)));
    for (int i = 0; i <= n; ++i)
      for (int j = 0; j <= n; ++j) {
        const Vec3d p(-side / 2 + i * kSpacing / 2, -side / 2 + j * kSpacing / 2, 0);
        Solid(p, wet(p));
      }
  }
  io::ParticleFrame Build() const {
    io::ParticleFrame f;
    f.spacing = kSpacing;
    f.SetPositions(x);
    f.Set("phase", phase);
    f.Set("water_film", film);
    f.Set("object_id", object);
    return f;
  }
};

TEST(IceMetrics, SmoothSphereHasNoNoiseNoHandlesAndOnePiece) {
  // A 10 d_p ball resting on a solid particle: one piece, touching, genus 0, curved far below 1/d_p.
  FrameBuilder b;
  b.Solid({0, 0, 0}, false);
  const io::TriMesh ball = Icosphere(10 * kSpacing, 4, {0, 0, 10 * kSpacing});
  const IceMetrics m = MeasureIce(ball, b.Build(), kGravity, {}, {});
  EXPECT_EQ(m.components, 1u);
  EXPECT_EQ(m.specks, 0u);
  EXPECT_EQ(m.tiny_pieces, 0u);
  EXPECT_EQ(m.handles, 0);
  EXPECT_LT(m.noise_rms, 0.025);  // the Taubin filter's own small shrinkage of a 10 d_p sphere
  EXPECT_EQ(m.sharp_area_fraction, 0.0);
  EXPECT_NEAR(m.area, 4 * 3.14159265 * std::pow(10 * kSpacing, 2), 0.02 * 4 * 3.14159265 * std::pow(10 * kSpacing, 2));
}

// The volume ratio compares what the mesh encloses with what the ice particles stand for.
TEST(IceMetrics, VolumeRatioIsTheMeshVolumeOverTheIceParticles) {
  FrameBuilder b;
  b.Solid({0, 0, 0}, false);
  for (int i = 0; i < 1000; ++i) b.Ice({0, 0, 10 * kSpacing});  // 1000 d_p³
  const double radius = std::cbrt(1000 * std::pow(kSpacing, 3) * 3 / (4 * 3.14159265));
  const IceMetrics m = MeasureIce(Icosphere(radius, 4, {0, 0, 10 * kSpacing}), b.Build(), kGravity, {}, {});
  EXPECT_NEAR(m.volume_ratio, 1.0, 0.02);  // the icosphere's facets hold slightly less than the ball
  EXPECT_EQ(MeasureIce({}, b.Build(), kGravity, {}, {}).volume_ratio, 0.0);
}

TEST(IceMetrics, ParticleScaleBumpsAreNoise) {
  // The same ball with bumps of a particle's size: the noise and the sharp area rise well above it.
  FrameBuilder b;
  b.Solid({0, 0, 0}, false);
  io::TriMesh smooth = Icosphere(10 * kSpacing, 5, {0, 0, 10 * kSpacing});
  io::TriMesh bumpy = smooth;
  AddRadialNoise(bumpy, 0.3 * kSpacing, 7, {0, 0, 10 * kSpacing});
  const IceMetrics s = MeasureIce(smooth, b.Build(), kGravity, {}, {});
  const IceMetrics n = MeasureIce(bumpy, b.Build(), kGravity, {}, {});
  EXPECT_GT(n.noise_rms, 0.05);
  EXPECT_GT(n.noise_rms, 10 * s.noise_rms);
  EXPECT_GT(n.sharp_area_fraction, 0.2);
}

TEST(IceMetrics, VerticesSlidAlongTheSurfaceAreNotNoise) {
  // The smooth ball with every vertex moved along the sphere by up to 0.3 edges: uneven triangles
  // (as a decimated mesh has) over the same smooth surface read as smooth, not as bumps.
  FrameBuilder b;
  b.Solid({0, 0, 0}, false);
  const Vec3d center{0, 0, 10 * kSpacing};
  const io::TriMesh smooth = Icosphere(10 * kSpacing, 5, center);
  io::TriMesh slid = smooth;
  const double edge = Norm(Vec3d(smooth.positions[smooth.triangles[0][1]] - smooth.positions[smooth.triangles[0][0]]));
  std::mt19937_64 rng(12345);
  std::uniform_real_distribution<double> uniform(-0.3 * edge, 0.3 * edge);
  for (auto& p : slid.positions) {
    const Vec3d moved = Vec3d(p) - center + Vec3d(uniform(rng), uniform(rng), uniform(rng));
    p = Vec3f(center + moved * (10 * kSpacing / Norm(moved)));
  }
  const IceMetrics s = MeasureIce(smooth, b.Build(), kGravity, {}, {});
  const IceMetrics m = MeasureIce(slid, b.Build(), kGravity, {}, {});
  EXPECT_LT(m.noise_rms, 0.025);
  EXPECT_LT(m.noise_rms, 2 * s.noise_rms + 0.005);
}

TEST(IceMetrics, FloatingPieceIsASpeckAndSmallPieceIsTiny) {
  FrameBuilder b;
  b.Solid({0, 0, 0}, false);
  io::TriMesh mesh = Icosphere(5 * kSpacing, 3, {0, 0, 5 * kSpacing});  // resting on the solid
  Append(mesh, Icosphere(0.8 * kSpacing, 2, {0, 0, 30 * kSpacing}));    // a droplet in the air
  const IceMetrics m = MeasureIce(mesh, b.Build(), kGravity, {}, {});
  EXPECT_EQ(m.components, 2u);
  EXPECT_EQ(m.specks, 1u);
  EXPECT_EQ(m.tiny_pieces, 1u);
}

TEST(IceMetrics, TorusHasOneHandle) {
  FrameBuilder b;
  b.Solid({0, 0, 0}, false);
  const io::TriMesh torus = NoisyTorus(20000, 3);
  const IceMetrics m = MeasureIce(torus, b.Build(), kGravity, {}, {});
  EXPECT_EQ(m.handles, 1);
}

TEST(IceMetrics, GlazeCoversTheIcedShareOfTheWettedSurfaceWithItsThickness) {
  // A wet 0.4 m plate; a one-particle ice layer over the half x < 0, at d_p/2 above the plate.
  FrameBuilder b;
  b.Plate(0.4, [](const Vec3d&) { return true; });
  for (double x = -0.2; x < -1e-9; x += kSpacing)
    for (double y = -0.2; y <= 0.2 + 1e-9; y += kSpacing) b.Ice({x + kSpacing / 2, y, kSpacing / 2});
  const IceMetrics m = MeasureIce({}, b.Build(), kGravity, {}, {});
  EXPECT_EQ(m.floating_ice, 0u);
  // Covered: the 20 plate columns under the layer and the two next to it (within 1.5 d_p), of 41.
  EXPECT_NEAR(m.glaze_coverage, 22.0 / 41.0, 1e-9);
  EXPECT_NEAR(m.thickness_mean, 1.0, 0.1);  // the layer's centres lie d_p/2 up, plus half a particle
  EXPECT_TRUE(m.icicles.empty());
}

TEST(IceMetrics, DryPlateCountsNoGlazeAndObjectsFilterTheSurface) {
  FrameBuilder b;
  b.Plate(0.2, [](const Vec3d& p) { return p.x < 0; });
  const IceMetrics all = MeasureIce({}, b.Build(), kGravity, {}, {});
  const IceMetrics none = MeasureIce({}, b.Build(), kGravity, {5}, {});
  EXPECT_GT(all.wetted, 0u);
  EXPECT_EQ(all.covered, 0u);
  EXPECT_EQ(all.glaze_coverage, 0.0);
  EXPECT_EQ(none.wetted, 0u);  // object 5 does not exist: nothing measured
}

TEST(IceMetrics, HangingChainIsAnIcicleAndAStubIsNot) {
  // Under a plate at z = 0: a 10-particle chain hangs down, a 2-particle stub does not count.
  FrameBuilder b;
  b.Plate(0.3, [](const Vec3d&) { return true; });
  for (int k = 1; k <= 10; ++k) b.Ice({0.05, 0, -k * kSpacing});
  for (int k = 1; k <= 2; ++k) b.Ice({-0.08, 0, -k * kSpacing});
  const IceMetrics m = MeasureIce({}, b.Build(), kGravity, {}, {});
  ASSERT_EQ(m.icicles.size(), 1u);
  EXPECT_EQ(m.hanging_icicles, 1u);
  EXPECT_NEAR(m.icicles[0].length, 10, 0.01);
  EXPECT_LT(m.icicles[0].angle_to_gravity_deg, 1);
  EXPECT_NEAR(m.icicles[0].tip.z, -10 * kSpacing, 1e-6);

  // The same chain standing up from the plate is an icicle too, but it does not hang.
  FrameBuilder up;
  up.Plate(0.3, [](const Vec3d&) { return true; });
  for (int k = 1; k <= 10; ++k) up.Ice({0.05, 0, k * kSpacing});
  const IceMetrics column = MeasureIce({}, up.Build(), kGravity, {}, {});
  ASSERT_EQ(column.icicles.size(), 1u);
  EXPECT_EQ(column.hanging_icicles, 0u);
  EXPECT_GT(column.icicles[0].angle_to_gravity_deg, 179);
}

TEST(IceMetrics, IceConnectedToNoSolidFloats) {
  FrameBuilder b;
  b.Solid({0, 0, 0}, true);
  for (int k = 0; k < 4; ++k) b.Ice({1.0 + k * kSpacing, 0, 1.0});
  const IceMetrics m = MeasureIce({}, b.Build(), kGravity, {}, {});
  EXPECT_EQ(m.ice, 4u);
  EXPECT_EQ(m.floating_ice, 4u);
  EXPECT_TRUE(m.icicles.empty());
}

}  // namespace
}  // namespace rime::clean
