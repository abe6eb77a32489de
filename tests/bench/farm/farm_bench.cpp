// What a farm task costs: bakes a 60-frame scene locally (rime-bake -j 1) and through
// `rime-bake --farm slurm` on a single-node Slurm cluster on localhost (rime/test/local_slurm.h),
// then prints both wall times and, per Slurm task, the wait from submission to start and the time
// from start to end beside the stage tools' own time (the rest is the task's overhead).
//   rime-bench-farm [--frames N] [--chunk C] [--json FILE] [--keep]
#include <CLI/CLI.hpp>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fmt/format.h>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "rime/test/files.h"
#include "rime/test/local_slurm.h"
#include "rime/test/measure.h"

#include "rime/test/small_bake_scene.h"

namespace fs = std::filesystem;
using nlohmann::json;
using Clock = std::chrono::steady_clock;

namespace {

std::string Scene(int frames) { return rime::test::SmallBakeScene("farm_bench", frames - 1); }

using rime::test::ReadFile;

int Run(const std::string& command) {
  const int status = std::system(command.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

struct Stats {
  double mean = 0, median = 0, max = 0;
  std::size_t count = 0;
};
Stats Summarize(std::vector<double> v) {
  Stats s;
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  for (double x : v) s.mean += x / v.size();
  s.median = rime::test::Median(v);
  s.max = v.back();
  s.count = v.size();
  return s;
}
json ToJson(const Stats& s) { return {{"mean", s.mean}, {"median", s.median}, {"max", s.max}, {"count", s.count}}; }

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Local bake (-j 1) against a farm bake on a localhost Slurm cluster: wall times and per-task overhead"};
  int frames = 60, chunk = 1;
  bool keep = false;
  std::string json_path = RIME_BENCH_OUTPUT_DIR "/results.json";
  app.add_option("--frames", frames, "Frames of the scene")->check(CLI::Range(2, 1000))->capture_default_str();
  app.add_option("--chunk", chunk, "Frames per array task")->check(CLI::PositiveNumber)->capture_default_str();
  app.add_option("--json", json_path, "JSON output file")->capture_default_str();
  app.add_flag("--keep", keep, "Keep the run's folder in the build folder (outputs, logs, the cluster's logs)");
  CLI11_PARSE(app, argc, argv);

  if (const auto missing = rime::test::LocalSlurm::MissingBinary()) {
    std::fprintf(stderr, "rime-bench-farm: Slurm is not installed (%s not found; Debian: apt install slurm-wlm)\n", missing->c_str());
    return 2;
  }
  const fs::path root = fs::path(RIME_BENCH_OUTPUT_DIR) / fmt::format("run.{}", getpid());
  fs::create_directories(root);
  std::ofstream(root / "scene.toml") << Scene(frames);
  std::ofstream(root / "site.toml") << fmt::format("[farm]\nchunk = {}\ncpus_per_task = 1\n", chunk);
  const std::string bake = RIME_BINARY_DIR "/bin/rime-bake";
  const auto command = [&](const std::string& out, const std::string& args) {
    return fmt::format("'{}' '{}' clean -o '{}' {} > '{}/bake.txt' 2>&1", bake, (root / "scene.toml").string(), (root / out).string(), args,
                       root.string());
  };

  // 1. Local, one frame at a time.
  const rime::test::Stopwatch local_watch;
  if (Run(command("local", "-j 1 --json-summary " + (root / "local.json").string())) != 0) {
    std::fprintf(stderr, "local bake failed:\n%s", ReadFile(root / "bake.txt").c_str());
    return 1;
  }
  const double local_wall = local_watch.seconds();
  const json local = json::parse(ReadFile(root / "local.json"));

  // 2. The same bake through the localhost cluster, from submission until --farm status shows
  // nothing queued or running.
  rime::test::LocalSlurm cluster;
  if (const std::string problem = cluster.Start(root / "slurm"); !problem.empty()) {
    std::fprintf(stderr, "cannot start the localhost Slurm cluster: %s\n", problem.c_str());
    return 1;
  }
  const std::string site = "--farm-config " + (root / "site.toml").string();
  const rime::test::Stopwatch farm_watch;
  const double submit_epoch = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  if (Run(command("farm", site + " --farm slurm --json-summary " + (root / "submit.json").string())) != 0) {
    std::fprintf(stderr, "submission failed:\n%s", ReadFile(root / "bake.txt").c_str());
    return 1;
  }
  const double submit_seconds = farm_watch.seconds();
  json status;
  for (const auto deadline = Clock::now() + std::chrono::minutes(15);;) {
    Run(command("farm", site + " --farm status --json-summary " + (root / "status.json").string()));
    status = json::parse(ReadFile(root / "status.json"), nullptr, false);
    bool busy = status.is_discarded();
    if (!busy)
      for (const auto& [stage, counts] : status["stages"].items()) busy = busy || counts["queued"] > 0 || counts["running"] > 0;
    if (!busy) break;
    if (Clock::now() > deadline) {
      std::fprintf(stderr, "the farm bake did not finish within 15 minutes\n");
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
  }
  const double farm_wall = farm_watch.seconds();
  int failed = 0;
  for (const auto& [stage, counts] : status["stages"].items()) failed += counts["failed"].get<int>() + counts["missing"].get<int>();

  // 3. Per task, from the wall-clock stamps every farm task writes into its Slurm log: the wait from
  // submission to start (for dependent tasks this includes waiting for their upstream), the time
  // from start to end, and the stage tools' own time in it (the job records the task wrote); the
  // rest is the task's overhead. For cleanup, the latency from its frame's surface task ending to
  // its own start; for surface, from the simulation writing the frame to the frame being surfaced.
  const json submitted = json::parse(ReadFile(root / "submit.json"));
  std::map<std::string, double> tool_seconds;  // job id -> seconds
  for (const auto& entry : fs::directory_iterator(root / "farm/cache/.rime-bake/records")) {
    const json r = json::parse(ReadFile(entry.path()));
    tool_seconds[r["job"].get<std::string>()] = r["record"]["seconds"].get<double>();
  }
  const auto stamp = [](const std::string& log, const char* what) {
    const auto at = log.find(what);
    return at == std::string::npos ? -1.0 : std::atof(log.c_str() + at + std::strlen(what));
  };
  const auto frame_mtime = [&](int frame) {
    const fs::path p = root / fmt::format("farm/cache/sim/particles.{:04d}.h5part", frame);
    struct stat info {};
    if (stat(p.c_str(), &info) != 0) return -1.0;
    return static_cast<double>(info.st_mtim.tv_sec) + 1e-9 * static_cast<double>(info.st_mtim.tv_nsec);
  };
  struct Task {
    double start = -1, end = -1, tool = 0;
  };
  std::map<std::string, std::map<int, Task>> tasks;  // group -> array index (-1 single) -> task
  for (const auto& s : submitted["submitted"]) {
    const std::string group = s["group"], job = s["job_id"];
    std::vector<int> indices = s["tasks"].get<std::vector<int>>();
    if (indices.empty()) indices = {-1};
    for (int k : indices) {
      const std::string name = k < 0 ? fmt::format("{}.{}.log", group, job) : fmt::format("{}.{}_{}.log", group, job, k);
      const std::string log = ReadFile(root / "farm/cache/logs/farm" / name);
      Task t{stamp(log, (" started at ")), stamp(log, (" finished at ")), 0};
      if (k < 0) t.tool = tool_seconds[group];
      for (int f = k * chunk; k >= 0 && f < (k + 1) * chunk && f < frames; ++f) t.tool += tool_seconds[fmt::format("{}.{:04d}", group, f)];
      tasks[group][k] = t;
    }
  }
  std::printf("%d frames, %d per array task, on a localhost cluster of %u CPUs\n", frames, chunk, std::thread::hardware_concurrency());
  std::printf("local  -j 1: %7.1f s wall\n", local_wall);
  std::printf("farm       : %7.1f s wall (submission %.2f s)%s\n", farm_wall, submit_seconds, failed ? "  SOME JOBS FAILED" : "");
  std::printf("\n%-9s %5s %15s %15s %9s %15s %20s\n", "group", "tasks", "submit->start", "start->end", "tool", "overhead", "frame latency");
  std::printf("%-9s %5s %15s %15s %9s %15s %20s\n", "", "", "mean/max s", "mean/max s", "mean s", "mean/max s", "mean/max s");
  json groups = json::object();
  for (const auto& s : submitted["submitted"]) {
    const std::string group = s["group"];
    std::vector<double> wait, run, tool, overhead, latency;
    for (const auto& [k, t] : tasks[group]) {
      if (t.start < 0 || t.end < 0) continue;
      wait.push_back(t.start - submit_epoch);
      run.push_back(t.end - t.start);
      tool.push_back(t.tool);
      overhead.push_back(t.end - t.start - t.tool);
      if (group == "clean" && tasks["surface"].count(k)) latency.push_back(t.start - tasks["surface"][k].end);
      if (group == "surface") latency.push_back(t.end - frame_mtime(std::min(frames - 1, (k + 1) * chunk - 1)));
    }
    const Stats w = Summarize(wait), r = Summarize(run), tl = Summarize(tool), o = Summarize(overhead), l = Summarize(latency);
    std::printf("%-9s %5zu %7.2f/%6.2f %7.2f/%6.2f %9.3f %7.2f/%6.2f %11s\n", group.c_str(), r.count, w.mean, w.max, r.mean, r.max, tl.mean,
                o.mean, o.max, l.count ? fmt::format("{:.2f}/{:.2f}", l.mean, l.max).c_str() : "");
    groups[group] = {{"submit_to_start_s", ToJson(w)}, {"start_to_end_s", ToJson(r)}, {"tool_s", ToJson(tl)}, {"overhead_s", ToJson(o)}};
    if (l.count) groups[group]["frame_latency_s"] = ToJson(l);
  }
  std::printf(
      "(frame latency: cleanup = its start after the frame's surface task ended; surface = its end after the simulation wrote the "
      "frame)\n");
  // Streaming: surface tasks that finished before the simulation did.
  int streamed = 0;
  const double sim_end = tasks["sim"].count(-1) ? tasks["sim"][-1].end : -1;
  for (const auto& [k, t] : tasks["surface"]) streamed += t.end > 0 && t.end < sim_end;
  std::printf("%d of %zu surface tasks finished before the simulation ended\n", streamed, tasks["surface"].size());
  const json out = {{"machine", rime::test::MachineDescription()},
                    {"commit", rime::test::SourceCommit(RIME_SOURCE_DIR)},
                    {"frames", frames},
                    {"chunk", chunk},
                    {"cpus", std::thread::hardware_concurrency()},
                    {"local_wall_s", local_wall},
                    {"local_stages", local["stages"]},
                    {"farm_wall_s", farm_wall},
                    {"farm_submit_s", submit_seconds},
                    {"farm_failed_or_missing", failed},
                    {"surface_tasks_done_before_sim_end", streamed},
                    {"farm_groups", groups}};
  std::ofstream(json_path) << out.dump(2) << "\n";
  std::printf("wrote %s\n", json_path.c_str());
  cluster.Stop();
  if (!keep) fs::remove_all(root);
  else std::printf("kept %s\n", root.string().c_str());
  return failed ? 1 : 0;
}
