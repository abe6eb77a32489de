#include "bake_graph.h"

#include <unistd.h>

#include <algorithm>
#include <fmt/format.h>

#include "rime/core/error.h"
#include "rime/io/particles.h"

namespace fs = std::filesystem;

namespace rime::bake {
namespace {

constexpr const char* kStageNames[kStageCount] = {"boundary", "sim", "surface", "clean", "preview"};

fs::path RequireTool(const GraphOptions& options, const std::string& name) {
  const fs::path program = options.tools_folder / name;
  if (access(program.c_str(), X_OK) != 0)
    throw InputError(
        fmt::format("stage tool {} not found or not executable (build it, or point --tools at the folder that holds it)", name),
        program.string());
  return program;
}

std::string Padded(std::int64_t frame) { return fmt::format("{:04}", frame); }

// Paths in the key are written relative to the output folder (or as given for files outside it),
// so the key names what the command does, not where the output folder happens to live.
std::string KeyPath(const fs::path& p, const BakeLayout& layout) {
  const fs::path relative = fs::absolute(p).lexically_normal().lexically_relative(fs::absolute(layout.output).lexically_normal());
  if (!relative.empty() && *relative.begin() != "..") return "$OUT/" + relative.generic_string();
  return p.generic_string();
}

}  // namespace

const char* StageName(Stage stage) { return kStageNames[static_cast<int>(stage)]; }

std::optional<Stage> ParseStage(const std::string& name) {
  for (int s = 0; s < kStageCount; ++s)
    if (name == kStageNames[s]) return static_cast<Stage>(s);
  for (const auto& [former, current] : {std::pair{"cleanup", "clean"}, {"simulate", "sim"}, {"simulation", "sim"}})
    if (name == former) throw Error(ExitCode::kUsage, fmt::format("stage '{}' is now called '{}'", former, current));
  return std::nullopt;
}

std::vector<std::string> SectionsReadBy(Stage stage, const SceneDocument& doc) {
  switch (stage) {
    case Stage::kBoundary:
      return {"water", "solid", "scene.quality"};
    case Stage::kSim: {
      std::vector<std::string> sections;
      for (const auto& s : doc.sections())
        if (s != "surface" && s != "clean" && s != "bake" && s != "farm") sections.push_back(s);
      return sections;
    }
    case Stage::kSurface:  // [freezing] holds the ice anisotropy parameters (k_r, k_n, N_eps) it may reuse
      return {"surface", "water", "freezing", "scene.quality"};
    case Stage::kClean:
      return {"clean", "surface", "water", "scene.quality"};
    case Stage::kPreview:
      return {"bake", "solid", "water_block", "emitter", "domain", "scene.fps"};
  }
  return {};
}

std::vector<Job> BuildGraph(const SceneDocument& doc, const BakeLayout& layout, const GraphOptions& options, Stage target) {
  const io::Scene& scene = doc.scene();
  const std::string scene_path = layout.scene_file.string();
  std::vector<Job> jobs;
  // Limits that do not change results: after the key arguments, like -j and --device.
  const auto limits = [&](Job& job, bool per_frame) {
    if (options.memory_budget > 0) {
      const std::uint64_t share =
          per_frame ? options.memory_budget / std::uint64_t(std::max(1, options.parallel_frames)) : options.memory_budget;
      job.args.insert(job.args.end(), {"--memory-budget", std::to_string(std::max<std::uint64_t>(share, 1))});
    }
    if (!options.sandbox.empty()) job.args.insert(job.args.end(), {"--sandbox", options.sandbox.string()});
  };
  const auto add = [&](Job job) {
    job.sections = SectionsReadBy(job.stage, doc);
    job.log = layout.logs() / (job.id + ".log");
    if (job.key_args.empty()) {
      for (const auto& a : job.args) job.key_args.push_back(a == scene_path ? std::string("$SCENE") : a);
      for (auto& a : job.key_args)
        if (a != "$SCENE" && (fs::path(a).has_parent_path())) a = KeyPath(a, layout);
    }
    jobs.push_back(std::move(job));
  };

  // 1. Boundary particles for every solid (one tool run for the whole scene).
  {
    Job job;
    job.stage = Stage::kBoundary;
    job.id = "boundary";
    job.tool_name = "rime-boundary";
    job.program = RequireTool(options, job.tool_name);
    job.args = {scene_path, "-o", layout.boundary().string()};
    for (const auto& solid : scene.solids) {
      if (solid.shape == io::SolidShape::kMesh) job.inputs.push_back(scene.Resolve(solid.mesh));
      job.outputs.push_back(layout.boundary() / (solid.name + ".h5part"));
    }
    job.exclusive = true;
    add(std::move(job));
    limits(jobs.back(), false);
  }
  if (target == Stage::kBoundary) return jobs;

  // 2. Simulation: alone, every frame; resumable after an interruption.
  const std::int64_t last_frame = scene.FrameCount();
  {
    Job job;
    job.stage = Stage::kSim;
    job.id = "sim";
    job.tool_name = "rime-sim";
    job.program = RequireTool(options, job.tool_name);
    job.args = {scene_path, "--boundary", layout.boundary().string(), "-o", layout.sim().string()};
    add(job);  // key_args without --device / -j: they do not change what is computed
    Job& added = jobs.back();
    if (options.device != "auto") added.args.insert(added.args.end(), {"--device", options.device});
    limits(added, false);
    added.inputs = jobs.front().outputs;
    added.dependencies = {"boundary"};
    for (std::int64_t f = 0; f <= last_frame; ++f) added.outputs.push_back(io::FramePath(layout.sim(), "particles", f, "h5part"));
    added.outputs.push_back(layout.sim() / "particles.h5part");
    added.outputs.push_back(layout.sim() / "stats.jsonl");
    added.exclusive = true;
    added.resumable = true;
    added.resume_folder = layout.sim();
  }
  if (target == Stage::kSim) return jobs;

  const std::int64_t first = std::max<std::int64_t>(0, options.first_frame);
  const std::int64_t last = std::min(last_frame, options.last_frame);
  // Frame-parallel jobs share the cores; the simulation gets them all (no -j).
  const auto frame_threads = [&](std::vector<std::string>& args) {
    if (options.cpu_threads > 0) args.insert(args.end(), {"-j", std::to_string(options.cpu_threads)});
  };

  // 3-5. Per frame: surface → clean → preview render. What rime-surface writes follows the
  // scene's [surface] phase ("ice", "water", "both") and formats (obj, ply, vdb).
  const io::SurfaceSettings& surfacing = scene.surface;
  std::vector<std::string> phases;
  if (surfacing.phase != io::SurfacePhases::kWater) phases.push_back("ice");
  if (surfacing.phase != io::SurfacePhases::kIce) phases.push_back("water");
  const auto has_format = [&](const char* ext) {
    return std::find(surfacing.formats.begin(), surfacing.formats.end(), ext) != surfacing.formats.end();
  };
  // The cleanup cleans the ice mesh (the water mesh when only water is surfaced), read as OBJ when
  // the surface writes OBJ, else PLY.
  const std::string cleaned_phase = phases.front();
  const char* mesh_format = has_format("obj") ? "obj" : "ply";
  if (target >= Stage::kClean && !has_format("obj") && !has_format("ply"))
    throw InputError(
        "[surface] formats has no mesh format (obj or ply), so the clean stage has nothing to clean; add \"obj\" or "
        "bake only up to the surface stage",
        scene_path + ": surface.formats");
  const fs::path preview_data = layout.cache() / "preview";
  const bool preview = target == Stage::kPreview && options.blender.has_value();
  for (std::int64_t f = first; f <= last; ++f) {
    const fs::path particles = io::FramePath(layout.sim(), "particles", f, "h5part");
    Job surface;
    surface.stage = Stage::kSurface;
    surface.frame = f;
    surface.id = "surface." + Padded(f);
    surface.tool_name = "rime-surface";
    surface.program = RequireTool(options, surface.tool_name);
    surface.args = {particles.string(), "-o", layout.surface().string(), "--scene", scene_path};
    surface.inputs = {particles};
    surface.dependencies = {"sim"};
    for (const auto& phase : phases)
      for (const char* ext : {"vdb", "obj", "ply"})
        if (has_format(ext)) surface.outputs.push_back(io::FramePath(layout.surface(), phase, f, ext));
    add(surface);
    frame_threads(jobs.back().args);
    limits(jobs.back(), true);
    if (target == Stage::kSurface) continue;

    const fs::path mesh = io::FramePath(layout.surface(), cleaned_phase, f, mesh_format);
    const std::string cleaned = cleaned_phase + "_clean";
    Job cleanup;
    cleanup.stage = Stage::kClean;
    cleanup.frame = f;
    cleanup.id = "clean." + Padded(f);
    cleanup.tool_name = "rime-clean";
    cleanup.program = RequireTool(options, cleanup.tool_name);
    cleanup.args = {mesh.string(), "-o", layout.clean().string(), "--scene", scene_path};
    cleanup.inputs = {mesh};
    cleanup.dependencies = {surface.id};
    cleanup.skip_when_input_mesh_empty = true;
    for (const char* ext : {"obj", "ply", "json"}) cleanup.outputs.push_back(io::FramePath(layout.clean(), cleaned, f, ext));
    add(cleanup);
    frame_threads(jobs.back().args);
    limits(jobs.back(), true);
    if (!preview) continue;

    Job render;
    render.stage = Stage::kPreview;
    render.frame = f;
    render.id = "preview." + Padded(f);
    render.tool_name = "blender";
    render.program = *options.blender;
    const fs::path clean_mesh = io::FramePath(layout.clean(), cleaned, f, "obj");
    const fs::path water_mesh = io::FramePath(layout.surface(), "water", f, "obj");
    const fs::path image = io::FramePath(layout.preview(), "frame", f, "png");
    render.args = {"--background",
                   "--factory-startup",
                   "-noaudio",
                   "--python",
                   (preview_data / "render_preview.py").string(),
                   "--",
                   "--setup",
                   (preview_data / "preview_scene.json").string(),
                   "--ice",
                   clean_mesh.string(),
                   "--water",
                   water_mesh.string(),
                   "--output",
                   image.string()};
    render.inputs = {preview_data / "render_preview.py", preview_data / "preview_scene.json"};
    render.optional_inputs = {clean_mesh, water_mesh};  // frames without ice have no cleaned mesh
    render.dependencies = {cleanup.id};
    render.outputs = {image};
    add(std::move(render));
  }

  // Contact sheet and MP4 of all rendered frames (ffmpeg), written under temporary names first.
  if (preview && options.ffmpeg && first <= last) {
    Job assemble;
    assemble.stage = Stage::kPreview;
    assemble.id = "preview.movie";
    assemble.tool_name = "ffmpeg";
    assemble.program = "/bin/sh";
    const fs::path pattern = layout.preview() / "frame.%04d.png";
    const fs::path sheet = layout.preview() / "contact_sheet.png", movie = layout.preview() / "preview.mp4";
    const std::int64_t count = last - first + 1;
    const int columns = std::min<std::int64_t>(doc.bake().contact_sheet_columns, count);
    const std::int64_t rows = (count + columns - 1) / columns;
    // Paths reach the shell as positional parameters, never inside the script text: an output
    // folder named `x'; rm -rf ~; '` is then just a folder name. Only numbers are formatted in.
    // ffmpeg reads "file:" paths (no "name:" taken for a protocol), the input pattern with any '%'
    // of the folder doubled, and writes the contact sheet as one literal file name (-update 1).
    std::string folder_pattern = layout.preview().string();
    for (std::size_t at = 0; (at = folder_pattern.find('%', at)) != std::string::npos; at += 2) folder_pattern.insert(at, "%");
    const std::string input = "file:" + (fs::path(folder_pattern) / pattern.filename()).string();
    const std::string script = fmt::format(
        "set -e; ff=\"$1\"; input=\"$2\"; sheet=\"$3\"; movie=\"$4\"; "
        "\"$ff\" -nostdin -y -loglevel error -start_number {first} -i \"$input\" "
        "-vf 'scale=320:-2,tile={columns}x{rows}' -frames:v 1 -update 1 \"file:$sheet.tmp.png\" && mv -- \"$sheet.tmp.png\" \"$sheet\"; "
        "\"$ff\" -nostdin -y -loglevel error -framerate {fps} -start_number {first} -i \"$input\" "
        "-vf 'pad=ceil(iw/2)*2:ceil(ih/2)*2' -c:v libx264 -pix_fmt yuv420p \"file:$movie.tmp.mp4\" && mv -- \"$movie.tmp.mp4\" \"$movie\"",
        fmt::arg("first", first), fmt::arg("columns", columns), fmt::arg("rows", rows), fmt::arg("fps", scene.info.fps));
    assemble.args = {"-c", script, "rime-bake-preview", options.ffmpeg->string(), input, sheet.string(), movie.string()};
    assemble.key_args = {"contact sheet + mp4", std::to_string(first), std::to_string(last), std::to_string(columns)};
    for (std::int64_t f = first; f <= last; ++f) {
      assemble.inputs.push_back(io::FramePath(layout.preview(), "frame", f, "png"));
      assemble.dependencies.push_back("preview." + Padded(f));
    }
    assemble.inputs.push_back(*options.ffmpeg);  // its version is part of the key
    assemble.outputs = {sheet, movie};
    add(std::move(assemble));
  }
  return jobs;
}

}  // namespace rime::bake
