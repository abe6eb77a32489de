/// @file bake_runner.h
/// @brief Decides which jobs are stale and runs them: cheap checks first, content hashes when a
/// file's size or mtime changed, incomplete markers for interrupted jobs, early cutoff when a
/// rerun writes byte-identical output (the downstream keys hash input content, not timestamps).
#pragma once

#include <array>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "bake_graph.h"
#include "bake_state.h"

namespace rime::bake {

/// rime-bake's own exit codes beyond the shared ones (README.md "rime-bake").
constexpr int kExitStageFailed = 7;  // a stage tool failed: the message names stage, frame and log
constexpr int kExitOnlyRefused = 8;  // --only: inputs missing or stale (pass --force to run anyway)

struct RunOptions {
  std::optional<Stage> only;  // --only STAGE: rerun that stage's jobs on cached inputs
  bool force = false;         // rerun selected jobs even when up to date (--only: accept stale inputs)
  bool dry_run = false;       // print the commands that would run
  bool explain = false;       // print why each job is stale
  int parallel_frames = 1;    // -j
  /// Farm task: run just these jobs (other tasks bring their inputs up to date), beside other farm
  /// tasks: the bake lock is taken shared and each job's record is written to its own file.
  bool farm_task = false;
  std::vector<std::string> farm_jobs;
};

struct StageSummary {
  int ran = 0, cached = 0, failed = 0, not_run = 0;
  int empty = 0;       // of `ran`: frames with an empty input mesh, nothing to clean (tool not run)
  double seconds = 0;  // wall time of the jobs that ran (summed over parallel jobs)
};

struct BakeResult {
  std::array<StageSummary, kStageCount> stages{};
  int exit_code = 0;
  std::string failure;  // one line; empty on success
  double seconds = 0;
};

/// Why a job would run; empty when it is up to date.
struct Verdict {
  std::vector<std::string> reasons;
  JobRecord fresh;  // key and components computed from the current inputs
  std::vector<std::string> missing_inputs;
  bool stale() const { return !reasons.empty(); }
};

/// Last non-empty line of a log: stage tools end a failure with `tool: error: ...`.
std::string LastLogLine(const std::filesystem::path& log);

/// Present while a job runs, holding its key; left behind when it fails or is interrupted.
std::filesystem::path IncompleteMarker(const BakeLayout& layout, const std::string& job_id);

class Runner {
 public:
  Runner(const SceneDocument& doc, const BakeLayout& layout, std::vector<Job> jobs, RunOptions options);
  BakeResult Run();
  /// Staleness of one job against the recorded state (no side effects besides stamp updates).
  Verdict Evaluate(const Job& job);
  /// Why each job would run (empty: up to date). A job downstream of one that would run is listed
  /// too, since it reruns unless early cutoff finds the upstream output byte-identical.
  std::vector<std::vector<std::string>> Plan();

 private:
  struct Impl;
  std::vector<std::vector<std::string>> Plan(const std::vector<bool>& selected, const std::set<std::size_t>& forced);
  void RemoveStaleTemporaries();
  const SceneDocument& doc_;
  BakeLayout layout_;
  std::vector<Job> jobs_;
  RunOptions options_;
  BakeState state_;
};

/// The table printed at the end: stage, jobs run, cached, failed, time.
std::string SummaryTable(const BakeResult& result, bool preview_skipped);

}  // namespace rime::bake
