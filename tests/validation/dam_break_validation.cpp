// Collapse of a water column against the experiment of Martin & Moyce (1952): surge-front position
// along the floor against time, both dimensionless, for the classic column of width a and height
// 2a (n² = 2) in a channel (quasi two-dimensional: the water fills the channel's depth).
//
// Reference: J. C. Martin and W. J. Moyce, "Part IV. An experimental study of the collapse of
// liquid columns on a rigid horizontal plane", Phil. Trans. R. Soc. Lond. A 244 (882), 312-324
// (1952), doi:10.1098/rsta.1952.0006. Their variables: Z = z/a (z: front distance from the back
// wall, a: initial column width), T = n t sqrt(g/a) with n² = height/width, i.e. T = t sqrt(2g/a)
// for n² = 2. The points below are their Table 2 (two-dimensional collapse, a = 2¼ in, n² = 2) as
// transcribed in the Ocellaris examples (T. Landet); PySPH's digitisation of the same case from
// their Fig. 3 (pysph/examples/db_exp_data.py) agrees within 0.05 in Z at equal T.
//
// Usage: rime_validation_dam_break [--full] [--viscosity]   (RIME_VALIDATION_FULL=1 = --full)
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "rime/exec/device.h"
#include "rime/sph/simulation.h"
#include "rime/test/validation.h"
#include "rime/test/sph_scenes.h"

namespace rime::validation {
namespace {

struct Point {
  double T, Z;
};
constexpr Point kMartinMoyce[] = {{0.41, 1.11}, {0.84, 1.22}, {1.19, 1.44}, {1.43, 1.67}, {1.63, 1.89},
                                  {1.83, 2.11}, {1.98, 2.33}, {2.20, 2.56}, {2.32, 2.78}, {2.51, 3.00},
                                  {2.65, 3.22}, {2.83, 3.44}, {2.98, 3.67}, {3.11, 3.89}, {3.33, 4.11}};
constexpr double kA = 0.05715;  // m: the experiment's a = 2¼ in (only matters with viscosity on)
constexpr double kG = 9.81;

// Front: the furthest fluid particle along x that has at least kMinNeighbors fluid particles
// within 2 d_p, so isolated spray drops ahead of the surge do not count.
constexpr int kMinNeighbors = 3;

template <class T>
double FrontX(const std::vector<Vec3<T>>& x, double dp) {
  // Uniform grid of cell 2 d_p over the cloud's bounding box; cells hold particle indices.
  Vec3d lo = Vec3d::Splat(1e300), hi = Vec3d::Splat(-1e300);
  for (const auto& p : x) lo = Min(lo, Vec3d(p)), hi = Max(hi, Vec3d(p));
  const double cell = 2 * dp;
  const int nx = int((hi.x - lo.x) / cell) + 1, ny = int((hi.y - lo.y) / cell) + 1, nz = int((hi.z - lo.z) / cell) + 1;
  std::vector<std::vector<int>> cells(std::size_t(nx) * ny * nz);
  auto index = [&](int i, int j, int k) { return (std::size_t(k) * ny + j) * nx + i; };
  auto coord = [&](double v, double l) { return int((v - l) / cell); };
  for (int i = 0; i < int(x.size()); ++i) cells[index(coord(x[i].x, lo.x), coord(x[i].y, lo.y), coord(x[i].z, lo.z))].push_back(i);
  // Candidates from the far end inwards: the first with enough neighbours is the front.
  std::vector<int> order(x.size());
  for (int i = 0; i < int(x.size()); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](int a, int b) { return x[a].x > x[b].x; });
  for (int i : order) {
    const int ci = coord(x[i].x, lo.x), cj = coord(x[i].y, lo.y), ck = coord(x[i].z, lo.z);
    int count = 0;
    for (int k = std::max(ck - 1, 0); k <= std::min(ck + 1, nz - 1); ++k)
      for (int j = std::max(cj - 1, 0); j <= std::min(cj + 1, ny - 1); ++j)
        for (int c = std::max(ci - 1, 0); c <= std::min(ci + 1, nx - 1); ++c)
          for (int n : cells[index(c, j, k)])
            if (n != i && SquaredNorm(Vec3d(x[n]) - Vec3d(x[i])) < cell * cell) ++count;
    if (count >= kMinNeighbors) return x[i].x;
  }
  return lo.x;
}

struct Sample {
  double T, Z;
};

int Run(const Options& o) {
  // Resolution: a/d_p lattice columns across the column width, ny across the channel depth.
  const int per_a = o.full ? 40 : 16;
  const int ny = o.full ? 8 : 4;
  const double dp = kA / per_a;
  const double T_end = 3.4;                       // past the last experimental point
  const double t_scale = std::sqrt(2 * kG / kA);  // T = t sqrt(2g/a) (n² = 2)

  io::Scene scene = sph::test::ColumnScene(dp, per_a, ny, 2 * per_a, 0);
  scene.fluid.precision = rime::io::Precision::kFloat;
  scene.solver.time_step = rime::io::TimeStep::kCfl;  // spec §7 defaults: CFL 0.4, Δt ≤ 6 ms
  // Inviscid by default: the spec's sticky viscosity (β0 β1 = 1 m/s, ν_eff ≈ 0.1 h m²/s) is an
  // artistic setting ~100x the viscosity of water at these spacings; --viscosity shows its effect.
  scene.modules = {"gravity"};
  if (o.viscosity) scene.modules.insert("viscosity");

  // Channel [0, 6a] x [0, depth] x [0, 2.5a]; the water stands 1.1 d_p from the walls (spec §3).
  const double length = 6 * kA, depth = sph::test::BoxWidth(dp, ny), wall = 2.5 * kA;
  sph::Simulation<float> sim(scene, exec::Device::Cpu());
  sim.AddBoundaryObject(sph::test::BoxBoundary(dp, length, depth, wall), "box");
  sim.Initialize();

  // Walls act 0.6 d_p in front of their particles (rest density is reached 1.1 d_p away, and a
  // particle fills d_p/2 on either side), so the water initially spans [0.6 d_p, 0.6 d_p + a]
  // with a = per_a d_p; the front z is measured from there and its particle's half width added.
  const double origin = 0.6 * dp;
  auto front_z = [&] { return FrontX(sim.Positions(), dp) + 0.5 * dp - origin; };
  std::printf(
      "column a = %.4f m = %d d_p (d_p = %.3g mm), height 2a, %d particles across the channel depth, "
      "%lld water particles, %lld boundary particles; modules: %s\n",
      kA, per_a, 1e3 * dp, ny, (long long)sim.fluid_count(), (long long)sim.boundary_count(),
      o.viscosity ? "gravity, viscosity (spec defaults)" : "gravity only (inviscid)");

  Stopwatch watch;
  std::vector<Sample> samples{{0.0, front_z() / kA}};
  const double dT = 0.02;
  int iterations = 0;
  while (sim.time() * t_scale < T_end - 1e-9) {
    const double stop = (std::floor(sim.time() * t_scale / dT + 1e-6) + 1) * dT / t_scale;
    while (sim.time() < stop - 1e-12) iterations += sim.Step(sim.NextTimeStep(stop)).pressure_iterations;
    samples.push_back({sim.time() * t_scale, front_z() / kA});
  }
  const double wall_s = watch.seconds();
  std::printf("simulated %.3f s (T = %.2f) in %lld steps, %d pressure iterations, %.1f s wall\n", sim.time(), T_end,
              (long long)sim.step_count(), iterations, wall_s);

  // Simulated front at the experiment's times (linear between samples 0.02 apart in T).
  auto z_at = [&](double T) {
    if (T <= 0) return samples.front().Z;
    for (std::size_t i = 1; i < samples.size(); ++i)
      if (samples[i].T >= T) {
        const double w = (T - samples[i - 1].T) / (samples[i].T - samples[i - 1].T);
        return samples[i - 1].Z + w * (samples[i].Z - samples[i - 1].Z);
      }
    return samples.back().Z;
  };
  // Mean and max |relative deviation| over the points with T <= 3, the simulation delayed by `delay`.
  struct Stats {
    double mean = 0, worst = 0, signed_mean = 0;
  };
  auto stats = [&](double delay) {
    Stats st;
    int count = 0;
    for (const Point& p : kMartinMoyce) {
      if (p.T > 3) continue;
      const double dev = (z_at(p.T - delay) - p.Z) / p.Z;
      st.mean += std::fabs(dev), st.signed_mean += dev, st.worst = std::max(st.worst, std::fabs(dev)), ++count;
    }
    st.mean /= count, st.signed_mean /= count;
    return st;
  };
  std::printf("\n   T     Z exp   Z sim   deviation\n");
  for (const Point& p : kMartinMoyce) {
    const double z = z_at(p.T);
    std::printf("  %.2f   %.2f    %.3f   %+6.1f%%%s\n", p.T, p.Z, z, 100 * (z - p.Z) / p.Z,
                p.T <= 3 ? "" : "   (T > 3: not in the statistics)");
  }
  const Stats raw = stats(0);
  std::printf("\nT <= 3: mean |deviation| %.1f%%, max |deviation| %.1f%%, mean signed deviation %+.1f%%\n", 100 * raw.mean, 100 * raw.worst,
              100 * raw.signed_mean);
  // Diagnosis only (not a criterion): the start of the experiment (release of the column) is not
  // modelled, so report how well the curve's shape fits once the simulation is delayed by the
  // best constant ΔT.
  double best_delay = 0;
  for (double d = 0; d <= 0.8 + 1e-9; d += 0.005)
    if (stats(d).mean < stats(best_delay).mean) best_delay = d;
  const Stats shifted = stats(best_delay);
  std::printf("best time shift: simulation delayed by dT = %.3f (%.1f ms): mean |deviation| %.1f%%, max %.1f%%\n", best_delay,
              1e3 * best_delay / t_scale, 100 * shifted.mean, 100 * shifted.worst);
  // The Lethe project's example of this experiment (chaos-polymtl/lethe, examples/multiphysics/
  // dam-break/dam-break-2d.py) delays its simulation by a fixed T = 0.175, without a stated reason.
  const Stats lethe = stats(0.175);
  std::printf("with Lethe's fixed delay dT = 0.175: mean |deviation| %.1f%%, max %.1f%%\n", 100 * lethe.mean, 100 * lethe.worst);

  // Tolerances. Full (a = 40 d_p): the target, 10 % mean (20 % for the worst point).
  // Fast (a = 16 d_p): the front is resolved to 1/16 of a, 2-6 % of Z by itself, so 20 % / 30 %.
  const double mean_tol = o.full ? 0.10 : 0.20, max_tol = o.full ? 0.20 : 0.30;
  bool ok = true;
  ok &= Check(raw.mean <= mean_tol, fmt::format("mean |deviation| {:.1f}% <= {:.0f}%", 100 * raw.mean, 100 * mean_tol));
  ok &= Check(raw.worst <= max_tol, fmt::format("max |deviation| {:.1f}% <= {:.0f}%", 100 * raw.worst, 100 * max_tol));
  ok &= Check(sim.removed_total() == 0, fmt::format("no particle left the domain ({} removed)", sim.removed_total()));
  return ok ? 0 : 1;
}

}  // namespace
}  // namespace rime::validation

int main(int argc, char** argv) {
  using namespace rime::validation;
  const Options o = ParseOptions(argc, argv, "usage: rime_validation_dam_break [--full] [--viscosity]");
  PrintRunInfo("dam break vs Martin & Moyce (1952)", o);
  return Run(o);
}
