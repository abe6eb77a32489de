// IISPH solver tests: rest state, hydrostatic pressure, momentum conservation of every pairwise
// module, the module registry, resume determinism and divergence detection.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <random>

#include "rime/core/error.h"
#include "rime/exec/memory.h"
#include "rime/neighbors/grid.h"
#include "rime/sph/kernels.h"
#include "rime/sph/simulation.h"
#include "rime/test/sph_scenes.h"

namespace rime::sph {
namespace {

template <class T>
std::unique_ptr<Simulation<T>> MakeColumn(io::Scene scene, int nx, int ny, int nz, double wall_height) {
  const double dp = scene.fluid.spacing;
  auto sim = std::make_unique<Simulation<T>>(scene, exec::Device::Cpu());
  sim->AddBoundaryObject(test::BoxBoundary(dp, test::BoxWidth(dp, nx), test::BoxWidth(dp, ny), wall_height), "box");
  sim->Initialize();
  return sim;
}

// Fluid–fluid neighbor lists with kernel values for a cloud without boundaries (kernel tests).
struct FluidOnlyPairs {
  FluidOnlyPairs(const exec::DeviceArray<Vec3d>& x, double h)
      : kernel(h), ff(exec::Device::Cpu()), fb(exec::Device::Cpu()), w(exec::Device::Cpu()), grad(exec::Device::Cpu()) {
    const Index n = Index(x.size());
    neighbors::UniformGrid<double> grid(exec::Device::Cpu());
    grid.Build(x.data(), n, 2 * h);
    grid.Query(x.data(), n, 2 * h, true, ff);
    fb.offsets.resize(n + 1);
    fb.offsets.SetZero();
    w.resize(ff.pairs());
    grad.resize(ff.pairs());
    exec::cpu::ParallelFor(
        n, neighbors::kernels::PairValues<double>{x.data(), x.data(), ff.offsets.data(), ff.indices.data(), kernel, w.data(), grad.data()});
  }
  Pairs<double> FF() const { return {ff.offsets.data(), ff.indices.data(), w.data(), grad.data()}; }
  Pairs<double> FB() const { return {fb.offsets.data(), nullptr, nullptr, nullptr}; }
  CubicSpline<double> kernel;
  neighbors::NeighborList ff, fb;
  exec::DeviceArray<double> w;
  exec::DeviceArray<Vec3d> grad;
};

template <class T>
double MaxSpeed(const Simulation<T>& sim) {
  double m = 0;
  for (const auto& v : sim.Velocities()) m = std::max(m, double(Norm(v)));
  return m;
}

// Kinetic plus potential energy of the water, J.
template <class T>
double MechanicalEnergy(const Simulation<T>& sim, const io::Scene& scene) {
  const double m = scene.fluid.particle_mass();
  const auto x = sim.Positions();
  const auto v = sim.Velocities();
  double e = 0;
  for (std::size_t i = 0; i < x.size(); ++i) e += m * (0.5 * double(Dot(v[i], v[i])) - Dot(scene.solver.gravity, Vec3d(x[i])));
  return e;
}

TEST(Iisph, BlockAtRestStaysAtRest) {
  io::Scene scene = test::ColumnScene(0.02, 8, 8, 8, 0.3);
  scene.modules = {"gravity", "viscosity"};
  auto sim = MakeColumn<float>(scene, 8, 8, 8, 0.3);
  ASSERT_EQ(sim->fluid_count(), 512);
  auto mean_speed = [&] {
    double mean = 0;
    for (const auto& v : sim->Velocities()) mean += Norm(v) / sim->fluid_count();
    return mean;
  };
  StepStats last;
  auto run_to = [&](double t) {
    while (sim->time() < t - 1e-9) last = sim->Step(sim->NextTimeStep(t));
  };
  run_to(1.0);
  const double speed_1s = MaxSpeed(*sim), mean_1s = mean_speed();
  run_to(4.0);
  const double energy_4s = MechanicalEnergy(*sim, scene);
  run_to(8.0);
  const double energy_8s = MechanicalEnergy(*sim, scene), speed_8s = MaxSpeed(*sim), mean_8s = mean_speed();
  RecordProperty("max_speed_after_1s", std::to_string(speed_1s));
  RecordProperty("max_speed_after_8s", std::to_string(speed_8s));
  std::printf(
      "block at rest: max / mean speed after 1 s %.3g / %.3g m/s, after 8 s %.3g / %.3g m/s; mechanical energy 4 s -> 8 s "
      "%+.3g mJ; average density error %.3g%% predicted, %.3g%% measured, %d iterations\n",
      speed_1s, mean_1s, speed_8s, mean_8s, 1e3 * (energy_8s - energy_4s), 100 * last.average_density_error,
      100 * last.measured_density_error, last.pressure_iterations);
  // From this lattice start the 1e-3 m/s after 1 s is not reached, and no solver setting
  // reaches it: the lattice is no equilibrium of the discrete model. On any regular lattice the
  // SPH divergence and gradient are blind to a mode that alternates from layer to layer (their
  // symmetric sums vanish for it), so even an exactly converged first step (3000 Jacobi iterations)
  // lets every other layer fall at about 0.9 g; the top layer, 15 % under-dense with p = 0, sinks
  // 0.4 d_p into the hollows below, and the floor layer moves 0.07 d_p closer to the floor. That
  // releases 60-80 mJ (the centroid drops 0.07-0.1 d_p), which viscosity takes seconds to remove.
  // With 2 iterations, a lid (a closed tank) halved the speed at 1 s (0.022 m/s), and η 1e-4 or
  // 1e-5 changed nothing (0.048 m/s). Once settled, the block does stay at rest (the next test).
  // Bounds: the run is chaotic; perturbing the start by 1e-4..3e-3 d_p or running in double gave
  // 0.026-0.051 / 0.0049-0.0064 m/s here, and 0.0047-0.013 / 0.0008-0.0016 m/s at 8 s, with
  // min_iterations = 2; 0.049 / 0.0050 and 0.0034 / 0.0003 m/s with 3.
  EXPECT_LT(speed_1s, 0.06);
  EXPECT_LT(mean_1s, 0.008);
  // What must hold: nothing feeds the motion once the lattice has settled. The wall viscosity used
  // to act on v + Δt g before the pressure solve and so held wall-adjacent water up by friction; the
  // block then circulated (up along the walls, down inside), mechanical energy rose by 2 mJ between
  // 4 and 8 s (in 5 of the 6 perturbed runs), and it kept 5-20 mm/s for 20 s. Now the energy keeps
  // falling (by 0.6-1.9 mJ).
  EXPECT_LT(energy_8s, energy_4s);
  EXPECT_LT(speed_8s, 0.02);
  EXPECT_LT(mean_8s, 0.002);
  // "Average density error below η" holds for the solve's prediction (what η is
  // checked against); the measured compression of this block is 0.23 % at 8 s (printed; README, stats.jsonl).
  EXPECT_LT(last.average_density_error, scene.solver.eta);
  EXPECT_EQ(sim->removed_total(), 0);
}

// What a watch of the settled 8³ block shows (SettledBlockStaysAtRest and the breathing guard).
struct SettledWatch {
  double largest_rise = 0;  // J, the most the mechanical energy rose above its lowest value so far
  double tolerance = 0;     // J, one float ulp of every particle's height, as potential energy
  double energy_change = 0, max_speed = 0, max_predicted = 0, max_measured = 0;
};

// Settles the block from its lattice for `settle` seconds, then watches it for `watch` seconds
// after every step.
SettledWatch WatchSettledBlock(int min_iterations, double settle, double watch) {
  io::Scene scene = test::ColumnScene(0.02, 8, 8, 8, 0.3);
  scene.modules = {"gravity", "viscosity"};
  scene.solver.min_iterations = min_iterations;
  auto sim = MakeColumn<float>(scene, 8, 8, 8, 0.3);
  while (sim->time() < settle - 1e-9) sim->Step(sim->NextTimeStep(settle));
  SettledWatch result;
  for (const auto& x : sim->Positions())
    result.tolerance += scene.fluid.particle_mass() * Norm(scene.solver.gravity) * (std::nextafter(x.z, INFINITY) - x.z);
  const double start = MechanicalEnergy(*sim, scene);
  double lowest = start, energy = start;
  while (sim->time() < settle + watch - 1e-9) {
    const StepStats stats = sim->Step(sim->NextTimeStep(settle + watch));
    energy = MechanicalEnergy(*sim, scene);
    result.largest_rise = std::max(result.largest_rise, energy - lowest);
    lowest = std::min(lowest, energy);
    result.max_speed = std::max(result.max_speed, MaxSpeed(*sim));
    result.max_predicted = std::max(result.max_predicted, stats.average_density_error);
    result.max_measured = std::max(result.max_measured, stats.measured_density_error);
  }
  result.energy_change = energy - start;
  std::printf(
      "settled block, min %d pressure iterations, watched %.0f-%.0f s: mechanical energy %+.3g uJ, largest rise %.3g uJ "
      "(tolerance %.3g uJ); max speed %.3g mm/s; average density error up to %.3g%% predicted, %.3g%% measured\n",
      min_iterations, settle, settle + watch, 1e6 * result.energy_change, 1e6 * result.largest_rise, 1e6 * result.tolerance,
      1e3 * result.max_speed, 100 * result.max_predicted, 100 * result.max_measured);
  return result;
}

// The 8³ block above, settled from its lattice for 30 s at the default settings and watched for
// 1 s: nothing may feed its motion, so its mechanical energy never rises above its lowest value
// so far by more than the tolerance (docs/reliability.md). Speed alone cannot say this: the
// packing keeps releasing potential energy in bursts (up to 6 mm/s), whose timing depends on how
// the build rounds, while the energy falls in each of them. The tolerance, one float ulp of every
// height as potential energy (0.3 µJ), exceeds what one step's rounding of the positions can
// change; settled water stays at half of it or less (0.02-0.15 µJ).
TEST(Iisph, SettledBlockStaysAtRest) {
  const SettledWatch watch = WatchSettledBlock(io::SolverSettings{}.min_iterations, 30, 1);
  EXPECT_LT(watch.largest_rise, watch.tolerance) << "the solver fed the settled block's motion";
  EXPECT_LT(watch.max_predicted, io::SolverSettings{}.eta);
}

// The check above has teeth in every build: with Ihmsen's minimum of 2 pressure iterations the
// solve stops early in most steps, and a block that sinks as a whole compresses only its floor
// layer, which the average error hardly sees. The block then breathes, in phase, at about
// 2.6 mm/s for as long as it runs, the solve pumping tens of µJ into it every few steps.
TEST(Iisph, SettledBlockBreathesWithTwoPressureIterations) {
  const SettledWatch watch = WatchSettledBlock(2, 10, 1);
  EXPECT_GT(watch.largest_rise, watch.tolerance);
}

// A sealed tank full of water (the lid 1.1 d_p above the top layer, as the walls): the packing
// jams under the lid and rearranges for tens of seconds, in bursts of up to 15 mm/s, so no
// at-rest speed bound holds here (0.3-6.8 mm/s at 35-60 s). What must hold is that the bursts are
// the packing releasing potential energy, not the solver feeding it: the mechanical energy falls
// in every second (by 6-4061 µJ over 30 s), and no particle leaves or overlaps the lid. A warm
// start of 0.95 (unstable on the settled block) fails this: the energy rose between 7
// and 8 s.
TEST(Iisph, SealedFullTankOnlyLosesEnergy) {
  io::Scene scene = test::ColumnScene(0.02, 8, 8, 8, 0);
  scene.modules = {"gravity", "viscosity"};
  const double dp = scene.fluid.spacing, width = test::BoxWidth(dp, 8), lid = 1.1 * dp + 7 * dp + 1.1 * dp;
  Simulation<float> sim(scene, exec::Device::Cpu());
  sim.AddBoundaryObject(test::SealedBoxBoundary(dp, width, width, lid), "box");
  sim.Initialize();
  ASSERT_EQ(sim.fluid_count(), 512);
  double energy = MechanicalEnergy(sim, scene), max_density_error = 0, highest = 0;
  for (int second = 1; second <= 10; ++second) {
    while (sim.time() < second - 1e-9) {
      const StepStats st = sim.Step(sim.NextTimeStep(second));
      max_density_error = std::max(max_density_error, st.max_density_error);
    }
    const double now = MechanicalEnergy(sim, scene);
    EXPECT_LT(now, energy) << "mechanical energy rose between " << second - 1 << " and " << second << " s";
    energy = now;
    for (const auto& x : sim.Positions()) highest = std::max(highest, double(x.z));
  }
  std::printf("sealed full tank: max speed at 10 s %.3g m/s, max predicted density error %.3g%%, highest particle %.3f d_p below the lid\n",
              MaxSpeed(sim), 100 * max_density_error, (lid - highest) / dp);
  EXPECT_LT(highest, lid - 0.5 * dp);
  EXPECT_LT(max_density_error, 0.01);
  EXPECT_EQ(sim.removed_total(), 0);
}

// Output frames must not jolt water at rest: NextTimeStep takes equal steps up to each frame time,
// since a short last step before the frame makes the adaptive Δt jump there, and each jump kicks
// the block (kinetic energy about 100 times what settled water keeps).
TEST(Iisph, OutputFramesDoNotJoltWaterAtRest) {
  for (const double fps : {24.0, 25.0}) {
    io::Scene scene = test::ColumnScene(0.02, 8, 8, 8, 0.3);
    scene.modules = {"gravity", "viscosity"};
    scene.solver.time_step = rime::io::TimeStep::kCfl;
    auto sim = MakeColumn<float>(scene, 8, 8, 8, 0.3);
    int frame = 1;
    auto run_frame = [&](std::vector<double>& steps) {
      while (sim->time() < frame / fps - 1e-9) steps.push_back(sim->Step(sim->NextTimeStep(frame / fps)).dt);
      ++frame;
    };
    std::vector<double> steps;
    while (frame / fps < 3.0 + 1e-9) run_frame(steps);
    double kinetic = 0;
    int count = 0;
    for (; frame / fps < 5.0 + 1e-9;) {
      steps.clear();
      run_frame(steps);
      // Equal steps that end exactly on the frame, none above the adaptive limit.
      ASSERT_GE(steps.size(), 2u);
      for (double dt : steps) ASSERT_NEAR(dt, steps.front(), 1e-9 * dt) << fps << " fps, frame " << frame - 1;
      EXPECT_NEAR(sim->time(), (frame - 1) / fps, 1e-9);
      for (const auto& v : sim->Velocities()) kinetic += 0.5 * scene.fluid.particle_mass() * Dot(v, v);
      ++count;
    }
    kinetic /= count;
    std::printf("%g fps: mean kinetic energy over 3-5 s %.3g uJ, max speed at 5 s %.3g m/s, dt %.4g ms\n", fps, 1e6 * kinetic,
                MaxSpeed(*sim), 1e3 * steps.front());
    EXPECT_LT(kinetic, 40e-6) << fps << " fps";
    EXPECT_LT(MaxSpeed(*sim), 0.02) << fps << " fps";
  }
}

// StepStats::measured_density_error is the water's actual compression at the start of the step:
// checked against densities summed over every fluid and boundary particle (no grid) from the
// positions after the previous step, on a column collapsing in a box.
TEST(Iisph, MeasuredDensityErrorIsTheActualCompression) {
  const double dp = 0.02;
  io::Scene scene = test::ColumnScene(dp, 10, 6, 20, 0.6);
  Simulation<double> sim(scene, exec::Device::Cpu());
  sim.AddBoundaryObject(test::BoxBoundary(dp, test::BoxWidth(dp, 40), test::BoxWidth(dp, 6), 0.6), "box");
  sim.Initialize();
  const CubicSpline<double> kernel(scene.fluid.smoothing_length());
  const double mass = scene.fluid.particle_mass(), rho0 = scene.fluid.rest_density;
  const auto boundary = sim.BoundaryPositions();
  const auto volume = sim.BoundaryVolumes();
  double predicted = 0, measured = 0;
  for (int step = 0; step < 60; ++step) {
    const auto x = sim.Positions();
    const StepStats st = sim.Step(0.002);
    if (step % 20 != 19) {
      predicted += st.average_density_error;
      continue;
    }
    double compression = 0;
    for (const auto& xi : x) {
      double rho = 0;
      for (const auto& xj : x) rho += mass * kernel.W(xi - xj);
      for (std::size_t b = 0; b < boundary.size(); ++b) rho += rho0 * volume[b] * kernel.W(xi - boundary[b]);
      compression += std::max(0.0, rho - rho0);
    }
    compression /= double(x.size()) * rho0;
    EXPECT_NEAR(st.measured_density_error, compression, 1e-9) << "step " << step;
    EXPECT_GT(compression, 1e-4) << "the collapsing column is compressed somewhere";
    measured += compression;
  }
  std::printf("collapsing column: predicted average density error %.3g%% (mean of 57 steps), measured %.3g%% (3 steps)\n",
              100 * predicted / 57, 100 * measured / 3);
}

// A 0.5 m column at d_p = 12.5 mm under the default adaptive step (CFL 0.4, Δt ≤ 6 ms). At rest the
// CFL speed is the head speed √(2 g H): without it the column stepped at 6 ms, fell before the
// Jacobi solve had built its pressure, and diverged within 0.1 s.
TEST(Iisph, TallColumnSettlesUnderTheDefaultAdaptiveStep) {
  const double dp = 0.0125;
  io::Scene scene = test::ColumnScene(dp, 16, 16, 40, 0);
  scene.solver.time_step = rime::io::TimeStep::kCfl;
  scene.modules = {"gravity", "viscosity"};
  Simulation<float> sim(scene, exec::Device::Cpu());
  const double width = test::BoxWidth(dp, 16);
  sim.AddBoundaryObject(test::BoxBoundary(dp, width, width, 0.6), "box");
  sim.Initialize();
  const double head = 39 * dp;  // the column's extent: first to last layer
  const double dt0 = sim.NextTimeStep(1.0);
  const double head_step = scene.solver.cfl * dp / std::sqrt(2 * 9.81 * head);
  EXPECT_NEAR(dt0, 1.0 / std::ceil(1.0 / head_step), 1e-6 * dt0) << "equal steps up to the stop, none above the head-speed step";
  double max_density_error = 0;
  while (sim.time() < 0.4 - 1e-9) {
    const StepStats st = sim.Step(sim.NextTimeStep(0.4));
    ASSERT_LE(st.dt, scene.solver.cfl * dp / std::sqrt(2 * 9.81 * 0.95 * head)) << "the head speed bounds the step";
    max_density_error = std::max(max_density_error, st.max_density_error);
  }
  double max_speed = 0;
  for (const auto& v : sim.Velocities()) max_speed = std::max(max_speed, double(Norm(v)));
  std::printf("tall column: %lld steps in 0.4 s, max predicted density error %.2f%%, max speed at the end %.3f m/s\n",
              (long long)sim.step_count(), 100 * max_density_error, max_speed);
  EXPECT_EQ(sim.removed_total(), 0);
  EXPECT_LT(max_density_error, 0.05);
  EXPECT_LT(max_speed, 0.3);
}

// Pressure profile of a 0.5 m column against ρ0 g depth (spec T13 / issue acceptance): pressures
// and heights of each particle averaged over the last 0.3 s of 1.2 s, binned by depth.
TEST(Iisph, HydrostaticPressureProfile) {
  const double dp = 0.02, t_end = 1.2, t_average = 0.3;
  const int width_particles = 16, layers = 25;  // 0.5 m; 16 wide so that most particles are 2.5 d_p from the walls
  io::Scene scene = test::ColumnScene(dp, width_particles, width_particles, layers, 0.6);
  scene.modules = {"gravity", "viscosity"};  // spec T13 runs with the sticky viscosities
  auto sim = MakeColumn<double>(scene, width_particles, width_particles, layers, 0.6);
  const std::size_t n = sim->fluid_count();
  std::vector<double> p(n), z(n);
  std::vector<Vec3d> x(n);
  int samples = 0;
  while (sim->time() < t_end - 1e-9) {
    sim->Step(sim->NextTimeStep(t_end));
    if (sim->time() < t_end - t_average) continue;
    // Keyed by particle id: the solver reorders particles along a space-filling curve.
    const auto pi = sim->Pressures();
    const auto xi = sim->Positions();
    const auto id = sim->Ids();
    for (std::size_t i = 0; i < n; ++i) p[id[i]] += pi[i], z[id[i]] += xi[i].z, x[id[i]] = xi[i];
    ++samples;
  }
  for (std::size_t i = 0; i < n; ++i) p[i] /= samples, z[i] /= samples;
  // Free surface from the volume: each particle fills dp³ and the Akinci walls act 0.6 dp from
  // their particles (rest density is reached 1.1 dp from a wall, spec §3).
  const double width = test::BoxWidth(dp, width_particles);
  const double surface = 0.6 * dp + double(n) * dp * dp * dp / ((width - 1.2 * dp) * (width - 1.2 * dp));
  const double rho0 = 1000, g = 9.81, floor_layer = 1.1 * dp;
  auto away_from_side_walls = [&](const Vec3d& q) {
    return q.x > 2.5 * dp && q.x < width - 2.5 * dp && q.y > 2.5 * dp && q.y < width - 2.5 * dp;
  };
  // Interior: at least 5 d_p below the surface and 5 d_p above the floor layer. The top layers carry
  // almost no pressure (free-surface particles are under-dense and clamped to p = 0) and the bottom
  // layers show the known Akinci+IISPH wall overshoot (spec T13); both are printed, not asserted.
  auto interior = [&](double zi) { return surface - zi >= 5 * dp && zi - floor_layer >= 5 * dp; };
  // Least-squares line p = c0 + c1 z over the interior particles: slope −ρ0 g, and its zero
  // crossing is the effective free surface.
  double sz = 0, sp = 0, szz = 0, szp = 0;
  int count = 0;
  for (std::size_t i = 0; i < n; ++i)
    if (away_from_side_walls(x[i]) && interior(z[i])) sz += z[i], sp += p[i], szz += z[i] * z[i], szp += z[i] * p[i], ++count;
  const double slope = (count * szp - sz * sp) / (count * szz - sz * sz), intercept = (sp - slope * sz) / count;
  const double effective_surface = -intercept / slope, offset = surface - effective_surface;
  std::printf("hydrostatic: fitted dp/dz = %.1f Pa/m (rho0 g = %.1f, %+.2f%%); effective free surface %.2f d_p below the volume's\n", slope,
              -rho0 * g, 100 * (-slope / (rho0 * g) - 1), offset / dp);
  EXPECT_NEAR(-slope / (rho0 * g), 1.0, 0.05);
  EXPECT_GT(offset, -0.5 * dp);
  EXPECT_LT(offset, 0.75 * dp);
  struct Bin {
    double p = 0, z = 0;
    int count = 0;
  };
  std::map<int, Bin> bins;  // by depth, 2.5 d_p wide: the start lattice rearranges into no crisp layers
  for (std::size_t i = 0; i < n; ++i) {
    if (!away_from_side_walls(x[i])) continue;
    Bin& b = bins[int(std::floor((surface - z[i]) / (2.5 * dp)))];
    b.p += p[i], b.z += z[i], b.count += 1;
  }
  double worst = 0, worst_offset = 0;
  for (auto& [k, b] : bins) {
    b.p /= b.count, b.z /= b.count;
    const double ratio = b.p / (rho0 * g * (surface - b.z)), ratio_offset = b.p / (rho0 * g * (effective_surface - b.z));
    std::printf("depth %.3f m (%3d particles): p/(rho0 g depth) = %.3f, against the effective surface %.3f%s\n", surface - b.z, b.count,
                ratio, ratio_offset, interior(b.z) ? "" : "  (top or bottom layers, not asserted)");
    if (!interior(b.z)) continue;
    worst = std::max(worst, std::fabs(ratio - 1));
    worst_offset = std::max(worst_offset, std::fabs(ratio_offset - 1));
    EXPECT_NEAR(ratio, 1.0, 0.10) << "depth " << surface - b.z;
    EXPECT_NEAR(ratio_offset, 1.0, 0.05) << "depth " << surface - b.z;
  }
  const double speed = MaxSpeed(*sim);
  std::printf("hydrostatic: interior bins within %.1f%% of rho0 g depth (%.1f%% against the effective surface); max speed %.3g m/s\n",
              100 * worst, 100 * worst_offset, speed);
  EXPECT_LT(speed, 0.15);
}

// Pairwise forces conserve momentum: Σ_i m a_i = 0 without boundaries (spec T6).
TEST(Iisph, PairwiseModulesConserveMomentum) {
  const double dp = 0.02, h = dp;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<Vec3d> x, v;
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j)
      for (int k = 0; k < 6; ++k) {
        x.push_back(Vec3d(i, j, k) * dp + Vec3d(u(rng), u(rng), u(rng)) * (0.2 * dp));
        v.push_back(Vec3d(u(rng), u(rng), u(rng)));
      }
  const Index n = Index(x.size());
  const exec::Device cpu = exec::Device::Cpu();
  exec::DeviceArray<Vec3d> dx(cpu, x), dv(cpu, v);
  const FluidOnlyPairs pairs(dx, h);
  const CubicSpline<double>& kernel = pairs.kernel;
  const Pairs<double> FF = pairs.FF(), FB = pairs.FB();
  const double mass = 1000 * dp * dp * dp;
  std::vector<double> rho(n);
  for (auto& r : rho) r = 1000 * (1 + 0.1 * u(rng));
  std::vector<double> pressure(n);
  for (auto& p : pressure) p = 500 * (1 + u(rng));
  exec::DeviceArray<double> d_rho(cpu, rho), d_p(cpu, pressure), color(cpu, n), energy(cpu, n), p_prev(cpu, n);
  exec::DeviceArray<Vec3d> accel(cpu, n), vel_out(cpu, v), pos_out(cpu, x), v_adv(cpu, v);
  auto total = [&]() {
    const auto a = accel.ToHost();
    Vec3d sum{}, scale{};
    for (const auto& ai : a) sum += ai * mass, scale += Vec3d(std::fabs(ai.x), std::fabs(ai.y), std::fabs(ai.z)) * mass;
    return std::make_pair(Norm(sum), Norm(scale));
  };
  auto check = [&](const char* name) {
    const auto [sum, scale] = total();
    EXPECT_GT(scale, 0) << name << " produced no force";
    EXPECT_LT(sum, 1e-12 * scale) << name;
    accel.SetZero();
  };
  exec::cpu::ParallelFor(
      n, kernels::ViscosityAcceleration<double>{FF, dx.data(), dv.data(), d_rho.data(), mass, 1e-3, 1.0, h, 0.01, false, accel.data()});
  check("viscosity");
  exec::cpu::ParallelFor(n, kernels::SurfaceColor<double>{FF, FB, d_rho.data(), nullptr, mass, kernel.W0(), color.data()});
  exec::cpu::ParallelFor(n, kernels::SurfaceEnergy<double>{FF, d_rho.data(), color.data(), mass, energy.data()});
  exec::cpu::ParallelFor(
      n, kernels::SurfaceTensionAcceleration<double>{FF, FB, d_rho.data(), energy.data(), nullptr, mass, 0.02, 0.02, accel.data()});
  check("surface tension");
  exec::DeviceArray<Vec3d> normal(cpu, n);
  exec::cpu::ParallelFor(n, kernels::AkinciNormal<double>{FF, d_rho.data(), mass, 2 * h, normal.data()});
  exec::cpu::ParallelFor(n, kernels::AkinciSurfaceTensionAcceleration<double>{FF, FB, dx.data(), nullptr, d_rho.data(), normal.data(),
                                                                              nullptr, mass, 0.05, 0.05, 1000, 2 * h, accel.data()});
  check("Akinci 2013 surface tension");
  exec::cpu::ParallelFor(n, kernels::AirPressureAcceleration<double>{FF, FB, d_rho.data(), nullptr, mass, 5000, accel.data()});
  check("air pressure");
  // Pressure: IntegratePressure with dt = 1 and zero v_adv leaves v = a^p.
  v_adv.SetZero();
  exec::cpu::ParallelFor(n, kernels::IntegratePressure<double>{FF, FB, d_p.data(), d_rho.data(), nullptr, v_adv.data(), mass, 1.0,
                                                               accel.data(), pos_out.data(), p_prev.data()});
  check("pressure");
}

// Akinci 2013's adhesion spline vanishes at both ends of (H/2, H]; rounding there must give 0, not
// NaN from a negative fourth root, and it is positive inside.
TEST(Iisph, AkinciAdhesionIsFiniteAtTheEndsOfItsRange) {
  for (float H : {0.02f, 0.0264f, 0.04f, 1.0f}) {
    for (float r : {0.5f * H, std::nextafter(0.5f * H, H), std::nextafter(H, 0.0f), H, 0.75f * H}) {
      const float a = kernels::AkinciAdhesion(r, H);
      EXPECT_TRUE(std::isfinite(a) && a >= 0) << "H " << H << " r " << r << ": " << a;
    }
    EXPECT_GT(kernels::AkinciAdhesion(0.75f * H, H), 0.0f);
    EXPECT_EQ(kernels::AkinciAdhesion(0.4f * H, H), 0.0f);
  }
}

// Surface tension pulls an elongated block of water towards a sphere (no gravity, no solids). The
// elongation is the ratio of the largest to the smallest principal moment of the particles'
// gyration tensor, 4 at the start (2:1:1); after 0.6 s (a fifth of the blob's Rayleigh period)
// it must fall well below that of the same block without surface tension, for both models.
TEST(Iisph, SurfaceTensionRoundsAnElongatedBlock) {
  auto run = [](const std::string& model) {
    io::Scene scene;
    const double dp = 0.01;
    scene.fluid.spacing = dp;
    scene.modules = {"viscosity"};
    if (!model.empty()) scene.modules.insert("surface_tension");
    io::ParseEnum(model.empty() ? "he2014" : model, scene.surface_tension.model);
    scene.solver.time_step = rime::io::TimeStep::kFixed;
    scene.solver.dt = 0.002;
    io::FluidBlock block;
    block.min = {0, 0, 0};
    block.max = {15 * dp, 7 * dp, 7 * dp};
    scene.fluid_blocks.push_back(block);
    Simulation<double> sim(scene, exec::Device::Cpu());
    sim.Initialize();
    while (sim.time() < 0.6 - 1e-9) sim.Step(sim.NextTimeStep(0.6));
    const auto x = sim.Positions();
    Vec3d c{};
    for (const auto& p : x) c += p / double(x.size());
    Mat3<double> g{};
    for (const auto& p : x) {
      EXPECT_TRUE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z)) << model;
      g += Mat3<double>::OuterProduct(p - c, p - c) * (1.0 / double(x.size()));
    }
    EXPECT_EQ(sim.removed_total(), 0) << model;
    Vec3d values;
    Mat3<double> vectors;
    SymmetricEigen(g, values, vectors);
    return values.x / values.z;
  };
  const double control = run("");
  std::printf("elongation after 0.6 s without surface tension: %.2f (4.05 at the start)\n", control);
  EXPECT_GT(control, 3.8) << "without surface tension the block should keep its shape";
  for (const std::string model : {"he2014", "akinci2013"}) {
    const double e = run(model);
    std::printf("elongation after 0.6 s with %s surface tension: %.2f\n", model.c_str(), e);
    EXPECT_LT(e, control - 0.5) << model << " did not round the block";
  }
}

TEST(Iisph, ModuleThatIsOffAllocatesAndRunsNothing) {
  io::Scene scene = test::ColumnScene(0.02, 4, 4, 4, 0.2);
  scene.modules = {"gravity", "viscosity"};
  auto sim = MakeColumn<float>(scene, 4, 4, 4, 0.2);
  for (int i = 0; i < 5; ++i) sim->Step(0.002);
  EXPECT_FALSE(sim->modules().HasAttribute("color"));
  EXPECT_FALSE(sim->modules().HasAttribute("color_energy"));
  EXPECT_EQ(sim->modules().Launches("surface_tension"), 0);
  EXPECT_EQ(sim->modules().Launches("air_pressure"), 0);
  EXPECT_EQ(sim->modules().Launches("viscosity"), 5);
  scene.modules = {"gravity", "surface_tension"};
  auto with = MakeColumn<float>(scene, 4, 4, 4, 0.2);
  for (int i = 0; i < 5; ++i) with->Step(0.002);
  EXPECT_TRUE(with->modules().HasAttribute("color"));
  EXPECT_EQ(with->modules().Launches("surface_tension"), 5);
  EXPECT_EQ(with->modules().Launches("viscosity"), 0);
}

// A run resumed from a checkpoint produces bit-identical results (same thread count).
TEST(Iisph, ResumeIsBitIdentical) {
  io::Scene scene = test::ColumnScene(0.02, 6, 6, 6, 0.3);
  scene.modules = {"gravity", "viscosity", "surface_tension"};
  scene.solver.time_step = rime::io::TimeStep::kCfl;
  scene.fluid_blocks[0].velocity = {0.5, 0.2, 0};
  auto straight = MakeColumn<float>(scene, 6, 6, 6, 0.3);
  while (straight->time() < 0.05 - 1e-9) straight->Step(straight->NextTimeStep(0.05));
  const io::ParticleFrame checkpoint = straight->Snapshot(1);
  while (straight->time() < 0.1 - 1e-9) straight->Step(straight->NextTimeStep(0.1));

  Simulation<float> resumed(scene, exec::Device::Cpu());
  resumed.AddBoundaryObject(test::BoxBoundary(0.02, test::BoxWidth(0.02, 6), test::BoxWidth(0.02, 6), 0.3), "box");
  resumed.Restore(checkpoint);
  while (resumed.time() < 0.1 - 1e-9) resumed.Step(resumed.NextTimeStep(0.1));
  EXPECT_EQ(resumed.step_count(), straight->step_count());
  EXPECT_EQ(resumed.time(), straight->time());
  const auto a = straight->Positions(), b = resumed.Positions();
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a[i], b[i]) << "particle " << i;
  EXPECT_EQ(straight->Velocities(), resumed.Velocities());
}

TEST(Iisph, AbsurdTimeStepIsReportedAsDivergence) {
  io::Scene scene = test::ColumnScene(0.02, 6, 6, 6, 0.3);
  scene.solver.dt = 0.5;
  scene.solver.max_iterations = 20;
  auto sim = MakeColumn<float>(scene, 6, 6, 6, 0.3);
  try {
    for (int i = 0; i < 20; ++i) sim->Step(0.5);
    FAIL() << "no divergence reported";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kDiverged);
    const std::string what = e.what();
    EXPECT_NE(what.find("diverged at step"), std::string::npos) << what;
    EXPECT_NE(what.find("particle id"), std::string::npos) << what;
  }
}

}  // namespace
}  // namespace rime::sph

namespace rime::sph {
namespace {

// T10 and T9: on a full lattice a_ii = −0.425 Δt²/h² (h = d_p), and a fluid at rest with
// ρ^adv = ρ0 keeps p = 0 through the Jacobi iterations.
TEST(Iisph, LatticeDiagonalAndRestFixedPoint) {
  const double dp = 0.02, h = dp, dt = 0.002;
  std::vector<Vec3d> x;
  for (int i = 0; i < 9; ++i)
    for (int j = 0; j < 9; ++j)
      for (int k = 0; k < 9; ++k) x.push_back(Vec3d(i, j, k) * dp);
  const Index n = Index(x.size());
  const exec::Device cpu = exec::Device::Cpu();
  exec::DeviceArray<Vec3d> dx(cpu, x), v(cpu, n);
  const FluidOnlyPairs pairs(dx, h);
  const CubicSpline<double>& kernel = pairs.kernel;
  const Pairs<double> FF = pairs.FF(), FB = pairs.FB();
  const double mass = 1000 * dp * dp * dp;
  exec::DeviceArray<double> rho(cpu, n), err(cpu, n), p_prev(cpu, n), adv(cpu, n), aii(cpu, n), p(cpu, n), p_next(cpu, n), comp(cpu, n);
  exec::DeviceArray<Vec3d> dii(cpu, n), s(cpu, n);
  exec::cpu::ParallelFor(n, kernels::Density<double>{FF, FB, nullptr, mass, kernel.W0(), 1000.0, rho.data(), err.data()});
  const std::size_t centre = 4 * 81 + 4 * 9 + 4;
  EXPECT_NEAR(rho.ToHost()[centre] / 1000, 0.99997, 1e-4);
  // Force rest: density error zero everywhere so ρ^adv = ρ0.
  err.SetZero();
  exec::cpu::ParallelFor(n, kernels::PredictAdvection<double>{FF, FB, v.data(), nullptr, nullptr, rho.data(), err.data(), p_prev.data(),
                                                              mass, dt, 1.0, 0.5, dii.data(), adv.data(), aii.data(), p.data()});
  EXPECT_NEAR(aii.ToHost()[centre] / (dt * dt / (h * h)), -0.425, 0.425 * 0.02);
  for (int it = 0; it < 5; ++it) {
    exec::cpu::ParallelFor(n, kernels::DisplacementSum<double>{FF, p.data(), rho.data(), mass, dt, s.data()});
    exec::cpu::ParallelFor(n, kernels::PressureUpdate<double>{FF, FB, s.data(), dii.data(), aii.data(), p.data(), rho.data(), adv.data(),
                                                              nullptr, mass, dt, 0.5, 1e-12, p_next.data(), comp.data()});
    p.swap(p_next);
  }
  for (double pi : p.ToHost()) ASSERT_EQ(pi, 0.0);
}

}  // namespace
}  // namespace rime::sph
