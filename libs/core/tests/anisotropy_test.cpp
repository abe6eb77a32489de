// Yu & Turk anisotropy and the anisotropic kernel W_A (spec §8, invariants T4 and T25).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "rime/core/anisotropy.h"

namespace rime {
namespace {

using anisotropy::Params;
using Mat3d = Mat3<double>;

Mat3d RandomRotation(std::mt19937& rng) {
  std::normal_distribution<double> n(0, 1);
  // Normalised random quaternion -> rotation matrix.
  double q[4] = {n(rng), n(rng), n(rng), n(rng)};
  const double len = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  for (double& v : q) v /= len;
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  Mat3d r;
  r.m[0][0] = 1 - 2 * (y * y + z * z), r.m[0][1] = 2 * (x * y - w * z), r.m[0][2] = 2 * (x * z + w * y);
  r.m[1][0] = 2 * (x * y + w * z), r.m[1][1] = 1 - 2 * (x * x + z * z), r.m[1][2] = 2 * (y * z - w * x);
  r.m[2][0] = 2 * (x * z - w * y), r.m[2][1] = 2 * (y * z + w * x), r.m[2][2] = 1 - 2 * (x * x + y * y);
  return r;
}

// PCA of a set of neighbour offsets with W weights at smoothing length h (self included).
anisotropy::Anisotropy<double> Pca(const std::vector<Vec3d>& offsets, double h, const Params<double>& p = {}) {
  const CubicSpline<double> kernel(h);
  anisotropy::CovarianceAccumulator<double> acc;
  acc.AddSelf(kernel.W0());
  for (const Vec3d& r : offsets)
    if (Norm(r) < 2 * h) acc.Add(r, kernel.W(r));
  return anisotropy::Compute(acc.Covariance(p.center_on_particle), acc.neighbors, h, p);
}

std::vector<Vec3d> Lattice(double spacing, int half, bool planar = false, bool linear = false) {
  std::vector<Vec3d> out;
  for (int k = planar || linear ? 0 : -half; k <= (planar || linear ? 0 : half); ++k)
    for (int j = linear ? 0 : -half; j <= (linear ? 0 : half); ++j)
      for (int i = -half; i <= half; ++i)
        if (i || j || k) out.push_back(Vec3d(i, j, k) * spacing);
  return out;
}

void ExpectMatrixNear(const Mat3d& a, const Mat3d& b, double tol) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(a.m[i][j], b.m[i][j], tol) << "entry " << i << j;
}

// T4: ∫ W_A dV = 1 for random SPD G, by Monte Carlo over the ellipsoidal support's bounding box.
TEST(Anisotropy, KernelIntegratesToOneForRandomG) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> stretch(0.2, 1.0), unit(-1, 1);
  for (int trial = 0; trial < 4; ++trial) {
    anisotropy::Anisotropy<double> a;
    a.rotation = RandomRotation(rng);
    a.stretch = {stretch(rng), stretch(rng), stretch(rng)};
    const double h = 0.03;
    const Mat3d G = a.G(h);
    // Support: ‖G r‖ < 2 ⇒ ‖r‖ < 2 h max(s).
    const double extent = 2 * h * std::max({a.stretch.x, a.stretch.y, a.stretch.z});
    const int samples = 400000;
    double sum = 0;
    for (int s = 0; s < samples; ++s) sum += anisotropy::Kernel(Vec3d(unit(rng), unit(rng), unit(rng)) * extent, G);
    const double integral = sum / samples * std::pow(2 * extent, 3);
    EXPECT_NEAR(integral, 1.0, 0.02) << "stretches " << a.stretch.x << " " << a.stretch.y << " " << a.stretch.z;
  }
}

// T4: exactly, by quadrature in the eigen-frame: ∫ W_A = det(G) ∫ σ3 B(‖G r‖) dr = ∫ σ3 B(‖u‖) du.
TEST(Anisotropy, KernelEqualsIsotropicKernelForGIdentityOverH) {
  const double h = 0.02;
  const CubicSpline<double> kernel(h);
  const Mat3d G = Mat3d::Identity() * (1 / h);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> unit(-2.2 * h, 2.2 * h);
  for (int s = 0; s < 1000; ++s) {
    const Vec3d r(unit(rng), unit(rng), unit(rng));
    EXPECT_NEAR(anisotropy::Kernel(r, G), kernel.W(r), 1e-9 * kernel.W0());
  }
}

TEST(Anisotropy, IdealLatticeGivesIsotropicG) {
  const double h = 0.02;  // h = d_p
  const auto a = Pca(Lattice(h, 3), h);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(a.stretch[k], 1.0, 2e-3);
  ExpectMatrixNear(a.G(h), Mat3d::Identity() * (1 / h), 2e-3 / h);
}

TEST(Anisotropy, StretchesFollowTheMeasuredSpread) {
  // A lattice squeezed along a rotated axis: the smallest stretch lies along that axis.
  std::mt19937 rng(11);
  const Mat3d rot = RandomRotation(rng);
  const double h = 1.0;
  std::vector<Vec3d> pts;
  for (const Vec3d& p : Lattice(h, 3)) pts.push_back(rot * Vec3d(p.x, p.y, 0.5 * p.z));
  Params<double> p;
  p.s_max = 10;  // a denser neighbourhood spreads more than the lattice: keep s_1 unclamped
  const auto a = Pca(pts, h, p);
  const Vec3d axis = rot.Column(2), smallest = a.rotation.Column(2);
  EXPECT_NEAR(std::fabs(Dot(axis, smallest)), 1.0, 1e-6);
  EXPECT_LT(a.stretch.z, a.stretch.x);
  EXPECT_GE(a.stretch.x, a.stretch.y);
  EXPECT_GE(a.stretch.y, a.stretch.z);
}

// T25: isolated or nearly isolated particles fall back to k_n.
TEST(Anisotropy, IsolatedParticleUsesKn) {
  const double h = 0.05;
  Params<double> p;
  for (const std::vector<Vec3d>& offsets : {std::vector<Vec3d>{}, std::vector<Vec3d>{{0.01, 0, 0}, {0, 0.02, 0}}}) {
    const auto a = Pca(offsets, h, p);
    ExpectMatrixNear(a.G(h), Mat3d::Identity() * (1 / (p.k_n * h)), 1e-9 / h);
  }
  // Duplicated positions: enough neighbours, zero spread -> isolated, not a division by zero.
  const auto dup = Pca(std::vector<Vec3d>(10, Vec3d(0, 0, 0)), h, p);
  ExpectMatrixNear(dup.G(h), Mat3d::Identity() * (1 / (p.k_n * h)), 1e-9 / h);
}

// T25: collinear and coplanar neighbourhoods give finite G with s_k >= s_1/k_r.
TEST(Anisotropy, DegenerateNeighbourhoodsStayFinite) {
  const double h = 0.02;
  std::mt19937 rng(5);
  for (bool planar : {false, true}) {
    const Mat3d rot = RandomRotation(rng);
    std::vector<Vec3d> pts;
    for (const Vec3d& p : Lattice(0.5 * h, 3, planar, !planar)) pts.push_back(rot * p);
    Params<double> p;
    p.s_min = 1e-6;  // so that the k_r floor, not s_min, is what keeps G invertible
    const auto a = Pca(pts, h, p);
    for (int k = 0; k < 3; ++k) {
      EXPECT_GE(a.stretch[k], a.stretch.x / p.k_r * (1 - 1e-12)) << (planar ? "coplanar" : "collinear") << " k=" << k;
      EXPECT_GT(a.stretch[k], 0);
    }
    const Mat3d G = a.G(h);
    EXPECT_TRUE(std::isfinite(Determinant(G)));
    EXPECT_GT(Determinant(G), 0);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) EXPECT_TRUE(std::isfinite(G.m[i][j]));
  }
}

TEST(Anisotropy, ClampsToStretchRange) {
  Params<double> p;
  Mat3d huge = Mat3d::Identity() * 100.0;
  EXPECT_EQ(anisotropy::Compute(huge, 20, 1.0, p).stretch.x, p.s_max);
  Mat3d tiny = Mat3d::Identity() * 1e-3;
  EXPECT_EQ(anisotropy::Compute(tiny, 20, 1.0, p).stretch.z, p.s_min);
}

TEST(Anisotropy, ParticleCenteredCovarianceDiffersFromMeanCentered) {
  anisotropy::CovarianceAccumulator<double> acc;
  acc.Add({1, 0, 0}, 1);
  acc.Add({1, 0, 0}, 1);
  EXPECT_DOUBLE_EQ(acc.Covariance(false).m[0][0], 0.0);
  EXPECT_DOUBLE_EQ(acc.Covariance(true).m[0][0], 1.0);
  EXPECT_DOUBLE_EQ(acc.MeanOffset().x, 1.0);
}

TEST(Anisotropy, ComponentsRoundTrip) {
  std::mt19937 rng(2);
  anisotropy::Anisotropy<double> a;
  a.rotation = RandomRotation(rng);
  a.stretch = {0.9, 0.5, 0.25};
  const Mat3d d = a.D();
  double c[6];
  anisotropy::ToComponents(d, c);
  ExpectMatrixNear(anisotropy::FromComponents(c), d, 0);
  // D's eigenvalues are 1/s.
  Vec3d values;
  Mat3d vectors;
  SymmetricEigen(d, values, vectors);
  EXPECT_NEAR(values.x, 4.0, 1e-12);
  EXPECT_NEAR(values.z, 1 / 0.9, 1e-12);
}

}  // namespace
}  // namespace rime
