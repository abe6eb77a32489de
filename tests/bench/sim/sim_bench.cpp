// Simulation benchmark: the PERFORMANCE.md dam break (1x1x1 m block in the corner of a 4x3x1.5 m
// box, fixed dt = 1 ms, eta = 0.1 %, Akinci boundaries at half spacing) at ~50k and ~200k water
// particles, with module variants side by side, and a mostly frozen block (1 % of it still water)
// beside the same block all liquid. Prints the split per phase, SPlisHSPlasH's figures on the same
// scene beside Rime's, and writes JSON.
//   rime-bench-sim [--steps N] [--warmup N] [--repeats R] [--json FILE] [--quick] [--only NAME]...
// The reference protocol (PERFORMANCE.md averages 1 s of simulated time from the start):
//   rime-bench-sim --warmup 0 --steps 1000 --repeats 1 --only "dam break 50k"
#include <sys/resource.h>

#include <cstdlib>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>

#include "rime/exec/device.h"
#include "rime/sph/simulation.h"
#include "rime/test/measure.h"
#include "rime/test/dam_break.h"

using namespace rime;

namespace {

using test::Median;

struct Result {
  std::string name;
  std::int64_t particles = 0, boundary = 0;
  std::int64_t ice = 0;
  double ms_step = 0, cpu_ms_step = 0, us_particle_step = 0, neighbors = 0, forces = 0, pressure = 0, integration = 0, freezing = 0,
         iterations = 0;
  double grid = 0, fluid_lists = 0, boundary_lists = 0, rest = 0;
  double memory_mib = 0;
};

// The shared dam break with a water cube of `block` metres a side.
io::Scene DamBreak(double block, std::set<std::string> modules) {
  return test::DamBreakScene(int(std::floor(block / test::kDamBreakSpacing)), std::move(modules));
}

// The default minimum of 3 pressure iterations keeps settled water from breathing (README); this
// case, at Ihmsen's 2, shows what the third costs where 2 would do.
io::Scene MinIterations(io::Scene scene, int min_iterations) {
  scene.solver.min_iterations = min_iterations;
  return scene;
}

// The mostly frozen case: a block of 37 x 37 x 36 ice particles (glaze on the floor, stacked as
// the dam break's water block) with 8 x 8 x 8 water particles resting on it, the same modules as
// the liquid freezing case. Built through a frame: the water rows of a plain start turn into ice.
constexpr int kStillWaterSide = 8;

io::Scene MostlyFrozen(double dp) {
  io::Scene scene = DamBreak(1.0, {"gravity", "viscosity", "freezing"});
  io::FluidBlock water;
  water.min = scene.fluid_blocks[0].min + Vec3d(14.5 * dp, 14.5 * dp, 36 * dp);  // centred on the ice, in its hollows
  water.max = water.min + Vec3d(kStillWaterSide - 1, kStillWaterSide - 1, kStillWaterSide - 1) * dp;
  scene.fluid_blocks[0].max.z = scene.fluid_blocks[0].min.z + 35 * dp;
  scene.fluid_blocks.push_back(water);
  return scene;
}

// Turns the water rows of the first block (those below `ice_top`) into ice at rest, with the water
// film that the water which froze left on the ice and on the floor around it.
void FreezeBlock(sph::Simulation<float>& sim, double dp, double ice_top) {
  io::ParticleFrame f = sim.Snapshot(0);
  auto& phase = std::get<std::vector<std::uint8_t>>(f.attributes.at("phase"));
  const auto& z = f.Get<float>("z");
  for (const char* c : {"local_0", "local_1", "local_2"}) f.Set(c, std::vector<float>(phase.size(), 0.0f));
  auto& local_x = std::get<std::vector<float>>(f.attributes.at("local_0"));
  auto& local_y = std::get<std::vector<float>>(f.attributes.at("local_1"));
  auto& local_z = std::get<std::vector<float>>(f.attributes.at("local_2"));
  auto& volume = std::get<std::vector<float>>(f.attributes.at("volume"));
  auto& kind = std::get<std::vector<std::uint8_t>>(f.attributes.at("ice_kind"));
  auto& film = std::get<std::vector<float>>(f.attributes.at("water_film"));
  const auto& x = f.Get<float>("x");
  const auto& y = f.Get<float>("y");
  const std::size_t water = std::size_t(sim.fluid_count());
  for (std::size_t i = 0; i < phase.size(); ++i) {
    local_x[i] = x[i], local_y[i] = y[i], local_z[i] = z[i];  // the box does not move: local = world
    const bool floor_near_ice = i >= water && z[i] < 0.5 * dp && x[i] < ice_top + dp && y[i] < ice_top + dp;
    if (floor_near_ice) film[i] = 0.5f;
    if (i >= water || z[i] > ice_top) continue;
    film[i] = 0.5f;
    phase[i] = static_cast<std::uint8_t>(io::Phase::kIce);
    volume[i] = float(dp * dp * dp);  // the ice volume cap, what lattice ice gets
    kind[i] = 1;                      // glaze
  }
  sim.Restore(f);
}

Result Run(const std::string& name, const io::Scene& scene, int warmup, int steps, int repeats, bool frozen = false) {
  Result r;
  r.name = name;
  std::vector<double> ms, cpu, nb, fo, pr, in, fz, it, gr, fl, bl, re;
  for (int rep = 0; rep < repeats; ++rep) {
    const std::unique_ptr<sph::Simulation<float>> made = test::MakeDamBreak(scene, exec::Device::Cpu());
    sph::Simulation<float>& sim = *made;
    if (frozen) FreezeBlock(sim, scene.fluid.spacing, scene.fluid_blocks[0].max.z + 0.5 * scene.fluid.spacing);
    for (int s = 0; s < warmup; ++s) sim.Step(0.001);  // let the block start falling
    sim.EnableTimings(true);
    std::int64_t iterations = 0;
    const auto t0 = std::chrono::steady_clock::now();
    const double cpu0 = test::ProcessCpuSeconds();
    for (int s = 0; s < steps; ++s) iterations += sim.Step(0.001).pressure_iterations;
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    cpu.push_back(1e3 * (test::ProcessCpuSeconds() - cpu0) / steps);
    const auto& t = sim.timings();
    ms.push_back(1e3 * wall / steps);
    nb.push_back(1e3 * t.neighbor_search / steps);
    fo.push_back(1e3 * t.non_pressure / steps);
    pr.push_back(1e3 * t.pressure_solve / steps);
    in.push_back(1e3 * t.integration / steps);
    fz.push_back(1e3 * t.freezing / steps);
    gr.push_back(1e3 * t.grid_build / steps);
    fl.push_back(1e3 * t.fluid_lists / steps);
    bl.push_back(1e3 * t.boundary_lists / steps);
    re.push_back(ms.back() - nb.back() - pr.back() - fz.back());
    it.push_back(double(iterations) / steps);
    r.particles = sim.fluid_count();
    r.boundary = sim.boundary_count();
    r.ice = sim.ice_count();
  }
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  r.memory_mib = usage.ru_maxrss / 1024.0;
  r.ms_step = Median(ms);
  r.cpu_ms_step = Median(cpu);
  r.us_particle_step = 1e3 * r.ms_step / double(r.particles);
  r.neighbors = Median(nb), r.forces = Median(fo), r.pressure = Median(pr), r.integration = Median(in), r.freezing = Median(fz),
  r.iterations = Median(it);
  r.grid = Median(gr), r.fluid_lists = Median(fl), r.boundary_lists = Median(bl), r.rest = Median(re);
  return r;
}

}  // namespace

// SPlisHSPlasH's IISPH on the same scene and machine kind (PERFORMANCE.md's side-by-side: 2 threads,
// minimum 2 iterations, η 0.1 %, 159k Poisson-disk boundary particles, the first simulated second).
constexpr double kReferenceStepMs[2] = {165, 205};
constexpr double kReferenceNeighborMs[2] = {49, 57};
constexpr double kReferencePressureMs = 58;

int main(int argc, char** argv) {
  CLI::App app{"Rime simulation benchmark (dam break)"};
  int steps = 50, warmup = 20, repeats = 3, threads = 0;
  std::vector<std::string> only;
  std::string json_path = RIME_BENCH_OUTPUT_DIR "/results.json";
  bool quick = false;
  app.add_option("--steps", steps, "Timed steps per run");
  app.add_option("--warmup", warmup, "Untimed steps before the timed ones (the block starts falling)");
  app.add_option("--only", only, "Run only the cases of these names (repeatable)");
  app.add_option("--repeats", repeats, "Runs per case (the median is reported)");
  app.add_option("-j,--threads", threads, "CPU threads (default all)");
  app.add_option("--json", json_path, "JSON output file")->capture_default_str();
  app.add_flag("--quick", quick, "Only the 50k cases");
  CLI11_PARSE(app, argc, argv);
  exec::SetCpuThreads(threads);
  const double dp = test::kDamBreakSpacing;
  const double load_before = test::LoadAverage();
  std::vector<Result> results;
  struct Case {
    std::string name;
    io::Scene scene;
    bool frozen = false;
  };
  const std::vector<Case> cases = {{"dam break 50k", DamBreak(1.0, {"gravity"})},
                                   {"dam break 50k, min 2 iterations", MinIterations(DamBreak(1.0, {"gravity"}), 2)},
                                   {"dam break 50k + viscosity", DamBreak(1.0, {"gravity", "viscosity"})},
                                   {"dam break 50k + surface tension", DamBreak(1.0, {"gravity", "surface_tension"})},
                                   {"dam break 50k + viscosity + freezing", DamBreak(1.0, {"gravity", "viscosity", "freezing"})},
                                   {"50k, 99 % frozen + viscosity + freezing", MostlyFrozen(dp), true},
                                   {"dam break 200k", DamBreak(1.6, {"gravity"})}};
  for (const Case& c : cases) {
    if (!only.empty() && std::find(only.begin(), only.end(), c.name) == only.end()) continue;
    if (only.empty() && quick && c.name == "dam break 200k") continue;
    results.push_back(Run(c.name, c.scene, warmup, steps, repeats, c.frozen));
  }
  if (results.empty()) {
    std::fprintf(stderr, "rime-bench-sim: no case of the names given\n");
    return 2;
  }
  const double load_after = test::LoadAverage();
  std::printf(
      "\nRime simulation benchmark, %d CPU threads, float, dt = 1 ms, eta = 0.1 %%, median of %d runs of %d steps after %d warm-up steps; "
      "load average %.2f before, %.2f after\n",
      exec::CpuThreads(), repeats, steps, warmup, load_before, load_after);
  std::printf(
      "milliseconds per step (wall; CPUms/st: CPU time of all threads); neighbour search = grid (binning, reordering) + ff and fb lists "
      "(each with its kernel values and "
      "gradients); rest = step - neighbours - pressure - freezing\n");
  std::printf("%-40s %6s %6s %7s %8s %8s %8s %6s %6s %6s %7s %8s %8s %6s %5s %7s %5s\n", "case", "water", "ice", "boundary", "ms/step",
              "CPUms/st", "us/p-step", "grid", "ff", "fb", "neighb.", "pressure", "freezing", "rest", "iter.", "peakMiB", "frz%");
  nlohmann::json out = nlohmann::json::array();
  for (const Result& r : results) {
    std::printf("%-40s %6lld %6lld %7lld %8.2f %8.2f %8.3f %6.2f %6.2f %6.2f %7.2f %8.2f %8.2f %6.2f %5.2f %7.0f %5.1f\n", r.name.c_str(),
                (long long)r.particles, (long long)r.ice, (long long)r.boundary, r.ms_step, r.cpu_ms_step, r.us_particle_step, r.grid,
                r.fluid_lists, r.boundary_lists, r.neighbors, r.pressure, r.freezing, r.rest, r.iterations, r.memory_mib,
                100 * r.freezing / r.ms_step);
    out.push_back({{"case", r.name},
                   {"water_particles", r.particles},
                   {"ice_particles", r.ice},
                   {"boundary_particles", r.boundary},
                   {"ms_per_step", r.ms_step},
                   {"cpu_ms_per_step", r.cpu_ms_step},
                   {"us_per_particle_step", r.us_particle_step},
                   {"neighbor_search_ms", r.neighbors},
                   {"grid_build_ms", r.grid},
                   {"fluid_lists_ms", r.fluid_lists},
                   {"boundary_lists_ms", r.boundary_lists},
                   {"non_pressure_ms", r.forces},
                   {"pressure_solve_ms", r.pressure},
                   {"integration_ms", r.integration},
                   {"freezing_ms", r.freezing},
                   {"rest_ms", r.rest},
                   {"pressure_iterations", r.iterations},
                   {"peak_memory_mib", r.memory_mib},
                   {"threads", exec::CpuThreads()},
                   {"warmup_steps", warmup},
                   {"timed_steps", steps},
                   {"repeats", repeats},
                   {"load_average_before", load_before},
                   {"load_average_after", load_after}});
  }
  std::printf(
      "%-40s %6d %6s %7s %4.0f-%3.0f %8s %8s %6s %6s %6s %3.0f-%3.0f %8.0f   (SPlisHSPlasH IISPH, same scene and machine kind, 2 threads, "
      "min 2 iterations, 159k boundary particles; PERFORMANCE.md)\n",
      "SPlisHSPlasH reference", 50653, "", "", kReferenceStepMs[0], kReferenceStepMs[1], "", "", "", "", "", kReferenceNeighborMs[0],
      kReferenceNeighborMs[1], kReferencePressureMs);
  out.push_back({{"case", "SPlisHSPlasH reference (PERFORMANCE.md)"},
                 {"ms_per_step_min", kReferenceStepMs[0]},
                 {"ms_per_step_max", kReferenceStepMs[1]},
                 {"neighbor_search_ms_min", kReferenceNeighborMs[0]},
                 {"neighbor_search_ms_max", kReferenceNeighborMs[1]},
                 {"pressure_solve_ms", kReferencePressureMs},
                 {"pressure_iterations", 2}});
  auto find = [&](const std::string& name) -> const Result* {
    for (const Result& r : results)
      if (r.name == name) return &r;
    return nullptr;
  };
  if (const Result* two = find("dam break 50k, min 2 iterations"))
    std::printf(
        "min 2 iterations: %.3f us per particle-step (target <= 0.55), %.1f-%.1fx SPlisHSPlasH's step; lists %.2f ms (target <= 5), "
        "neighbour search %.1f-%.1fx SPlisHSPlasH's\n",
        two->us_particle_step, kReferenceStepMs[0] / two->ms_step, kReferenceStepMs[1] / two->ms_step,
        two->fluid_lists + two->boundary_lists, kReferenceNeighborMs[0] / two->neighbors, kReferenceNeighborMs[1] / two->neighbors);
  const Result* liquid = find("dam break 50k + viscosity + freezing");
  const Result* frozen = find("50k, 99 % frozen + viscosity + freezing");
  if (liquid)
    std::printf("freezing share of the liquid freezing step: %.1f %% (target <= 25 %%)\n", 100 * liquid->freezing / liquid->ms_step);
  if (liquid && frozen)
    std::printf("mostly frozen step / liquid step: %.1f %% (target <= 15 %%)\n", 100 * frozen->ms_step / liquid->ms_step);
  std::ofstream(json_path) << nlohmann::json{{"benchmark", "sim"},
                                             {"machine", test::MachineDescription()},
                                             {"commit", test::SourceCommit(RIME_SOURCE_DIR)},
                                             {"threads", exec::CpuThreads()},
                                             {"load_average_before", load_before},
                                             {"load_average_after", load_after},
                                             {"results", out}}
                                  .dump(2)
                           << "\n";
  std::printf("(peak memory is the process maximum so far, so it is cumulative down the table)\nwrote %s\n", json_path.c_str());
  return 0;
}
