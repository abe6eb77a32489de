/// @file farm.h
/// @brief rime-bake on a Slurm cluster. The submitter turns the stale part of the bake graph into
/// Slurm jobs (boundary and simulation as single jobs, the per-frame stages as job arrays chained
/// per frame) and exits; every task is a `rime-bake --farm-task` run on a node that runs its jobs
/// exactly like a local bake and records each result in the cache. Nothing central stays alive.
/// Assumes a filesystem shared by the submitting machine and every node, at the same paths: the
/// scene, the output folder (with its cache) and the Rime binaries.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "bake_graph.h"
#include "farm_settings.h"
#include "scene_document.h"

namespace rime::bake {

/// rime-bake's exit code when Slurm's commands are missing or the scheduler refuses a submission.
constexpr int kExitFarmRefused = 9;

/// What every farm verb works on: the same graph a local bake of `target` would run.
struct FarmContext {
  const SceneDocument* doc = nullptr;
  BakeLayout layout;  // absolute paths: the nodes see them as they are
  GraphOptions graph;
  Stage target = Stage::kPreview;
  FarmSettings settings;
  std::filesystem::path node_rime_bake;  // rime-bake as the nodes see it
  std::filesystem::path node_tools;      // the stage tools' folder as the nodes see it
  bool dry_run = false, explain = false, force = false;
};

/// `--farm slurm` (resubmit = false) and `--farm resubmit`: submits the stale jobs; resubmit leaves
/// out jobs whose task is still queued or running. Returns rime-bake's exit code.
int FarmSubmit(const FarmContext& farm, bool resubmit, nlohmann::json& summary);
/// `--farm status`: done / queued / running / failed / missing per stage and frame.
int FarmStatus(const FarmContext& farm, nlohmann::json& summary);
/// `--farm cancel`: cancels this bake's jobs and waits until they have left the queue.
int FarmCancel(const FarmContext& farm, nlohmann::json& summary);

/// The target and frame range of the last submission, so the verbs default to what was submitted.
struct FarmRecordedBake {
  std::string target;
  std::int64_t first = 0, last = 0;
};
std::optional<FarmRecordedBake> RecordedFarmBake(const BakeLayout& layout);

/// The batch script every task runs: its arguments are the task's command line, passed by sbatch
/// as an argument vector, so no scene value is ever interpreted by a shell. Scene values appear in
/// it only as the site's `#SBATCH` lines, one option each (LoadFarmSettings refuses line breaks).
std::string TaskScriptText(const FarmSettings& settings);

/// Refuses (rime::Error) when jobs of the last submission are still queued or running: a local
/// bake beside them would overwrite what they write.
void RefuseWhileFarmJobsAlive(const BakeLayout& layout);

/// The hidden `--farm-task GROUP` of a node: runs the jobs of GROUP (a whole-scene job id such as
/// "sim", or a per-frame stage name with the chunk of frames from $SLURM_ARRAY_TASK_ID) in order.
/// With `sim_job`, waits for each particle frame the running simulation job writes.
int FarmTask(const FarmContext& farm, const std::string& group, int chunk, const std::string& sim_job);

}  // namespace rime::bake
