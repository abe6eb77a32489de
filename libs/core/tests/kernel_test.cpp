// Physical properties of the cubic spline kernel (spec §1, invariants T1–T3).
#include <gtest/gtest.h>

#include <cmath>

#include "rime/core/kernel.h"

namespace rime {
namespace {

// ∫ W dV = 4π ∫_0^{2h} W(r) r² dr, by composite Simpson on each smooth piece [0,h] and [h,2h].
double RadialIntegral(const CubicSpline<double>& k) {
  auto simpson = [&](double a, double b, int n) {
    const double dx = (b - a) / n;
    double s = 0;
    for (int i = 0; i <= n; ++i) {
      const double r = a + i * dx;
      const double f = k.W(r) * r * r;
      s += f * (i == 0 || i == n ? 1 : (i % 2 ? 4 : 2));
    }
    return s * dx / 3;
  };
  return 4 * M_PI * (simpson(0, k.h, 2000) + simpson(k.h, 2 * k.h, 2000));
}

TEST(CubicSpline, IntegratesToOne) {
  for (double h : {0.01, 0.02, 1.0, 3.7}) {
    EXPECT_NEAR(RadialIntegral(CubicSpline<double>(h)), 1.0, 1e-6) << "h = " << h;
  }
}

TEST(CubicSpline, ValuesAndContinuity) {
  const CubicSpline<double> k(0.5);
  EXPECT_DOUBLE_EQ(k.W(0.0), 1.0 / (M_PI * 0.125));
  EXPECT_DOUBLE_EQ(k.W0(), k.W(0.0));
  EXPECT_EQ(k.W(1.0), 0.0);
  EXPECT_EQ(k.W(1.5), 0.0);
  for (double q : {1.0, 2.0}) {  // W and B' continuous at the knots
    EXPECT_NEAR(CubicSpline<double>::Shape(q - 1e-9), CubicSpline<double>::Shape(q + 1e-9), 1e-7);
    EXPECT_NEAR(CubicSpline<double>::ShapeDerivative(q - 1e-9), CubicSpline<double>::ShapeDerivative(q + 1e-9), 1e-7);
  }
  for (double q = 0; q < 2.5; q += 0.01) EXPECT_GE(CubicSpline<double>::Shape(q), 0.0);
  // The branch-free form (vectorised loops) is the same function, knots and outside included.
  for (double q = 0; q < 3; q += 0.03125) {
    EXPECT_DOUBLE_EQ(CubicSpline<double>::ShapeBranchFree(q), CubicSpline<double>::Shape(q)) << q;
    EXPECT_FLOAT_EQ(CubicSpline<float>::ShapeBranchFree(float(q)), CubicSpline<float>::Shape(float(q))) << q;
  }
}

TEST(CubicSpline, GradientMatchesFiniteDifferenceAndIsAntisymmetric) {
  const CubicSpline<double> k(0.7);
  const Vec3d points[] = {{0.1, 0.2, -0.3}, {0.5, 0.4, 0.2}, {-0.9, 0.3, 0.6}, {0.0, 0.0, 1.2}};
  for (const Vec3d& r : points) {
    const Vec3d g = k.Gradient(r);
    const double eps = 1e-6;
    for (int a = 0; a < 3; ++a) {
      Vec3d rp = r, rm = r;
      rp[a] += eps;
      rm[a] -= eps;
      const double fd = (k.W(rp) - k.W(rm)) / (2 * eps);
      EXPECT_NEAR(g[a], fd, 1e-6 * std::max(1.0, std::fabs(fd)));
    }
    const Vec3d gm = k.Gradient(-r);
    EXPECT_NEAR(gm.x, -g.x, 1e-15);
    EXPECT_LE(Dot(r, g), 0.0);  // points towards the other particle
  }
  EXPECT_EQ(k.Gradient(Vec3d(0, 0, 0)), Vec3d(0, 0, 0));
}

// On a cubic lattice with h = spacing the volume-weighted kernel sum is 1 (0.99997) and the
// gradient sum vanishes (spec §1, T3).
TEST(CubicSpline, LatticeSumsWithHEqualSpacing) {
  const double dp = 0.02;
  const CubicSpline<double> k(dp);
  double sum = 0;
  Vec3d grad{0, 0, 0};
  int neighbours = 0;
  for (int i = -3; i <= 3; ++i)
    for (int j = -3; j <= 3; ++j)
      for (int l = -3; l <= 3; ++l) {
        const Vec3d r{-i * dp, -j * dp, -l * dp};
        sum += dp * dp * dp * k.W(r);
        grad += k.Gradient(r) * (dp * dp * dp);
        if (Norm(r) < 2 * dp && (i || j || l)) ++neighbours;
      }
  EXPECT_NEAR(sum, 1.0, 1e-3);
  EXPECT_NEAR(sum, 0.99997, 1e-4);
  EXPECT_EQ(neighbours, 26);
  EXPECT_NEAR(Norm(grad), 0.0, 1e-12);
}

TEST(CubicSpline, FloatMatchesDouble) {
  const CubicSpline<float> kf(0.02f);
  const CubicSpline<double> kd(0.02);
  for (double r = 0; r < 0.04; r += 0.001) EXPECT_NEAR(kf.W(float(r)) / kd.W(r + 1e-30), 1.0, 1e-5) << r;
}

}  // namespace
}  // namespace rime
