// Simulation benchmark: the PERFORMANCE.md dam break (1x1x1 m block in the corner of a 4x3x1.5 m
// box, fixed dt = 1 ms, eta = 0.1 %, Akinci boundaries at half spacing) at ~50k and ~200k water
// particles, with module variants side by side. Prints a table and writes JSON.
//   rime-bench-sim [--steps N] [--warmup N] [--repeats R] [--json FILE] [--quick] [--only NAME]
// The reference protocol (PERFORMANCE.md averages 1 s of simulated time from the start):
//   rime-bench-sim --warmup 0 --steps 1000 --repeats 1 --only "dam break 50k"
#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>

#include "rime/exec/device.h"
#include "rime/sph/simulation.h"
#include "../../../libs/sph/tests/test_scenes.h"

using namespace rime;

namespace {

struct Result {
  std::string name;
  std::int64_t particles = 0, boundary = 0;
  double ms_step = 0, us_particle_step = 0, neighbors = 0, forces = 0, pressure = 0, integration = 0, freezing = 0, iterations = 0;
  double memory_mib = 0;
};

io::Scene DamBreak(double dp, double block, std::vector<std::string> modules) {
  io::Scene scene;
  scene.fluid.spacing = dp;
  scene.modules = {modules.begin(), modules.end()};
  scene.solver.time_step = rime::io::TimeStep::kFixed;
  scene.solver.dt = 0.001;
  scene.solver.eta = 0.001;
  scene.freezing.glaze_threshold = 0.05;  // the examples' calibrated thresholds
  scene.freezing.icicle_threshold = 0.01;
  io::FluidBlock b;
  b.min = {1.1 * dp, 1.1 * dp, 1.1 * dp};
  const double n = std::floor(block / dp);
  b.max = b.min + Vec3d(n - 1, n - 1, n - 1) * dp;
  scene.fluid_blocks.push_back(b);
  io::SolidObject box;
  box.name = "box";
  scene.solids.push_back(box);
  return scene;
}

// The default minimum of 3 pressure iterations keeps settled water from breathing (README); this
// case, at Ihmsen's 2, shows what the third costs where 2 would do.
io::Scene MinIterations(io::Scene scene, int min_iterations) {
  scene.solver.min_iterations = min_iterations;
  return scene;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

Result Run(const std::string& name, const io::Scene& scene, int warmup, int steps, int repeats) {
  Result r;
  r.name = name;
  std::vector<double> ms, nb, fo, pr, in, fz, it;
  for (int rep = 0; rep < repeats; ++rep) {
    sph::Simulation<float> sim(scene, exec::Device::Cpu());
    sim.AddBoundaryObject(sph::test::BoxBoundary(scene.fluid.spacing, 4.0, 3.0, 1.5), "box");
    sim.Initialize();
    for (int s = 0; s < warmup; ++s) sim.Step(0.001);  // let the block start falling
    sim.EnableTimings(true);
    std::int64_t iterations = 0;
    const auto t0 = std::chrono::steady_clock::now();
    for (int s = 0; s < steps; ++s) iterations += sim.Step(0.001).pressure_iterations;
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const auto& t = sim.timings();
    ms.push_back(1e3 * wall / steps);
    nb.push_back(1e3 * t.neighbor_search / steps);
    fo.push_back(1e3 * t.non_pressure / steps);
    pr.push_back(1e3 * t.pressure_solve / steps);
    in.push_back(1e3 * t.integration / steps);
    fz.push_back(1e3 * t.freezing / steps);
    it.push_back(double(iterations) / steps);
    r.particles = sim.fluid_count();
    r.boundary = sim.boundary_count();
  }
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  r.memory_mib = usage.ru_maxrss / 1024.0;
  r.ms_step = Median(ms);
  r.us_particle_step = 1e3 * r.ms_step / double(r.particles);
  r.neighbors = Median(nb), r.forces = Median(fo), r.pressure = Median(pr), r.integration = Median(in), r.freezing = Median(fz), r.iterations = Median(it);
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Rime simulation benchmark (dam break)"};
  int steps = 50, warmup = 20, repeats = 3, threads = 0;
  std::string only;
  std::string json_path = "sim_bench.json";
  bool quick = false;
  app.add_option("--steps", steps, "Timed steps per run");
  app.add_option("--warmup", warmup, "Untimed steps before the timed ones (the block starts falling)");
  app.add_option("--only", only, "Run only the case of this name");
  app.add_option("--repeats", repeats, "Runs per case (the median is reported)");
  app.add_option("-j,--threads", threads, "CPU threads (default all)");
  app.add_option("--json", json_path, "JSON output file");
  app.add_flag("--quick", quick, "Only the 50k cases");
  CLI11_PARSE(app, argc, argv);
  exec::SetCpuThreads(threads);
  const double dp = 0.0264;
  std::vector<Result> results;
  const std::vector<std::pair<std::string, io::Scene>> cases = {
      {"dam break 50k", DamBreak(dp, 1.0, {"gravity"})},
      {"dam break 50k, min 2 iterations", MinIterations(DamBreak(dp, 1.0, {"gravity"}), 2)},
      {"dam break 50k + viscosity", DamBreak(dp, 1.0, {"gravity", "viscosity"})},
      {"dam break 50k + surface tension", DamBreak(dp, 1.0, {"gravity", "surface_tension"})},
      {"dam break 50k + viscosity + freezing", DamBreak(dp, 1.0, {"gravity", "viscosity", "freezing"})},
      {"dam break 200k", DamBreak(dp, 1.6, {"gravity"})}};
  for (const auto& [name, scene] : cases) {
    if (!only.empty() && name != only) continue;
    if (only.empty() && quick && name == "dam break 200k") continue;
    results.push_back(Run(name, scene, warmup, steps, repeats));
  }
  if (results.empty()) {
    std::fprintf(stderr, "rime-bench-sim: no case named \"%s\"\n", only.c_str());
    return 2;
  }
  std::printf("\nRime simulation benchmark, %d CPU threads, float, dt = 1 ms, eta = 0.1 %%, median of %d runs of %d steps after %d warm-up steps\n",
              exec::CpuThreads(), repeats, steps, warmup);
  std::printf("%-38s %8s %8s %9s %9s %8s %8s %8s %8s %8s %7s %9s\n", "case", "water", "boundary", "ms/step", "us/p-step", "neighb.",
              "forces", "pressure", "integr.", "freezing", "iter.", "peak MiB");
  nlohmann::json out = nlohmann::json::array();
  for (const Result& r : results) {
    std::printf("%-38s %8lld %8lld %9.2f %9.3f %8.2f %8.2f %8.2f %8.2f %8.2f %7.2f %9.0f\n", r.name.c_str(), (long long)r.particles,
                (long long)r.boundary, r.ms_step, r.us_particle_step, r.neighbors, r.forces, r.pressure, r.integration, r.freezing,
                r.iterations, r.memory_mib);
    out.push_back({{"case", r.name}, {"water_particles", r.particles}, {"boundary_particles", r.boundary}, {"ms_per_step", r.ms_step},
                   {"us_per_particle_step", r.us_particle_step}, {"neighbor_search_ms", r.neighbors}, {"non_pressure_ms", r.forces},
                   {"pressure_solve_ms", r.pressure}, {"integration_ms", r.integration}, {"freezing_ms", r.freezing},
                   {"pressure_iterations", r.iterations},
                   {"peak_memory_mib", r.memory_mib}, {"threads", exec::CpuThreads()}, {"warmup_steps", warmup}, {"timed_steps", steps},
                   {"repeats", repeats}});
  }
  std::ofstream(json_path) << out.dump(2) << "\n";
  std::printf("(peak memory is the process maximum so far, so it is cumulative down the table)\nwrote %s\n", json_path.c_str());
  return 0;
}
