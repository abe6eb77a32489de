// rime-boundary: meshes or the solids of a scene -> boundary particle files (stage 1).
#include <fmt/format.h>

#include <algorithm>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "rime/boundary/object.h"
#include "rime/boundary/shapes.h"
#include "rime/core/error.h"
#include "rime/core/log.h"
#include "rime/core/memory_budget.h"
#include "rime/core/progress.h"
#include "rime/exec/device.h"
#include "rime/io/scene.h"
#include "override_flags.h"
#include "tool.h"

namespace {

namespace fs = std::filesystem;
using namespace rime;

struct Options {
  std::string input, output;
  tool::OverrideFlags<io::SolidObject> solid;    // --spacing-ratio; mesh only: --scale, --rotate, --translate, --up-axis, --separate-parts
  tool::OverrideFlags<io::FluidSettings> water;  // --spacing, --smoothing-ratio
  std::string name;
  std::uint32_t object_id = 0;
  double max_particles = 50e6;
};

// Solid fields whose flags only a single mesh takes: a scene sets them per [[solid]].
constexpr std::string_view kMeshOnlyFields[] = {"scale", "rotate", "translate", "up_axis", "merge_meshes"};

bool IsScene(const fs::path& p) { return p.extension() == ".toml"; }

nlohmann::json Summarize(const boundary::BoundaryObject& o, const fs::path& file) {
  log::Info(
      "{}: {} triangles read, {} degenerate skipped, {} particles written (d_b = {:.4g} m, mean nearest-neighbour spacing "
      "{:.4g} m = {:.2f} d_b, {} near-duplicates removed), bounds ({:.4g}, {:.4g}, {:.4g}) .. ({:.4g}, {:.4g}, {:.4g}) m, {}",
      o.name, o.stats.triangles, o.stats.degenerate_skipped, o.size(), o.boundary_spacing, o.mean_spacing,
      o.mean_spacing / o.boundary_spacing, o.stats.near_duplicates_removed, o.bounds_min.x, o.bounds_min.y, o.bounds_min.z, o.bounds_max.x,
      o.bounds_max.y, o.bounds_max.z, FormatDuration(o.seconds));
  return {{"name", o.name},
          {"file", file.string()},
          {"shape", o.shape},
          {"source", o.source},
          {"mesh_hash", o.mesh_hash},
          {"object_id", o.object_id},
          {"meshes", o.meshes},
          {"triangles_read", o.stats.triangles},
          {"degenerate_skipped", o.stats.degenerate_skipped},
          {"vertex_samples", o.stats.vertex_samples},
          {"edge_samples", o.stats.edge_samples},
          {"face_samples", o.stats.face_samples},
          {"near_duplicates_removed", o.stats.near_duplicates_removed},
          {"particles", o.size()},
          {"particle_spacing", o.particle_spacing},
          {"boundary_spacing", o.boundary_spacing},
          {"smoothing_length", o.smoothing_length},
          {"mean_spacing", o.mean_spacing},
          {"bounds_min", {o.bounds_min.x, o.bounds_min.y, o.bounds_min.z}},
          {"bounds_max", {o.bounds_max.x, o.bounds_max.y, o.bounds_max.z}},
          {"transform", o.transform_text},
          {"seconds", o.seconds}};
}

// Peak bytes of sampling one object: the imported mesh with its weld table and edges per triangle;
// samples with normals, Z-curve keys, the duplicate-removal grid and the volume neighbour lists
// per particle. Calibrated against measured peaks in docs/reliability.md.
double SamplingBytes(double triangles, double particles) { return triangles * 100 + particles * 120; }

int Run(const Options& opt, const tool::CommonOptions& common) {
  const auto start = std::chrono::steady_clock::now();
  const Sandbox sandbox = tool::MakeSandbox(common);
  sandbox.Require(opt.input, "input", ExitCode::kUsage);
  sandbox.Require(opt.output, "-o", ExitCode::kUsage);
  const MemoryBudget budget = tool::Budget(common);
  boundary::BoundarySettings settings;
  settings.device = exec::SelectDevice(common.device);
  if (!(opt.max_particles >= 1)) throw Error(ExitCode::kUsage, "--max-particles must be at least 1");
  settings.max_particles = static_cast<std::uint64_t>(opt.max_particles);
  const fs::path input(opt.input), output(opt.output);
  // Objects are all built before any is written, so the ones built so far stay in memory.
  double held_bytes = 0;
  settings.before_sampling = [&](double triangles, double particles, const std::string& where) {
    CheckMemoryBudget(budget, held_bytes + SamplingBytes(triangles, particles),
                      fmt::format("{} triangles and {} particles", FormatCount(triangles), FormatCount(particles)),
                      fmt::format("{}, spacing {:.3g} mm", where, settings.particle_spacing * 1e3));
  };
  const auto hold = [&](const boundary::BoundaryObject& object) { held_bytes += double(object.size()) * 40; };

  // Every object is built before anything is written, so bad input leaves no output behind.
  std::vector<std::pair<boundary::BoundaryObject, fs::path>> objects;
  std::string scene_hash;
  if (IsScene(input)) {
    if (!opt.name.empty() ||
        std::any_of(std::begin(kMeshOnlyFields), std::end(kMeshOnlyFields), [&](std::string_view field) { return opt.solid.Given(field); }))
      throw Error(ExitCode::kUsage,
                  "--scale, --rotate, --translate, --up-axis, --name and --separate-parts are for a single mesh; "
                  "a scene file sets them per [[solid]]");
    const io::Scene scene = io::LoadScene(input);
    scene_hash = scene.hash;
    io::FluidSettings water = scene.fluid;
    opt.water.ApplyTo(water);
    settings.UseWater(water);
    if (scene.solids.empty()) log::Warn("{} has no [[solid]]: nothing to sample", input.string());
    Progress progress("solids", Index(scene.solids.size()));
    for (std::size_t k = 0; k < scene.solids.size(); ++k) {
      io::SolidObject solid = scene.solids[k];
      opt.solid.ApplyTo(solid);
      const fs::path mesh_path = solid.shape == io::SolidShape::kMesh ? scene.Resolve(solid.mesh) : fs::path();
      if (solid.shape == io::SolidShape::kMesh)
        sandbox.Require(mesh_path, fmt::format("{}: solid '{}' mesh", input.string(), solid.name), ExitCode::kBadInput);
      sandbox.Require(output / (solid.name + ".h5part"), "-o", ExitCode::kUsage);
      objects.emplace_back(boundary::BuildBoundaryObject(solid, std::uint32_t(k), mesh_path, settings), output / (solid.name + ".h5part"));
      hold(objects.back().first);
      progress.Update(Index(k + 1), solid.name);
    }
    progress.Finish();
  } else {
    io::SolidObject solid;
    solid.shape = io::SolidShape::kMesh;
    solid.mesh = input;
    solid.name = opt.name.empty() ? input.stem().string() : opt.name;
    opt.solid.ApplyTo(solid);
    io::FluidSettings water;
    opt.water.ApplyTo(water);
    settings.UseWater(water);
    if (output.extension() != ".h5part") throw Error(ExitCode::kUsage, "the output of a single mesh is a .h5part file", output.string());
    objects.emplace_back(boundary::BuildBoundaryObject(solid, opt.object_id, input, settings), output);
  }

  nlohmann::json summaries = nlohmann::json::array();
  std::size_t total = 0;
  for (const auto& [object, file] : objects) {
    if (file.has_parent_path()) fs::create_directories(file.parent_path());
    boundary::WriteBoundaryFile(file, object, scene_hash);
    summaries.push_back(Summarize(object, file));
    total += object.size();
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  log::Info("wrote {} boundary particles in {} file(s) in {} ({} threads, {})", total, objects.size(), FormatDuration(seconds),
            exec::CpuThreads(), settings.device.description);
  tool::WriteSummary(common, {{"tool", "rime-boundary"},
                              {"input", input.string()},
                              {"output", output.string()},
                              {"objects", summaries},
                              {"particles", total},
                              {"seconds", seconds},
                              {"peak_memory_bytes", tool::PeakMemoryBytes()},
                              {"device", settings.device.description},
                              {"threads", exec::CpuThreads()}});
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "Samples solid objects with boundary particles (Akinci 2012: one layer on vertices, edges and faces at spacing\n"
      "d_b = ratio * d_p, with boundary volumes V_b) and writes one H5Part file per object.\n"
      "  rime-boundary MESH -o FILE.h5part      one mesh file (OBJ, PLY, STL, glTF/GLB, FBX, ... through assimp)\n"
      "  rime-boundary SCENE.toml -o FOLDER     every [[solid]] of a scene: FOLDER/<solid name>.h5part\n"
      "--scale, --rotate, --translate, --up-axis, --separate-parts, --name and --object-id are for a single mesh;\n"
      "a scene sets them per [[solid]]."};
  tool::CommonOptions common;
  Options opt;
  tool::Setup(app, "rime-boundary", common, tool::kThreads | tool::kDevice | tool::kJsonSummary | tool::kMemoryBudget | tool::kSandbox);
  app.add_option("input", opt.input, "A mesh file, or a scene file (.toml)")->required();
  app.add_option("-o,--output", opt.output, "Output .h5part file (mesh) or folder (scene)")->required();
  // The scene's [water] values, or the built-in ones for a mesh; BuildBoundaryObject refuses bad values naming the input.
  opt.water.AddTo(app, /*check_ranges=*/false);
  opt.solid.AddTo(app, /*check_ranges=*/false);
  app.add_option("--name", opt.name, "Mesh only: object name stored in the file (default: the file name without extension)");
  app.add_option("--object-id", opt.object_id, "Mesh only: object id stored with every particle (default 0)");
  app.add_option("--max-particles", opt.max_particles,
                 "Refuse (exit 3) when an object would get more boundary particles than this; estimated before sampling")
      ->capture_default_str();
  return tool::Main(app, argc, argv, common, [&] { return Run(opt, common); });
}
