// Akinci boundary volumes (spec §3, T5): kernel against brute force, plane lattice values and the
// sampling-independent wall density.
#include <gtest/gtest.h>

#include <random>

#include "rime/boundary/sampler.h"
#include "rime/boundary/shapes.h"
#include "rime/boundary/volume_kernels.h"
#include "rime/boundary/volumes.h"
#include "rime/core/kernel.h"
#include "rime/exec/parallel.h"
#include "rime/neighbors/grid.h"

namespace rime::boundary {
namespace {

template <class T>
void CompareWithBruteForce() {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> jitter(-0.3, 0.3);
  const double h = 0.02;
  // A sampled sphere, jittered so that neighbour counts vary, plus an isolated particle.
  SampleOptions options;
  options.spacing = 0.5 * h;
  const SurfaceSamples s = SampleSurface(MakeSphere(0.1, options.spacing), options);
  std::vector<Vec3<T>> points;
  for (const Vec3f& p : s.positions)
    points.push_back(
        Vec3<T>(T(p.x + jitter(rng) * options.spacing), T(p.y + jitter(rng) * options.spacing), T(p.z + jitter(rng) * options.spacing)));
  points.push_back(Vec3<T>(T(5), T(5), T(5)));
  const std::vector<T> fast = ComputeBoundaryVolumes<T>(exec::Device::Cpu(), points, T(h));
  ASSERT_EQ(fast.size(), points.size());
  const CubicSpline<double> kernel(h);
  for (std::size_t b = 0; b < points.size(); b += 3) {
    double sum = kernel.W0();
    for (std::size_t k = 0; k < points.size(); ++k)
      if (k != b) sum += kernel.W(Norm(Vec3d(points[b]) - Vec3d(points[k])));
    EXPECT_NEAR(double(fast[b]), 1.0 / sum, 1e-5 / sum) << "particle " << b;
  }
  EXPECT_NEAR(double(fast.back()), 1.0 / kernel.W0(), 1e-6 / kernel.W0());  // alone: 1/W0 = pi h^3
}

TEST(BoundaryVolumes, KernelMatchesBruteForceFloat) { CompareWithBruteForce<float>(); }
TEST(BoundaryVolumes, KernelMatchesBruteForceDouble) { CompareWithBruteForce<double>(); }

// The per-particle kernel (the GPU's, and the simulation's partial update near new ice) and the
// CPU's cell-by-cell SIMD path agree exactly, so a partial update never disagrees with a full one.
template <class T>
void ExpectPerParticleKernelAgrees() {
  SampleOptions options;
  options.spacing = 0.01;
  const SurfaceSamples s = SampleSurface(MakeTorus(0.2, 0.05, options.spacing), options);
  std::vector<Vec3<T>> points(s.positions.begin(), s.positions.end());
  for (std::size_t i = 0; i < points.size(); i += 97) points.push_back(points[i]);  // coincident pairs
  const exec::Device cpu = exec::Device::Cpu();
  const CubicSpline<T> kernel(T(0.02));
  neighbors::UniformGrid<T> grid(cpu);
  grid.Build(points.data(), Index(points.size()), kernel.SupportRadius());
  std::vector<T> per_particle(points.size());
  exec::ParallelFor(cpu, Index(points.size()), kernels::BoundaryVolume<T>{grid.view(), kernel, per_particle.data()});
  const std::vector<T> whole = ComputeBoundaryVolumes<T>(cpu, points, T(0.02));
  for (std::size_t i = 0; i < points.size(); ++i) ASSERT_EQ(per_particle[i], whole[i]) << i;
}

TEST(BoundaryVolumes, PerParticleKernelAndCpuPathAgreeFloat) { ExpectPerParticleKernelAgrees<float>(); }
TEST(BoundaryVolumes, PerParticleKernelAndCpuPathAgreeDouble) { ExpectPerParticleKernelAgrees<double>(); }

TEST(BoundaryVolumes, EmptyInput) { EXPECT_TRUE(ComputeBoundaryVolumes<float>(exec::Device::Cpu(), std::vector<Vec3f>{}, 0.1f).empty()); }

// Spec §3 / T5: a plane sampled at d_b in {1, 0.75, 0.5} d_p (h = d_p) gives interior volumes
// {1.427, 0.803, 0.357} d_p^3, and a fluid particle of a half-space lattice at z0 = d_p above it
// has density 1.0645 rho0 for all three spacings.
TEST(BoundaryVolumes, PlaneLatticeValuesAndSamplingIndependence) {
  const double dp = 0.02, h = dp;
  const CubicSpline<double> kernel(h);
  const double ratios[3] = {1.0, 0.75, 0.5};
  const double spec_volume[3] = {1.427, 0.803, 0.357};
  double densities[3];
  for (int r = 0; r < 3; ++r) {
    SCOPED_TRACE(::testing::Message() << "d_b = " << ratios[r] << " d_p");
    const double db = ratios[r] * dp;
    const double side = 30 * dp;  // a whole number of d_b for all three ratios
    SampleOptions options;
    options.spacing = db;
    const SurfaceSamples s = SampleSurface(MakePlane(side, side, db), options);
    const std::size_t per_side = std::size_t(std::llround(side / db)) + 1;
    ASSERT_EQ(s.size(), per_side * per_side) << "the plane must sample as a square lattice";
    const std::vector<float> volume = ComputeBoundaryVolumes<float>(exec::Device::Cpu(), s.positions, float(h));

    // Interior particle (the one at the origin) against the spec value and against the infinite
    // lattice sum evaluated directly.
    std::size_t center = 0;
    for (std::size_t i = 0; i < s.size(); ++i)
      if (SquaredNorm(s.positions[i]) < SquaredNorm(s.positions[center])) center = i;
    ASSERT_LT(Norm(s.positions[center]), 1e-6);
    double lattice_sum = 0;
    for (int i = -10; i <= 10; ++i)
      for (int j = -10; j <= 10; ++j) lattice_sum += kernel.W(db * std::hypot(double(i), double(j)));
    const double lattice_volume = 1.0 / lattice_sum;  // includes W0 at i = j = 0
    EXPECT_NEAR(volume[center], lattice_volume, 1e-5 * lattice_volume);
    EXPECT_NEAR(volume[center] / (dp * dp * dp), spec_volume[r], 0.0015);

    // Density of a fluid particle at z0 = d_p above the centre, in a half-space fluid lattice.
    const Vec3d x(0, 0, dp);
    double fluid = kernel.W0();  // itself
    for (int i = -3; i <= 3; ++i)
      for (int j = -3; j <= 3; ++j)
        for (int k = 0; k <= 3; ++k)
          if (i || j || k) fluid += kernel.W(Norm(Vec3d(i * dp, j * dp, k * dp)));
    double wall = 0;
    for (std::size_t b = 0; b < s.size(); ++b) wall += double(volume[b]) * kernel.W(Norm(x - Vec3d(s.positions[b])));
    densities[r] = fluid * dp * dp * dp + wall;  // rho / rho0 (m = rho0 d_p^3, Psi = rho0 V_b)
    EXPECT_NEAR(densities[r], 1.0645, 0.01 * 1.0645);
    std::printf("d_b = %.2f d_p: V_b = %.4f d_p^3 (spec %.3f), wall density at z0 = d_p: %.5f rho0\n", ratios[r],
                volume[center] / (dp * dp * dp), spec_volume[r], densities[r]);
  }
  const double lo = std::min({densities[0], densities[1], densities[2]});
  const double hi = std::max({densities[0], densities[1], densities[2]});
  EXPECT_LT((hi - lo) / lo, 0.01) << "density depends on the boundary sampling";
}

}  // namespace
}  // namespace rime::boundary
