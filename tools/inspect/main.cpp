// rime-inspect: measures what a bake's ice looks like, frame by frame (docs/ice-metrics.md):
// specks, particle-scale noise, topology, glaze coverage and thickness, icicles.
// Thin: find a bake's particle frames and cleaned meshes, run clean::MeasureIce, print a table, write JSON.
#include <algorithm>
#include <filesystem>
#include <regex>

#include <fmt/format.h>

#include "rime/core/atomic_file.h"
#include "rime/core/error.h"
#include "rime/core/log.h"
#include "rime/io/mesh.h"
#include "rime/io/particles.h"
#include "rime/io/scene.h"
#include "rime/clean/ice_metrics.h"
#include "tool.h"

namespace fs = std::filesystem;
using namespace rime;

namespace {

nlohmann::json ToJson(std::int64_t frame, double time, const clean::IceMetrics& m) {
  nlohmann::json icicles = nlohmann::json::array();
  for (const auto& i : m.icicles)
    icicles.push_back({{"length_dp", i.length},
                       {"width_dp", i.width},
                       {"base", {i.base.x, i.base.y, i.base.z}},
                       {"tip", {i.tip.x, i.tip.y, i.tip.z}},
                       {"angle_to_gravity_deg", i.angle_to_gravity_deg},
                       {"angle_to_flow_deg", i.angle_to_flow_deg},
                       {"particles", i.particles}});
  return {{"frame", frame},
          {"time", time},
          {"water_particles", m.water},
          {"ice_particles", m.ice},
          {"floating_ice_particles", m.floating_ice},
          {"triangles", m.triangles},
          {"components", m.components},
          {"specks", m.specks},
          {"tiny_pieces", m.tiny_pieces},
          {"area_m2", m.area},
          {"handles", m.handles},
          {"handles_per_1000_dp2", m.handles_per_1000_dp2},
          {"noise_rms_dp", m.noise_rms},
          {"noise_smoothing_passes", m.smoothing_passes},
          {"sharp_area_fraction", m.sharp_area_fraction},
          {"volume_ratio", m.volume_ratio},
          {"wetted_solid_particles", m.wetted},
          {"covered_solid_particles", m.covered},
          {"glaze_coverage", m.glaze_coverage},
          {"thickness_mean_dp", m.thickness_mean},
          {"thickness_spread_dp", m.thickness_spread},
          {"icicle_count", m.icicles.size()},
          {"hanging_icicles", m.hanging_icicles},
          {"icicle_length_mean_dp", m.icicle_length_mean},
          {"icicle_length_max_dp", m.icicle_length_max},
          {"icicles", icicles}};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "Measures the ice of a bake frame by frame, from the cleaned ice meshes (<output>/clean/ice_clean.NNNN.obj) and the\n"
      "particle frames (<output>/cache/sim/particles.NNNN.h5part): specks (pieces touching no solid), tiny pieces, noise\n"
      "(RMS distance to a smoothed copy, and the area share curved at the particle scale), handles, glaze coverage of the\n"
      "wetted object surface and its thickness, and icicles (slender ice reaching 3 d_p or more from the solid). Lengths in\n"
      "particle spacings d_p. Prints a table and writes <output>/inspect.json (docs/ice-metrics.md defines each column)."};
  tool::CommonOptions common;
  tool::Setup(app, "rime-inspect", common, tool::kFrames | tool::kJsonSummary);
  std::string scene_file, output, json_file, mesh_stem = "ice_clean";
  bool raw = false;
  clean::IceMetricsSettings settings;
  app.add_option("SCENE", scene_file, "Scene file of the bake")->required();
  app.add_option("-o,--output", output, "Bake output folder (default: out/<scene name>, as rime-bake)");
  app.add_option("--json", json_file, "Where to write the per-frame metrics (default: <output>/inspect.json)");
  app.add_flag("--raw", raw, "Measure the surface stage's meshes (<output>/surface/ice.NNNN.obj) instead of the cleaned ones");
  app.add_option("--smoothing-passes", settings.smoothing_passes,
                 fmt::format("Taubin passes of the smoothed copy the noise is measured against, at an edge length of d_p/2 [{}]",
                             settings.smoothing_passes));
  app.add_option("--icicle-length", settings.icicle_length,
                 fmt::format("Shortest icicle, d_p from the solid surface [{}]", settings.icicle_length));
  return tool::Main(app, argc, argv, common, [&] {
    const io::Scene scene = io::LoadScene(scene_file);
    const fs::path out = output.empty() ? fs::path("out") / scene.info.name : fs::path(output);
    const fs::path sim = out / "cache" / "sim";
    const fs::path meshes = raw ? out / "surface" : out / "clean";
    const std::string stem = raw ? "ice" : mesh_stem;
    if (!fs::is_directory(sim)) throw InputError("no particle frames: bake the scene first (rime-bake " + scene_file + ")", sim.string());
    std::set<std::uint32_t> objects;  // glaze is measured on the objects, not on the ground
    for (std::uint32_t i = 0; i < scene.solids.size(); ++i)
      if (scene.solids[i].shape != io::SolidShape::kPlane) objects.insert(i);
    const tool::FrameRange range = tool::ParseFrames(common.frames);
    std::vector<std::int64_t> frames;
    static const std::regex name(R"(^particles\.(\d+)\.h5part$)");
    for (const auto& entry : fs::directory_iterator(sim)) {
      std::smatch m;
      const std::string file = entry.path().filename().string();
      if (std::regex_match(file, m, name) && range.Contains(std::stoll(m[1]))) frames.push_back(std::stoll(m[1]));
    }
    std::sort(frames.begin(), frames.end());
    if (frames.empty()) throw InputError("no particle frames in the requested range", sim.string());

    nlohmann::json rows = nlohmann::json::array();
    fmt::print("{:>5} {:>6} {:>6} {:>6} {:>6} {:>5} {:>7} {:>6} {:>6} {:>6} {:>7} {:>9} {:>7} {:>6} {:>6}\n", "frame", "water", "ice",
               "pieces", "specks", "tiny", "handles", "noise", "sharp", "glaze", "thick", "icicles", "hanging", "len", "max");
    fmt::print("{:>5} {:>6} {:>6} {:>6} {:>6} {:>5} {:>7} {:>6} {:>6} {:>6} {:>7} {:>9} {:>7} {:>6} {:>6}\n", "", "", "", "", "", "",
               "/1k dp2", "dp", "area", "cover", "dp", "", "", "dp", "dp");
    for (std::int64_t f : frames) {
      const io::ParticleFrame frame = io::ReadParticleFrame(io::FramePath(sim, "particles", f, "h5part"), "particles");
      const fs::path mesh_file = io::FramePath(meshes, stem, f, "obj");
      const bool has_mesh = fs::exists(mesh_file);
      // A frame without ice may have no mesh; one with ice and no mesh is not cleaned yet and would read as "no ice".
      const auto& phase = frame.Get<std::uint8_t>("phase");
      if (!has_mesh && std::find(phase.begin(), phase.end(), std::uint8_t(io::Phase::kIce)) != phase.end()) {
        // rime-bake does not clean an empty surface: ice too small to survive the level-set filters.
        const fs::path surfaced = io::FramePath(out / "surface", "ice", f, "obj");
        if (raw || !fs::exists(surfaced) || io::ReadMesh(surfaced).triangle_count() > 0) {
          log::Warn("frame {}: {} is missing (not cleaned yet?); frame skipped", f, mesh_file.string());
          continue;
        }
      }
      const io::TriMesh mesh = has_mesh ? io::ReadMesh(mesh_file) : io::TriMesh{};
      const clean::IceMetrics m = clean::MeasureIce(mesh, frame, scene.solver.gravity, objects, settings);
      fmt::print(
          "{:>5} {:>6} {:>6} {:>6} {:>6} {:>5} {:>7.2f} {:>6.3f} {:>6.3f} {:>6.2f} {:>4.2f}±{:<4.2f} {:>7} {:>7} {:>6.1f} {:>6.1f}\n", f,
          m.water, m.ice, m.components, m.specks, m.tiny_pieces, m.handles_per_1000_dp2, m.noise_rms, m.sharp_area_fraction,
          m.glaze_coverage, m.thickness_mean, m.thickness_spread, m.icicles.size(), m.hanging_icicles, m.icicle_length_mean,
          m.icicle_length_max);
      rows.push_back(ToJson(f, frame.time, m));
    }
    const nlohmann::json doc = {{"format", "rime.inspect"},  {"version", 1},  {"scene", scene_file}, {"spacing", scene.fluid.spacing},
                                {"meshes", meshes.string()}, {"frames", rows}};
    const fs::path json_path = json_file.empty() ? out / "inspect.json" : fs::path(json_file);
    WriteFileAtomically(json_path, doc.dump(1) + "\n");
    log::Info("metrics of {} frames written to {}", rows.size(), json_path.string());
    tool::WriteSummary(common, doc);
    return 0;
  });
}
