// rime-bake: runs the stages of a scene like make, rerunning only what is stale (README.md "rime-bake").
#include <fmt/format.h>

#include <filesystem>
#include <thread>

#include "bake_graph.h"
#include "bake_runner.h"
#include "farm.h"
#include "preview_script.h"
#include "process.h"
#include "rime/core/error.h"
#include "rime/core/log.h"
#include "scene_document.h"
#include "tool.h"

namespace fs = std::filesystem;
using namespace rime;
using namespace rime::bake;

namespace {

// The output folder and every folder the bake writes under it (one could be a symlink leading
// out), and each mesh the scene names, resolved the way rime-boundary resolves it.
void RequireInSandbox(const Sandbox& sandbox, const io::Scene& scene, const BakeLayout& layout) {
  if (!sandbox.enabled()) return;
  for (const io::SolidObject& solid : scene.solids)
    if (solid.shape == io::SolidShape::kMesh)
      sandbox.Require(scene.Resolve(solid.mesh), fmt::format("{}: solid '{}' mesh", scene.file.string(), solid.name), ExitCode::kBadInput);
  for (const fs::path& folder : {layout.output, layout.cache(), layout.state_folder(), layout.logs(), layout.boundary(), layout.sim(),
                                 layout.surface(), layout.clean(), layout.preview(), layout.cache() / "preview"})
    sandbox.Require(folder, "-o", ExitCode::kUsage);
  for (const char* name : {"state.json", "lock"}) sandbox.Require(layout.state_folder() / name, "-o (bake state)", ExitCode::kUsage);
}

// Every file a job reads or writes: a file inside the output folder can itself be a symlink.
// Programs hashed into a key (ffmpeg) are tools, not data, like --tools.
void RequireInSandbox(const Sandbox& sandbox, const Job& job, const GraphOptions& graph) {
  if (!sandbox.enabled()) return;
  const std::string field = fmt::format("-o ({} job)", job.id);
  for (const auto* paths : {&job.inputs, &job.optional_inputs, &job.outputs})
    for (const fs::path& p : *paths)
      if (p != graph.ffmpeg && p != graph.blender) sandbox.Require(p, field, ExitCode::kUsage);
  sandbox.Require(job.log, field, ExitCode::kUsage);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "Bakes a scene: boundary -> sim -> surface -> clean (-> preview), rerunning only the jobs whose tool, command, scene "
      "sections or input files changed. Outputs go to <output>/surface, <output>/clean and <output>/preview; particles, "
      "logs and the bake state to <output>/cache."};
  tool::CommonOptions common;
  tool::Setup(app, "rime-bake", common, tool::kDevice | tool::kFrames | tool::kJsonSummary | tool::kMemoryBudget | tool::kSandbox);
  app.get_option("--frames")
      ->description(
          "Frame range A-B (or a single frame A) of the per-frame stages (surface, clean, preview); the simulation "
          "always computes every frame to the scene's end_time. Default: all");
  app.get_option("--memory-budget")
      ->description(
          "Passed to every stage tool, which refuses to start (exit 10, nothing written) when the peak memory it "
          "estimates from its inputs exceeds it; the per-frame stages each get SIZE divided by -j. SIZE: 512M, 4G, "
          "1.5GiB or bytes (powers of 1024). Default: each tool takes the memory available when it starts");
  app.get_option("--sandbox")
      ->description(
          "Refuse (nothing written) when the scene, a mesh path in the scene, the output folder, the cache or any "
          "file a job reads or writes does not resolve inside DIR after following symlinks; passed to every stage tool");
  std::string scene_file, target_name = "all", only_name, output, tools_folder;
  int parallel_frames = 1;
  bool force = false, dry_run = false, explain = false, clean = false;
  app.add_option("scene", scene_file, "Scene file (TOML)")->required();
  app.add_option("target", target_name,
                 "Last stage to bring up to date: boundary, sim, surface, clean, preview or all (= preview; skipped without Blender)")
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
  app.add_option("--tools", tools_folder,
                 "Folder holding rime-boundary, rime-sim, rime-surface, rime-clean (default: rime-bake's own folder)");
  std::string farm, farm_config, farm_task, farm_sim_job;
  int farm_chunk = 1;
  app.add_option("--farm", farm,
                 "Bake on a Slurm cluster (docs/farm.md): slurm submits the stale jobs and exits; status shows each stage and frame; "
                 "resubmit submits what failed or is missing; cancel cancels this bake's jobs")
      ->check(CLI::IsMember({"slurm", "status", "resubmit", "cancel"}));
  app.add_option("--farm-config", farm_config,
                 "Site settings for --farm: a TOML file with a [farm] table (default: $RIME_FARM_CONFIG); "
                 "the scene's own [farm] table overrides it");
  // What a farm task runs on a node (written by --farm slurm, not typed by users).
  app.add_option("--farm-task", farm_task)->group("");
  app.add_option("--farm-chunk", farm_chunk)->group("")->check(CLI::PositiveNumber);
  app.add_option("--farm-sim-job", farm_sim_job)->group("");
  app.footer(
      "Exit codes: 0 ok (everything up to the target is up to date), 1 internal failure, 2 bad command line, 3 bad scene file or "
      "missing stage tool, 5 cannot write the output or cache, a stage tool could not write its output, or another rime-bake is using the "
      "folder (the message names its pid, host and start time), 7 a stage failed (the message names stage, frame and log), "
      "8 --only refused (inputs missing or stale), 9 --farm: Slurm's commands missing or a submission refused, 10 a stage tool refused to "
      "start above its --memory-budget, 130 interrupted (rerun to continue; the simulation resumes).");

  return tool::Main(app, argc, argv, common, [&]() -> int {
    // The farm verbs default to the target and frames of the last submission.
    const bool farm_verb = farm == "status" || farm == "resubmit" || farm == "cancel";
    if (farm_verb && (app.count("target") == 0 || app.count("--frames") == 0)) {
      BakeLayout recorded_layout;
      recorded_layout.output = output;
      if (output.empty()) recorded_layout.output = fs::path("out") / SceneDocument::Load(scene_file).scene().info.name;
      if (const auto recorded = RecordedFarmBake(recorded_layout)) {
        if (app.count("target") == 0) target_name = recorded->target;
        if (app.count("--frames") == 0) common.frames = fmt::format("{}-{}", recorded->first, recorded->last);
      }
    }
    const auto target = ParseStage(target_name == "all" ? "preview" : target_name);
    if (!target)
      throw Error(ExitCode::kUsage, fmt::format("unknown target '{}' (boundary, sim, surface, clean, preview, all)", target_name));
    std::optional<Stage> only;
    if (!only_name.empty()) {
      only = ParseStage(only_name);
      if (!only)
        throw Error(ExitCode::kUsage, fmt::format("unknown stage '{}' for --only (boundary, sim, surface, clean, preview)", only_name));
    }

    const Sandbox sandbox = tool::MakeSandbox(common);
    sandbox.Require(scene_file, "scene", ExitCode::kUsage);
    const std::uint64_t memory_budget = common.memory_budget.empty() ? 0 : ParseByteSize(common.memory_budget);
    const SceneDocument doc = SceneDocument::Load(scene_file);
    BakeLayout layout;
    layout.scene_file = scene_file;
    layout.output = output.empty() ? fs::path("out") / doc.scene().info.name : fs::path(output);
    RequireInSandbox(sandbox, doc.scene(), layout);

    if (clean) {
      RefuseWhileFarmJobsAlive(layout);
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
    if (!farm_task.empty()) {
      // A farm task gives each tool the CPUs Slurm allocated to it.
      const char* allocated = std::getenv("SLURM_CPUS_PER_TASK");
      graph.cpu_threads = allocated ? std::max(1, std::atoi(allocated)) : 0;
    }
    graph.device = common.device;
    graph.memory_budget = memory_budget;
    graph.parallel_frames = parallel_frames;
    if (sandbox.enabled()) graph.sandbox = sandbox.root();
    // RIME_BLENDER picks a Blender outside PATH (studios keep several versions), or "none" to skip
    // the preview stage whatever is installed.
    const char* chosen_blender = std::getenv("RIME_BLENDER");
    const bool blender_off = chosen_blender && std::string(chosen_blender) == "none";
    if (chosen_blender && *chosen_blender && !blender_off) {
      if (!fs::exists(chosen_blender))
        throw Error(ExitCode::kBadInput, fmt::format("RIME_BLENDER names {}, which does not exist", chosen_blender));
      graph.blender = fs::path(chosen_blender);
    } else if (!blender_off) {
      graph.blender = FindOnPath("blender");
    }
    graph.ffmpeg = FindOnPath("ffmpeg");
    const Stage last_stage = only ? *only : *target;
    const bool preview_skipped = last_stage == Stage::kPreview && !graph.blender;
    if (preview_skipped && blender_off) log::Debug("preview stage skipped: RIME_BLENDER=none");
    else if (preview_skipped)
      log::Info(
          "preview stage skipped: blender is not on PATH (install Blender 3.4 or newer to get PNG frames, a contact sheet and an MP4)");
    else if (last_stage == Stage::kPreview && !graph.ffmpeg)
      log::Info("ffmpeg is not on PATH: the preview stage renders PNG frames only (no contact sheet, no MP4)");
    if (only == Stage::kPreview && !graph.blender) return 0;

    if (!farm.empty() || !farm_task.empty()) {
      if (only) throw Error(ExitCode::kUsage, "--only cannot be combined with --farm");
      FarmContext context;
      context.doc = &doc;
      context.layout = layout;
      context.layout.scene_file = fs::absolute(scene_file).lexically_normal();
      context.layout.output = fs::absolute(layout.output).lexically_normal();
      context.graph = graph;
      context.graph.tools_folder = fs::absolute(graph.tools_folder);
      context.target = last_stage;
      std::optional<fs::path> site_file;
      if (!farm_config.empty()) site_file = farm_config;
      else if (const char* env = std::getenv("RIME_FARM_CONFIG"); env && *env) site_file = env;
      if (farm_task.empty()) context.settings = LoadFarmSettings(site_file, scene_file);  // a task runs what was submitted
      const fs::path bin_dir = context.settings.bin_dir.empty() ? ExecutableFolder() : fs::path(context.settings.bin_dir);
      context.node_rime_bake = bin_dir / "rime-bake";
      context.node_tools = tools_folder.empty() && !context.settings.bin_dir.empty() ? bin_dir : context.graph.tools_folder;
      context.dry_run = dry_run;
      context.explain = explain;
      context.force = force;
      nlohmann::json summary = {{"scene", scene_file}, {"output", layout.output.string()}, {"dry_run", dry_run}};
      int code = 0;
      if (!farm_task.empty()) {
        InstallSignalHandlers();  // Slurm's SIGTERM (scancel, time limit) stops the tool; its job stays incomplete
        return FarmTask(context, farm_task, farm_chunk, farm_sim_job);
      }
      if (farm == "status") code = FarmStatus(context, summary);
      else if (farm == "cancel") code = FarmCancel(context, summary);
      else {
        if (!dry_run && last_stage == Stage::kPreview && graph.blender) WritePreviewFiles(doc, context.layout);
        code = FarmSubmit(context, farm == "resubmit", summary);
      }
      summary["exit_code"] = code;
      tool::WriteSummary(common, summary);
      return code;
    }
    if (!dry_run) RefuseWhileFarmJobsAlive(layout);

    std::vector<Job> jobs = BuildGraph(doc, layout, graph, last_stage);
    for (const Job& job : jobs) RequireInSandbox(sandbox, job, graph);
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

    nlohmann::json summary = {
        {"scene", scene_file}, {"output", layout.output.string()}, {"exit_code", result.exit_code},     {"seconds", result.seconds},
        {"dry_run", dry_run},  {"failure", result.failure},        {"preview_skipped", preview_skipped}};
    for (int s = 0; s < kStageCount; ++s) {
      const StageSummary& st = result.stages[s];
      summary["stages"][StageName(static_cast<Stage>(s))] = {{"ran", st.ran},       {"empty", st.empty},     {"cached", st.cached},
                                                             {"failed", st.failed}, {"not_run", st.not_run}, {"seconds", st.seconds}};
    }
    tool::WriteSummary(common, summary);
    int jobs_seen = 0;  // none when the bake was refused before running anything (--only, the lock)
    for (const auto& st : result.stages) jobs_seen += st.ran + st.cached + st.failed + st.not_run;
    if (result.exit_code == kExitOnlyRefused || (result.exit_code == static_cast<int>(ExitCode::kIo) && jobs_seen == 0))
      throw Error(static_cast<ExitCode>(result.exit_code), result.failure);
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
