#include <gtest/gtest.h>

#include <random>

#include "rime/core/math.h"

namespace rime {
namespace {

Mat3<double> RandomRotation(std::mt19937& rng) {
  std::normal_distribution<double> n;
  Vec3d a{n(rng), n(rng), n(rng)}, b{n(rng), n(rng), n(rng)};
  a /= Norm(a);
  b -= a * Dot(a, b);
  b /= Norm(b);
  return Mat3<double>::FromColumns(a, b, Cross(a, b));
}

TEST(SymmetricEigen, ReconstructsRandomAndDegenerateMatrices) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0, 2);
  const Vec3d cases[] = {{u(rng), u(rng), u(rng)}, {1, 1, 1}, {2, 0, 0}, {1, 1, 0}, {3, 1e-9, 1e-9}, {0, 0, 0}};
  for (const Vec3d& d : cases) {
    const Mat3<double> r = RandomRotation(rng);
    Mat3<double> diag;
    diag.m[0][0] = d.x, diag.m[1][1] = d.y, diag.m[2][2] = d.z;
    const Mat3<double> a = r * diag * Transpose(r);
    Vec3d values;
    Mat3<double> vectors;
    SymmetricEigen(a, values, vectors);
    EXPECT_GE(values.x, values.y);
    EXPECT_GE(values.y, values.z);
    Mat3<double> vd = vectors;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) vd.m[i][j] *= values[j];
    const Mat3<double> back = vd * Transpose(vectors);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) EXPECT_NEAR(back.m[i][j], a.m[i][j], 1e-12);
    const Mat3<double> vtv = Transpose(vectors) * vectors;  // orthonormal
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) EXPECT_NEAR(vtv.m[i][j], i == j ? 1.0 : 0.0, 1e-12);
  }
}

TEST(SymmetricEigen, FloatPrecision) {
  Mat3<float> a;
  a.m[0][0] = 2, a.m[1][1] = 1, a.m[2][2] = 0.5f, a.m[0][1] = a.m[1][0] = 0.3f;
  Vec3f values;
  Mat3<float> vectors;
  SymmetricEigen(a, values, vectors);
  const Vec3f v0 = vectors.Column(0);
  const Vec3f av = a * v0;
  EXPECT_NEAR(Norm(av - v0 * values.x), 0.0f, 1e-5f);
}

// Float: the sweeps stop at rounding level, and the result must still be float-accurate, for
// random, repeated and nearly repeated eigenvalues (anisotropy matrices are often nearly isotropic).
TEST(SymmetricEigen, FloatReconstructsToRoundingLevel) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0.1, 2);
  for (int trial = 0; trial < 200; ++trial) {
    const double base = u(rng);
    const Vec3d d = trial % 3 == 0   ? Vec3d{u(rng), u(rng), u(rng)}
                    : trial % 3 == 1 ? Vec3d{base, base, u(rng)}
                                     : Vec3d{base, base * (1 + 1e-4), base * (1 - 1e-4)};
    const Mat3<double> r = RandomRotation(rng);
    Mat3<double> diag;
    diag.m[0][0] = d.x, diag.m[1][1] = d.y, diag.m[2][2] = d.z;
    const Mat3<double> ad = r * diag * Transpose(r);
    Mat3<float> a;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) a.m[i][j] = float(ad.m[i][j]);
    Vec3f values;
    Mat3<float> vectors;
    SymmetricEigen(a, values, vectors);
    Mat3<float> vd = vectors;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) vd.m[i][j] *= values[j];
    const Mat3<float> back = vd * Transpose(vectors), vtv = Transpose(vectors) * vectors;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        EXPECT_NEAR(back.m[i][j], a.m[i][j], 2e-6f * 2) << "trial " << trial;
        EXPECT_NEAR(vtv.m[i][j], i == j ? 1.0f : 0.0f, 2e-6f) << "trial " << trial;
      }
  }
}

TEST(SolveSpd, MatchesDirectProduct) {
  Mat3<double> a;
  const double vals[3][3] = {{4, 1, 0.5}, {1, 3, 0.2}, {0.5, 0.2, 2}};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) a.m[i][j] = vals[i][j];
  const Vec3d x{0.3, -1.2, 2.5};
  const Vec3d solved = SolveSpd(a, a * x);
  EXPECT_NEAR(Norm(solved - x), 0.0, 1e-13);
  EXPECT_NEAR(Determinant(Mat3<double>::Identity()), 1.0, 0);
}

TEST(Rotation, EulerXYZAndAxisAngle) {
  const Mat3<double> quarter_x = RotationXYZDegrees(Vec3d(90, 0, 0));
  EXPECT_NEAR(Norm(quarter_x * Vec3d(0, 1, 0) - Vec3d(0, 0, 1)), 0.0, 1e-15) << "y-up becomes z-up";
  const Mat3<double> r = RotationXYZDegrees(Vec3d(30, -45, 120));
  const Mat3<double> expected = AxisAngleRotation(Vec3d(0, 0, 2), 120 * M_PI / 180) * AxisAngleRotation(Vec3d(0, 3, 0), -45 * M_PI / 180) *
                                AxisAngleRotation(Vec3d(4, 0, 0), 30 * M_PI / 180);
  const Mat3<double> rtr = Transpose(r) * r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      EXPECT_NEAR(r.m[i][j], expected.m[i][j], 1e-15);
      EXPECT_NEAR(rtr.m[i][j], i == j ? 1.0 : 0.0, 1e-15);
    }
  EXPECT_NEAR(Determinant(r), 1.0, 1e-15);
}

}  // namespace
}  // namespace rime
