// rime-sim: simulates a scene's water (IISPH) around its solids and writes one H5Part frame per
// output frame; every frame is a complete checkpoint (--resume continues from the last one).
#include <csignal>
#include <filesystem>
#include <fstream>
#include <future>
#include <regex>

#include <fmt/format.h>

#include "rime/core/atomic_file.h"
#include "rime/core/error.h"
#include "rime/core/log.h"
#include "rime/core/memory_budget.h"
#include "rime/core/progress.h"
#include "rime/exec/device.h"
#include "rime/io/particles.h"
#include "rime/io/scene.h"
#include "rime/sph/simulation.h"
#include "memory_estimate.h"
#include "override_flags.h"
#include "tool.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

volatile std::sig_atomic_t g_interrupted = 0;
void OnInterrupt(int) { g_interrupted = 1; }

struct Options {
  std::string scene;
  std::string boundary_dir;
  std::string output;
  bool resume = false;
};

// The last frame file in `folder` that reads back completely (writes are atomic, but a file may
// come from an older, different run: it must at least open).
std::int64_t LastCompleteFrame(const fs::path& folder) {
  std::int64_t last = -1;
  if (!fs::exists(folder)) return last;
  static const std::regex pattern(R"(particles\.(\d+)\.h5part)");
  for (const auto& entry : fs::directory_iterator(folder)) {
    std::smatch m;
    const std::string name = entry.path().filename().string();
    if (std::regex_match(name, m, pattern)) last = std::max<std::int64_t>(last, std::stoll(m[1]));
  }
  return last;
}

// Writes output frames on a background thread, so that HDF5 compression and disk writes overlap
// the next frame's steps (the snapshot itself is taken on the simulation thread). One write is in
// flight at a time. Each job writes the stats log first, then the frame, then the sequence index:
// the index lists a frame only once it is complete, and the stats log always holds a line for
// every complete frame (a resume keeps the lines up to its frame and drops any newer one). A
// failed write (disk full) is rethrown by the next Submit or by Finish; if the simulation stops
// with an error first, the destructor still waits for the write in flight, so every frame it
// reported as complete is on disk.
class FrameWriter {
 public:
  FrameWriter() = default;
  FrameWriter(const FrameWriter&) = delete;
  FrameWriter& operator=(const FrameWriter&) = delete;
  ~FrameWriter() {
    if (!pending_.valid()) return;
    try {
      pending_.get();
    } catch (const std::exception& e) {
      rime::log::Error("{}", e.what());
    }
  }
  template <class Job>
  void Submit(Job job) {
    Finish();
    pending_ = std::async(std::launch::async, std::move(job));
  }
  void Finish() {
    if (pending_.valid()) pending_.get();
  }

 private:
  std::future<void> pending_;
};

template <class T>
int Run(const rime::io::Scene& scene, const Options& opt, const rime::tool::CommonOptions& common, const rime::Sandbox& sandbox,
        const rime::MemoryBudget& budget) {
  using namespace rime;
  const exec::Device device = exec::SelectDevice(common.device);
  // Default: the "boundary" folder beside the output folder (how rime-bake lays out its cache).
  const fs::path boundary_dir =
      opt.boundary_dir.empty() ? fs::path(opt.output).lexically_normal().parent_path() / "boundary" : fs::path(opt.boundary_dir);
  std::vector<io::ParticleFrame> boundaries;
  double boundary_particles = 0;
  for (const io::SolidObject& solid : scene.solids) {
    const fs::path file = boundary_dir / (solid.name + ".h5part");
    sandbox.Require(file, "--boundary", ExitCode::kUsage);
    if (!fs::exists(file))
      throw InputError(fmt::format("boundary file for solid '{}' not found; run rime-boundary {} -o {} first", solid.name,
                                   scene.file.string(), boundary_dir.string()),
                       file.string());
    boundaries.push_back(io::ReadParticleFrame(file, "boundary"));
    boundary_particles += double(boundaries.back().size());
  }
  // Refused before the simulation allocates its arrays and before any frame is written.
  SimulationCounts counts;
  counts.fluid = scene.WaterParticles();
  counts.boundary = boundary_particles;
  counts.freezing = scene.Enabled("freezing");
  counts.scalar_bytes = sizeof(T);
  CheckMemoryBudget(budget, EstimateSimulationBytes(counts),
                    fmt::format("{} water and {} boundary particles", FormatCount(counts.fluid), FormatCount(counts.boundary)),
                    fmt::format("scene {}, spacing {:.3g} mm", scene.file.string(), scene.fluid.spacing * 1e3));
  sph::Simulation<T> sim(scene, device);
  for (std::size_t k = 0; k < boundaries.size(); ++k) {
    sim.AddBoundaryObject(boundaries[k], scene.solids[k].name);
    boundaries[k] = {};
  }
  const fs::path out(opt.output);
  fs::create_directories(out);
  const double fps = scene.info.fps;
  const double end_time = scene.info.end_time;
  const std::int64_t last_frame = static_cast<std::int64_t>(std::floor(end_time * fps + 1e-9));

  std::vector<std::string> stats_lines;
  std::vector<io::IndexEntry> index;
  std::int64_t first_frame = 0;
  const fs::path stats_path = out / "stats.jsonl";
  const std::int64_t resume_from = opt.resume ? LastCompleteFrame(out) : -1;
  if (resume_from >= 0) {
    const fs::path checkpoint = io::FramePath(out, "particles", resume_from, "h5part");
    const io::ParticleFrame frame = io::ReadParticleFrame(checkpoint, "particles");
    if (frame.scene_hash != scene.hash)
      log::Warn("resuming from {} written for a different version of the scene (hash {} vs {})", checkpoint.string(), frame.scene_hash,
                scene.hash);
    sim.Restore(frame);
    first_frame = resume_from;
    log::Info("resuming from frame {} (t = {:.4f} s)", resume_from, sim.time());
    std::ifstream in(stats_path);
    for (std::string line; std::getline(in, line);) {
      try {
        if (json::parse(line).at("frame").get<std::int64_t>() <= resume_from) stats_lines.push_back(line);
      } catch (const std::exception&) {}
    }
  } else {
    sim.Initialize();
    io::WriteParticleFrame(io::FramePath(out, "particles", 0, "h5part"), sim.Snapshot(0));
  }
  for (std::int64_t f = 0; f <= first_frame; ++f) index.push_back({io::FramePath(out, "particles", f, "h5part"), f / fps});
  io::WriteSequenceIndex(out / "particles.h5part", index);
  log::Info("{} water particles, {} boundary particles, {} frames at {} fps on {}", sim.fluid_count(), sim.boundary_count(), last_frame,
            fps, device.description);

  sim.EnableTimings(true);
  const auto wall_start = std::chrono::steady_clock::now();
  std::int64_t total_steps = 0, total_iterations = 0, particle_steps = 0, removed = 0;
  double max_speed = 0, worst_error = 0, measured_sum = 0;
  Progress progress("frames", last_frame - first_frame);
  FrameWriter writer;
  for (std::int64_t f = first_frame + 1; f <= last_frame; ++f) {
    const double stop = f / fps;
    const auto frame_start = std::chrono::steady_clock::now();
    std::int64_t steps = 0, iterations = 0, max_iterations = 0;
    double dt_min = 1e30, dt_max = 0, sum_error = 0, sum_measured = 0, max_error = 0, frame_speed = 0;
    while (sim.time() < stop - 1e-9 * std::max(1.0, stop)) {
      if (g_interrupted)
        throw Error(ExitCode::kInterrupted, fmt::format("interrupted during frame {}; frames up to {} are complete", f, f - 1));
      const double dt = sim.NextTimeStep(stop);
      sph::StepStats s;
      try {
        s = sim.Step(dt);
      } catch (const Error& e) {
        if (e.code() != ExitCode::kDiverged) throw;
        throw Error(e.code(), fmt::format("frame {}: {}; frames up to {} are valid", f, e.message(), f - 1), out.string());
      }
      ++steps;
      iterations += s.pressure_iterations;
      max_iterations = std::max<std::int64_t>(max_iterations, s.pressure_iterations);
      dt_min = std::min(dt_min, s.dt), dt_max = std::max(dt_max, s.dt);
      sum_error += s.average_density_error;
      sum_measured += s.measured_density_error;
      max_error = std::max(max_error, s.max_density_error);
      frame_speed = std::max(frame_speed, s.max_speed);
      particle_steps += s.fluid_particles;
      removed += s.removed_particles;
      if (!s.converged) log::Debug("step {}: pressure solve stopped at {} iterations", sim.step_count(), s.pressure_iterations);
      progress.Update(f - 1 - first_frame, fmt::format("t={:.3f}s dt={:.2g}s {} it", sim.time(), dt, s.pressure_iterations));
    }
    index.push_back({io::FramePath(out, "particles", f, "h5part"), f / fps});
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - frame_start).count();
    json line = {{"frame", f},
                 {"time", sim.time()},
                 {"steps", steps},
                 {"dt_min", steps ? dt_min : 0},
                 {"dt_max", dt_max},
                 {"pressure_iterations_mean", steps ? double(iterations) / steps : 0},
                 {"pressure_iterations_max", max_iterations},
                 {"density_error_mean", steps ? sum_error / steps : 0},
                 {"density_error_max", max_error},
                 {"density_error_measured_mean", steps ? sum_measured / steps : 0},
                 {"max_speed", frame_speed},
                 {"fluid_particles", sim.fluid_count()},
                 {"ice_particles", sim.ice_count()},
                 {"removed_total", sim.removed_total()},
                 {"wall_seconds", wall}};
    stats_lines.push_back(line.dump());
    std::string stats_text;
    for (const std::string& l : stats_lines) stats_text += l + "\n";
    writer.Submit([frame = sim.Snapshot(f), index, stats_text, &out, &stats_path, path = index.back().frame_file] {
      WriteFileAtomically(stats_path, stats_text);
      io::WriteParticleFrame(path, frame);
      io::WriteSequenceIndex(out / "particles.h5part", index);
    });
    total_steps += steps;
    total_iterations += iterations;
    measured_sum += sum_measured;
    max_speed = std::max(max_speed, frame_speed);
    worst_error = std::max(worst_error, max_error);
    progress.Update(f - first_frame, fmt::format("t={:.3f}s", sim.time()));
  }
  writer.Finish();
  progress.Finish();
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  const auto& t = sim.timings();
  const double us_per_particle_step = particle_steps ? 1e6 * wall / double(particle_steps) : 0;
  log::Info(
      "done: {} frames, {} steps, {:.2f} pressure iterations/step, measured density error {:.3g}% on average, max speed {:.3g} m/s, "
      "{} water, {} ice, {} particles left the domain",
      last_frame - first_frame, total_steps, total_steps ? double(total_iterations) / total_steps : 0.0,
      total_steps ? 100 * measured_sum / double(total_steps) : 0.0, max_speed, sim.fluid_count(), sim.ice_count(), removed);
  const double total = std::max(1e-12, t.total());
  log::Info(
      "time: {} total, {:.3g} us per particle-step (neighbors {:.0f}%, forces {:.0f}%, pressure {:.0f}%, integration {:.0f}%, "
      "freezing {:.0f}%), peak memory {} MiB, {} threads",
      FormatDuration(wall), us_per_particle_step, 100 * t.neighbor_search / total, 100 * t.non_pressure / total,
      100 * t.pressure_solve / total, 100 * t.integration / total, 100 * t.freezing / total, tool::PeakMemoryBytes() >> 20,
      exec::CpuThreads());
  tool::WriteSummary(common, {{"tool", "rime-sim"},
                              {"scene", scene.file.string()},
                              {"frames", last_frame - first_frame},
                              {"resumed_from", resume_from},
                              {"steps", total_steps},
                              {"pressure_iterations_mean", total_steps ? double(total_iterations) / total_steps : 0},
                              {"max_speed", max_speed},
                              {"density_error_max", worst_error},
                              {"density_error_measured_mean", total_steps ? measured_sum / double(total_steps) : 0},
                              {"fluid_particles", sim.fluid_count()},
                              {"boundary_particles", sim.boundary_count()},
                              {"removed_particles", sim.removed_total()},
                              {"ice_particles", sim.ice_count()},
                              {"wall_seconds", wall},
                              {"us_per_particle_step", us_per_particle_step},
                              {"peak_memory_bytes", tool::PeakMemoryBytes()},
                              {"device", device.description},
                              {"threads", exec::CpuThreads()}});
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "Simulates the water of a scene (IISPH with viscosity, surface tension, air pressure and freezing) and writes\n"
      "one H5Part frame per output frame: FOLDER/particles.NNNN.h5part, the sequence index FOLDER/particles.h5part\n"
      "(open it in ParaView) and FOLDER/stats.jsonl. Every frame is a complete checkpoint."};
  rime::tool::CommonOptions common;
  Options opt;
  rime::tool::Setup(
      app, "rime-sim", common,
      rime::tool::kThreads | rime::tool::kDevice | rime::tool::kJsonSummary | rime::tool::kMemoryBudget | rime::tool::kSandbox);
  app.add_option("scene", opt.scene, "Scene file (TOML)")->required()->check(CLI::ExistingFile);
  app.add_option("-o,--output", opt.output, "Output folder for the frames")->required();
  app.add_option("--boundary", opt.boundary_dir, "Folder with the boundary files written by rime-boundary (default: OUTPUT/../boundary)");
  app.add_flag("--resume", opt.resume, "Continue from the last complete frame in the output folder");
  rime::tool::OverrideFlags<rime::io::SceneInfo> scene_overrides;  // --end-time
  scene_overrides.AddTo(app);
  std::signal(SIGINT, OnInterrupt);
  std::signal(SIGTERM, OnInterrupt);
  return rime::tool::Main(app, argc, argv, common, [&] {
    const rime::Sandbox sandbox = rime::tool::MakeSandbox(common);
    sandbox.Require(opt.scene, "scene", rime::ExitCode::kUsage);
    sandbox.Require(opt.output, "-o", rime::ExitCode::kUsage);
    if (!opt.boundary_dir.empty()) sandbox.Require(opt.boundary_dir, "--boundary", rime::ExitCode::kUsage);
    const rime::MemoryBudget budget = rime::tool::Budget(common);
    rime::io::Scene scene = rime::io::LoadScene(opt.scene);
    scene_overrides.ApplyTo(scene.info);
    return scene.fluid.precision == rime::io::Precision::kDouble ? Run<double>(scene, opt, common, sandbox, budget)
                                                                 : Run<float>(scene, opt, common, sandbox, budget);
  });
}
