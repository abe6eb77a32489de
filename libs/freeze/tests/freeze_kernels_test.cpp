// The freezing kernels in isolation against the spec's invariants (§13 T15–T19).
#include <gtest/gtest.h>

#include <random>

#include "rime/exec/memory.h"
#include "rime/freeze/kernels.h"
#include "rime/neighbors/grid.h"

namespace rime::freeze {
namespace {

using exec::DeviceArray;
constexpr double kDp = 0.02, kH = 0.02;

FreezeParams<double> Params() {
  FreezeParams<double> p{};
  p.h = kH;
  p.mass = 1000 * kDp * kDp * kDp;
  p.film_max = p.mass;
  p.alpha_solid = p.alpha_ice = 1;
  p.dt_ref = 0.006;
  p.glaze_threshold = 0.004;
  p.icicle_threshold = 1e-4;
  p.growth_sign = 1;
  return p;
}

// A plane of boundary particles at spacing 0.5 dp with Akinci-like volumes.
std::vector<Vec3d> Plane(int n) {
  std::vector<Vec3d> x;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) x.push_back({i * 0.5 * kDp, j * 0.5 * kDp, 0});
  return x;
}

TEST(FreezeKernels, FilmDiffusionConservesAndKeepsBounds) {
  const exec::Device cpu = exec::Device::Cpu();
  const auto x = Plane(30);
  const Index nb = Index(x.size());
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<double> film(nb, 0.0), volume(nb);
  for (Index b = 0; b < nb; ++b) {
    volume[b] = 0.357 * kDp * kDp * kDp * (0.8 + 0.4 * u(rng));  // uneven volumes: symmetry must still hold
    if (x[b].x < 0.15 && x[b].y < 0.2) film[b] = u(rng);
  }
  DeviceArray<Vec3d> dx(cpu, x);
  DeviceArray<double> dfilm(cpu, film), dvol(cpu, volume), lap(cpu, nb), lambda(cpu, nb);
  DeviceArray<std::uint32_t> touched(cpu, nb);
  std::vector<std::uint32_t> all(nb);
  for (Index b = 0; b < nb; ++b) all[b] = std::uint32_t(b);
  DeviceArray<std::uint32_t> list(cpu, all);
  neighbors::UniformGrid<double> grid(cpu);
  grid.Build(dx.data(), nb, 2 * kH);
  neighbors::NeighborList near(cpu);
  grid.Query(dx.data(), nb, 2 * kH, false, near);
  DeviceArray<std::uint32_t> row_begin(cpu, nb), row_length(cpu, nb), pool(cpu, near.pairs());
  DeviceArray<double> x_grad(cpu, near.pairs()), denominator(cpu, near.pairs());
  const CubicSpline<double> kernel(kH);
  exec::cpu::ParallelFor(nb, kernels::StoreRows<double>{.list = list.data(),
                                                        .offsets = near.offsets.data(),
                                                        .indices = near.indices.data(),
                                                        .base = 0,
                                                        .x = dx.data(),
                                                        .kernel = kernel,
                                                        .epsilon = 0.01,
                                                        .begin = row_begin.data(),
                                                        .length = row_length.data(),
                                                        .pool = pool.data(),
                                                        .x_grad = x_grad.data(),
                                                        .denominator = denominator.data()});
  const kernels::NeighborRows<double> rows{.begin = row_begin.data(),
                                           .length = row_length.data(),
                                           .pool = pool.data(),
                                           .x_grad = x_grad.data(),
                                           .denominator = denominator.data()};
  const double lo = *std::min_element(film.begin(), film.end()), hi = *std::max_element(film.begin(), film.end());
  double before = 0;
  for (double f : film) before += f;
  const double diffusivity = 0.15 * kDp * kDp / 0.006, dt = 0.006;
  for (int step = 0; step < 20; ++step) {
    exec::cpu::ParallelFor(nb, kernels::FilmLaplacian<double>{.list = list.data(),
                                                              .rows = rows,
                                                              .volume = dvol.data(),
                                                              .film = dfilm.data(),
                                                              .laplacian = lap.data(),
                                                              .lambda = lambda.data()});
    const double lambda_max = *std::max_element(lambda.data(), lambda.data() + nb);
    ASSERT_LE(dt * diffusivity * lambda_max, 1.0) << "default diffusion must need no sub-stepping at dt_ref (spec §9.3)";
    exec::cpu::ParallelFor(nb,
                           kernels::ApplyFilmDiffusion<double>{list.data(), lap.data(), dt * diffusivity, dfilm.data(), touched.data()});
  }
  const auto after = dfilm.ToHost();
  double sum = 0;
  for (double f : after) {
    sum += f;
    EXPECT_GE(f, lo - 1e-15);
    EXPECT_LE(f, hi + 1e-15);
  }
  EXPECT_NEAR(sum, before, 1e-12 * before) << "diffusion must conserve the total film (T16)";
  int spread = 0;  // dry particles that received film: diffusion did something
  for (Index b = 0; b < nb; ++b) spread += film[b] == 0 && after[b] > 0;
  EXPECT_GT(spread, 10);
}

TEST(FreezeKernels, TransferIsBoundedAndMonotone) {
  const exec::Device cpu = exec::Device::Cpu();
  // One boundary particle under a dense blob of fluid (α = 1: the fastest possible transfer).
  std::vector<Vec3d> fluid;
  for (int i = -2; i <= 2; ++i)
    for (int j = -2; j <= 2; ++j)
      for (int k = 0; k <= 2; ++k) fluid.push_back(Vec3d(i, j, k) * (0.5 * kDp));  // 8x denser than rest
  const Index n = Index(fluid.size());
  DeviceArray<Vec3d> fx(cpu, fluid), fv(cpu, std::vector<Vec3d>(n, Vec3d(1, 0, 0)));
  std::vector<Sym6<double>> d(n);
  for (auto& s : d) s = {{1, 1, 1, 0, 0, 0}};
  DeviceArray<Sym6<double>> dd(cpu, d);
  DeviceArray<Vec3d> bx(cpu, std::vector<Vec3d>{{0, 0, -0.3 * kDp}});
  DeviceArray<double> bvol(cpu, std::vector<double>{2.0 * kDp * kDp * kDp}), film(cpu, std::vector<double>{0.0});
  DeviceArray<std::uint8_t> phase(cpu, std::vector<std::uint8_t>{1}), valid(cpu, 1);
  DeviceArray<Vec3d> growth(cpu, 1);
  DeviceArray<std::uint32_t> touched(cpu, 1);
  std::vector<std::uint32_t> offsets{0, std::uint32_t(n)}, index(n);
  for (Index j = 0; j < n; ++j) index[j] = std::uint32_t(j);
  DeviceArray<std::uint32_t> doff(cpu, offsets), dind(cpu, index), active(cpu, std::vector<std::uint32_t>{0});
  const kernels::FilmAndGrowth<double> k{
      active.data(),           doff.data(), dind.data(), bx.data(),   bvol.data(),   phase.data(), fx.data(),     fv.data(), dd.data(),
      CubicSpline<double>(kH), Params(),    0.006,       film.data(), growth.data(), valid.data(), touched.data()};
  double last = 0;
  for (int step = 0; step < 10; ++step) {
    touched.SetZero();
    k(0);
    EXPECT_EQ(touched.ToHost()[0], film.ToHost()[0] != last ? 1u : 0u) << "a changed film is reported to the diffusion's caches";
    const double f = film.ToHost()[0];
    EXPECT_GE(f, last) << "transfer alone never lowers the film (T17)";
    EXPECT_LE(f, 1.0) << "film above Γ_max (T15)";
    last = f;
  }
  EXPECT_EQ(last, 1.0) << "saturated contact fills the film";
  // Uniform flow past an isolated particle with isotropic G: the growth direction is the flow (T18).
  const Vec3d g = growth.ToHost()[0];
  EXPECT_EQ(valid.ToHost()[0], 1);
  EXPECT_NEAR(std::acos(std::min(1.0, g.x / Norm(g))), 0.0, 1e-6);
}

// gravity_growth tilts the growth direction of ice (not of solids) towards gravity: with the flow
// sideways, water below an ice particle freezes onto it and water above it does not.
TEST(FreezeKernels, GravityGrowthFavoursWaterBelowIce) {
  FreezeParams<double> p = Params();
  p.growth_sign = -1;
  p.fr_clamp = true;
  p.gravity_dir = {0, 0, -1};
  const Vec3d sideways_flow{1, 0, 0};
  const Vec3d water_below{0, 0, 0.01}, water_above{0, 0, -0.01};  // x_b − x_j
  EXPECT_EQ(kernels::FreezingFraction(sideways_flow, true, water_below, p, true), 0.0) << "w = 0 is Eq. 26 alone";
  p.gravity_growth = 3;
  const double below = kernels::FreezingFraction(sideways_flow, true, water_below, p, true);
  EXPECT_NEAR(below, 3 / std::sqrt(10.0), 1e-12) << "direction ĝv + 3ĝ, normalised";
  EXPECT_EQ(kernels::FreezingFraction(sideways_flow, true, water_above, p, true), 0.0);
  EXPECT_EQ(kernels::FreezingFraction(sideways_flow, true, water_below, p, false), 0.0) << "glaze on solids ignores gravity";
  EXPECT_EQ(kernels::FreezingFraction(sideways_flow, false, water_below, p, true), 1.0) << "no recorded flow: straight down";
  p.growth_sign = 1;  // the printed Eq. 31 grows against the direction, so the tilt flips with it
  EXPECT_NEAR(kernels::FreezingFraction(-1.0 * sideways_flow, true, water_below, p, true), below, 1e-12);
}

// tip_growth raises fr on ice to a power: water straight below the tip keeps fr = 1, water beside
// an icicle (60° off the growth direction) drops from 1/2 to 1/2^n; glaze on solids is unchanged.
TEST(FreezeKernels, TipGrowthFavoursWaterBelowTheTip) {
  FreezeParams<double> p = Params();
  p.growth_sign = -1;
  p.fr_clamp = true;
  const Vec3d downward_flow{0, 0, -1};
  const Vec3d below_tip{0, 0, 0.01};                                            // x_b − x_j: water under b
  const Vec3d beside{0.01 * std::sin(M_PI / 3), 0, 0.01 * std::cos(M_PI / 3)};  // 60° off the vertical
  EXPECT_NEAR(kernels::FreezingFraction(downward_flow, true, beside, p, true), 0.5, 1e-12) << "n = 1 is Eq. 31";
  p.tip_growth = 4;
  EXPECT_NEAR(kernels::FreezingFraction(downward_flow, true, below_tip, p, true), 1.0, 1e-12);
  EXPECT_NEAR(kernels::FreezingFraction(downward_flow, true, beside, p, true), 1.0 / 16, 1e-12);
  EXPECT_NEAR(kernels::FreezingFraction(downward_flow, true, beside, p, false), 0.5, 1e-12) << "glaze on solids ignores tip_growth";
}

TEST(FreezeKernels, FreezingFractionAndEnergy) {
  const FreezeParams<double> p = Params();
  std::mt19937 rng(5);
  std::normal_distribution<double> n;
  for (int t = 0; t < 1000; ++t) {
    const Vec3d g{n(rng), n(rng), n(rng)}, r{n(rng), n(rng), n(rng)};
    const double fr = kernels::FreezingFraction(g, true, r * 0.01, p);
    EXPECT_GE(fr, 0.0);
    EXPECT_LE(fr, 1.0);
  }
  EXPECT_EQ(kernels::FreezingFraction(Vec3d(1, 0, 0), false, Vec3d(0.01, 0, 0), p), 0.5);
  EXPECT_EQ(kernels::FreezingFraction(Vec3d(1, 0, 0), true, Vec3d(1e-12, 0, 0), p), 0.5);
  // Upstream fluid (x_b − x_j parallel to the flow) gives fr = 1 (spec §9.5).
  EXPECT_DOUBLE_EQ(kernels::FreezingFraction(Vec3d(2, 0, 0), true, Vec3d(0.01, 0, 0), p), 1.0);
  FreezeParams<double> flipped = p;
  flipped.growth_sign = -1;
  EXPECT_DOUBLE_EQ(kernels::FreezingFraction(Vec3d(2, 0, 0), true, Vec3d(0.01, 0, 0), flipped), 0.0);

  // ce = 0 without film or beyond the support; ce >= 0 otherwise (T19), via the phase decision.
  const exec::Device cpu = exec::Device::Cpu();
  const std::vector<Vec3d> fluid{{0, 0, 0}};
  DeviceArray<Vec3d> fx(cpu, fluid);
  DeviceArray<Sym6<double>> dd(cpu, std::vector<Sym6<double>>{{{1, 1, 1, 0, 0, 0}}});
  const std::vector<Vec3d> boundary{{0.5 * kDp, 0, 0}, {0.041, 0, 0}, {0, 0.5 * kDp, 0}};
  DeviceArray<Vec3d> bx(cpu, boundary), growth(cpu, 3);
  DeviceArray<std::uint8_t> phase(cpu, std::vector<std::uint8_t>{1, 1, 2}), valid(cpu, 3);
  DeviceArray<std::uint32_t> off(cpu, std::vector<std::uint32_t>{0, 3}), ind(cpu, std::vector<std::uint32_t>{0, 1, 2});
  DeviceArray<std::uint32_t> decision(cpu, 1), trigger(cpu, 1);
  DeviceArray<double> es(cpu, 1), ei(cpu, 1);
  for (const auto& films : {std::vector<double>{0, 0, 0}, std::vector<double>{0, 1, 0}, std::vector<double>{1, 1, 1}}) {
    DeviceArray<double> film(cpu, films);
    kernels::PhaseDecision<double>{.fb_offsets = off.data(),
                                   .fb_index = ind.data(),
                                   .x = fx.data(),
                                   .d = dd.data(),
                                   .boundary_x = bx.data(),
                                   .boundary_phase = phase.data(),
                                   .film = film.data(),
                                   .growth = growth.data(),
                                   .growth_valid = valid.data(),
                                   .kernel = CubicSpline<double>(kH),
                                   .params = p,
                                   .decision = decision.data(),
                                   .trigger = trigger.data(),
                                   .energy_solid = es.data(),
                                   .energy_ice = ei.data()}(0);
    if (films[0] == 0 && films[2] == 0) {
      EXPECT_EQ(es.ToHost()[0], 0.0) << "no film or out of support: no energy";
      EXPECT_EQ(ei.ToHost()[0], 0.0);
      EXPECT_EQ(decision.ToHost()[0], kNotIce);
    } else {
      // fr = 0.5, isotropic: ce = B(q)/4 · 0.5 at q = 0.5 -> 0.36 > gzth: glaze, triggered by particle 0.
      EXPECT_NEAR(es.ToHost()[0], 0.5 * CubicSpline<double>::Shape(0.5) / 4, 1e-12);
      EXPECT_EQ(decision.ToHost()[0], kGlaze);
      EXPECT_EQ(trigger.ToHost()[0], 0u);
    }
  }
}

// The nucleation delay holds a candidate back until its clock reaches the delay, and a step below
// the thresholds restarts the clock.
TEST(FreezeKernels, NucleationDelayCountsUninterruptedTime) {
  exec::Device cpu = exec::Device::Cpu();
  DeviceArray<std::uint32_t> decision(cpu, 1);
  DeviceArray<double> clock(cpu, 1);
  const kernels::NucleationDelay<double> delay{.dt = 0.01, .delay = 0.03, .decision = decision.data(), .contact_time = clock.data()};
  auto step = [&](std::uint32_t candidate) {
    decision.assign(std::vector<std::uint32_t>{candidate});
    delay(0);
    return decision.ToHost()[0];
  };
  EXPECT_EQ(step(kGlaze), kNotIce);
  EXPECT_EQ(step(kGlaze), kNotIce);
  EXPECT_EQ(step(kNotIce), kNotIce);
  EXPECT_EQ(clock.ToHost()[0], 0.0) << "a step below the thresholds restarts the clock";
  EXPECT_EQ(step(kIcicle), kNotIce);
  EXPECT_EQ(step(kIcicle), kNotIce);
  EXPECT_EQ(step(kIcicle), kIcicle) << "three uninterrupted steps of 0.01 s reach the 0.03 s delay";
}

}  // namespace
}  // namespace rime::freeze
