// rime-surface: particle frames -> OpenVDB level sets and triangle meshes (README "rime-surface").
#include <tbb/parallel_for.h>

#include <fmt/format.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <map>
#include <mutex>
#include <regex>
#include <set>
#include <sstream>
#include <variant>

#include "rime/core/error.h"
#include "rime/core/log.h"
#include "rime/core/memory_budget.h"
#include "rime/core/progress.h"
#include "rime/exec/device.h"
#include "rime/io/mesh.h"
#include "rime/io/particles.h"
#include "rime/io/scene.h"
#include "rime/surface/frame_input.h"
#include "rime/surface/reconstruct.h"
#include "override_flags.h"
#include "tool.h"

namespace fs = std::filesystem;
using namespace rime;

namespace {

struct Options {
  std::vector<std::string> inputs;
  std::string output;
  std::string scene;
  std::string field;
  bool strict = false, keep_voids = false;
};

struct FrameFile {
  std::int64_t frame = 0;
  fs::path path;
};

const std::regex kFrameName(R"(^(.*)\.(\d+)\.h5part$)");

// Frame files of a folder, or of the sequence an index file (`particles.h5part`) belongs to.
std::vector<FrameFile> ListSequence(const fs::path& folder, const std::string& stem) {
  std::vector<FrameFile> out;
  for (const auto& entry : fs::directory_iterator(folder)) {
    std::smatch m;
    const std::string name = entry.path().filename().string();
    if (entry.is_regular_file() && std::regex_match(name, m, kFrameName) && (stem.empty() || m[1] == stem))
      out.push_back({std::stoll(m[2]), entry.path()});
  }
  return out;
}

std::vector<FrameFile> CollectFrames(const std::vector<std::string>& inputs, const tool::FrameRange& range, bool range_given) {
  std::map<std::int64_t, fs::path> frames;
  bool sequence = false;
  for (const std::string& input : inputs) {
    const fs::path path(input);
    std::error_code ec;
    if (fs::is_directory(path, ec)) {
      sequence = true;
      for (const FrameFile& f : ListSequence(path, "")) frames.emplace(f.frame, f.path);
      continue;
    }
    if (!fs::exists(path, ec)) throw InputError("input frame not found", input);
    std::smatch m;
    const std::string name = path.filename().string();
    if (!std::regex_match(name, m, kFrameName)) {
      // A sequence index (e.g. particles.h5part): its frames are the numbered files beside it.
      sequence = true;
      const std::string stem = path.stem().string();
      for (const FrameFile& f : ListSequence(path.parent_path().empty() ? fs::path(".") : path.parent_path(), stem))
        frames.emplace(f.frame, f.path);
      continue;
    }
    // The frame number is the file's `frame` attribute (names may be renamed).
    const io::ParticleFrame header = io::ReadParticleFrameHeader(path, "particles");
    frames.emplace(header.frame, path);
  }
  std::vector<FrameFile> out;
  for (const auto& [frame, path] : frames)
    if (range.Contains(frame)) out.push_back({frame, path});
  if (range_given) {
    // Every frame of the requested range must be there: name the missing ones before writing anything.
    std::vector<std::int64_t> missing;
    const std::int64_t first = range.first, last = range.last == INT64_MAX ? (out.empty() ? first : out.back().frame) : range.last;
    for (std::int64_t f = first; f <= last && missing.size() < 20; ++f)
      if (!frames.count(f)) missing.push_back(f);
    if (!missing.empty())
      throw InputError(
          fmt::format("missing frame{} {} in range {}-{}", missing.size() > 1 ? "s" : "", fmt::join(missing, ", "), first, last),
          inputs.size() == 1 ? inputs[0] : "inputs");
  }
  // Check every header (format, version, kind) before any output is written.
  for (const FrameFile& f : out) io::ReadParticleFrameHeader(f.path, "particles");
  if (out.empty())
    throw InputError(sequence ? "no frame files (NAME.NNNN.h5part) found" : "no input frames in the requested range",
                     fmt::format("{}", fmt::join(inputs, " ")));
  return out;
}

struct PhaseJob {
  io::Phase phase;
  std::string prefix;
  surface::Field field;
};

struct FrameReport {
  std::int64_t frame = 0;
  std::string phase;
  surface::Stats stats;
  double seconds = 0;
  std::vector<std::string> files;
};

// Bytes of a frame's datasets in memory: every row, boundary included, stays read while the frame
// is surfaced.
double FrameBytes(const io::ParticleFrame& frame) {
  double bytes = 0;
  for (const auto& [name, data] : frame.attributes)
    bytes += std::visit([](const auto& values) { return double(values.size() * sizeof(values[0])); }, data);
  return bytes;
}

// Refuses, before any output exists, when the frames that run side by side would need more memory
// than the budget: each frame's estimate comes from the grid leaves its particles touch, plus the
// frame itself.
void CheckMemory(const std::vector<FrameFile>& frames, const std::vector<PhaseJob>& jobs, const surface::Settings& settings,
                 const surface::SelectOptions& select, const MemoryBudget& budget) {
  std::vector<double> estimates(frames.size());
  std::vector<double> voxels(frames.size());
  std::vector<double> voxel_sizes(frames.size());
  tbb::parallel_for(std::size_t(0), frames.size(), [&](std::size_t k) {
    const io::ParticleFrame frame = io::ReadParticleFrame(frames[k].path, "particles");
    const double frame_bytes = FrameBytes(frame);
    for (const PhaseJob& job : jobs) {
      std::vector<std::string> ignored;  // SelectPhase warns again when the frame is surfaced
      const surface::ParticleSet particles = surface::SelectPhase(frame, job.phase, select, ignored);
      surface::Settings s = settings;
      s.field = job.field;
      std::uint64_t v = 0;
      const double bytes = frame_bytes + double(surface::EstimateMemoryBytes(particles, s, &v));
      // Phases of a frame are surfaced one after the other: the larger one sets the peak.
      if (bytes > estimates[k]) {
        estimates[k] = bytes;
        voxels[k] = double(v);
        voxel_sizes[k] = particles.size() ? surface::VoxelSize(particles, s) : 0;
      }
    }
  });
  // Frames run side by side, up to one per thread: the largest ones may meet.
  const std::size_t concurrent = std::min<std::size_t>(frames.size(), std::size_t(std::max(1, exec::CpuThreads())));
  std::size_t worst = 0;
  // Taken after the check and in no estimate: the code pages of OpenVDB and the writers that the
  // run touches, each thread's malloc arena and the grids' top-level nodes. It decides a small
  // frame's peak: 8–23 MiB measured on frames of 3.3k particles with 1 and 2 threads.
  const double after_check = (20.0 + 3.0 * double(std::max(1, exec::CpuThreads()))) * 1048576;
  const double total = ConcurrentPeak(estimates, concurrent, &worst) + after_check;
  const double total_voxels = ConcurrentPeak(voxels, concurrent);
  const std::string context =
      concurrent > 1
          ? fmt::format("{} frames at once, largest {}, voxel {:.3g} mm", concurrent, frames[worst].path.string(), voxel_sizes[worst] * 1e3)
          : fmt::format("frame {}, voxel {:.3g} mm", frames[worst].path.string(), voxel_sizes[worst] * 1e3);
  CheckMemoryBudget(budget, total, FormatCount(total_voxels) + " voxels", context);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "Turns ice (and water) particles of rime-sim frames into OpenVDB level sets and triangle meshes "
      "(anisotropic ellipsoids, spec §10)."};
  tool::CommonOptions common;
  tool::Setup(app, "rime-surface", common, tool::kThreads | tool::kFrames | tool::kJsonSummary | tool::kMemoryBudget | tool::kSandbox);
  Options o;
  app.add_option("frames", o.inputs, "Particle frames (NAME.NNNN.h5part), a folder of them, or the sequence index NAME.h5part")->required();
  app.add_option("-o,--output", o.output, "Output folder (created); writes ice.NNNN.{vdb,obj,ply} and water.NNNN.*")->required();
  app.add_option("--scene", o.scene, "Scene file whose [surface] section gives the defaults (flags override it)");
  tool::OverrideFlags<io::SurfaceSettings> overrides;
  overrides.AddTo(app);
  app.add_option("--field", o.field,
                 "Field for every phase (else the scene's ice_field and water_field): ellipsoids, kernel_sum or isotropic")
      ->check(CLI::IsMember(io::EnumNames<io::SurfaceField>()));
  app.add_flag("--strict", o.strict, "Refuse ice frames without stored anisotropy instead of falling back to isotropic");
  app.add_flag("--keep-voids", o.keep_voids, "Keep enclosed gaps between ellipsoids as voids (inner shells in the mesh)");

  return tool::Main(app, argc, argv, common, [&]() -> int {
    const auto start = std::chrono::steady_clock::now();
    const Sandbox sandbox = tool::MakeSandbox(common);
    for (const std::string& input : o.inputs) sandbox.Require(input, "input", ExitCode::kUsage);
    sandbox.Require(o.output, "-o", ExitCode::kUsage);
    if (!o.scene.empty()) sandbox.Require(o.scene, "--scene", ExitCode::kUsage);
    MemoryBudget budget = tool::Budget(common);
    io::SurfaceSettings surfacing;
    if (!o.scene.empty()) surfacing = io::LoadScene(o.scene).surface;
    if (common.memory_budget.empty() && surfacing.memory_budget_gb > 0)
      budget = {std::uint64_t(surfacing.memory_budget_gb * 1e9), o.scene + ": surface.memory_budget_gb"};
    overrides.ApplyTo(surfacing);
    if (overrides.Given("voxel_size") && surfacing.voxel_size > 0 && overrides.Given("resolution") && surfacing.resolution > 0)
      throw Error(ExitCode::kUsage, "give --voxel-size or --resolution, not both");
    if (surfacing.resolution == 1) throw Error(ExitCode::kUsage, "--resolution must be 0 (off) or at least 2");
    if (surfacing.formats.empty()) throw Error(ExitCode::kUsage, "--format needs at least one of obj, ply, vdb");
    const auto has = [&](const char* f) {
      return std::find(surfacing.formats.begin(), surfacing.formats.end(), f) != surfacing.formats.end();
    };

    surface::Settings settings = surface::FromScene(surfacing, surfacing.ice_field);  // the field is set per phase
    // An explicit voxel size wins over the scene's fixed grid.
    if (overrides.Given("voxel_size") && surfacing.voxel_size > 0) settings.resolution = 0;
    settings.keep_voids = o.keep_voids;

    std::vector<PhaseJob> jobs;
    const auto field_for = [&](surface::Field phase_default) { return o.field.empty() ? phase_default : surface::ParseField(o.field); };
    if (surfacing.phase != io::SurfacePhases::kWater) jobs.push_back({io::Phase::kIce, "ice", field_for(surfacing.ice_field)});
    if (surfacing.phase != io::SurfacePhases::kIce) jobs.push_back({io::Phase::kFluid, "water", field_for(surfacing.water_field)});

    const tool::FrameRange range = tool::ParseFrames(common.frames);
    const std::vector<FrameFile> frames = CollectFrames(o.inputs, range, !common.frames.empty());
    for (const FrameFile& f : frames) sandbox.Require(f.path, "input frame", ExitCode::kUsage);
    surface::SelectOptions select;
    select.strict = o.strict;
    CheckMemory(frames, jobs, settings, select, budget);
    std::error_code ec;
    fs::create_directories(o.output, ec);
    if (ec || !fs::is_directory(o.output)) throw IoError("cannot create the output folder", o.output);

    std::mutex mutex;
    std::vector<FrameReport> reports;
    Progress progress("frames", Index(frames.size()));
    tbb::parallel_for(std::size_t(0), frames.size(), [&](std::size_t k) {
      const FrameFile& ff = frames[k];
      const io::ParticleFrame frame = io::ReadParticleFrame(ff.path, "particles");
      for (const PhaseJob& job : jobs) {
        const auto t0 = std::chrono::steady_clock::now();
        std::vector<std::string> warnings;
        surface::ParticleSet particles = surface::SelectPhase(frame, job.phase, select, warnings);
        for (const auto& w : warnings) log::Warn("{}", w);
        if (particles.size() == 0)
          log::Warn("{}: frame {} has no {} particles; writing empty {} outputs", ff.path.string(), frame.frame, job.prefix, job.prefix);
        surface::Settings s = settings;
        s.field = job.field;
        const surface::Result result = surface::Reconstruct(particles, s);
        FrameReport report;
        report.frame = frame.frame;
        report.phase = job.prefix;
        report.stats = result.stats;
        if (has("vdb")) {
          const fs::path p = io::FramePath(o.output, job.prefix, frame.frame, "vdb");
          surface::WriteVdb(p, result);
          report.files.push_back(p.string());
        }
        for (const char* ext : {"obj", "ply"}) {
          if (!has(ext)) continue;
          const fs::path p = io::FramePath(o.output, job.prefix, frame.frame, ext);
          io::WriteMesh(p, result.mesh);
          report.files.push_back(p.string());
        }
        report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        log::Debug(
            "frame {} {}: {} particles, {} active voxels, {} triangles, {:.2f} s (prepare {:.2f}, rasterize {:.2f}, "
            "filters {:.2f}, mesh {:.2f})",
            report.frame, report.phase, report.stats.particles, report.stats.active_voxels, report.stats.triangles, report.seconds,
            report.stats.seconds_prepare, report.stats.seconds_rasterize, report.stats.seconds_filter, report.stats.seconds_mesh);
        std::lock_guard<std::mutex> lock(mutex);
        reports.push_back(std::move(report));
      }
      progress.Advance();
    });
    progress.Finish();
    std::sort(reports.begin(), reports.end(),
              [](const FrameReport& a, const FrameReport& b) { return std::tie(a.frame, a.phase) < std::tie(b.frame, b.phase); });

    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const std::uint64_t peak = tool::PeakMemoryBytes();
    nlohmann::json summary;
    summary["tool"] = "rime-surface";
    summary["output"] = o.output;
    summary["seconds"] = seconds;
    summary["peak_memory_bytes"] = peak;
    std::uint64_t particles = 0, voxels = 0, triangles = 0;
    for (const FrameReport& r : reports) {
      particles += r.stats.particles, voxels += r.stats.active_voxels, triangles += r.stats.triangles;
      summary["frames"].push_back({{"frame", r.frame},
                                   {"phase", r.phase},
                                   {"particles", r.stats.particles},
                                   {"active_voxels", r.stats.active_voxels},
                                   {"triangles", r.stats.triangles},
                                   {"voxel_size", r.stats.voxel_size},
                                   {"filled_void_voxels", r.stats.filled_void_voxels},
                                   {"seconds", r.seconds},
                                   {"files", r.files}});
      log::Info("frame {:>5} {:<5} {:>9} particles {:>10} active voxels {:>9} triangles {:>8.2f} s", r.frame, r.phase, r.stats.particles,
                r.stats.active_voxels, r.stats.triangles, r.seconds);
    }
    summary["particles"] = particles;
    summary["active_voxels"] = voxels;
    summary["triangles"] = triangles;
    log::Info("{} frame(s): {} particles read, {} active voxels, {} triangles in {:.2f} s; peak memory {:.0f} MB; output in {}",
              frames.size(), particles, voxels, triangles, seconds, peak / 1e6, o.output);
    tool::WriteSummary(common, summary);
    return 0;
  });
}
