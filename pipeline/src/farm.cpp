#include "farm.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <fmt/format.h>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <thread>
#include <tuple>

#include "bake_runner.h"
#include "process.h"
#include "rime/core/atomic_file.h"
#include "rime/core/error.h"
#include "rime/core/log.h"
#include "rime/core/progress.h"

namespace fs = std::filesystem;
using nlohmann::json;
using Clock = std::chrono::steady_clock;

namespace rime::bake {
namespace {

constexpr const char* kJobsFormat = "rime.farm-jobs";
constexpr int kJobsVersion = 1;
constexpr auto kCancelTimeout = std::chrono::seconds(120);

Error Refused(const std::string& what) { return Error(static_cast<ExitCode>(kExitFarmRefused), what); }

fs::path JobsFile(const BakeLayout& layout) { return layout.state_folder() / "farm-jobs.json"; }
fs::path TaskScript(const BakeLayout& layout) { return layout.state_folder() / "farm-task.sh"; }
fs::path FarmLogs(const BakeLayout& layout) { return layout.logs() / "farm"; }

// What one Slurm job runs: a whole-scene job (named by its id) or a per-frame stage (an array).
std::string GroupOf(const Job& job) { return job.frame >= 0 ? StageName(job.stage) : job.id; }

std::string OneLine(const std::string& text) {
  std::string out;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);) {
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    if (!out.empty()) out += "; ";
    out += line;
  }
  return out;
}

// "0-3,5,7-9" (Slurm's --array syntax, also used for frame lists in messages).
std::string Ranges(std::vector<std::int64_t> values) {
  std::sort(values.begin(), values.end());
  values.erase(std::unique(values.begin(), values.end()), values.end());
  std::string out;
  for (std::size_t i = 0; i < values.size();) {
    std::size_t j = i;
    while (j + 1 < values.size() && values[j + 1] == values[j] + 1) ++j;
    if (!out.empty()) out += ",";
    out += j == i ? std::to_string(values[i]) : fmt::format("{}-{}", values[i], values[j]);
    i = j + 1;
  }
  return out;
}

// ---- Slurm's client commands -------------------------------------------------------------------

fs::path SlurmCommand(const std::string& name) {
  const auto path = FindOnPath(name);
  if (!path)
    throw Refused(
        fmt::format("{} not found on PATH: --farm needs Slurm's client commands (sbatch, squeue, sacct, scancel) on this "
                    "machine (Debian: apt install slurm-client)",
                    name));
  return *path;
}

bool FinishedState(const std::string& state) {
  static const std::set<std::string> kFinished = {"COMPLETED", "FAILED",   "CANCELLED", "TIMEOUT", "OUT_OF_MEMORY", "NODE_FAIL",
                                                  "BOOT_FAIL", "DEADLINE", "PREEMPTED", "REVOKED", "SPECIAL_EXIT"};
  return kFinished.count(state.substr(0, state.find(' '))) > 0;
}

// Adds "123_4" -> state for "123_4", and for "123_[0-5,7%2]" (array tasks not split off yet) one
// entry per task.
void AddQueueEntry(const std::string& id, const std::string& state, std::map<std::string, std::string>& queue) {
  const auto bracket = id.find("_[");
  if (bracket == std::string::npos) {
    queue[id] = state;
    return;
  }
  const std::string job = id.substr(0, bracket);
  std::string list = id.substr(bracket + 2);
  list = list.substr(0, list.find_first_of("]%"));
  std::istringstream parts(list);
  for (std::string part; std::getline(parts, part, ',');) {
    const auto dash = part.find('-');
    const std::int64_t a = std::stoll(part.substr(0, dash)), b = dash == std::string::npos ? a : std::stoll(part.substr(dash + 1));
    for (std::int64_t k = a; k <= b; ++k) queue[fmt::format("{}_{}", job, k)] = state;
  }
}

// This user's jobs and array tasks the controller knows: Slurm id ("123", "123_4") -> state. With
// `finished`, those that ended recently (kept MinJobAge seconds), else those queued or running.
std::map<std::string, std::string> SqueueStates(bool finished) {
  const Captured r = CaptureProcess(SlurmCommand("squeue"), {"--noheader", "--array", "--me", "--states=all", "--format=%i|%T"});
  if (r.code != 0) throw Refused(fmt::format("squeue failed: {}", OneLine(r.err)));
  std::map<std::string, std::string> states;
  std::istringstream lines(r.out);
  for (std::string line; std::getline(lines, line);) {
    const auto bar = line.find('|');
    if (bar == std::string::npos) continue;
    const std::string state = line.substr(bar + 1);
    if (FinishedState(state) == finished) AddQueueEntry(line.substr(0, bar), state, states);
  }
  return states;
}
std::map<std::string, std::string> QueueStates() { return SqueueStates(false); }

// The queue, or nothing (with a warning) where Slurm's commands or controller cannot be reached:
// for views that still say something useful from the cache alone.
std::map<std::string, std::string> QueueStatesOrWarn() {
  try {
    return QueueStates();
  } catch (const Error& e) {
    log::Warn("cannot read the Slurm queue ({}); showing what the cache knows", e.what());
    return {};
  }
}

// Whether one job is still queued or running; nullopt when the controller cannot be asked.
std::optional<bool> JobAlive(const std::string& job_id) {
  const Captured r = CaptureProcess(SlurmCommand("squeue"), {"--noheader", "--jobs=" + job_id, "--format=%T"});
  if (r.code != 0) {
    if (r.err.find("Invalid job id") != std::string::npos) return false;  // finished and purged
    return std::nullopt;
  }
  std::istringstream lines(r.out);
  for (std::string state; std::getline(lines, state);)
    if (!state.empty() && !FinishedState(state)) return true;
  return false;
}

// Final states of finished jobs: from the controller while it keeps them, then from the accounting
// database where the site has one. Best effort: empty where neither knows them any more.
std::map<std::string, std::string> FinishedStates(const std::vector<std::string>& job_ids) {
  std::map<std::string, std::string> states;
  try {
    states = SqueueStates(true);
  } catch (const Error&) {}
  const auto sacct = FindOnPath("sacct");
  if (!sacct || job_ids.empty()) return states;
  std::string ids;
  for (const auto& id : job_ids) ids += (ids.empty() ? "" : ",") + id;
  const Captured r = CaptureProcess(*sacct, {"--noheader", "--parsable2", "--allocations", "--jobs=" + ids, "--format=JobID,State"});
  if (r.code != 0) return states;  // e.g. no accounting storage configured
  std::istringstream lines(r.out);
  for (std::string line; std::getline(lines, line);) {
    const auto bar = line.find('|');
    if (bar == std::string::npos) continue;
    std::string state = line.substr(bar + 1);
    state = state.substr(0, state.find(' '));  // "CANCELLED by 0"
    std::map<std::string, std::string> entry;
    if (!state.empty()) AddQueueEntry(line.substr(0, bar), state, entry);
    for (const auto& [id, value] : entry) states.emplace(id, value);  // the controller's view first
  }
  return states;
}

// ---- The record of submitted jobs (<cache>/.rime-bake/farm-jobs.json) ---------------------------

struct Submission {
  std::string group, job_id;
  std::int64_t first = 0;  // frame of array index 0
  int chunk = 1;
  std::vector<std::int64_t> tasks;  // array indices; empty for a single job

  bool Covers(const Job& job) const {
    if (job.frame < 0) return tasks.empty();
    return std::binary_search(tasks.begin(), tasks.end(), (job.frame - first) / chunk);
  }
  std::string TaskId(const Job& job) const { return job.frame < 0 ? job_id : fmt::format("{}_{}", job_id, (job.frame - first) / chunk); }
  fs::path Log(const BakeLayout& layout, const Job& job) const { return FarmLogs(layout) / fmt::format("{}.{}.log", group, TaskId(job)); }
};

struct JobsRecord {
  std::string target;
  std::int64_t first = 0, last = 0;
  std::vector<Submission> submissions;  // oldest first

  /// The latest submission that ran (or runs) this job.
  const Submission* For(const Job& job) const {
    for (auto it = submissions.rbegin(); it != submissions.rend(); ++it)
      if (it->group == GroupOf(job) && it->Covers(job)) return &*it;
    return nullptr;
  }
  std::vector<std::string> JobIds() const {
    std::vector<std::string> ids;
    for (const auto& s : submissions) ids.push_back(s.job_id);
    return ids;
  }
};

JobsRecord ReadJobs(const BakeLayout& layout) {
  JobsRecord record;
  std::ifstream in(JobsFile(layout));
  if (!in) return record;
  try {
    const json root = json::parse(in);
    if (root.value("format", "") != kJobsFormat || root.value("version", 0) != kJobsVersion) throw std::runtime_error("unknown format");
    record.target = root.at("target").get<std::string>();
    record.first = root.at("first").get<std::int64_t>();
    record.last = root.at("last").get<std::int64_t>();
    for (const auto& s : root.at("submissions")) {
      Submission sub;
      sub.group = s.at("group").get<std::string>();
      sub.job_id = s.at("job_id").get<std::string>();
      sub.first = s.at("first").get<std::int64_t>();
      sub.chunk = s.at("chunk").get<int>();
      sub.tasks = s.at("tasks").get<std::vector<std::int64_t>>();
      record.submissions.push_back(std::move(sub));
    }
  } catch (const std::exception& e) {
    log::Warn("ignoring {} ({}): the farm jobs of this bake are unknown", JobsFile(layout).string(), e.what());
    return {};
  }
  return record;
}

void WriteJobs(const BakeLayout& layout, const JobsRecord& record) {
  json submissions = json::array();
  for (const auto& s : record.submissions)
    submissions.push_back({{"group", s.group}, {"job_id", s.job_id}, {"first", s.first}, {"chunk", s.chunk}, {"tasks", s.tasks}});
  const json root = {{"format", kJobsFormat}, {"version", kJobsVersion}, {"target", record.target},
                     {"first", record.first}, {"last", record.last},     {"submissions", submissions}};
  WriteFileAtomically(JobsFile(layout), root.dump(1) + "\n");
}

std::vector<std::string> AliveJobIds(const JobsRecord& record, const std::map<std::string, std::string>& queue) {
  std::set<std::string> queued_jobs;  // "123" for "123" and for its array tasks "123_4"
  for (const auto& [id, state] : queue) queued_jobs.insert(id.substr(0, id.find('_')));
  std::vector<std::string> alive;
  for (const auto& s : record.submissions)
    if (queued_jobs.count(s.job_id)) alive.push_back(s.job_id);
  return alive;
}

// The per-frame stages' frame range (the graph's, after --frames).
std::pair<std::int64_t, std::int64_t> FrameSpan(const FarmContext& farm) {
  return {std::max<std::int64_t>(0, farm.graph.first_frame), std::min(farm.doc->scene().FrameCount(), farm.graph.last_frame)};
}

}  // namespace

std::string TaskScriptText(const FarmSettings& settings) {
  std::string text = "#!/bin/sh\n# rime-bake farm task: runs its arguments (a `rime-bake --farm-task` command line) unchanged.\n";
  for (const auto& line : settings.sbatch_lines) text += "#SBATCH " + line + "\n";
  text +=
      "if [ ! -x \"$1\" ]; then\n"
      "  echo \"rime-bake: error: $1 is not executable on node $(hostname): rime-bake --farm assumes the Rime binaries (farm.bin_dir), "
      "the scene and the output folder are on a filesystem every node sees at the same paths\" >&2\n"
      "  exit 2\n"
      "fi\n"
      "exec \"$@\"\n";
  return text;
}

std::optional<FarmRecordedBake> RecordedFarmBake(const BakeLayout& layout) {
  const JobsRecord record = ReadJobs(layout);
  if (record.target.empty()) return std::nullopt;
  return FarmRecordedBake{record.target, record.first, record.last};
}

void RefuseWhileFarmJobsAlive(const BakeLayout& layout) {
  const JobsRecord record = ReadJobs(layout);
  if (record.submissions.empty() || !FindOnPath("squeue")) return;
  std::vector<std::string> alive;
  try {
    alive = AliveJobIds(record, QueueStates());
  } catch (const Error& e) {
    log::Warn("cannot check for farm jobs of this bake ({})", e.what());
    return;
  }
  if (!alive.empty())
    throw Error(ExitCode::kIo,
                fmt::format("Slurm jobs of this bake are queued or running ({}); a local bake now would write the same files: "
                            "wait for them (--farm status) or cancel them (--farm cancel)",
                            fmt::join(alive, ", ")),
                layout.output.string());
}

int FarmSubmit(const FarmContext& farm, bool resubmit, json& summary) {
  const BakeLayout& layout = farm.layout;
  const fs::path sbatch = farm.dry_run ? fs::path("sbatch") : SlurmCommand("sbatch");
  const JobsRecord previous = ReadJobs(layout);
  std::map<std::string, std::string> queue;
  if (!previous.submissions.empty()) {
    if (farm.dry_run) queue = QueueStatesOrWarn();  // a dry run shows the plan even without a controller
    else queue = QueueStates();
  }
  const std::vector<std::string> alive = AliveJobIds(previous, queue);
  if (!resubmit && !alive.empty())
    throw Error(ExitCode::kIo,
                fmt::format("Slurm jobs of this bake are still queued or running ({}): see --farm status; --farm resubmit "
                            "submits what failed or is missing beside them, --farm cancel stops them",
                            fmt::join(alive, ", ")),
                layout.output.string());

  const std::vector<Job> jobs = BuildGraph(*farm.doc, layout, farm.graph, farm.target);
  RunOptions run;
  run.force = farm.force;
  Runner runner(*farm.doc, layout, jobs, run);
  const auto reasons = runner.Plan();
  const auto [first, last] = FrameSpan(farm);
  const int chunk = farm.settings.chunk;

  // Groups in pipeline order; a job whose task is still queued or running (resubmit) is left to it.
  struct Planned {
    std::string group;
    Stage stage = Stage::kBoundary;
    bool per_frame = false;
    int stale = 0;
    std::vector<std::int64_t> frames;
    std::vector<std::string> alive_jobs;  // earlier submissions of this group still in the queue
    std::string job_id;                   // once submitted
  };
  std::vector<Planned> groups;
  std::set<std::int64_t> indices;  // array indices, shared by every per-frame array so `aftercorr` pairs them
  for (std::size_t i = 0; i < jobs.size(); ++i) {
    const Job& job = jobs[i];
    const std::string group = GroupOf(job);
    auto found = std::find_if(groups.begin(), groups.end(), [&](const Planned& p) { return p.group == group; });
    if (found == groups.end()) {
      found = groups.insert(groups.end(), Planned{});
      found->group = group;
      found->stage = job.stage;
      found->per_frame = job.frame >= 0;
    }
    Planned& planned = *found;
    if (reasons[i].empty()) {
      if (farm.explain && farm.dry_run) std::printf("# %s: up to date\n", job.id.c_str());
      continue;
    }
    if (const Submission* sub = previous.For(job); sub && queue.count(sub->TaskId(job))) {
      if (std::find(planned.alive_jobs.begin(), planned.alive_jobs.end(), sub->job_id) == planned.alive_jobs.end())
        planned.alive_jobs.push_back(sub->job_id);
      if (farm.explain) std::printf("# %s: stale, but its task %s is still queued or running\n", job.id.c_str(), sub->TaskId(job).c_str());
      continue;
    }
    if (farm.explain) std::printf("# %s: %s\n", job.id.c_str(), fmt::format("{}", fmt::join(reasons[i], "; ")).c_str());
    ++planned.stale;
    if (job.frame >= 0) {
      planned.frames.push_back(job.frame);
      indices.insert((job.frame - first) / chunk);
    }
  }
  std::vector<std::int64_t> tasks(indices.begin(), indices.end());

  const FarmSettings& site = farm.settings;
  std::vector<Submission> submitted;
  json submitted_json = json::array();
  const auto cancel_submitted = [&] {
    if (submitted.empty()) return;
    std::vector<std::string> ids;
    for (const auto& s : submitted) ids.push_back(s.job_id);
    CaptureProcess(SlurmCommand("scancel"), ids);
  };
  if (!farm.dry_run && std::any_of(groups.begin(), groups.end(), [](const Planned& p) { return p.stale > 0; })) {
    fs::create_directories(FarmLogs(layout));
    WriteFileAtomically(TaskScript(layout), TaskScriptText(site));
  }
  for (std::size_t g = 0; g < groups.size(); ++g) {
    Planned& planned = groups[g];
    if (planned.stale == 0) continue;
    const bool is_sim = planned.stage == Stage::kSim;
    const int stage = static_cast<int>(planned.stage);
    std::vector<std::string> args = {"--parsable", fmt::format("--job-name=rime:{}:{}", farm.doc->scene().info.name, planned.group),
                                     "--chdir=" + layout.output.string(), "--kill-on-invalid-dep=yes"};
    args.push_back("--output=" + (FarmLogs(layout) / (planned.group + (planned.per_frame ? ".%A_%a.log" : ".%j.log"))).string());
    const std::string partition = is_sim && !site.sim_partition.empty() ? site.sim_partition : site.partition;
    if (!partition.empty()) args.push_back("--partition=" + partition);
    if (!site.account.empty()) args.push_back("--account=" + site.account);
    if (!site.qos.empty()) args.push_back("--qos=" + site.qos);
    if (!site.time[stage].empty()) args.push_back("--time=" + site.time[stage]);
    if (!site.memory[stage].empty()) args.push_back("--mem=" + site.memory[stage]);
    const int cpus = is_sim && site.sim_cpus_per_task > 0 ? site.sim_cpus_per_task : site.cpus_per_task;
    args.push_back(fmt::format("--cpus-per-task={}", cpus));
    if (is_sim && site.gpus && farm.graph.device != "cpu") args.push_back("--gres=" + site.gpu_gres);

    // Wait for the nearest upstream group submitted now: per frame (`aftercorr`) between arrays,
    // for the simulation's start when this array streams its frames (at most stream_tasks tasks
    // at once until the simulation ends: the tasks lift that throttle then), else for success.
    // Jobs of earlier submissions still in the queue (resubmit) only have to end: a task whose
    // input is then missing fails with a clear message.
    std::vector<std::string> dependencies;
    std::string sim_job;
    for (std::size_t u = g; u-- > 0;) {
      if (groups[u].stale == 0) continue;
      const std::string id = farm.dry_run ? fmt::format("<{} job>", groups[u].group) : groups[u].job_id;
      if (planned.per_frame && groups[u].per_frame) dependencies.push_back("aftercorr:" + id);
      else if (planned.per_frame && groups[u].stage == Stage::kSim && site.stream_tasks > 0) {
        dependencies.push_back("after:" + id);
        sim_job = id;
      } else {
        dependencies.push_back("afterok:" + id);
      }
      break;
    }
    if (planned.per_frame)
      args.push_back("--array=" + Ranges(tasks) + (sim_job.empty() ? std::string() : fmt::format("%{}", site.stream_tasks)));
    for (std::size_t u = 0; u < g; ++u)
      for (const auto& id : groups[u].alive_jobs) dependencies.push_back("afterany:" + id);
    if (!dependencies.empty()) args.push_back(fmt::format("--dependency={}", fmt::join(dependencies, ",")));

    args.push_back(TaskScript(layout).string());
    const std::vector<std::string> task = {farm.node_rime_bake.string(),
                                           layout.scene_file.string(),
                                           StageName(planned.stage),
                                           "-o",
                                           layout.output.string(),
                                           "--tools",
                                           farm.node_tools.string(),
                                           "--device",
                                           farm.graph.device,
                                           "--frames",
                                           fmt::format("{}-{}", first, last),
                                           "--farm-task",
                                           planned.group,
                                           "--farm-chunk",
                                           std::to_string(chunk)};
    args.insert(args.end(), task.begin(), task.end());
    if (!sim_job.empty()) args.insert(args.end(), {"--farm-sim-job", sim_job});
    if (farm.force) args.push_back("--force");
    // The limits given at submission hold on the node too: the task passes them to its tools.
    if (farm.graph.memory_budget > 0) args.insert(args.end(), {"--memory-budget", std::to_string(farm.graph.memory_budget)});
    if (!farm.graph.sandbox.empty()) args.insert(args.end(), {"--sandbox", farm.graph.sandbox.string()});

    if (farm.dry_run) {
      std::printf("%s\n", CommandLine(sbatch, args).c_str());
      continue;
    }
    const Captured r = CaptureProcess(sbatch, args);
    const std::string job_id = r.out.substr(0, r.out.find_first_of(";\n"));
    if (r.code != 0 || job_id.empty() || job_id.find_first_not_of("0123456789") != std::string::npos) {
      cancel_submitted();
      throw Refused(fmt::format("sbatch refused the {} job: {}{}", planned.group, OneLine(r.err.empty() ? r.out : r.err),
                                submitted.empty() ? "" : " (the jobs submitted before it were cancelled)"));
    }
    planned.job_id = job_id;
    Submission sub{planned.group, job_id, first, chunk, planned.per_frame ? tasks : std::vector<std::int64_t>{}};
    const std::string what = planned.per_frame ? fmt::format(" (array {}: {} tasks of up to {} frames; stale frames {})", Ranges(tasks),
                                                             tasks.size(), chunk, Ranges(planned.frames))
                                               : std::string();
    log::Info("submitted {} as Slurm job {}{}", planned.group, job_id, what);
    submitted_json.push_back({{"group", planned.group}, {"job_id", job_id}, {"tasks", sub.tasks}, {"frames", planned.frames}});
    submitted.push_back(std::move(sub));
  }

  int stale = 0;
  for (const auto& p : groups) stale += p.stale;
  summary["farm"] = resubmit ? "resubmit" : "slurm";
  summary["stale_jobs"] = stale;
  summary["submitted"] = submitted_json;
  if (stale == 0) {
    if (!farm.dry_run)
      log::Info("nothing to submit: every job up to {} is up to date{}", StageName(farm.target), alive.empty() ? "" : " or still queued");
    return 0;
  }
  if (farm.dry_run) {
    std::fflush(stdout);
    std::fprintf(stderr, "rime-bake: dry run: %d stale jobs would be submitted\n", stale);
    return 0;
  }
  JobsRecord record = resubmit ? previous : JobsRecord{};
  record.target = StageName(farm.target);
  record.first = first;
  record.last = last;
  record.submissions.insert(record.submissions.end(), submitted.begin(), submitted.end());
  try {
    WriteJobs(layout, record);
  } catch (...) {
    cancel_submitted();  // jobs that --farm status/cancel could not find must not run
    throw;
  }
  log::Info("follow with: rime-bake {} --farm status", layout.scene_file.string());
  return 0;
}

int FarmStatus(const FarmContext& farm, json& summary) {
  const BakeLayout& layout = farm.layout;
  const JobsRecord record = ReadJobs(layout);
  std::map<std::string, std::string> queue, finished;
  if (!record.submissions.empty()) {
    queue = QueueStatesOrWarn();
    finished = FinishedStates(record.JobIds());
  }
  const std::vector<Job> jobs = BuildGraph(*farm.doc, layout, farm.graph, farm.target);
  Runner runner(*farm.doc, layout, jobs, RunOptions{});

  enum State { kDone, kQueued, kRunning, kFailed, kMissing, kStates };
  static constexpr const char* kStateNames[kStates] = {"done", "queued", "running", "failed", "missing"};
  std::array<std::array<int, kStates>, kStageCount> counts{};
  // Per group (a whole-scene job or a per-frame stage) and state: its frames, in pipeline order.
  std::vector<std::tuple<std::string, int, std::vector<std::int64_t>>> frames_by;
  std::string details;
  json listed = json::array();
  int failed = 0;
  for (const Job& job : jobs) {
    State state = kDone;
    std::string slurm_task, slurm_state;
    fs::path log;
    if (runner.Evaluate(job).stale()) {
      const Submission* sub = record.For(job);
      if (sub) {
        slurm_task = sub->TaskId(job);
        if (const auto it = queue.find(slurm_task); it != queue.end()) slurm_state = it->second;
        else if (const auto f = finished.find(slurm_task); f != finished.end()) slurm_state = f->second;
      }
      const bool queued = sub && queue.count(slurm_task);
      if (queued) {
        state = slurm_state == "PENDING" ? kQueued : kRunning;
      } else if (fs::exists(IncompleteMarker(layout, job.id))) {
        state = kFailed;  // its task started the job and did not finish it
        log = job.log;
      } else if (!slurm_state.empty() && slurm_state != "COMPLETED" && slurm_state != "CANCELLED") {
        state = kFailed;  // the task failed before the job started (a node that cannot see the files, a time limit)
        log = sub->Log(layout, job);
      } else {
        state = kMissing;
      }
      if (state == kFailed) {
        ++failed;
        const std::string last = LastLogLine(log);
        details += fmt::format("{} failed{}{}: {}log: {}\n", job.id, slurm_task.empty() ? "" : " (Slurm task " + slurm_task,
                               slurm_task.empty() ? "" : (slurm_state.empty() ? ")" : ", " + slurm_state + ")"),
                               last.empty() ? "" : last + "; ", log.string());
      }
      listed.push_back({{"id", job.id},
                        {"stage", StageName(job.stage)},
                        {"frame", job.frame},
                        {"state", kStateNames[state]},
                        {"slurm_task", slurm_task},
                        {"slurm_state", slurm_state},
                        {"log", log.string()}});
    }
    ++counts[static_cast<int>(job.stage)][state];
    if (state == kDone || state == kFailed) continue;  // failed jobs are listed one by one below the table
    auto it = std::find_if(frames_by.begin(), frames_by.end(),
                           [&](const auto& entry) { return std::get<0>(entry) == GroupOf(job) && std::get<1>(entry) == state; });
    if (it == frames_by.end()) it = frames_by.insert(frames_by.end(), {GroupOf(job), state, {}});
    std::get<2>(*it).push_back(job.frame);
  }

  std::string table = fmt::format("{:<10} {:>6} {:>7} {:>8} {:>7} {:>8}\n", "stage", "done", "queued", "running", "failed", "missing");
  json stages = json::object();
  for (int s = 0; s < kStageCount; ++s) {
    const auto& c = counts[s];
    if (c[kDone] + c[kQueued] + c[kRunning] + c[kFailed] + c[kMissing] == 0) continue;
    table += fmt::format("{:<10} {:>6} {:>7} {:>8} {:>7} {:>8}\n", StageName(static_cast<Stage>(s)), c[kDone], c[kQueued], c[kRunning],
                         c[kFailed], c[kMissing]);
    for (int k = 0; k < kStates; ++k) stages[StageName(static_cast<Stage>(s))][kStateNames[k]] = c[k];
  }
  for (const auto& [group, state, frames] : frames_by)
    table += fmt::format("{}{}: {}\n", group, frames.front() < 0 ? "" : " frames " + Ranges(frames), kStateNames[state]);
  std::printf("%s%s", table.c_str(), details.c_str());
  int missing = 0;
  for (const auto& c : counts) missing += c[kMissing];
  if (failed + missing > 0)
    std::printf(
        "%d jobs failed and %d are missing (never ran, cancelled, or their dependency failed): `rime-bake %s --farm resubmit` submits "
        "them\n",
        failed, missing, layout.scene_file.string().c_str());
  if (record.submissions.empty()) std::printf("no farm submission is recorded for this bake (%s)\n", JobsFile(layout).string().c_str());
  std::fflush(stdout);
  summary["farm"] = "status";
  summary["stages"] = stages;
  summary["jobs"] = listed;
  return failed > 0 ? kExitStageFailed : 0;
}

int FarmCancel(const FarmContext& farm, json& summary) {
  const BakeLayout& layout = farm.layout;
  const JobsRecord record = ReadJobs(layout);
  summary["farm"] = "cancel";
  summary["cancelled"] = json::array();
  if (record.submissions.empty()) {
    log::Info("no farm submission is recorded for this bake ({}): nothing to cancel", JobsFile(layout).string());
    return 0;
  }
  std::vector<std::string> alive = AliveJobIds(record, QueueStates());
  if (alive.empty()) {
    log::Info("no job of this bake is queued or running");
    return 0;
  }
  if (farm.dry_run) {
    std::printf("%s\n", CommandLine("scancel", alive).c_str());
    return 0;
  }
  const Captured r = CaptureProcess(SlurmCommand("scancel"), alive);
  if (r.code != 0) throw Refused(fmt::format("scancel failed: {}", OneLine(r.err)));
  // Running tasks get SIGTERM: their tools stop, and the jobs they ran keep their incomplete
  // markers (no output looks finished). Wait until the scheduler has let them go.
  const auto deadline = Clock::now() + kCancelTimeout;
  while (!AliveJobIds(record, QueueStates()).empty()) {
    if (Clock::now() > deadline)
      throw Error(ExitCode::kIo,
                  fmt::format("jobs {} are still leaving the queue after {} s; check again with --farm status", fmt::join(alive, ", "),
                              std::chrono::duration_cast<std::chrono::seconds>(kCancelTimeout).count()));
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
  }
  log::Info("cancelled Slurm jobs {}; jobs that were running are marked incomplete and rerun with the next bake", fmt::join(alive, ", "));
  summary["cancelled"] = alive;
  return 0;
}

int FarmTask(const FarmContext& farm, const std::string& group, int chunk, const std::string& sim_job) {
  const BakeLayout& layout = farm.layout;
  // Wall-clock stamps in the task's Slurm log: how long a task waited and ran, beside its jobs' logs.
  const auto now = [] { return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count(); };
  log::Info("farm task {} started at {:.3f} s since the epoch", group, now());
  if (!fs::exists(TaskScript(layout))) {
    char host[256] = "this node";
    gethostname(host, sizeof host - 1);
    throw IoError(fmt::format("the bake's cache is not visible on node {}: rime-bake --farm assumes the output folder is on a filesystem "
                              "every node sees at the same path",
                              host),
                  layout.cache().string());
  }
  const std::vector<Job> jobs = BuildGraph(*farm.doc, layout, farm.graph, farm.target);
  std::int64_t lo = INT64_MIN, hi = INT64_MAX;
  if (const char* index = std::getenv("SLURM_ARRAY_TASK_ID")) {
    lo = FrameSpan(farm).first + std::stoll(index) * chunk;
    hi = lo + chunk - 1;
  }
  std::vector<const Job*> selected;
  for (const Job& job : jobs)
    if (job.frame >= 0 ? StageName(job.stage) == group && job.frame >= lo && job.frame <= hi : job.id == group) selected.push_back(&job);
  if (selected.empty())  // the submitting machine's graph had these jobs: this node's differs
    throw InputError(
        fmt::format("farm task {}: this node's bake graph has no such job{} (the preview stage needs Blender on the nodes' PATH)", group,
                    lo == INT64_MIN ? std::string() : fmt::format(" in frames {}-{}", lo, hi)),
        layout.scene_file.string());

  const fs::path sim_marker = IncompleteMarker(layout, "sim");
  std::string sim_key;
  // Once the simulation has ended, every task of this array may start: lift the throttle that kept
  // all but a few of them from waiting for frames meanwhile (any task that notices does it).
  bool throttle_lifted = sim_job.empty() || !std::getenv("SLURM_ARRAY_JOB_ID");
  const auto lift_throttle_once_sim_ended = [&](std::optional<bool> sim_alive) {
    if (throttle_lifted || (sim_alive ? *sim_alive : JobAlive(sim_job) != false)) return;
    const Captured r = CaptureProcess(SlurmCommand("scontrol"),
                                      {"update", fmt::format("JobId={}", std::getenv("SLURM_ARRAY_JOB_ID")), "ArrayTaskThrottle=0"});
    // Finished tasks make scontrol exit non-zero ("Job has already finished"); the rest say "No error".
    if (r.code != 0 && r.err.find("No error") == std::string::npos) log::Warn("cannot lift the array's throttle: {}", OneLine(r.err));
    throttle_lifted = true;
  };
  for (const Job* job : selected) {
    if (!sim_job.empty() && !job->inputs.empty()) {
      // The simulation job streams frames: one is final once it exists under the incomplete
      // marker of the current simulation key (the simulation writes the marker before its first
      // frame), or once the simulation job has ended without leaving a marker.
      const auto sim = std::find_if(jobs.begin(), jobs.end(), [](const Job& j) { return j.id == "sim"; });
      if (sim_key.empty()) sim_key = Runner(*farm.doc, layout, jobs, RunOptions{}).Evaluate(*sim).fresh.key;
      const fs::path& frame = job->inputs.front();
      const auto marker_key = [&] { return fs::exists(sim_marker) ? ReadFileOrEmpty(sim_marker) : std::string(); };
      int failed_queries = 0;
      bool announced = false;
      while (!(fs::exists(frame) && marker_key() == sim_key)) {
        if (Interrupted())
          throw Error(ExitCode::kInterrupted, fmt::format("{}: interrupted while waiting for frame {}", job->id, job->frame));
        const std::optional<bool> alive = JobAlive(sim_job);
        if (!alive && ++failed_queries > 120) throw Refused(fmt::format("cannot ask Slurm whether simulation job {} still runs", sim_job));
        if (alive == false) {
          lift_throttle_once_sim_ended(false);
          const std::string key = marker_key();
          if (fs::exists(frame) && (key.empty() || key == sim_key)) break;
          throw Error(static_cast<ExitCode>(kExitStageFailed), fmt::format("simulation job {} ended without writing frame {} ({}); see {}",
                                                                           sim_job, job->frame, frame.string(), sim->log.string()));
        }
        if (!announced) log::Info("{}: waiting for simulation job {} to write {}", job->id, sim_job, frame.string());
        announced = true;
        std::this_thread::sleep_for(std::chrono::seconds(1));
      }
    }
    RunOptions run;
    run.farm_task = true;
    run.farm_jobs = {job->id};
    run.force = farm.force;
    Runner runner(*farm.doc, layout, jobs, run);
    const BakeResult result = runner.Run();
    if (result.exit_code != 0) throw Error(static_cast<ExitCode>(result.exit_code), result.failure);
    const StageSummary& s = result.stages[static_cast<int>(job->stage)];
    log::Info("{}: {}", job->id, s.ran ? fmt::format("done in {}", FormatDuration(s.seconds)) : std::string("up to date"));
    lift_throttle_once_sim_ended(std::nullopt);
  }
  log::Info("farm task {} finished at {:.3f} s since the epoch", group, now());
  return 0;
}

}  // namespace rime::bake
