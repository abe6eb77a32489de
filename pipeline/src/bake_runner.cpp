#include "bake_runner.h"

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <fmt/format.h>
#include <fstream>
#include <map>
#include <mutex>
#include <set>
#include <sstream>
#include <thread>

#include "bake_lock.h"
#include "process.h"
#include "rime/core/atomic_file.h"
#include "rime/core/error.h"
#include "rime/core/hash.h"
#include "rime/core/log.h"
#include "rime/core/memory_budget.h"
#include "rime/core/progress.h"
#include "rime/io/particles.h"

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace rime::bake {
namespace {

std::string DescribeComponent(const std::string& component) {
  if (component == "tool") return "the tool binary";
  if (component == "command") return "the command line";
  if (component.rfind("scene:", 0) == 0) return fmt::format("scene section [{}]", component.substr(6));
  if (component.rfind("input:", 0) == 0) return fmt::format("input {}", component.substr(6));
  return component;
}

// Whether an OBJ or PLY file has at least one face (rime-surface writes empty meshes for frames
// without ice). Reads the OBJ until its first face, or the PLY header.
bool MeshHasFaces(const fs::path& mesh) {
  std::ifstream in(mesh, std::ios::binary);
  std::string line;
  if (mesh.extension() == ".ply") {
    while (std::getline(in, line) && line.rfind("end_header", 0) != 0) {
      std::istringstream words(line);
      std::string element, name;
      long long count = 0;
      if (words >> element >> name >> count && element == "element" && name == "face") return count > 0;
    }
    return false;
  }
  while (std::getline(in, line))
    if (line.size() > 1 && line[0] == 'f' && (line[1] == ' ' || line[1] == '\t')) return true;
  return false;
}

std::string FrameSuffix(const Job& job) { return job.frame >= 0 ? fmt::format(" on frame {}", job.frame) : std::string(); }

enum class Status { kPending, kRunning, kDone, kFailed, kNotRun };

}  // namespace

struct Runner::Impl {
  explicit Impl(Runner& r) : runner(r) {}
  Runner& runner;
  std::mutex mutex;
  std::condition_variable wake;
  std::mutex save_mutex;
  std::vector<Status> status;
  std::set<std::size_t> forced;  // --only / --force: run even when up to date
  BakeResult result;
  bool stop = false;

  fs::path Marker(const Job& job) const { return IncompleteMarker(runner.layout_, job.id); }

  // The state is rewritten at most every couple of seconds (it lists every file, so saving after
  // each of thousands of frame jobs would be quadratic) and at the end. A job whose record was not
  // saved yet simply reruns after a crash: its key is unknown, so it counts as never built.
  Clock::time_point last_save{};
  void Save(bool now) {
    std::lock_guard lock(save_mutex);
    if (!now && Clock::now() - last_save < std::chrono::seconds(2)) return;
    runner.state_.Save();
    last_save = Clock::now();
  }

  void Fail(const Job& job, int exit_code, std::string message) {
    std::lock_guard lock(mutex);
    if (result.failure.empty()) {
      result.failure = std::move(message);
      result.exit_code = exit_code;
    }
    stop = true;
  }

  /// Runs one job if stale; returns its final status. Called on a worker thread.
  Status Execute(std::size_t index) {
    const Job& job = runner.jobs_[index];
    const Verdict verdict = runner.Evaluate(job);
    StageSummary& summary = result.stages[static_cast<int>(job.stage)];
    if (!verdict.stale() && !forced.count(index)) {
      log::Debug("{}: up to date", job.id);
      std::lock_guard lock(mutex);
      ++summary.cached;
      return Status::kDone;
    }
    if (runner.options_.explain) {
      const auto reasons = verdict.stale() ? verdict.reasons : std::vector<std::string>{"requested (--only/--force)"};
      log::Info("{} runs: {}", job.id, fmt::join(reasons, "; "));
    }
    if (!verdict.missing_inputs.empty()) {
      Fail(job, kExitStageFailed,
           fmt::format("stage {}{} cannot run: input {} is missing", StageName(job.stage), FrameSuffix(job),
                       verdict.missing_inputs.front()));
      return Status::kFailed;
    }

    if (job.skip_when_input_mesh_empty && !job.inputs.empty() && !MeshHasFaces(job.inputs.front())) {
      log::Debug("{}: {} has no triangles, nothing to clean", job.id, job.inputs.front().string());
      for (const auto& output : job.outputs) {
        std::error_code ec;
        fs::remove(output, ec);  // an older cleaned mesh of this frame would no longer match its input
      }
      JobRecord record = verdict.fresh;
      record.outputs.clear();
      runner.state_.SetRecord(job.id, std::move(record));
      std::error_code ec;
      fs::remove(Marker(job), ec);
      std::lock_guard lock(mutex);
      ++summary.ran;
      ++summary.empty;
      return Status::kDone;
    }

    std::vector<std::string> args = job.args;
    const fs::path marker = Marker(job);
    if (job.resumable) {
      // Resume only a run of the same key that was cut off; anything else restarts from scratch so
      // frames computed with other parameters cannot survive.
      const bool same_run_interrupted = fs::exists(marker) && ReadFileOrEmpty(marker) == verdict.fresh.key;
      if (same_run_interrupted && !job.outputs.empty() && fs::exists(job.outputs.front())) {
        args.push_back("--resume");
        log::Info("{}: continuing the interrupted run from its last complete frame (--resume)", job.id);
      } else {
        std::error_code ec;
        fs::remove_all(job.resume_folder, ec);
      }
    }
    // Snakemake-style incomplete marker: present while the job runs, removed after success.
    fs::create_directories(marker.parent_path());
    WriteFileAtomically(marker, verdict.fresh.key);

    log::Debug("{}: {}", job.id, CommandLine(job.program, args));
    const auto start = Clock::now();
    const int code = RunProcess(job.program, args, job.log);
    const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
    {
      std::lock_guard lock(mutex);
      summary.seconds += seconds;
    }
    if (code != 0) {
      if (Interrupted()) {
        Fail(job, static_cast<int>(ExitCode::kInterrupted),
             fmt::format("interrupted during stage {}{}; rerun the same command to continue (log: {})", StageName(job.stage),
                         FrameSuffix(job), job.log.string()));
      } else {
        const std::string last = LastLogLine(job.log);
        // A tool that could not write its output (disk full, file too large, permissions), or
        // that refused to start above its memory budget, passes its code on: both are about the
        // machine, not the scene.
        const bool passed_on = code == static_cast<int>(ExitCode::kIo) || code == static_cast<int>(ExitCode::kOverBudget);
        Fail(job, passed_on ? code : kExitStageFailed,
             fmt::format("stage {} failed{} ({} exited with code {}{}); log: {}", StageName(job.stage), FrameSuffix(job), job.tool_name,
                         code, last.empty() ? "" : ": " + last, job.log.string()));
      }
      return Status::kFailed;
    }

    JobRecord record = verdict.fresh;
    record.seconds = seconds;
    for (const auto& output : job.outputs) {
      const auto hash = runner.state_.ContentHash(output);
      if (!hash) {
        Fail(job, kExitStageFailed,
             fmt::format("stage {} failed{}: {} exited without writing {}; log: {}", StageName(job.stage), FrameSuffix(job), job.tool_name,
                         output.string(), job.log.string()));
        return Status::kFailed;
      }
      record.outputs[runner.state_.Name(output)] = *hash;
    }
    runner.state_.SetRecord(job.id, std::move(record));
    Save(job.exclusive);  // the simulation's record is saved at once: losing it would mean a full rerun
    std::error_code ec;
    fs::remove(marker, ec);
    std::lock_guard lock(mutex);
    ++summary.ran;
    return Status::kDone;
  }
};

std::string LastLogLine(const fs::path& log) {
  std::ifstream in(log);
  std::string line, last;
  while (std::getline(in, line))
    if (line.find_first_not_of(" \t\r") != std::string::npos) last = line;
  return last;
}

fs::path IncompleteMarker(const BakeLayout& layout, const std::string& job_id) { return layout.state_folder() / "incomplete" / job_id; }

Runner::Runner(const SceneDocument& doc, const BakeLayout& layout, std::vector<Job> jobs, RunOptions options)
    : doc_(doc), layout_(layout), jobs_(std::move(jobs)), options_(options), state_(layout.output, layout.state_folder() / "state.json") {
  if (options_.farm_task) state_.UsePerJobRecords();
  state_.Load();
}

Verdict Runner::Evaluate(const Job& job) {
  Verdict v;
  auto& c = v.fresh.components;
  c["tool"] = state_.ContentHash(job.program).value_or("missing");
  std::string command = job.tool_name;
  for (const auto& a : job.key_args) command += '\0' + a;
  c["command"] = HexHash(Hash64(command));
  for (const auto& s : job.sections) c["scene:" + s] = doc_.SectionHash(s);
  for (const auto& input : job.inputs) {
    const auto hash = state_.ContentHash(input);
    if (!hash) v.missing_inputs.push_back(input.string());
    c["input:" + state_.Name(input)] = hash.value_or("missing");
  }
  for (const auto& input : job.optional_inputs)
    if (const auto hash = state_.ContentHash(input)) c["input:" + state_.Name(input)] = *hash;
  std::string all;
  for (const auto& [name, value] : c) all += name + "=" + value + "\n";
  v.fresh.key = HexHash(Hash64(all));

  if (fs::exists(IncompleteMarker(layout_, job.id))) v.reasons.push_back("left incomplete by an interrupted or failed run");
  const auto record = state_.Record(job.id);
  if (!record) {
    if (v.reasons.empty()) v.reasons.push_back("never built");
    return v;
  }
  if (record->key != v.fresh.key) {
    for (const auto& [name, value] : c) {
      const auto old = record->components.find(name);
      if (old == record->components.end()) v.reasons.push_back(DescribeComponent(name) + " is new");
      else if (old->second != value) v.reasons.push_back(DescribeComponent(name) + (value == "missing" ? " is missing" : " changed"));
    }
    for (const auto& [name, value] : record->components)
      if (!c.count(name)) v.reasons.push_back(DescribeComponent(name) + " is no longer used");
  }
  // A frame with nothing to clean was recorded without outputs; its key covers the input mesh.
  const bool recorded_empty = job.skip_when_input_mesh_empty && record->outputs.empty();
  for (const auto& output : job.outputs) {
    if (recorded_empty) break;
    const auto hash = state_.ContentHash(output);
    const auto recorded = record->outputs.find(state_.Name(output));
    if (!hash) v.reasons.push_back(fmt::format("output {} is missing", output.string()));
    else if (recorded != record->outputs.end() && recorded->second != *hash)
      v.reasons.push_back(fmt::format("output {} was changed after it was written", output.string()));
  }
  return v;
}

BakeResult Runner::Run() {
  const auto start = Clock::now();
  Impl impl(*this);
  const std::size_t n = jobs_.size();
  impl.status.assign(n, Status::kPending);
  std::map<std::string, std::size_t> index_of;
  for (std::size_t i = 0; i < n; ++i) index_of[jobs_[i].id] = i;

  // --only STAGE: the selected jobs always run; every job upstream of them must be up to date.
  std::vector<bool> selected(n, true);
  if (options_.farm_task) {
    for (std::size_t i = 0; i < n; ++i) {
      selected[i] = std::find(options_.farm_jobs.begin(), options_.farm_jobs.end(), jobs_[i].id) != options_.farm_jobs.end();
      if (!selected[i]) impl.status[i] = Status::kDone;  // another farm task's business
      else if (options_.force) impl.forced.insert(i);
    }
  } else if (options_.only) {
    std::vector<std::string> problems;
    for (std::size_t i = 0; i < n; ++i) {
      selected[i] = jobs_[i].stage == *options_.only;
      if (!selected[i]) continue;
      impl.forced.insert(i);
      for (const auto& input : jobs_[i].inputs)
        if (!fs::exists(input)) problems.push_back(fmt::format("input {} of {} is missing", input.string(), jobs_[i].id));
    }
    for (std::size_t i = 0; i < n && problems.size() < 5; ++i) {
      if (selected[i]) continue;
      const Verdict v = Evaluate(jobs_[i]);
      if (v.stale()) problems.push_back(fmt::format("{} is stale ({})", jobs_[i].id, fmt::join(v.reasons, "; ")));
    }
    if (!problems.empty() && !options_.force) {
      BakeResult refused;
      refused.exit_code = kExitOnlyRefused;
      refused.failure = fmt::format(
          "--only {} refused: {}{}; run `rime-bake {} {}` to bring its inputs up to date, or add --force to use them as they are",
          StageName(*options_.only), problems.front(),
          problems.size() > 1 ? fmt::format(" (and {} more problems)", problems.size() - 1) : "", layout_.scene_file.string(),
          StageName(*options_.only));
      return refused;
    }
    for (std::size_t i = 0; i < n; ++i)
      if (!selected[i]) impl.status[i] = Status::kDone;  // upstream counts as satisfied
  } else if (options_.force) {
    for (std::size_t i = 0; i < n; ++i) impl.forced.insert(i);
  }

  if (options_.dry_run) {
    const auto reasons = Plan(selected, impl.forced);
    for (std::size_t i = 0; i < n; ++i) {
      if (!selected[i]) continue;
      const Job& job = jobs_[i];
      StageSummary& summary = impl.result.stages[static_cast<int>(job.stage)];
      if (reasons[i].empty()) {
        ++summary.cached;
        if (options_.explain) std::printf("# %s: up to date\n", job.id.c_str());
        continue;
      }
      ++summary.ran;
      if (options_.explain) std::printf("# %s: %s\n", job.id.c_str(), fmt::format("{}", fmt::join(reasons[i], "; ")).c_str());
      std::printf("%s\n", CommandLine(job.program, job.args).c_str());
    }
    std::fflush(stdout);
    impl.result.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    return impl.result;
  }

  fs::create_directories(layout_.logs());
  fs::create_directories(layout_.state_folder());
  // One bake per output folder at a time: two would overwrite each other's outputs and state.
  // Farm tasks share the lock: each runs different jobs and writes its own records. The stage
  // tools inherit it, so it stays held until the last of them exits even if rime-bake is killed.
  std::optional<BakeLock> bake_lock;
  try {
    bake_lock.emplace(layout_.state_folder() / "lock", layout_.output, options_.farm_task);
  } catch (const Error& e) {
    BakeResult busy;
    busy.exit_code = static_cast<int>(e.code());
    busy.failure = e.what();
    return busy;
  }
  const ToolsInherit inherit_lock(bake_lock->fd());
  if (!options_.farm_task) RemoveStaleTemporaries();
  // Progress counts tasks of about one frame's work each, so that the ETA is not thrown off by the
  // simulation (one job that takes longer than all the others): it counts as one task per output
  // frame, advanced as its frames appear; every other job is one task.
  // The simulation's outputs are its frames (0 included), the sequence index and the stats log.
  const auto sim_frames = [&](std::size_t i) { return std::max<std::int64_t>(1, static_cast<std::int64_t>(jobs_[i].outputs.size()) - 2); };
  std::int64_t total_tasks = 0;
  std::array<std::int64_t, kStageCount> stage_total{};
  for (std::size_t i = 0; i < n; ++i)
    if (selected[i]) {
      ++stage_total[static_cast<int>(jobs_[i].stage)];
      total_tasks += jobs_[i].stage == Stage::kSim ? sim_frames(i) : 1;
    }
  Progress progress("tasks", total_tasks);
  std::vector<std::thread> threads(n);
  int running = 0;
  bool exclusive_running = false;
  std::int64_t sim_frames_seen = 0;
  const auto finished = [&](std::size_t i) {
    return impl.status[i] == Status::kDone || impl.status[i] == Status::kFailed || impl.status[i] == Status::kNotRun;
  };

  // Live display: jobs finished per stage, and the simulation's frames as they appear.
  const auto refresh_progress = [&] {
    std::array<std::int64_t, kStageCount> stage_done{};
    std::int64_t done = 0;
    std::string sim_status;
    for (std::size_t i = 0; i < n; ++i) {
      if (!selected[i]) continue;
      const std::int64_t tasks = jobs_[i].stage == Stage::kSim ? sim_frames(i) : 1;
      if (finished(i)) done += tasks, ++stage_done[static_cast<int>(jobs_[i].stage)];
      if (impl.status[i] == Status::kRunning && jobs_[i].stage == Stage::kSim) {
        while (sim_frames_seen < tasks && fs::exists(io::FramePath(layout_.sim(), "particles", sim_frames_seen, "h5part")))
          ++sim_frames_seen;
        sim_status = fmt::format("sim frame {}/{}", std::max<std::int64_t>(0, sim_frames_seen - 1), tasks - 1);
        done += sim_frames_seen;
      }
    }
    std::string status;
    for (int s = 0; s < kStageCount; ++s) {
      if (!stage_total[s]) continue;
      if (!status.empty()) status += ", ";
      status += s == static_cast<int>(Stage::kSim) && !sim_status.empty()
                    ? sim_status
                    : fmt::format("{} {}/{}", StageName(Stage(s)), stage_done[s], stage_total[s]);
    }
    progress.Update(done, status);
  };

  std::unique_lock lock(impl.mutex);
  while (true) {
    if (Interrupted()) impl.stop = true;
    for (std::size_t i = 0; i < n; ++i)
      if (threads[i].joinable() && finished(i)) {
        lock.unlock();
        threads[i].join();
        lock.lock();
      }
    bool waiting = false;
    for (std::size_t i = 0; i < n && !impl.stop; ++i) {
      if (impl.status[i] != Status::kPending) continue;
      const Job& job = jobs_[i];
      bool blocked = false, dependency_failed = false;
      for (const auto& dep : job.dependencies) {
        const auto it = index_of.find(dep);
        if (it == index_of.end()) continue;
        const Status s = impl.status[it->second];
        if (s == Status::kFailed || s == Status::kNotRun) dependency_failed = true;
        else if (s != Status::kDone) blocked = true;
      }
      if (dependency_failed) {
        impl.status[i] = Status::kNotRun;
        ++impl.result.stages[static_cast<int>(job.stage)].not_run;
        continue;
      }
      if (blocked) {
        waiting = true;
        continue;
      }
      if (exclusive_running || (job.exclusive && running > 0) || running >= std::max(1, options_.parallel_frames)) {
        waiting = true;
        break;
      }
      impl.status[i] = Status::kRunning;
      ++running;
      exclusive_running = job.exclusive;
      threads[i] = std::thread([&, i] {
        Status s;
        try {
          s = impl.Execute(i);
        } catch (const Error& e) {  // rime-bake's own writes (log, marker) keep their exit code
          impl.Fail(jobs_[i], static_cast<int>(e.code()), fmt::format("{}: {}", jobs_[i].id, e.what()));
          s = Status::kFailed;
        } catch (const std::exception& e) {
          impl.Fail(jobs_[i], static_cast<int>(ExitCode::kFailure), fmt::format("{}: {}", jobs_[i].id, e.what()));
          s = Status::kFailed;
        }
        std::lock_guard done_lock(impl.mutex);
        impl.status[i] = s;
        if (s == Status::kFailed) ++impl.result.stages[static_cast<int>(jobs_[i].stage)].failed;
        --running;
        if (jobs_[i].exclusive) exclusive_running = false;
        impl.wake.notify_all();
      });
    }
    if (running == 0 && (impl.stop || !waiting)) break;

    refresh_progress();
    impl.wake.wait_for(lock, std::chrono::milliseconds(200));
  }
  for (std::size_t i = 0; i < n; ++i)
    if (impl.status[i] == Status::kPending) ++impl.result.stages[static_cast<int>(jobs_[i].stage)].not_run;
  refresh_progress();
  lock.unlock();
  for (auto& t : threads)
    if (t.joinable()) t.join();
  try {
    impl.Save(true);
  } catch (const Error& e) {  // a full disk: the first failure stays the message
    if (impl.result.failure.empty()) {
      impl.result.exit_code = static_cast<int>(e.code());
      impl.result.failure = e.what();
    } else {
      impl.result.failure += fmt::format("; the bake state could not be saved either: {}", e.what());
    }
  }
  progress.Finish();
  if (impl.result.exit_code == 0 && Interrupted()) {
    impl.result.exit_code = static_cast<int>(ExitCode::kInterrupted);
    impl.result.failure = "interrupted; rerun the same command to continue";
  }
  impl.result.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return impl.result;
}

// Temporaries are named `<final>.tmp.<pid>.<n>` (rime/core/atomic_file.h); one left in a folder
// the bake writes belongs to a writer that was killed, since the lock excludes live ones.
void Runner::RemoveStaleTemporaries() {
  std::set<fs::path> folders = {layout_.state_folder(), layout_.state_folder() / "incomplete"};
  for (const Job& job : jobs_)
    for (const auto& output : job.outputs) folders.insert(output.parent_path());
  int removed = 0;
  for (const fs::path& folder : folders) {
    std::error_code ec;
    for (fs::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec)) {
      const std::string name = it->path().filename().string();
      const auto tmp = name.rfind(".tmp.");
      if (tmp == std::string::npos || tmp == 0) continue;
      const std::string tail = name.substr(tmp + 5);  // "<pid>.<n>"
      const auto dot = tail.find('.');
      const bool digits = dot != std::string::npos && dot > 0 && dot + 1 < tail.size() &&
                          tail.find_first_not_of("0123456789.") == std::string::npos && tail.find('.', dot + 1) == std::string::npos;
      if (!digits) continue;
      std::error_code remove_ec;
      if (fs::remove(it->path(), remove_ec)) ++removed;
    }
  }
  if (removed) log::Info("removed {} temporary files left by an interrupted run", removed);
}

std::vector<std::vector<std::string>> Runner::Plan() {
  std::set<std::size_t> forced;
  if (options_.force)
    for (std::size_t i = 0; i < jobs_.size(); ++i) forced.insert(i);
  return Plan(std::vector<bool>(jobs_.size(), true), forced);
}

std::vector<std::vector<std::string>> Runner::Plan(const std::vector<bool>& selected, const std::set<std::size_t>& forced) {
  std::vector<std::vector<std::string>> reasons(jobs_.size());
  std::set<std::string> would_run;
  for (std::size_t i = 0; i < jobs_.size(); ++i) {
    if (!selected[i]) continue;
    const Job& job = jobs_[i];
    for (const auto& dep : job.dependencies)
      if (would_run.count(dep)) {
        reasons[i].push_back(fmt::format("after {} reruns (skipped then if its output comes out identical)", dep));
        break;
      }
    if (reasons[i].empty()) {
      reasons[i] = Evaluate(job).reasons;
      if (reasons[i].empty() && forced.count(i)) reasons[i].push_back("requested (--only/--force)");
    }
    if (!reasons[i].empty()) would_run.insert(job.id);
  }
  return reasons;
}

std::string SummaryTable(const BakeResult& result, bool preview_skipped) {
  std::string out = fmt::format("{:<10} {:>6} {:>7} {:>7} {:>8} {:>9}\n", "stage", "ran", "cached", "failed", "not run", "time");
  StageSummary total;
  for (int s = 0; s < kStageCount; ++s) {
    const StageSummary& st = result.stages[s];
    if (static_cast<Stage>(s) == Stage::kPreview && preview_skipped) {
      out += fmt::format("{:<10} {:>42}\n", "preview", "skipped (no blender on PATH)");
      continue;
    }
    if (st.ran + st.cached + st.failed + st.not_run == 0) continue;
    out += fmt::format("{:<10} {:>6} {:>7} {:>7} {:>8} {:>9}\n", StageName(static_cast<Stage>(s)), st.ran, st.cached, st.failed, st.not_run,
                       FormatDuration(st.seconds));
    total.ran += st.ran, total.cached += st.cached, total.failed += st.failed, total.not_run += st.not_run;
  }
  out += fmt::format("{:<10} {:>6} {:>7} {:>7} {:>8} {:>9}\n", "total", total.ran, total.cached, total.failed, total.not_run,
                     FormatDuration(result.seconds));
  for (int s = 0; s < kStageCount; ++s)
    if (result.stages[s].empty)
      out += fmt::format("{}: {} of the frames that ran had an empty mesh (no ice yet): nothing to clean, no cleaned file written\n",
                         StageName(static_cast<Stage>(s)), result.stages[s].empty);
  return out;
}

}  // namespace rime::bake
