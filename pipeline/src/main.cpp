// rime-bake: runs the stages of a scene like make, rerunning only what is stale (README.md "rime-bake").
#include <fmt/format.h>

#include <filesystem>
#include <thread>

#include "bake_graph.h"
#include "bake_runner.h"
#include "preview_script.h"
#include "process.h"
#include "rime/core/error.h"
#include "rime/core/log.h"
#include "scene_document.h"
#include "tool.h"

namespace fs = std::filesystem;
using namespace rime;
using namespace rime::bake;

int main(int argc, char** argv) {
  CLI::App app{
      "Bakes a scene: boundary -> sim -> surface -> cleanup (-> preview), rerunning only the jobs whose tool, command, scene "
      "sections or input files changed. Outputs go to <output>/surface, <output>/clean and <output>/preview; particles, "
      "logs and the bake state to <output>/cache."};
  tool::CommonOptions common;
  tool::Setup(app, "rime-bake", common, tool::kDevice | tool::kFrames | tool::kJsonSummary);
  std::string scene_file, target_name = "all", only_name, output, tools_folder;
  int parallel_frames = 1;
  bool force = false, dry_run = false, explain = false, clean = false;
  app.add_option("scene", scene_file, "Scene file (TOML)")->required();
  app.add_option("target", target_name,
                 "Last stage to bring up to date: boundary, sim, surface, cleanup, preview or all (= preview; skipped without Blender)")
      ->capture_default_str();
  app.add_option("--only", only_name, "Rerun just this stage on cached inputs; refused when they are missing or stale (see --force)");
  app.add_flag("--force", force, "Rerun the selected jobs even when up to date; with --only, accept stale inputs");
  app.add_option("-j,--jobs", parallel_frames, "Frames processed at once by the per-frame stages (the simulation always runs alone)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_flag("-n,--dry-run", dry_run, "Print the commands that would run, run nothing");
  app.add_flag("--explain", explain, "Say why each job is stale (with --dry-run: also which are up to date)");
  app.add_flag("--clean", clean, "Delete everything this bake produced for the scene (output stages and cache), then stop");
  app.add_option("-o,--output", output, "Output folder (default: out/<scene name>); the cache lives in <output>/cache");
  app.add_option("--tools", tools_folder, "Folder holding rime-boundary, rime-sim, rime-surface, rime-clean (default: rime-bake's own folder)");
  app.footer(
      "Exit codes: 0 ok (everything up to the target is up to date), 1 internal failure, 2 bad command line, 3 bad scene file or "
      "missing stage tool, 5 cannot write the output or cache (or another rime-bake is using it), 7 a stage failed (the message names stage, frame and log), "
      "8 --only refused (inputs missing or stale), 130 interrupted (rerun to continue; the simulation resumes).");

  return tool::Main(app, argc, argv, common, [&]() -> int {
    const auto target = ParseStage(target_name == "all" ? "preview" : target_name);
    if (!target) throw Error(ExitCode::kUsage, fmt::format("unknown target '{}' (boundary, sim, surface, cleanup, preview, all)", target_name));
    std::optional<Stage> only;
    if (!only_name.empty()) {
      only = ParseStage(only_name);
      if (!only) throw Error(ExitCode::kUsage, fmt::format("unknown stage '{}' for --only (boundary, sim, surface, cleanup, preview)", only_name));
    }

    const SceneDocument doc = SceneDocument::Load(scene_file);
    BakeLayout layout;
    layout.scene_file = scene_file;
    layout.output = output.empty() ? fs::path("out") / doc.scene().info.name : fs::path(output);

    if (clean) {
      for (const fs::path& folder : {layout.cache(), layout.surface(), layout.clean(), layout.preview()}) {
        std::error_code ec;
        const auto removed = fs::remove_all(folder, ec);
        if (ec) throw IoError(fmt::format("cannot delete: {}", ec.message()), folder.string());
        if (removed) log::Info("removed {} ({} files and folders)", folder.string(), removed);
      }
      std::error_code ec;
      fs::remove(layout.output, ec);  // only when empty
      return 0;
    }

    GraphOptions graph;
    graph.tools_folder = tools_folder.empty() ? ExecutableFolder() : fs::path(tools_folder);
    const tool::FrameRange frames = tool::ParseFrames(common.frames);
    graph.first_frame = frames.first;
    graph.last_frame = frames.last;
    const int cores = std::max(1u, std::thread::hardware_concurrency());
    graph.cpu_threads = parallel_frames > 1 ? std::max(1, cores / parallel_frames) : 0;
    graph.device = common.device;
    graph.blender = FindOnPath("blender");
    graph.ffmpeg = FindOnPath("ffmpeg");
    const Stage last_stage = only ? *only : *target;
    const bool preview_skipped = last_stage == Stage::kPreview && !graph.blender;
    if (preview_skipped)
      log::Info("preview stage skipped: blender is not on PATH (install Blender 3.4 or newer to get PNG frames, a contact sheet and an MP4)");
    else if (last_stage == Stage::kPreview && !graph.ffmpeg)
      log::Info("ffmpeg is not on PATH: the preview stage renders PNG frames only (no contact sheet, no MP4)");
    if (only == Stage::kPreview && !graph.blender) return 0;

    std::vector<Job> jobs = BuildGraph(doc, layout, graph, last_stage);
    if (!dry_run && std::any_of(jobs.begin(), jobs.end(), [](const Job& j) { return j.stage == Stage::kPreview; }))
      WritePreviewFiles(doc, layout);

    InstallSignalHandlers();
    RunOptions run;
    run.only = only;
    run.force = force;
    run.dry_run = dry_run;
    run.explain = explain;
    run.parallel_frames = parallel_frames;
    Runner runner(doc, layout, std::move(jobs), run);
    const BakeResult result = runner.Run();

    nlohmann::json summary = {{"scene", scene_file},         {"output", layout.output.string()}, {"exit_code", result.exit_code},
                              {"seconds", result.seconds},  {"dry_run", dry_run},                {"failure", result.failure},
                              {"preview_skipped", preview_skipped}};
    for (int s = 0; s < kStageCount; ++s) {
      const StageSummary& st = result.stages[s];
      summary["stages"][StageName(static_cast<Stage>(s))] = {
          {"ran", st.ran}, {"empty", st.empty}, {"cached", st.cached}, {"failed", st.failed}, {"not_run", st.not_run}, {"seconds", st.seconds}};
    }
    tool::WriteSummary(common, summary);
    if (result.exit_code == kExitOnlyRefused || result.exit_code == static_cast<int>(ExitCode::kIo)) throw Error(static_cast<ExitCode>(result.exit_code), result.failure);
    if (!common.quiet) {
      if (dry_run) {
        int would_run = 0, up_to_date = 0;
        for (const auto& st : result.stages) would_run += st.ran, up_to_date += st.cached;
        std::fprintf(stderr, "rime-bake: dry run: %d jobs would run, %d are up to date\n", would_run, up_to_date);
      } else {
        std::printf("%s", SummaryTable(result, preview_skipped).c_str());
        std::fflush(stdout);
      }
    }
    if (result.exit_code != 0) throw Error(static_cast<ExitCode>(result.exit_code), result.failure);
    if (!dry_run) log::Info("done: outputs in {}", layout.output.string());
    return 0;
  });
}
