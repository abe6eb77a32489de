// rime-clean: production cleanup of rime-surface meshes with CGAL, one frame at a time.
// Thin: parse options, find the frames, run clean::Clean on each (frames in parallel with -j),
// write meshes, reports and a summary.
#include <tbb/parallel_for.h>

#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <mutex>
#include <optional>
#include <regex>

#include "rime/core/atomic_file.h"
#include "rime/core/error.h"
#include "rime/core/log.h"
#include "rime/core/memory_budget.h"
#include "rime/core/progress.h"
#include "rime/exec/device.h"
#include "rime/io/mesh.h"
#include "rime/io/particles.h"
#include "rime/io/scene.h"
#include "rime/clean/clean.h"
#include "override_flags.h"
#include "tool.h"

namespace fs = std::filesystem;
using namespace rime;

namespace {

struct Frame {
  fs::path input;
  std::vector<fs::path> outputs;  // one mesh file, or .obj and .ply
  fs::path report;                // per-frame quality report beside folder outputs ("" for one file)
  std::string stem;               // "ice" of ice.0012.obj
  std::int64_t number = -1;       // -1: no frame number in the name
};

bool IsMeshFile(const fs::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext == ".obj" || ext == ".ply";
}

/// "ice.0012.obj" -> ("ice", 12); "ice_12.ply" -> ("ice", 12); "ball.obj" -> ("ball", -1).
Frame ParseName(const fs::path& input) {
  Frame f;
  f.input = input;
  static const std::regex numbered(R"(^(.*?)[._-]?(\d+)$)");
  const std::string stem = input.stem().string();
  std::smatch m;
  if (std::regex_match(stem, m, numbered) && !m[1].str().empty()) {
    f.stem = m[1];
    f.number = std::stoll(m[2]);
  } else {
    f.stem = stem;
  }
  return f;
}

/// Triangles a mesh file holds, counted without reading it into memory: a PLY's `element face`
/// count, an OBJ's `f` lines (a polygon of k corners counts k - 2). An unreadable file counts 0 and
/// is refused later by the reader, with its own message.
double CountTriangles(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::string line;
  double triangles = 0;
  if (path.extension() == ".ply" || path.extension() == ".PLY") {
    for (int lines = 0; lines < 10000 && std::getline(in, line) && line.rfind("end_header", 0) != 0; ++lines) {
      std::istringstream words(line);
      std::string element, name;
      double count = 0;
      if (words >> element >> name >> count && element == "element" && name == "face") triangles = count;
    }
    return triangles;
  }
  while (std::getline(in, line)) {
    if (line.size() < 2 || line[0] != 'f' || (line[1] != ' ' && line[1] != '\t')) continue;
    std::istringstream words(line.substr(2));
    int corners = 0;
    for (std::string w; words >> w;) ++corners;
    triangles += std::max(0, corners - 2);
  }
  return triangles;
}

// Peak bytes of cleaning a mesh of this many triangles: the input mesh, CGAL's Surface_mesh with
// its property maps, the AABB tree for the velocity transfer and the decimation and
// self-intersection scratch. Measured with the default steps: about 225 B per triangle above the
// process's base (docs/reliability.md); 300 B leaves room for the repair and remesh paths.
double CleanBytes(double triangles) { return triangles * 300; }

/// Adds the file to an error raised without one (libs/clean does not know file names).
[[noreturn]] void Rethrow(const Error& e, const fs::path& file) {
  throw Error(e.code(), e.message(), e.where().empty() ? file.string() : e.where());
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "Cleans rime-surface meshes with CGAL 5.5, frame by frame: repairs and orients the polygon soup, removes degenerate\n"
      "faces and small components (ice specks), fills small holes, optionally remeshes, smooths, decimates, and reports\n"
      "self-intersections. Per-vertex velocities (PLY vx vy vz) are carried to the output from the nearest input point.\n"
      "Lengths in m, areas in m^2, volumes in m^3. Defaults come from [clean] of --scene, else the built-in ones shown."};
  tool::CommonOptions common;
  tool::Setup(app, "rime-clean", common, tool::kThreads | tool::kFrames | tool::kJsonSummary | tool::kMemoryBudget | tool::kSandbox);
  app.get_option("-j")->description("Frames cleaned in parallel, and CPU threads in all (default: all cores)");

  std::vector<std::string> inputs;
  std::string output, format, scene_file, report_file;
  app.add_option("MESH", inputs, "Input meshes (.obj/.ply), or folders of them; frame numbers are read from names like ice.0012.obj")
      ->required();
  app.add_option("-o,--output", output,
                 "Output file (one input; its extension picks the format), or folder: ice.0012.obj -> "
                 "FOLDER/ice_clean.0012.{obj,ply} plus the frame's quality report ice_clean.0012.json")
      ->required();
  app.add_option("--format", format,
                 "Folder output: obj, ply or both [both: OBJ for every DCC, PLY with per-vertex velocity for motion blur]")
      ->check(CLI::IsMember({"obj", "ply", "both"}));
  app.add_option("--scene", scene_file, "Scene file whose [clean] section gives the defaults (options below override it)");
  app.add_option("--report", report_file, "Write every frame's quality report to this JSON file");

  auto* g = app.add_option_group("Operations (in this order)");
  tool::OverrideFlags<io::CleanupSettings> overrides;
  overrides.AddTo(*g);

  return tool::Main(app, argc, argv, common, [&]() -> int {
    const auto start = std::chrono::steady_clock::now();
    const Sandbox sandbox = tool::MakeSandbox(common);
    for (const std::string& in : inputs) sandbox.Require(in, "input", ExitCode::kUsage);
    sandbox.Require(output, "-o", ExitCode::kUsage);
    if (!scene_file.empty()) sandbox.Require(scene_file, "--scene", ExitCode::kUsage);
    if (!report_file.empty()) sandbox.Require(report_file, "--report", ExitCode::kUsage);
    const MemoryBudget budget = tool::Budget(common);
    io::CleanupSettings settings;
    if (!scene_file.empty()) settings = io::LoadScene(scene_file).cleanup;
    overrides.ApplyTo(settings);
    if (overrides.Given("target_edge") && !overrides.Given("remesh")) settings.remesh = true;
    const tool::FrameRange range = tool::ParseFrames(common.frames);

    // Inputs: files and folders of .obj/.ply, frames sorted by number, filtered by --frames.
    std::vector<Frame> frames;
    for (const std::string& in : inputs) {
      const fs::path p(in);
      std::error_code ec;
      if (fs::is_directory(p, ec)) {
        std::vector<fs::path> found;
        for (const auto& entry : fs::directory_iterator(p))
          if (entry.is_regular_file() && IsMeshFile(entry.path())) found.push_back(entry.path());
        if (found.empty()) throw InputError("folder holds no .obj or .ply files", p.string());
        std::sort(found.begin(), found.end());
        for (const fs::path& f : found) frames.push_back(ParseName(f));
      } else {
        if (!fs::exists(p, ec)) throw InputError("mesh file not found", p.string());
        if (!IsMeshFile(p)) throw InputError("unsupported mesh format (expected .obj or .ply)", p.string());
        frames.push_back(ParseName(p));
      }
    }
    std::erase_if(frames, [&](const Frame& f) { return f.number >= 0 && !range.Contains(f.number); });
    if (frames.empty()) throw Error(ExitCode::kUsage, "no input frame in the --frames range", common.frames);
    std::stable_sort(frames.begin(), frames.end(), [](const Frame& a, const Frame& b) { return a.number < b.number; });

    // Outputs: one file, or names in a folder.
    const fs::path out(output);
    std::error_code ec;
    const bool to_file = frames.size() == 1 && !fs::is_directory(out, ec) && IsMeshFile(out) && output.back() != '/';
    if (frames.size() > 1 && IsMeshFile(out) && !fs::is_directory(out, ec))
      throw Error(ExitCode::kUsage, "several inputs need an output folder, not a file", output);
    for (Frame& f : frames) {
      if (to_file) {
        f.outputs = {out};
      } else {
        const std::string stem = f.stem + "_clean";
        auto name = [&](const std::string& ext) {
          return f.number >= 0 ? io::FramePath(out, stem, f.number, ext) : out / (stem + "." + ext);
        };
        if (format != "ply") f.outputs.push_back(name("obj"));
        if (format != "obj") f.outputs.push_back(name("ply"));
        f.report = name("json");
      }
      for (const fs::path& o : f.outputs)
        if (fs::exists(o, ec) && fs::equivalent(o, f.input, ec))
          throw Error(ExitCode::kUsage, "output would overwrite its input", o.string());
    }
    // Before anything is written: the frames cleaned side by side (one per thread) must fit.
    std::vector<double> triangles(frames.size()), estimates(frames.size());
    for (std::size_t i = 0; i < frames.size(); ++i) {
      for (const fs::path& o : frames[i].outputs) sandbox.Require(o, "-o", ExitCode::kUsage);
      if (!frames[i].report.empty()) sandbox.Require(frames[i].report, "-o", ExitCode::kUsage);
      triangles[i] = CountTriangles(frames[i].input);
      estimates[i] = CleanBytes(triangles[i]);
    }
    const std::size_t at_once = std::min<std::size_t>(frames.size(), std::size_t(std::max(1, exec::CpuThreads())));
    std::size_t largest = 0;
    const double peak = ConcurrentPeak(estimates, at_once, &largest);
    CheckMemoryBudget(budget, peak, FormatCount(ConcurrentPeak(triangles, at_once)) + " triangles",
                      at_once > 1 ? fmt::format("{} meshes at once, largest {}", at_once, frames[largest].input.string())
                                  : fmt::format("mesh {}", frames[largest].input.string()));
    log::Info("cleaning {} frame(s) with {} thread(s)", frames.size(), exec::CpuThreads());
    std::vector<nlohmann::json> reports(frames.size());
    std::vector<std::string> lines(frames.size());
    std::atomic<std::size_t> faces_in{0}, faces_out{0}, warnings{0};
    std::atomic<bool> failed{false};
    std::mutex error_mutex;
    std::optional<Error> first_error;
    Progress progress("frames", std::int64_t(frames.size()));
    tbb::parallel_for(std::size_t(0), frames.size(), std::size_t(1), [&](std::size_t i) {
      if (failed) return;
      const Frame& f = frames[i];
      try {
        const auto t0 = std::chrono::steady_clock::now();
        const io::TriMesh mesh = io::ReadMesh(f.input);
        const double read_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        clean::CleanResult result;
        try {
          result = clean::Clean(mesh, settings);
        } catch (const Error& e) {
          Rethrow(e, f.input);
        }
        const auto t1 = std::chrono::steady_clock::now();
        for (const fs::path& o : f.outputs) io::WriteMesh(o, result.mesh);
        const double write_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
        for (const std::string& w : result.report.warnings) log::Warn("{}: {}", f.input.string(), w);
        warnings += result.report.warnings.size();
        faces_in += result.report.before.faces;
        faces_out += result.report.after.faces;
        nlohmann::json j = clean::ToJson(result.report);
        j["input"] = f.input.string();
        j["outputs"] = nlohmann::json::array();
        for (const fs::path& o : f.outputs) j["outputs"].push_back(o.string());
        if (f.number >= 0) j["frame"] = f.number;
        j["read_seconds"] = read_s;
        j["write_seconds"] = write_s;
        if (!f.report.empty()) WriteFileAtomically(f.report, j.dump(2) + "\n");
        reports[i] = std::move(j);
        lines[i] = f.input.filename().string() + ": " + clean::SummaryLine(result.report);
        log::Debug("{}", lines[i]);
        progress.Advance();
      } catch (const Error& e) {
        std::lock_guard lock(error_mutex);
        if (!first_error) first_error = e;
        failed = true;
      }
    });
    progress.Finish();
    if (first_error) throw *first_error;

    for (const std::string& line : lines) log::Info("{}", line);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (!report_file.empty()) WriteFileAtomically(report_file, nlohmann::json(reports).dump(2) + "\n");
    log::Info("{} frame(s), {} -> {} triangles in {:.2f} s ({:.0f}k input triangles/s with {} thread(s)); {} warning(s)", frames.size(),
              faces_in.load(), faces_out.load(), seconds, faces_in / seconds / 1e3, exec::CpuThreads(), warnings.load());
    nlohmann::json summary = {{"tool", "rime-clean"},
                              {"frames", frames.size()},
                              {"triangles_in", faces_in.load()},
                              {"triangles_out", faces_out.load()},
                              {"seconds", seconds},
                              {"input_triangles_per_second", faces_in / seconds},
                              {"threads", exec::CpuThreads()},
                              {"warnings", warnings.load()},
                              {"peak_memory_bytes", tool::PeakMemoryBytes()}};
    nlohmann::json outputs = nlohmann::json::array();
    for (const Frame& f : frames)
      for (const fs::path& o : f.outputs) outputs.push_back(o.string());
    summary["outputs"] = outputs;
    summary["reports"] = reports;
    tool::WriteSummary(common, summary);
    return 0;
  });
}
