// rime-bake under attack with the real stage tools: killed with SIGKILL at 30+ seeded moments
// spread over a whole bake (sometimes a stage tool is killed instead), each time rerun, until a
// run completes. Every final output then matches an uninterrupted bake byte for byte, no file
// under a final name is ever seen partial, and the simulation resumes rather than restarts.
// SIGINT and SIGTERM stop a bake with exit 130, and the next run finishes it.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fmt/format.h>
#include <random>
#include <set>
#include <sys/stat.h>

#include "rime/test/bake_outputs.h"
#include "rime/io/particles.h"
#include "rime/test/small_bake_scene.h"
#include "rime/test/temp_folder.h"

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace rime {
namespace {

constexpr int kLastFrame = 16;
constexpr int kKills = 40;
const std::string kScene = test::SmallBakeScene("torture", kLastFrame);

double Since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }
void Sleep(double seconds) { std::this_thread::sleep_for(std::chrono::duration<double>(seconds)); }

using test::FinalFiles;

// Pids whose parent is `parent` (from /proc/<pid>/stat), i.e. the stage tools a bake runs.
std::vector<pid_t> ChildrenOf(pid_t parent) {
  std::vector<pid_t> children;
  std::error_code ec;
  for (fs::directory_iterator it("/proc", ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;
    const std::string stat = test::ReadFile(it->path() / "stat");
    const auto close = stat.rfind(')');  // the command name in parentheses may hold spaces
    if (close == std::string::npos) continue;
    char state = 0;
    long ppid = 0;
    if (std::sscanf(stat.c_str() + close + 1, " %c %ld", &state, &ppid) == 2 && ppid == parent && state != 'Z')
      children.push_back(std::stoi(name));
  }
  return children;
}

bool Alive(pid_t pid) {
  const std::string stat = test::ReadFile(fmt::format("/proc/{}/stat", pid));
  const auto close = stat.rfind(')');
  return close != std::string::npos && close + 2 < stat.size() && stat[close + 2] != 'Z';
}

ino_t Inode(const fs::path& file) {
  struct stat st {};
  return ::stat(file.c_str(), &st) == 0 ? st.st_ino : 0;
}

class KillTorture : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    temp_ = std::make_unique<rime::test::TempFolder>("torture");
    root_ = temp_->path();
    std::ofstream(root_ / "torture.toml") << kScene;
    // The uninterrupted reference, with the moments at which its final files appeared.
    const auto start = Clock::now();
    const pid_t pid = test::Spawn(Args(Reference()), root_ / "reference.txt");
    ASSERT_GT(pid, 0);
    std::size_t seen = 0;
    int status = 0;
    while (waitpid(pid, &status, WNOHANG) == 0) {
      const std::size_t now = FinalFiles(Reference()).size();
      for (; seen < now; ++seen) appeared_.push_back(Since(start));
      Sleep(0.01);
    }
    reference_seconds_ = Since(start);
    ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << test::ReadFile(root_ / "reference.txt");
    reference_ = test::Outputs(Reference());
  }
  static void TearDownTestSuite() { temp_.reset(); }

  static fs::path Reference() { return root_ / "reference"; }
  static std::vector<std::string> Args(const fs::path& out) {
    return {RIME_BINARY_DIR "/bin/rime-bake", (root_ / "torture.toml").string(), "clean", "-o", out.string(), "-j", "2", "-q"};
  }

  static void ExpectNothingPartial(const fs::path& out, const std::string& when) {
    for (const std::string& problem : test::PartialFiles(out, reference_)) ADD_FAILURE() << when << ": " << problem;
  }

  // Waits until the tools a killed bake ran have exited (they get SIGTERM when it dies).
  static void WaitForTools(const std::vector<pid_t>& tools) {
    const auto deadline = Clock::now() + std::chrono::seconds(60);
    for (pid_t tool : tools)
      while (Alive(tool) && Clock::now() < deadline) Sleep(0.02);
  }

  static inline std::unique_ptr<rime::test::TempFolder> temp_;
  static inline fs::path root_;
  static inline std::vector<double> appeared_;
  static inline double reference_seconds_ = 0;
  static inline std::map<std::string, std::string> reference_;
};

TEST_F(KillTorture, SurvivesKillsAtSeededMomentsWithIdenticalOutputs) {
  const char* seed_text = std::getenv("RIME_TORTURE_SEED");
  const unsigned seed = seed_text ? static_cast<unsigned>(std::atoi(seed_text)) : 20261202u;
  std::mt19937 random(seed);
  std::vector<double> moments(kKills);
  std::uniform_real_distribution<double> over_the_bake(0.0, reference_seconds_);
  for (double& m : moments) m = over_the_bake(random);
  std::sort(moments.begin(), moments.end());

  const fs::path out = root_ / "killed";
  const auto start = Clock::now();
  int bake_kills = 0, tool_kills = 0, resumes = 0, busy_retries = 0, fresh_bakes = 0, fresh_from = -1;
  std::set<std::string> killed_tools;
  for (int k = 0; k < kKills; ++k) {
    // Kill moment k of the reference bake maps to "once as many final files exist as it had
    // then, plus the time it had spent since its last new file", so the kills sweep the stages.
    const std::size_t files_then = std::upper_bound(appeared_.begin(), appeared_.end(), moments[k]) - appeared_.begin();
    const double after_last_file = moments[k] - (files_then ? appeared_[files_then - 1] : 0.0);
    const bool kill_a_tool = std::uniform_int_distribution<int>(0, 3)(random) == 0;

    // The simulation's frames before this attempt, by inode: a resumed simulation keeps them.
    std::map<std::string, ino_t> frames_before;
    for (const std::string& name : FinalFiles(out))
      if (name.rfind("cache/sim/particles.0", 0) == 0) frames_before[name] = Inode(out / name);
    const fs::path sim_log = out / "cache/logs/sim.log";
    fs::remove(sim_log);  // present after the attempt only if the simulation ran in it

    const pid_t bake = test::Spawn(Args(out), root_ / "attempt.txt");
    ASSERT_GT(bake, 0);
    int status = 0;
    bool exited = false;
    const auto attempt = Clock::now();
    while (FinalFiles(out).size() < files_then && !(exited = waitpid(bake, &status, WNOHANG) == bake) && Since(attempt) < 120) Sleep(0.005);
    const auto reached = Clock::now();
    while (!exited && std::chrono::duration<double>(Clock::now() - reached).count() < after_last_file)
      if (!(exited = waitpid(bake, &status, WNOHANG) == bake)) Sleep(0.005);
    if (exited) {
      const std::string output = test::ReadFile(root_ / "attempt.txt");
      if (WIFEXITED(status) && WEXITSTATUS(status) == 5 && output.find("are still running") != std::string::npos) {
        // Tools of the previous, killed bake had not exited yet: the lock said so. Same moment again.
        ASSERT_LT(++busy_retries, 100) << output;
        Sleep(0.2);
        --k;
        continue;
      }
      ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "attempt " << k << " ended by itself:\n" << output;
      // The resumed work finished before this moment (it ran faster than the reference's timing,
      // as under a sanitizer on a loaded machine): check it, then kill a fresh bake at the moment.
      EXPECT_TRUE(test::Outputs(out) == reference_) << "attempt " << k << " completed with outputs that differ from the uninterrupted bake";
      if (fresh_from == k) break;  // a fresh bake finished before this moment too
      fresh_from = k;
      ++fresh_bakes;
      fs::remove_all(out);
      --k;
      continue;
    }
    std::vector<pid_t> tools = ChildrenOf(bake);
    if (kill_a_tool && !tools.empty()) {
      const pid_t victim = tools[std::uniform_int_distribution<std::size_t>(0, tools.size() - 1)(random)];
      const std::string name = test::ReadFile(fmt::format("/proc/{}/comm", victim));
      killed_tools.insert(name.substr(0, name.find('\n')));
      kill(victim, SIGKILL);
      ++tool_kills;
      const int code = test::WaitExit(bake);  // the bake reports the failed stage and stops
      EXPECT_TRUE(code == 7 || code == 0) << "attempt " << k << ": a killed tool must fail its stage (exit 7), got " << code << "\n"
                                          << test::ReadFile(root_ / "attempt.txt");
    } else {
      kill(bake, SIGKILL);
      ++bake_kills;
      test::WaitExit(bake);
    }
    const std::vector<pid_t> more = ChildrenOf(bake);
    tools.insert(tools.end(), more.begin(), more.end());
    WaitForTools(tools);
    ExpectNothingPartial(out, fmt::format("after kill {} ({:.2f} s into the reference bake)", k, moments[k]));

    // An interrupted simulation with frames on disk resumes: the rerun passes --resume and keeps
    // every frame already written.
    if (fs::exists(sim_log) && !frames_before.empty()) {
      const std::string log = test::ReadFile(sim_log);
      if (log.substr(0, log.find('\n')).find("--resume") != std::string::npos) ++resumes;
      else
        ADD_FAILURE() << "attempt " << k << " restarted the simulation instead of resuming after frame " << frames_before.size() - 1
                      << ":\n"
                      << log;
      for (const auto& [name, inode] : frames_before)
        EXPECT_EQ(Inode(out / name), inode) << name << " was rewritten: the simulation restarted";
    }
    if (HasFailure()) break;
  }
  ASSERT_FALSE(HasFailure());

  // The run that completes, then a check that it left nothing to do.
  std::string output;
  int code = 5;
  for (int tries = 0; tries < 50 && code == 5; ++tries) {
    code = test::Run(Args(out), root_ / "final.txt", output);
    if (code == 5) Sleep(0.2);
  }
  ASSERT_EQ(code, 0) << output;
  const double seconds = Since(start);
  EXPECT_TRUE(test::Outputs(out) == reference_) << "outputs after the kills differ from the uninterrupted bake";
  for (const auto& [name, bytes] : test::Outputs(out))
    if (reference_.count(name) == 0 || reference_.at(name) != bytes) ADD_FAILURE() << "differs or unexpected: " << name;
  for (const auto& [name, bytes] : reference_)
    if (!fs::exists(out / name)) ADD_FAILURE() << "missing: " << name;
  EXPECT_TRUE(fs::is_empty(out / "cache/.rime-bake/incomplete"));
  EXPECT_EQ(test::Run({RIME_BINARY_DIR "/bin/rime-bake", (root_ / "torture.toml").string(), "clean", "-o", out.string(), "-n"},
                      root_ / "dry.txt", output),
            0);
  EXPECT_NE(output.find("0 jobs would run"), std::string::npos) << output;
  EXPECT_GT(resumes, 0) << "no kill landed during the simulation with frames on disk";
  EXPECT_GE(bake_kills + tool_kills, 30);

  const std::string report = fmt::format(
      "kill torture (seed {}): {} kills survived ({} of rime-bake, {} of a stage tool: {}), {} simulation resumes, {} reruns refused "
      "while killed tools exited, {} fresh bakes after one completed between kills; outputs byte-identical to the uninterrupted bake ({} "
      "files); reference bake {:.1f} s, torture {:.1f} s",
      seed, bake_kills + tool_kills, bake_kills, tool_kills, fmt::join(killed_tools, " "), resumes, busy_retries, fresh_bakes,
      reference_.size(), reference_seconds_, seconds);
  std::printf("%s\n", report.c_str());
  RecordProperty("report", report);
}

// SIGINT (Ctrl-C) and SIGTERM (a scheduler's stop) reach rime-bake alone: it stops its tools,
// exits 130 and the next run finishes with the same outputs.
TEST_F(KillTorture, SigintAndSigtermStopWithExit130AndTheRerunFinishes) {
  const fs::path out = root_ / "signalled";
  const std::pair<int, std::string> signals[] = {{SIGINT, "cache/sim/particles.0002.h5part"}, {SIGTERM, "surface/water.0002.obj"}};
  for (const auto& [signal, trigger] : signals) {
    const pid_t bake = test::Spawn(Args(out), root_ / "signalled.txt");
    ASSERT_GT(bake, 0);
    int status = 0;
    bool exited = false;
    const auto start = Clock::now();
    while (!fs::exists(out / trigger) && !(exited = waitpid(bake, &status, WNOHANG) == bake) && Since(start) < 120) Sleep(0.005);
    ASSERT_FALSE(exited) << "the bake ended before " << trigger << " appeared:\n" << test::ReadFile(root_ / "signalled.txt");
    const std::vector<pid_t> tools = ChildrenOf(bake);
    kill(bake, signal);
    const auto stopping = Clock::now();
    const int code = test::WaitExit(bake);
    const std::string output = test::ReadFile(root_ / "signalled.txt");
    EXPECT_EQ(code, 130) << strsignal(signal) << ":\n" << output;
    EXPECT_LT(Since(stopping), 30.0) << strsignal(signal) << " took long to stop the bake";
    EXPECT_NE(output.find("interrupted"), std::string::npos) << output;
    for (pid_t tool : tools) EXPECT_FALSE(Alive(tool)) << "tool " << tool << " still runs after rime-bake exited";
    ExpectNothingPartial(out, strsignal(signal));
  }
  std::string output;
  ASSERT_EQ(test::Run(Args(out), root_ / "signalled.txt", output), 0) << output;
  EXPECT_TRUE(test::Outputs(out) == reference_) << "outputs after SIGINT and SIGTERM differ from the uninterrupted bake";
}

}  // namespace
}  // namespace rime
