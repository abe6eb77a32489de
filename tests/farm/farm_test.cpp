// rime-bake --farm on a real single-node Slurm cluster on localhost (rime/test/local_slurm.h): a farm bake
// writes the same bytes as a local bake (reports: the same apart from timings) and leaves a state both agree is up to date; a failed frame
// is reported with its log and resubmitted alone; a cancelled bake leaves no job and nothing that
// looks finished. The settings and --dry-run checks need no cluster.
#include <gtest/gtest.h>
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
#include <set>
#include <sstream>
#include <thread>

#include "rime/test/bake_outputs.h"
#include "rime/test/fake_tools.h"
#include "rime/test/local_slurm.h"
#include "rime/test/small_bake_scene.h"
#include "rime/test/temp_folder.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace rime {
namespace {

const std::string kRealScene = test::SmallBakeScene("farm", 5);

using test::kFakeLastFrame;
using test::kFakeScene;

constexpr auto kFarmTimeout = std::chrono::seconds(150);

using test::Outputs;
using test::ReadFile;

class Farm : public ::testing::Test {
 protected:
  static inline test::LocalSlurm* cluster_ = nullptr;
  static inline std::string cluster_problem_;
  static inline std::unique_ptr<rime::test::TempFolder> cluster_folder_;

  static void TearDownTestSuite() {
    delete cluster_;
    cluster_ = nullptr;
    cluster_folder_.reset();  // after the daemons have stopped writing into it
  }
  static fs::path ClusterFolder() {
    if (!cluster_folder_) cluster_folder_ = std::make_unique<rime::test::TempFolder>("farm_slurm");
    return cluster_folder_->path();
  }

  void SetUp() override {
    test::WriteFakeTools(root_ / "tools");
    std::ofstream(root_ / "real.toml") << kRealScene;
    std::ofstream(root_ / "fake.toml") << kFakeScene;
    // Two frames per array task; the simulation takes one CPU so a surface task can run beside it,
    // and one surface task at a time waits for frames until the simulation ends.
    std::ofstream(root_ / "site.toml") << "[farm]\nchunk = 2\ncpus_per_task = 1\nstream_tasks = 1\n\n[farm.time]\ndefault = \"10\"\n";
    // One frame per task: a failing frame then stops no other frame.
    std::ofstream(root_ / "site1.toml") << "[farm]\nchunk = 1\n";
    setenv("FAKE_LOG", (root_ / "invocations.log").c_str(), 1);
    setenv("FAKE_FRAMES", std::to_string(kFakeLastFrame).c_str(), 1);
    unsetenv("FAKE_FAIL");
    unsetenv("FAKE_SIM_SLEEP");
    unsetenv("RIME_FARM_CONFIG");
  }

  /// Starts the cluster once for the whole suite; the caller skips when Slurm is not installed.
  static bool ClusterUp() {
    if (cluster_) return true;
    if (const auto missing = test::LocalSlurm::MissingBinary()) {
      cluster_problem_ = fmt::format("Slurm is not installed ({} not found; Debian: apt install slurm-wlm)", *missing);
      return false;
    }
    cluster_ = new test::LocalSlurm;
    const std::string problem = cluster_->Start(ClusterFolder());
    if (!problem.empty()) {
      delete cluster_;
      cluster_ = nullptr;
      ADD_FAILURE() << "cannot start the localhost Slurm cluster: " << problem;
      return false;
    }
    return true;
  }

  /// Runs rime-bake with `args` (a scene under root_ named by `scene`); returns its exit code,
  /// stdout+stderr in output_ and the JSON summary in summary_.
  int RunBake(const std::string& scene, const fs::path& out, const std::string& args, bool fake_tools) {
    std::string command = fmt::format("'{}' '{}' -o '{}' --json-summary '{}' {}", RIME_BINARY_DIR "/bin/rime-bake",
                                      (root_ / scene).string(), out.string(), (root_ / "summary.json").string(), args);
    if (fake_tools) command += fmt::format(" --tools '{}'", (root_ / "tools").string());
    fs::remove(root_ / "summary.json");
    const int status = std::system((command + " > '" + (root_ / "bake.txt").string() + "' 2>&1").c_str());
    output_ = ReadFile(root_ / "bake.txt");
    summary_ = json::parse(ReadFile(root_ / "summary.json"), nullptr, false);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }

  /// Polls `--farm status` until no job of the bake is queued or running; returns the last status.
  json WaitForFarm(const std::string& scene, const fs::path& out, bool fake_tools) {
    const auto deadline = std::chrono::steady_clock::now() + kFarmTimeout;
    while (std::chrono::steady_clock::now() < deadline) {
      RunBake(scene, out, "--farm status", fake_tools);
      if (summary_.is_discarded()) return summary_;
      bool busy = false;
      for (const auto& [stage, counts] : summary_["stages"].items()) busy = busy || counts["queued"] > 0 || counts["running"] > 0;
      if (!busy) return summary_;
      std::this_thread::sleep_for(std::chrono::seconds(1));
    }
    ADD_FAILURE() << "the farm bake did not finish within " << kFarmTimeout.count() << " s:\n"
                  << output_ << test::LocalSlurm::Capture("squeue 2>&1");
    return summary_;
  }

  static int Count(const json& status, const std::string& state) {
    int n = 0;
    for (const auto& [stage, counts] : status["stages"].items()) n += counts[state].get<int>();
    return n;
  }
  int TotalRan() const {
    int ran = 0;
    for (const auto& [stage, s] : summary_["stages"].items()) ran += s["ran"].get<int>();
    return ran;
  }
  std::vector<std::string> Invocations() const {
    std::vector<std::string> lines;
    std::ifstream in(root_ / "invocations.log");
    for (std::string line; std::getline(in, line);) lines.push_back(line);
    return lines;
  }
  const json* StatusOf(const json& status, const std::string& id) const {
    for (const auto& job : status["jobs"])
      if (job["id"] == id) return &job;
    return nullptr;
  }

  rime::test::TempFolder temp_{"farm"};
  fs::path root_ = temp_.path();
  std::string output_;
  json summary_;
};

// Scene values full of shell syntax reach sbatch as literal arguments: the dry run's commands,
// run by bash with sbatch replaced by a function that prints its arguments, run nothing else.
TEST_F(Farm, HostileNamesReachSbatchAsLiteralArguments) {
  // Each command would create a marker file in the working folder, root_, if a shell ran it.
  const fs::path previous_folder = fs::current_path();
  fs::current_path(root_);
  const std::string hostile = "a;b $(touch p1) `touch p2` 'sq' \"dq\" & | ❄\nline 2; touch p3";
  std::string toml_name;
  for (char c : hostile) toml_name += c == '"' ? std::string("\\\"") : c == '\n' ? std::string("\\n") : std::string(1, c);
  std::string scene = kFakeScene;
  scene.insert(scene.find("[scene]\n") + 8, "name = \"" + toml_name + "\"\n");
  std::ofstream(root_ / "hostile.toml") << scene;
  const fs::path out = root_ / ("out " + hostile);
  std::string printed;
  ASSERT_EQ(test::Run({RIME_BINARY_DIR "/bin/rime-bake", (root_ / "hostile.toml").string(), "clean", "-o", out.string(), "--tools",
                       (root_ / "tools").string(), "--farm", "slurm", "--dry-run", "-q"},
                      root_ / "dry.txt", printed),
            0)
      << printed;
  printed.erase(printed.find("rime-bake: dry run:"));  // the closing count, printed last
  std::ofstream(root_ / "submit.sh") << "sbatch() { printf '%s\\0' \"$@\"; printf '\\n'; }\n" << printed;
  std::string args_text;
  ASSERT_EQ(test::Run({"/bin/bash", (root_ / "submit.sh").string()}, root_ / "args.txt", args_text), 0) << args_text;
  std::vector<std::string> args;
  for (std::size_t at = 0, end; (end = args_text.find('\0', at)) != std::string::npos; at = end + 1)
    args.push_back(args_text.substr(at, end - at));
  for (auto& a : args)
    if (!a.empty() && a.front() == '\n') a.erase(0, 1);
  const auto has = [&](const std::string& value) { return std::find(args.begin(), args.end(), value) != args.end(); };
  EXPECT_TRUE(has("--job-name=rime:" + hostile + ":boundary")) << args_text;
  EXPECT_TRUE(has("--chdir=" + out.string())) << args_text;
  EXPECT_TRUE(has(out.string())) << "the task's -o gets the folder literally:\n" << args_text;
  for (int k = 1; k <= 3; ++k) EXPECT_FALSE(fs::exists(root_ / fmt::format("p{}", k))) << "an injected command ran";
  fs::current_path(previous_folder);
}

// Settings errors name file, line and key; the dry run shows the sbatch commands (arrays chained
// per frame, the surface array streaming the simulation's frames) without any cluster.
TEST_F(Farm, DryRunShowsTheJobChainAndSettingsAreValidated) {
  ASSERT_EQ(
      RunBake("fake.toml", root_ / "out", "clean --farm slurm --dry-run --explain --farm-config " + (root_ / "site.toml").string(), true),
      0)
      << output_;
  EXPECT_NE(output_.find("# surface.0003: "), std::string::npos) << output_;
  EXPECT_NE(output_.find("--array=0-1%1"), std::string::npos) << output_;  // 4 frames, 2 per task; 1 may wait for frames
  EXPECT_NE(output_.find("--array=0-1 "), std::string::npos) << output_;   // cleanup: no throttle
  EXPECT_NE(output_.find("'--dependency=afterok:<boundary job>'"), std::string::npos) << output_;
  EXPECT_NE(output_.find("'--dependency=after:<sim job>'"), std::string::npos) << output_;
  EXPECT_NE(output_.find("'--dependency=aftercorr:<surface job>'"), std::string::npos) << output_;
  EXPECT_NE(output_.find("--time=10"), std::string::npos) << output_;
  EXPECT_NE(output_.find("--farm-task surface"), std::string::npos) << output_;
  EXPECT_FALSE(fs::exists(root_ / "out/cache/.rime-bake/farm-jobs.json"));
  EXPECT_EQ(output_.find("--memory-budget"), std::string::npos) << output_;

  // A memory budget and a sandbox given at submission reach every task's command line.
  ASSERT_EQ(RunBake("fake.toml", root_ / "out", "clean --farm slurm --dry-run --memory-budget 2G --sandbox '" + root_.string() + "'", true),
            0)
      << output_;
  for (const char* group : {"boundary", "sim", "surface", "clean"}) {
    const auto at = output_.find(fmt::format("--farm-task {} ", group));
    ASSERT_NE(at, std::string::npos) << group << "\n" << output_;
    const std::string line = output_.substr(at, output_.find('\n', at) - at);
    EXPECT_NE(line.find("--memory-budget 2147483648"), std::string::npos) << line;
    EXPECT_NE(line.find("--sandbox " + root_.string()), std::string::npos) << line;
  }

  // The simulation asks for a GPU only where the site has them and the device allows it.
  std::ofstream(root_ / "gpu_site.toml") << "[farm]\ngpus = true\nsim_partition = \"gpu\"\ncpus_per_task = 3\n";
  const auto sim_line = [&] {
    const auto at = output_.find("--job-name=rime:fake:sim");
    return at == std::string::npos ? std::string() : output_.substr(at, output_.find('\n', at) - at);
  };
  const std::string gpu_site = "--farm slurm --dry-run --farm-config " + (root_ / "gpu_site.toml").string();
  ASSERT_EQ(RunBake("fake.toml", root_ / "out", gpu_site + " --device cuda", true), 0) << output_;
  EXPECT_NE(sim_line().find("--gres=gpu:1"), std::string::npos) << output_;
  EXPECT_NE(sim_line().find("--partition=gpu"), std::string::npos) << output_;
  EXPECT_EQ(output_.find("--gres=gpu:1"), output_.rfind("--gres=gpu:1")) << "only the simulation asks for a GPU:\n" << output_;
  ASSERT_EQ(RunBake("fake.toml", root_ / "out", gpu_site + " --device cpu", true), 0) << output_;
  EXPECT_EQ(sim_line().find("--gres"), std::string::npos) << output_;
  EXPECT_NE(sim_line().find("--cpus-per-task=3"), std::string::npos) << output_;

  // The scene's [farm] keys override the site file's.
  std::ofstream(root_ / "own_chunk.toml") << kFakeScene << "\n[farm]\nchunk = 1\n";
  ASSERT_EQ(RunBake("own_chunk.toml", root_ / "out", "clean --farm slurm --dry-run --farm-config " + (root_ / "site.toml").string(), true),
            0)
      << output_;
  EXPECT_NE(output_.find("--array=0-3%1"), std::string::npos) << output_;  // the site file's stream_tasks stays
  EXPECT_NE(output_.find("--time=10"), std::string::npos) << output_;
  // Without streaming the surface array waits for the simulation to succeed.
  std::ofstream(root_ / "no_stream.toml") << kFakeScene << "\n[farm]\nstream_tasks = 0\n";
  ASSERT_EQ(RunBake("no_stream.toml", root_ / "out", "clean --farm slurm --dry-run", true), 0) << output_;
  EXPECT_NE(output_.find("'--dependency=afterok:<sim job>'"), std::string::npos) << output_;
  EXPECT_EQ(output_.find("--farm-sim-job"), std::string::npos) << output_;

  std::ofstream(root_ / "fake.toml", std::ios::app) << "\n[farm]\nchunk = 0\n";
  EXPECT_EQ(RunBake("fake.toml", root_ / "out", "--farm slurm --dry-run", true), 3) << output_;
  EXPECT_NE(
      output_.find("fake.toml:" + std::to_string(std::count(kFakeScene, kFakeScene + std::strlen(kFakeScene), '\n') + 3) + ": farm.chunk"),
      std::string::npos)
      << output_;
  std::ofstream(root_ / "bad_site.toml") << "[farm]\n[farm.time]\nsim = \"two hours\"\n";
  EXPECT_EQ(RunBake("real.toml", root_ / "out", "--farm slurm --dry-run --farm-config " + (root_ / "bad_site.toml").string(), true), 3)
      << output_;
  EXPECT_NE(output_.find("bad_site.toml:3: farm.time.sim"), std::string::npos) << output_;

  // Without Slurm's commands on PATH a submission stops with one clear line.
  const std::string path = std::getenv("PATH");
  setenv("PATH", "/nonexistent", 1);
  const int code = RunBake("real.toml", root_ / "out", "--farm slurm", true);
  setenv("PATH", path.c_str(), 1);
  EXPECT_EQ(code, 9) << output_;
  EXPECT_NE(output_.find("sbatch not found on PATH"), std::string::npos) << output_;
}

// What a node runs, without Slurm: a task of the surface array (index 1 of 2-frame chunks) runs
// frames 2-3 only and records them in per-job files that a later local bake takes as up to date.
TEST_F(Farm, TaskRunsItsChunkAndLocalBakeAdoptsItsRecords) {
  ASSERT_EQ(RunBake("fake.toml", root_ / "out", "sim", true), 0) << output_;
  const std::string task = "surface --frames 0-3 --farm-task surface --farm-chunk 2";
  setenv("SLURM_ARRAY_TASK_ID", "1", 1);
  EXPECT_EQ(RunBake("fake.toml", root_ / "out", task, true), 5) << output_;  // no submission: the cache counts as not shared
  EXPECT_NE(output_.find("filesystem every node sees"), std::string::npos) << output_;
  std::ofstream(root_ / "out/cache/.rime-bake/farm-task.sh") << "#!/bin/sh\n";  // what a submission writes first
  fs::remove(root_ / "invocations.log");
  ASSERT_EQ(RunBake("fake.toml", root_ / "out", task, true), 0) << output_;
  unsetenv("SLURM_ARRAY_TASK_ID");
  auto runs = Invocations();
  ASSERT_EQ(runs.size(), 2u) << output_;
  EXPECT_NE(runs[0].find("particles.0002.h5part"), std::string::npos);
  EXPECT_NE(runs[1].find("particles.0003.h5part"), std::string::npos);
  EXPECT_TRUE(fs::exists(root_ / "out/cache/.rime-bake/records/surface.0003.json"));
  fs::remove(root_ / "invocations.log");
  setenv("SLURM_ARRAY_TASK_ID", "1", 1);
  ASSERT_EQ(RunBake("fake.toml", root_ / "out", task, true), 0) << output_;
  EXPECT_TRUE(Invocations().empty()) << "the task's frames are up to date";
  ASSERT_EQ(RunBake("fake.toml", root_ / "out", task + " --force", true), 0) << output_;
  unsetenv("SLURM_ARRAY_TASK_ID");
  EXPECT_EQ(Invocations().size(), 2u) << "--force (passed on by --farm slurm --force) reruns them";

  fs::remove(root_ / "invocations.log");
  ASSERT_EQ(RunBake("fake.toml", root_ / "out", "surface", true), 0) << output_;
  runs = Invocations();
  ASSERT_EQ(runs.size(), 2u) << output_;  // frames 0 and 1 only
  EXPECT_NE(runs[0].find("particles.0000.h5part"), std::string::npos);
  EXPECT_NE(runs[1].find("particles.0001.h5part"), std::string::npos);
  EXPECT_FALSE(fs::exists(root_ / "out/cache/.rime-bake/records/surface.0003.json")) << "folded into state.json";
  ASSERT_EQ(RunBake("fake.toml", root_ / "out", "surface", true), 0) << output_;
  EXPECT_EQ(TotalRan(), 0) << output_;
}

TEST_F(Farm, BakeMatchesALocalBakeByteForByte) {
  if (!ClusterUp()) GTEST_SKIP() << cluster_problem_;
  ASSERT_EQ(RunBake("real.toml", root_ / "local", "clean -j 2", false), 0) << output_;

  const std::string farm = "clean --farm-config " + (root_ / "site.toml").string();
  ASSERT_EQ(RunBake("real.toml", root_ / "farm", farm + " --farm slurm", false), 0) << output_;
  ASSERT_EQ(summary_["submitted"].size(), 4u) << output_;  // boundary, sim, surface, cleanup
  const json status = WaitForFarm("real.toml", root_ / "farm", false);
  EXPECT_EQ(Count(status, "failed") + Count(status, "missing"), 0) << output_;
  EXPECT_EQ(Count(status, "done"), 2 + 2 * 6) << output_;

  const auto local = Outputs(root_ / "local"), farmed = Outputs(root_ / "farm");
  EXPECT_GT(local.size(), 30u);
  for (const auto& [name, bytes] : local) {
    const auto it = farmed.find(name);
    if (it == farmed.end()) ADD_FAILURE() << name << " is missing from the farm bake";
    else EXPECT_TRUE(it->second == bytes) << name << " differs between the farm and the local bake";
  }
  for (const auto& [name, bytes] : farmed) EXPECT_TRUE(local.count(name)) << name << " was written by the farm bake only";

  // A second submission finds everything up to date; so does a local bake of the farm's output.
  ASSERT_EQ(RunBake("real.toml", root_ / "farm", farm + " --farm slurm", false), 0) << output_;
  EXPECT_TRUE(summary_["submitted"].empty()) << output_;
  EXPECT_EQ(summary_["stale_jobs"], 0) << output_;
  ASSERT_EQ(RunBake("real.toml", root_ / "farm", "clean", false), 0) << output_;
  EXPECT_EQ(TotalRan(), 0) << output_;
}

TEST_F(Farm, FailedFrameIsReportedWithItsLogAndResubmittedAlone) {
  if (!ClusterUp()) GTEST_SKIP() << cluster_problem_;
  // A submission the scheduler refuses stops with its message and leaves nothing submitted.
  std::ofstream(root_ / "bad_partition.toml") << "[farm]\npartition = \"no_such_partition\"\n";
  EXPECT_EQ(RunBake("fake.toml", root_ / "out", "clean --farm slurm --farm-config " + (root_ / "bad_partition.toml").string(), true), 9)
      << output_;
  EXPECT_NE(output_.find("sbatch refused the boundary job: sbatch: error: invalid partition"), std::string::npos) << output_;
  EXPECT_FALSE(fs::exists(root_ / "out/cache/.rime-bake/farm-jobs.json"));

  const std::string farm = "clean --farm-config " + (root_ / "site1.toml").string();
  setenv("FAKE_FAIL", "surface:2", 1);  // exported to the tasks with the submitter's environment
  ASSERT_EQ(RunBake("fake.toml", root_ / "out", farm + " --farm slurm", true), 0) << output_;
  unsetenv("FAKE_FAIL");
  const json status = WaitForFarm("fake.toml", root_ / "out", true);
  const std::string status_text = output_;
  EXPECT_EQ(Count(status, "failed"), 1) << status_text;
  const json* surface = StatusOf(status, "surface.0002");
  ASSERT_NE(surface, nullptr) << status_text;
  EXPECT_EQ((*surface)["state"], "failed");
  const fs::path log = root_ / "out/cache/logs/surface.0002.log";
  EXPECT_EQ((*surface)["log"], log.string());
  EXPECT_EQ((*surface)["slurm_state"], "FAILED");
  EXPECT_NE(ReadFile(log).find("no particles in frame (fake)"), std::string::npos);
  EXPECT_NE(status_text.find("surface.0002 failed"), std::string::npos) << status_text;
  EXPECT_NE(status_text.find(log.string()), std::string::npos) << status_text;
  const json* cleanup = StatusOf(status, "clean.0002");
  ASSERT_NE(cleanup, nullptr) << status_text;
  EXPECT_EQ((*cleanup)["state"], "missing");  // its dependency failed, so Slurm never ran it
  EXPECT_EQ(Count(status, "done"), 2 + 2 * (kFakeLastFrame + 1) - 2) << status_text;

  fs::remove(root_ / "invocations.log");
  ASSERT_EQ(RunBake("fake.toml", root_ / "out", farm + " --farm resubmit", true), 0) << output_;
  const json after = WaitForFarm("fake.toml", root_ / "out", true);
  EXPECT_EQ(Count(after, "done"), 2 + 2 * (kFakeLastFrame + 1)) << output_;
  const auto runs = Invocations();
  ASSERT_EQ(runs.size(), 2u) << fmt::format("{}", fmt::join(runs, "\n"));
  EXPECT_EQ(runs[0].rfind("rime-surface ", 0), 0u);
  EXPECT_NE(runs[0].find("particles.0002.h5part"), std::string::npos);
  EXPECT_EQ(runs[1].rfind("rime-clean ", 0), 0u);
  EXPECT_NE(runs[1].find("ice.0002.obj"), std::string::npos);

  fs::remove(root_ / "invocations.log");
  ASSERT_EQ(RunBake("fake.toml", root_ / "out", "clean", true), 0) << output_;
  EXPECT_EQ(TotalRan(), 0) << output_;
  EXPECT_TRUE(Invocations().empty());
}

// With Blender on the PATH the preview stage runs too: an array paired with the cleanup's and the
// movie job after the whole array (fake Blender and ffmpeg).
TEST_F(Farm, PreviewFramesAndMovieRunOnTheFarm) {
  if (!ClusterUp()) GTEST_SKIP() << cluster_problem_;
  test::WriteFakePreviewTools(root_ / "preview_tools");
  const std::string path = std::getenv("PATH");
  setenv("PATH", ((root_ / "preview_tools").string() + ":" + path).c_str(), 1);
  const int code = RunBake("fake.toml", root_ / "out", "all --farm slurm --farm-config " + (root_ / "site.toml").string(), true);
  std::vector<std::string> groups;
  for (const auto& s : summary_["submitted"]) groups.push_back(s["group"]);
  const json status = WaitForFarm("fake.toml", root_ / "out", true);  // the same Blender, so the same keys
  setenv("PATH", path.c_str(), 1);
  ASSERT_EQ(code, 0) << output_;
  EXPECT_EQ(groups, (std::vector<std::string>{"boundary", "sim", "surface", "clean", "preview", "preview.movie"}));
  EXPECT_EQ(status["stages"]["preview"]["done"], kFakeLastFrame + 2) << output_;  // every frame and the movie
  EXPECT_EQ(Count(status, "failed") + Count(status, "missing"), 0) << output_;
  for (int f = 0; f <= kFakeLastFrame; ++f) EXPECT_TRUE(fs::exists(root_ / fmt::format("out/preview/frame.{:04}.png", f))) << f;
  EXPECT_TRUE(fs::exists(root_ / "out/preview/preview.mp4"));
}

TEST_F(Farm, CancelLeavesNoJobAndNothingThatLooksFinished) {
  if (!ClusterUp()) GTEST_SKIP() << cluster_problem_;
  const std::string farm = "clean --farm-config " + (root_ / "site.toml").string();
  setenv("FAKE_SIM_SLEEP", "5", 1);  // about 20 s: the cancel lands while it runs, even on a loaded machine
  ASSERT_EQ(RunBake("fake.toml", root_ / "out", farm + " --farm slurm", true), 0) << output_;
  unsetenv("FAKE_SIM_SLEEP");
  std::set<std::string> ours;
  for (const auto& s : summary_["submitted"]) ours.insert(s["job_id"].get<std::string>());
  ASSERT_EQ(ours.size(), 4u) << output_;

  // Cancel while the simulation runs and frame 1 exists (the surface task of frames 0-1 may be done).
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (!fs::exists(root_ / "out/cache/sim/particles.0001.h5part") && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  ASSERT_TRUE(fs::exists(root_ / "out/cache/sim/particles.0001.h5part")) << test::LocalSlurm::Capture("squeue 2>&1");
  EXPECT_EQ(RunBake("fake.toml", root_ / "out", "clean", true), 5) << output_;  // a local bake refuses meanwhile
  EXPECT_NE(output_.find("--farm cancel"), std::string::npos) << output_;
  ASSERT_EQ(RunBake("fake.toml", root_ / "out", farm + " --farm cancel", true), 0) << output_;
  EXPECT_FALSE(summary_["cancelled"].empty()) << output_;
  const std::string queue = test::LocalSlurm::Capture("squeue --noheader --format=%i 2>&1");
  for (const auto& id : ours) EXPECT_EQ(queue.find(id), std::string::npos) << "job " << id << " is still in the queue:\n" << queue;

  // Nothing the cancelled tasks left may pass as finished: the status shows nothing done after the
  // simulation, and a local bake completes the bake to the same bytes as an uninterrupted one.
  const json status = WaitForFarm("fake.toml", root_ / "out", true);
  EXPECT_EQ(Count(status, "queued") + Count(status, "running"), 0) << output_;
  const json* sim = StatusOf(status, "sim");
  ASSERT_NE(sim, nullptr) << output_;
  EXPECT_EQ((*sim)["state"], "failed") << output_;  // interrupted: its incomplete marker remains
  EXPECT_LT(status["stages"]["surface"]["done"], kFakeLastFrame + 1) << output_;
  ASSERT_EQ(RunBake("fake.toml", root_ / "out", "clean", true), 0) << output_;
  EXPECT_EQ(summary_["stages"]["sim"]["ran"], 1) << output_;
  EXPECT_NE(ReadFile(root_ / "out/cache/logs/sim.log").find("--resume"), std::string::npos) << "the cancelled simulation continues";
  ASSERT_EQ(RunBake("fake.toml", root_ / "reference", "clean", true), 0) << output_;
  EXPECT_TRUE(Outputs(root_ / "out") == Outputs(root_ / "reference"));
}

}  // namespace
}  // namespace rime
