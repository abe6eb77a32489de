// Speed/accuracy study: a small quasi-2D dam break (column a wide, 2a high, a few
// particles across the channel depth) swept over the knobs users turn, one at a time around the
// production defaults, plus the quality presets. Every setting records cost (wall and CPU time,
// steps, pressure iterations, peak RSS) and error (density error, volume drift, surge-front
// position and front particle positions against a reference run, and the pressure slope of a
// hydrostatic column run with the same knobs). The same dam break in a cold tank compares the
// presets' ice (count, and shape as the mean nearest distance to the reference run's ice), and the
// reference run's ice is surfaced at several voxel sizes (cost, distance from the finest surface).
// Prints tables, writes CSV and JSON, and plots error against cost with gnuplot when installed.
//   rime-bench-accuracy [--repeats R] [--end T] [--out DIR] [--only GROUP] [--no-freezing]
//                       [--no-hydrostatic] [--no-surface] [--no-plots]
// Each run is a child process (fork) so that its peak RSS and CPU time are its own (wait4).
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "rime/core/error.h"
#include "rime/exec/device.h"
#include "rime/io/particles.h"
#include "rime/sph/simulation.h"
#include "rime/test/sph_scenes.h"
#include "rime/test/measure.h"
#include "rime/test/run_in_child.h"
#include "rime/test/validation.h"
#if RIME_ACCURACY_SURFACE
#include "rime/surface/frame_input.h"
#include "rime/surface/reconstruct.h"
#endif

using namespace rime;
using nlohmann::json;

namespace {

constexpr double kA = 0.25;           // column width, m (height 2a)
constexpr double kDepth = 0.075;      // channel depth, m (6 particles at the base spacing)
constexpr int kBasePerA = 20;         // base resolution: a = 20 d_p (d_p = 12.5 mm)
constexpr double kSampleEvery = 0.1;  // s: the front is compared at 0.1, 0.2, ... s

struct Setting {
  std::string group, label;
  io::Scene scene;
  int per_a = kBasePerA;
  bool freezing = false;
  std::string snapshot;    // freezing reference: where to write its last frame (voxel-size sweep)
  double voxel_ratio = 0;  // voxel-size sweep: voxel / d_p
};

// Production defaults, or a preset's knobs taken from the scene parser (one source of truth).
io::Scene BaseScene(const std::string& quality, int per_a, bool freezing) {
  io::Scene preset;
  if (!quality.empty()) preset = io::ParseScene("[scene]\nquality = \"" + quality + "\"\n", "preset.toml");
  const double dp = kA / per_a;
  const int ny = std::max(2, int(std::lround(kDepth / dp)));
  io::Scene scene = sph::test::ColumnScene(dp, per_a, ny, 2 * per_a, 0);
  scene.solver = preset.solver;
  scene.fluid.precision = preset.fluid.precision;
  scene.fluid.smoothing_ratio = preset.fluid.smoothing_ratio;
  scene.solver.time_step = rime::io::TimeStep::kCfl;
  scene.modules = {"gravity"};
  if (freezing) {
    // The examples' calibrated thresholds; the tank walls and floor are the cold solid.
    scene.modules.insert("freezing");
    scene.freezing.glaze_threshold = 0.05;
    scene.freezing.icicle_threshold = 0.01;
  }
  return scene;
}

// Surge front: the furthest particle along x with at least 3 others within 2 d_p (spray ahead of
// the surge does not count), as z/a from the water's initial back face (walls act 0.6 d_p out).
template <class T>
double FrontZ(const std::vector<Vec3<T>>& x, double dp) {
  std::vector<int> order(x.size());
  for (int i = 0; i < int(x.size()); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](int a, int b) { return x[a].x > x[b].x; });
  const double r2 = 4 * dp * dp;
  for (int i : order) {
    int count = 0;
    for (int n = 0; n < int(x.size()) && count < 3; ++n)
      if (n != i && SquaredNorm(Vec3d(x[n]) - Vec3d(x[i])) < r2) ++count;
    if (count >= 3) return (x[i].x + 0.5 * dp - 0.6 * dp) / kA;
  }
  return 0;
}

template <class T>
json RunSim(const Setting& s, double end_time) {
  const io::Scene& scene = s.scene;
  const double dp = scene.fluid.spacing;
  const double length = 6 * kA, depth = sph::test::BoxWidth(dp, std::max(2, int(std::lround(kDepth / dp)))), wall = 2.5 * kA;
  sph::Simulation<T> sim(scene, exec::Device::Cpu());
  sim.AddBoundaryObject(sph::test::BoxBoundary(dp, length, depth, wall), "box");
  sim.Initialize();
  const double mass = scene.fluid.particle_mass(), rho0 = scene.fluid.rest_density;
  // Volume from the density, counting only compression (free-surface particles have a kernel
  // deficit that is not volume gain): V = sum m / max(rho, rho0).
  auto volume = [&] {
    double v = 0;
    for (T rho : sim.Densities()) v += mass / std::max(double(rho), rho0);
    return v;
  };
  const auto t0 = std::chrono::steady_clock::now();
  double err_sum = 0, err_max = 0, measured_sum = 0;
  long long iterations = 0, steps = 0, unconverged = 0;
  double volume0 = -1;
  std::vector<double> front;
  bool diverged = false;
  std::string failure;
  try {
    for (int k = 1; k * kSampleEvery <= end_time + 1e-9; ++k) {
      const double stop = k * kSampleEvery;
      while (sim.time() < stop - 1e-12) {
        const sph::StepStats st = sim.Step(sim.NextTimeStep(stop));
        if (volume0 < 0) volume0 = volume();  // after the first step: densities exist
        err_sum += st.average_density_error, err_max = std::max(err_max, st.max_density_error);
        measured_sum += st.measured_density_error;
        iterations += st.pressure_iterations, ++steps, unconverged += st.converged ? 0 : 1;
      }
      front.push_back(FrontZ(sim.Positions(), dp));
    }
  } catch (const std::exception& e) {
    diverged = true, failure = e.what();
  }
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  json r = {{"wall_s", wall_s},
            {"steps", steps},
            {"mean_iterations", steps ? double(iterations) / steps : 0.0},
            {"unconverged_steps", unconverged},
            {"mean_density_error", steps ? err_sum / steps : 0.0},
            {"max_density_error", err_max},
            {"mean_measured_density_error", steps ? measured_sum / steps : 0.0},
            {"volume_drift", diverged ? 0.0 : volume() / volume0 - 1},
            {"front_z", front},
            {"fluid", sim.fluid_count()},
            {"ice", sim.ice_count()},
            {"diverged", diverged},
            {"failure", failure},
            {"dp", dp},
            {"threads", exec::CpuThreads()}};
  if (s.freezing && !diverged) {
    const io::ParticleFrame frame = sim.Snapshot(0);
    const auto& phase = frame.Get<std::uint8_t>("phase");
    const auto fx = frame.GetPositions<double>();
    std::vector<std::array<double, 3>> ice;
    for (std::size_t i = 0; i < fx.size(); ++i)
      if (phase[i] == std::uint8_t(io::Phase::kIce)) ice.push_back({fx[i].x, fx[i].y, fx[i].z});
    r["ice_positions"] = ice;
    if (!s.snapshot.empty()) io::WriteParticleFrame(s.snapshot, frame);  // input of the voxel-size sweep
  }
  // Final positions by id, for the comparison with the reference run at the same spacing.
  const auto x = sim.Positions();
  const auto ids = sim.Ids();
  std::vector<std::vector<double>> by_id;
  for (std::size_t i = 0; i < x.size(); ++i) by_id.push_back({double(ids[i]), double(x[i].x), double(x[i].y), double(x[i].z)});
  r["positions"] = by_id;
  return r;
}

// Hydrostatic column with the setting's solver knobs (0.5 m high, 0.4 a wide per side but at least
// 8 particles, so the fit keeps some columns 2.5 d_p from the walls; d_p from the setting's
// resolution). The lattice start is not at rest: inviscid, the column still sloshes
// at 0.15-0.29 m/s after 6 s, which made the slope wander by ±4 % between settings. So the spec's
// viscosity is on (gravity alone on the dam break), and the column settles and is then averaged
// as the validation program's (3 s each); each particle's pressure and height are averaged, and
// p(z) is fitted over the particles at least 2.5 d_p from the walls, floor and surface. Returns the slope's relative error against −ρ0 g,
// the same fitted on either half of the window (their half-difference estimates the figure's noise) and the fastest particle at the end.
template <class T>
json RunHydrostatic(const Setting& s) {
  const int layers = s.per_a, across = std::max(8, int(std::lround(0.4 * s.per_a)));
  const double dp = 0.5 / layers;
  io::Scene scene = sph::test::ColumnScene(dp, across, across, layers, 0);
  scene.solver = s.scene.solver;
  scene.fluid.precision = s.scene.fluid.precision;
  scene.fluid.smoothing_ratio = s.scene.fluid.smoothing_ratio;
  scene.modules = {"gravity", "viscosity"};
  const double width = sph::test::BoxWidth(dp, across);
  sph::Simulation<T> sim(scene, exec::Device::Cpu());
  sim.AddBoundaryObject(sph::test::BoxBoundary(dp, width, width, 0.6), "box");
  sim.Initialize();
  const double settle = validation::kHydrostaticSettle, average = validation::kHydrostaticAverage;
  const double rho0 = scene.fluid.rest_density, g = 9.81;
  // Per particle: pressure and height sums and the step count, for each half of the window.
  struct Sums {
    double p = 0, z = 0, n = 0;
  };
  std::map<std::int64_t, std::array<Sums, 2>> sums;
  try {
    while (sim.time() < settle - 1e-9) sim.Step(sim.NextTimeStep(settle));
    while (sim.time() < settle + average - 1e-9) {
      sim.Step(sim.NextTimeStep(settle + average));
      const int half = sim.time() <= settle + 0.5 * average ? 0 : 1;
      const auto x = sim.Positions();
      const auto p = sim.Pressures();
      const auto id = sim.Ids();
      for (std::size_t i = 0; i < x.size(); ++i) {
        Sums& a = sums[id[i]][half];
        a.p += p[i], a.z += x[i].z, a.n += 1;
      }
    }
  } catch (const std::exception& e) {
    return {{"hydro_diverged", true}, {"hydro_failure", e.what()}};
  }
  const auto x_end = sim.Positions();
  std::map<std::int64_t, Vec3d> final_x;
  const auto ids = sim.Ids();
  for (std::size_t i = 0; i < x_end.size(); ++i) final_x[ids[i]] = Vec3d(x_end[i]);
  // Slope error of the fit over halves `first`..`last` of the window (0..1: all of it).
  auto slope_error = [&](int first, int last) {
    std::map<std::int64_t, Sums> window;  // per particle, over those halves
    double top = 0;
    for (const auto& [id, h] : sums) {
      Sums& a = window[id];
      for (int k = first; k <= last; ++k) a.p += h[k].p, a.z += h[k].z, a.n += h[k].n;
      top = std::max(top, a.z / a.n);
    }
    std::vector<double> z, p;
    for (const auto& [id, a] : window) {
      const double zi = a.z / a.n;
      const Vec3d xi = final_x[id];
      if (zi < 3.1 * dp || zi > top - 2.5 * dp || xi.x < 2.5 * dp || xi.x > width - 2.5 * dp || xi.y < 2.5 * dp || xi.y > width - 2.5 * dp)
        continue;
      z.push_back(zi), p.push_back(a.p / a.n);
    }
    return std::pair{-validation::FitLine(z, p).slope / (rho0 * g) - 1, z.size()};
  };
  const auto [error, particles] = slope_error(0, 1);
  const double noise = 0.5 * std::fabs(slope_error(0, 0).first - slope_error(1, 1).first);
  double max_speed = 0;
  for (const auto& v : sim.Velocities()) max_speed = std::max(max_speed, double(Norm(v)));
  return {{"hydro_slope_error", error}, {"hydro_noise", noise}, {"hydro_max_speed", max_speed}, {"hydro_particles", particles}};
}

// Symmetric mean nearest-neighbour distance between two point sets (brute force: a few thousand
// ice particles each), m; NaN when either is empty.
double ChamferDistance(const json& a, const json& b) {
  auto load = [](const json& j) {
    std::vector<Vec3d> v;
    for (const auto& p : j) v.push_back({p[0].get<double>(), p[1].get<double>(), p[2].get<double>()});
    return v;
  };
  const std::vector<Vec3d> pa = load(a), pb = load(b);
  if (pa.empty() || pb.empty()) return NAN;
  auto mean_nearest = [](const std::vector<Vec3d>& from, const std::vector<Vec3d>& to) {
    double sum = 0;
    for (const Vec3d& p : from) {
      double best = INFINITY;
      for (const Vec3d& q : to) best = std::min(best, SquaredNorm(p - q));
      sum += std::sqrt(best);
    }
    return sum / double(from.size());
  };
  return 0.5 * (mean_nearest(pa, pb) + mean_nearest(pb, pa));
}

// User + system CPU time of a rusage record, s.
enum class Job { kDamBreak, kHydrostatic, kVoxelSweep };

// Surface reconstruction of the freezing reference's ice (its last frame, default ellipsoid field)
// at voxel = ratio·d_p: cost, and the distance of its mesh from the finest (ratio kFinestVoxel)
// level set, sampled at the mesh's vertices, in d_p.
constexpr double kFinestVoxel = 0.2;
json RunVoxelSweep(const Setting& s) {
#if RIME_ACCURACY_SURFACE
  std::vector<std::string> warnings;
  const io::ParticleFrame frame = io::ReadParticleFrame(s.snapshot);
  const surface::ParticleSet ice = surface::SelectPhase(frame, io::Phase::kIce, {}, warnings);
  surface::Settings settings;
  settings.voxel_ratio = s.voxel_ratio;
  const auto t0 = std::chrono::steady_clock::now();
  const surface::Result coarse = surface::Reconstruct(ice, settings);
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  json r = {{"wall_s", wall_s},  {"surface_cpu_s", test::CpuSeconds(usage)}, {"surface_peak_rss_mib", usage.ru_maxrss / 1024.0},
            {"ice", ice.size()}, {"triangles", coarse.stats.triangles},      {"voxel_size", coarse.stats.voxel_size}};
  settings.voxel_ratio = kFinestVoxel;
  const surface::Result fine = surface::Reconstruct(ice, settings);
  std::vector<Vec3d> vertices(coarse.mesh.positions.begin(), coarse.mesh.positions.end());
  std::vector<double> d;
  for (const float phi : surface::SampleSurface(fine, vertices)) d.push_back(std::fabs(phi) / ice.spacing);
  std::sort(d.begin(), d.end());
  double mean = 0;
  for (const double x : d) mean += x / double(d.size());
  r["surface_error_mean_dp"] = d.empty() ? NAN : mean;
  r["surface_error_p95_dp"] = d.empty() ? NAN : d[d.size() * 95 / 100];
  return r;
#else
  (void)s;
  return {{"diverged", true}, {"failure", "built without rime_surface"}};
#endif
}

json RunJob(Job job, const Setting& s, double end_time) {
  const bool dbl = s.scene.fluid.precision == rime::io::Precision::kDouble;
  switch (job) {
    case Job::kDamBreak:
      return dbl ? RunSim<double>(s, end_time) : RunSim<float>(s, end_time);
    case Job::kHydrostatic:
      return dbl ? RunHydrostatic<double>(s) : RunHydrostatic<float>(s);
    case Job::kVoxelSweep:
      return RunVoxelSweep(s);
  }
  return {};
}

// One run in a child process: its JSON, with the child's own CPU time and peak RSS added.
json RunChild(const Setting& s, double end_time, int threads, Job job = Job::kDamBreak) {
  const test::ChildResult child = test::RunInChild([&] {
    json r;
    try {
      exec::SetCpuThreads(threads);
      r = RunJob(job, s, end_time);
    } catch (const std::exception& e) {
      r = {{"diverged", true}, {"failure", e.what()}};
    }
    return r.dump();
  });
  json r = child.output.empty() ? json{{"diverged", true}, {"failure", "child crashed"}} : json::parse(child.output);
  r["cpu_s"] = test::CpuSeconds(child.usage);
  r["peak_rss_mib"] = child.usage.ru_maxrss / 1024.0;
  return r;
}

using test::Median;

std::vector<Setting> Settings(bool with_freezing) {
  std::vector<Setting> v;
  auto add = [&](std::string group, std::string label, auto edit, int per_a = kBasePerA, std::string quality = "", bool fr = false) {
    Setting s{group, label, BaseScene(quality, per_a, fr), per_a, fr, "", 0.0};
    edit(s.scene);
    v.push_back(s);
  };
  auto none = [](io::Scene&) {};
  // The reference: the finest solver settings at the base spacing (double, eta 1e-5, CFL 0.1).
  auto reference = [](io::Scene& sc) {
    sc.solver.eta = 1e-5, sc.solver.cfl = 0.1, sc.solver.dt_max = 0.001, sc.solver.max_iterations = 2000;
    sc.fluid.precision = rime::io::Precision::kDouble;
  };
  add("reference", "reference (double, eta 1e-5, CFL 0.1, dt_max 1 ms)", reference);
  add("default", "production defaults", none);
  for (double eta : {1e-2, 3e-3, 3e-4, 1e-4})
    add("eta", "eta " + fmt::format("{:g}", eta), [=](io::Scene& sc) { sc.solver.eta = eta, sc.solver.max_iterations = 1000; });
  for (double cfl : {0.2, 0.6}) add("cfl", fmt::format("CFL {:g}", cfl), [=](io::Scene& sc) { sc.solver.cfl = cfl; });
  for (double dtm : {0.002, 0.01}) add("dt_max", fmt::format("dt_max {:g} ms", 1e3 * dtm), [=](io::Scene& sc) { sc.solver.dt_max = dtm; });
  for (int per_a : {14, 28}) add("spacing", fmt::format("a = {} d_p", per_a), none, per_a);
  add("min_iterations", "min 2 iterations (Ihmsen; the default is 3)", [](io::Scene& sc) { sc.solver.min_iterations = 2; });
  for (double w : {0.3, 0.7}) add("omega", fmt::format("omega {:g}", w), [=](io::Scene& sc) { sc.solver.omega = w; });
  add("kernel", "h = 1.2 d_p", [](io::Scene& sc) { sc.fluid.smoothing_ratio = 1.2; });
  add("precision", "double", [](io::Scene& sc) { sc.fluid.precision = rime::io::Precision::kDouble; });
  // Spec §6's two boundary terms of a_ii: the default counts wall particles as pushed by p_i, which
  // leaves water next to walls compressed whatever η is (the measured density error column).
  for (double eta : {1e-3, 1e-4})
    add("aii", fmt::format("a_ii consistent, eta {:g}", eta), [=](io::Scene& sc) {
      sc.solver.aii_boundary = rime::io::AiiBoundary::kConsistent, sc.solver.eta = eta, sc.solver.max_iterations = 1000;
    });
  for (const char* q : {"preview", "production", "reference"}) add("preset", std::string("preset ") + q, none, kBasePerA, q);
  // Preset candidates (combinations of the knobs above).
  auto combo = [](double eta, double cfl, double dt_max, int max_it, const char* precision) {
    return [=](io::Scene& sc) {
      sc.solver.eta = eta, sc.solver.cfl = cfl, sc.solver.dt_max = dt_max, sc.solver.max_iterations = max_it;
      rime::io::ParseEnum(precision, sc.fluid.precision);
    };
  };
  add("candidate", "eta 1e-2, CFL 0.6, dt_max 6 ms", combo(1e-2, 0.6, 0.006, 100, "float"));
  add("candidate", "eta 1e-2, CFL 0.6, dt_max 10 ms, <=100 it", combo(1e-2, 0.6, 0.01, 100, "float"));
  add("candidate", "eta 3e-3, CFL 0.6, dt_max 6 ms", combo(3e-3, 0.6, 0.006, 100, "float"));
  add("candidate", "eta 1e-3, CFL 0.6, dt_max 2 ms", combo(1e-3, 0.6, 0.002, 100, "float"));
  add("candidate", "eta 1e-3, CFL 0.4, dt_max 3 ms", combo(1e-3, 0.4, 0.003, 100, "float"));
  add("candidate", "eta 1e-4, CFL 0.2, dt_max 2 ms, float", combo(1e-4, 0.2, 0.002, 500, "float"));
  add("candidate", "eta 3e-4, CFL 0.2, dt_max 1 ms, double", combo(3e-4, 0.2, 0.001, 500, "double"));
  if (with_freezing) {
    add("freezing", "freezing: reference", reference, kBasePerA, "", true);
    for (const char* q : {"preview", "production", "reference"})
      add("freezing", std::string("freezing: preset ") + q, none, kBasePerA, q, true);
  }
  return v;
}

// results.csv's columns, each named once beside the value it writes, so that the header and the
// rows cannot drift apart. plot.gp reads the columns by position: append new ones at the end.
struct CsvColumn {
  const char* name;
  std::function<void(std::ostream&, const json&)> write;
};

std::vector<CsvColumn> CsvColumns() {
  const auto text = [](const char* k) { return [k](std::ostream& o, const json& r) { o << r.at(k).get<std::string>(); }; };
  const auto raw = [](const char* k) { return [k](std::ostream& o, const json& r) { o << r.at(k); }; };  // as JSON writes it
  const auto real = [](const char* k, double missing) {
    return [k, missing](std::ostream& o, const json& r) { o << r.value(k, missing); };
  };
  const auto count = [](const char* k) { return [k](std::ostream& o, const json& r) { o << r.value(k, 0LL); }; };
  const auto at = [](const char* k) { return [k](std::ostream& o, const json& r) { o << r.at(k).get<double>(); }; };
  return {{"group", text("group")},
          {"label", [](std::ostream& o, const json& r) { o << '"' << r.at("label").get<std::string>() << '"'; }},
          {"water", count("fluid")},
          {"dp", real("dp", 0.0)},
          {"eta", raw("eta")},
          {"cfl", raw("cfl")},
          {"dt_max", raw("dt_max")},
          {"omega", raw("omega")},
          {"smoothing_ratio", raw("smoothing_ratio")},
          {"precision", text("precision")},
          {"wall_s", raw("wall_s")},
          {"cpu_s", raw("cpu_s")},
          {"steps", count("steps")},
          {"mean_iterations", real("mean_iterations", 0.0)},
          {"peak_rss_mib", raw("peak_rss_mib")},
          {"mean_density_error", real("mean_density_error", 0.0)},
          {"max_density_error", real("max_density_error", 0.0)},
          {"volume_drift", real("volume_drift", 0.0)},
          {"front_error_mean", at("front_error_mean")},
          {"front_error_max", at("front_error_max")},
          {"front_position_diff_dp", at("front_position_diff_dp")},
          {"ice", count("ice")},
          {"ice_diff", at("ice_diff")},
          {"diverged", [](std::ostream& o, const json& r) { o << (r.value("diverged", false) ? 1 : 0); }},
          {"hydro_slope_error", real("hydro_slope_error", NAN)},
          {"hydro_max_speed", real("hydro_max_speed", NAN)},
          {"ice_shape_diff_dp", real("ice_shape_diff_dp", NAN)},
          {"mean_measured_density_error", real("mean_measured_density_error", 0.0)},
          {"hydro_noise", real("hydro_noise", NAN)}};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Rime speed/accuracy study (dam break over the solver knobs)"};
  int repeats = 3, threads = 0, freezing_repeats = 1;
  double end_time = 0.4;
  std::string out_dir = RIME_BENCH_OUTPUT_DIR, only;
  bool no_freezing = false, no_plots = false, no_hydrostatic = false, no_surface = false;
  app.add_option("--repeats", repeats, "Runs per setting (median time reported)");
  app.add_option("--end", end_time, "Simulated time, s (front sampled every 0.1 s)");
  app.add_option("-j,--threads", threads, "CPU threads (default all)");
  app.add_option("--out", out_dir, "Folder for results.csv, results.json and the plots");
  app.add_option("--only", only, "Run only this group (and the reference)");
  app.add_option("--freezing-repeats", freezing_repeats, "Runs per freezing setting (slow: the reference takes minutes)");
  app.add_flag("--no-freezing", no_freezing, "Skip the freezing scene");
  app.add_flag("--no-plots", no_plots, "Do not call gnuplot");
  app.add_flag("--no-hydrostatic", no_hydrostatic, "Skip the hydrostatic column run of each setting");
  app.add_flag("--no-surface", no_surface, "Skip the reconstruction voxel-size sweep on the freezing reference's ice");
  CLI11_PARSE(app, argc, argv);
  std::filesystem::create_directories(out_dir);
  const std::string load_before = test::LoadAverages();
  const unsigned hw = std::thread::hardware_concurrency();
  const int used_threads = threads > 0 ? threads : int(hw);

  std::vector<Setting> settings = Settings(!no_freezing);
  // The freezing reference's last frame, input of the voxel-size sweep; removed at the end.
  const std::string snapshot = (std::filesystem::path(out_dir) / fmt::format("freezing-reference.{}.h5part", getpid())).string();
  for (Setting& s : settings)
    if (s.label == "freezing: reference") s.snapshot = snapshot;
  std::vector<json> rows;
  json ref, fref;  // reference runs (plain, freezing)
  for (const Setting& s : settings) {
    if (!only.empty() && s.group != only && s.group != "reference" && !(only == "freezing" && s.label == "freezing: reference")) continue;
    std::vector<double> wall, cpu, rss;
    json first;
    for (int k = 0; k < (s.freezing ? freezing_repeats : repeats); ++k) {
      json r = RunChild(s, end_time, threads);
      if (k == 0) first = r;
      wall.push_back(r.value("wall_s", 0.0)), cpu.push_back(r["cpu_s"]), rss.push_back(r["peak_rss_mib"]);
      if (r.value("diverged", false)) break;
    }
    json row = first;
    if (!s.freezing && !no_hydrostatic && !row.value("diverged", false)) row.update(RunChild(s, end_time, threads, Job::kHydrostatic));
    row["group"] = s.group, row["label"] = s.label;
    row["eta"] = s.scene.solver.eta, row["cfl"] = s.scene.solver.cfl, row["dt_max"] = s.scene.solver.dt_max;
    row["omega"] = s.scene.solver.omega, row["smoothing_ratio"] = s.scene.fluid.smoothing_ratio;
    row["precision"] = std::string(rime::io::EnumName(s.scene.fluid.precision)), row["per_a"] = s.per_a,
    row["max_iterations"] = s.scene.solver.max_iterations;
    row["wall_s"] = Median(wall), row["cpu_s"] = Median(cpu), row["peak_rss_mib"] = Median(rss), row["repeats"] = int(wall.size());
    if (s.label.rfind("reference (", 0) == 0) ref = row;
    if (s.label == "freezing: reference") fref = row;
    // Errors against the reference run of the same scene.
    const json& base = s.freezing ? fref : ref;
    double front_mean = 0, front_max = 0;
    const auto fz = row.value("front_z", std::vector<double>{}), fz_ref = base.value("front_z", std::vector<double>{});
    const std::size_t nf = std::min(fz.size(), fz_ref.size());
    for (std::size_t i = 0; i < nf; ++i) {
      const double e = std::fabs(fz[i] - fz_ref[i]) / fz_ref[i];
      front_mean += e / nf, front_max = std::max(front_max, e);
    }
    const bool diverged = row.value("diverged", false);
    row["front_error_mean"] = nf && !diverged ? front_mean : NAN;
    row["front_error_max"] = nf && !diverged ? front_max : NAN;
    // Mean distance of the front particles (the 10 % furthest along x in the reference) from
    // their reference positions, in d_p; only at the reference's spacing (same particle ids).
    double pos_diff = NAN;
    if (s.per_a == kBasePerA && base.contains("positions") && row.contains("positions") && !row["diverged"].get<bool>()) {
      std::map<long long, Vec3d> mine;
      for (const auto& p : row["positions"])
        mine[(long long)p[0].get<double>()] = {p[1].get<double>(), p[2].get<double>(), p[3].get<double>()};
      std::vector<std::pair<double, long long>> by_x;
      std::map<long long, Vec3d> theirs;
      for (const auto& p : base["positions"]) {
        theirs[(long long)p[0].get<double>()] = {p[1].get<double>(), p[2].get<double>(), p[3].get<double>()};
        by_x.push_back({p[1].get<double>(), (long long)p[0].get<double>()});
      }
      std::sort(by_x.rbegin(), by_x.rend());
      const std::size_t n = std::max<std::size_t>(1, by_x.size() / 10);
      double sum = 0;
      std::size_t count = 0;
      for (std::size_t i = 0; i < n; ++i) {
        auto it = mine.find(by_x[i].second);
        if (it == mine.end()) continue;
        sum += Norm(it->second - theirs[by_x[i].second]), ++count;
      }
      if (count) pos_diff = sum / count / row["dp"].get<double>();
    }
    row["front_position_diff_dp"] = pos_diff;
    row["ice_diff"] = s.freezing && base.contains("ice") ? double(row.value("ice", 0LL) - base.value("ice", 0LL)) : NAN;
    if (s.freezing) {  // water turns to ice: the dam-break measures do not apply
      for (const char* key : {"front_error_mean", "front_error_max", "front_position_diff_dp", "volume_drift"}) row[key] = NAN;
    }
    row["ice_shape_diff_dp"] = s.freezing && row.contains("ice_positions") && base.contains("ice_positions")
                                   ? ChamferDistance(row["ice_positions"], base["ice_positions"]) / row["dp"].get<double>()
                                   : NAN;
    std::fprintf(stderr, "  %-52s %6.2f s wall  %5lld steps  front err %5.1f%%\n", s.label.c_str(), row["wall_s"].get<double>(),
                 row.value("steps", 0LL), 100 * front_mean);
    if (diverged) std::fprintf(stderr, "    diverged: %s\n", row.value("failure", std::string()).c_str());
    rows.push_back(row);
  }

  // Reconstruction voxel size, on the freezing reference's ice (the surface stage's own knob).
  std::vector<json> surface_rows;
  const bool reference_has_ice = fref.value("ice", 0LL) > 0;
  if (!no_surface && std::filesystem::exists(snapshot) && !reference_has_ice)
    std::fprintf(stderr, "  voxel sweep skipped: the freezing reference made no ice by %.2f s\n", end_time);
  if (!no_surface && std::filesystem::exists(snapshot) && reference_has_ice) {
    for (const double ratio : {1.0, 0.75, 0.5, 0.35, kFinestVoxel}) {
      Setting s;
      s.snapshot = snapshot, s.voxel_ratio = ratio;
      std::vector<double> wall, cpu, rss;
      json first;
      for (int k = 0; k < repeats; ++k) {
        json r = RunChild(s, end_time, threads, Job::kVoxelSweep);
        if (r.value("diverged", false)) {
          first = r;
          break;
        }
        if (k == 0) first = r;
        wall.push_back(r["wall_s"]), cpu.push_back(r["surface_cpu_s"]), rss.push_back(r["surface_peak_rss_mib"]);
      }
      if (first.value("diverged", false)) {
        std::fprintf(stderr, "  voxel sweep skipped: %s\n", first.value("failure", std::string()).c_str());
        break;
      }
      first["voxel_ratio"] = ratio;
      first["wall_s"] = Median(wall), first["surface_cpu_s"] = Median(cpu), first["surface_peak_rss_mib"] = Median(rss);
      std::fprintf(stderr, "  voxel %.2f d_p                                        %6.2f s wall\n", ratio, first["wall_s"].get<double>());
      surface_rows.push_back(first);
    }
  }

  std::filesystem::remove(snapshot);
  const std::string load_after = test::LoadAverages();
  std::printf(
      "\nRime speed/accuracy study: dam break a = %.2f m (height 2a), %.2f s simulated, %d CPU threads, median of %d runs; "
      "load average before %s, after %s\n",
      kA, end_time, used_threads, repeats, load_before.c_str(), load_after.c_str());
  std::printf(
      "errors against the reference run of the same scene; front error = |Z - Z_ref| / Z_ref at 0.1 s intervals; "
      "pos = mean displacement of the front's particles from the reference, in d_p; hydro%% = hydrostatic slope error "
      "(column 0.5 m, same knobs), +- its noise (half the difference between the two halves of the averaging window); ice shape = "
      "symmetric mean nearest distance to the reference's ice, in d_p\n");
  std::printf("%-46s %7s %6s %7s %6s %6s %8s %8s %8s %8s %7s %7s %6s %6s %7s %5s %6s %6s\n", "setting", "water", "wall s", "CPU s", "steps",
              "iter", "MiB", "rho avg%", "rho max%", "meas avg%", "vol %", "front%", "max%", "pos", "hydro%", "+-", "ice", "shape");
  std::ofstream csv(out_dir + "/results.csv");
  const std::vector<CsvColumn> columns = CsvColumns();
  for (std::size_t c = 0; c < columns.size(); ++c) csv << (c ? "," : "") << columns[c].name;
  csv << "\n";
  json out = json::array();
  for (json& r : rows) {
    const bool div = r.value("diverged", false);
    const double hydro = r.value("hydro_slope_error", NAN), hydro_noise = r.value("hydro_noise", NAN);
    const double shape = r.value("ice_shape_diff_dp", NAN);
    std::printf(
        "%-46s %7lld %6.2f %7.2f %6lld %6.1f %8.0f %8.3f %8.2f %9.3f %7.3f %7.2f %6.2f %6.2f %7.2f %5.2f %6s %6.2f%s\n",
        r["label"].get<std::string>().c_str(), r.value("fluid", 0LL), r["wall_s"].get<double>(), r["cpu_s"].get<double>(),
        r.value("steps", 0LL), r.value("mean_iterations", 0.0), r["peak_rss_mib"].get<double>(), 100 * r.value("mean_density_error", 0.0),
        100 * r.value("max_density_error", 0.0), 100 * r.value("mean_measured_density_error", 0.0), 100 * r.value("volume_drift", 0.0),
        100 * r["front_error_mean"].get<double>(), 100 * r["front_error_max"].get<double>(), r["front_position_diff_dp"].get<double>(),
        100 * hydro, 100 * hydro_noise, r["group"] == "freezing" ? std::to_string(r.value("ice", 0LL)).c_str() : "-", shape,
        div ? "  DIVERGED" : (r.value("hydro_diverged", false) ? "  hydrostatic column DIVERGED" : ""));
    for (std::size_t c = 0; c < columns.size(); ++c) {
      if (c) csv << ",";
      columns[c].write(csv, r);
    }
    csv << "\n";
    r.erase("positions");
    r.erase("ice_positions");
    out.push_back(r);
  }
  csv.close();
  if (!surface_rows.empty()) {
    std::printf(
        "\nReconstruction voxel size (freezing reference's %lld ice particles, ellipsoid field; error = distance of the mesh "
        "from the level set at voxel %.2f d_p, at the mesh's vertices, in d_p; median of %d runs):\n",
        surface_rows[0].value("ice", 0LL), kFinestVoxel, repeats);
    std::printf("%-14s %10s %8s %8s %10s %10s %10s\n", "voxel / d_p", "wall s", "CPU s", "MiB", "triangles", "err mean", "err p95");
    std::ofstream scsv(out_dir + "/surface.csv");
    scsv << "voxel_ratio,voxel_size,wall_s,cpu_s,peak_rss_mib,triangles,error_mean_dp,error_p95_dp\n";
    for (const json& r : surface_rows) {
      std::printf("%-14.2f %10.3f %8.3f %8.0f %10llu %10.3f %10.3f\n", r["voxel_ratio"].get<double>(), r["wall_s"].get<double>(),
                  r["surface_cpu_s"].get<double>(), r["surface_peak_rss_mib"].get<double>(), r["triangles"].get<unsigned long long>(),
                  r["surface_error_mean_dp"].get<double>(), r["surface_error_p95_dp"].get<double>());
      scsv << r["voxel_ratio"] << "," << r["voxel_size"] << "," << r["wall_s"] << "," << r["surface_cpu_s"] << ","
           << r["surface_peak_rss_mib"] << "," << r["triangles"] << "," << r["surface_error_mean_dp"] << "," << r["surface_error_p95_dp"]
           << "\n";
    }
  }
  json doc = {{"study", "dam break speed/accuracy"},
              {"machine", test::MachineDescription()},
              {"commit", test::SourceCommit(RIME_SOURCE_DIR)},
              {"column_width_m", kA},
              {"end_time_s", end_time},
              {"threads", used_threads},
              {"repeats", repeats},
              {"load_average_before", load_before},
              {"load_average_after", load_after},
              {"runs", out},
              {"voxel_sweep", surface_rows}};
  std::ofstream(out_dir + "/results.json") << doc.dump(2) << "\n";
  std::printf("wrote %s/results.csv and %s/results.json\n", out_dir.c_str(), out_dir.c_str());

  if (no_plots) return 0;
  if (std::system("command -v gnuplot > /dev/null 2>&1") != 0) {
    std::printf("gnuplot not found: plots skipped (apt-get install gnuplot-nox, then run plot.gp in %s)\n", out_dir.c_str());
    return 0;
  }
  const std::string cmd = "gnuplot -e \"dir='" + out_dir + "'\" " + std::string(RIME_ACCURACY_DIR) + "/plot.gp";
  if (std::system(cmd.c_str()) != 0) std::printf("gnuplot failed: %s\n", cmd.c_str());
  else std::printf("wrote %s/pareto_*.png\n", out_dir.c_str());
  return 0;
}
