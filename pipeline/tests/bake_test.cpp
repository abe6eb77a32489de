// rime-bake's decisions (what is stale, what runs, what it reports), tested by running the real
// rime-bake binary on fake stage tools (rime/test/fake_tools.h) that log every invocation.
#include <cstdlib>
#include <gtest/gtest.h>
#include <signal.h>
#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <fmt/format.h>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include "rime/test/bake_outputs.h"
#include "rime/test/fake_tools.h"
#include "rime/test/temp_folder.h"
#include "farm.h"
#include "rime/core/error.h"
#include "rime/io/scene.h"

namespace fs = std::filesystem;

namespace rime::bake {
namespace {

constexpr int kLastFrame = test::kFakeLastFrame;
const char* const kScene = test::kFakeScene;

using test::ReadFile;
using test::WriteFile;

class Bake : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    root_ = temp_ / info->name();  // a folder of its own, so that a test can make siblings outside it
    fs::create_directories(root_);
    test::WriteFakeTools(root_ / "tools");
    scene_ = root_ / "scene.toml";
    WriteFile(scene_, kScene);
    setenv("FAKE_LOG", (root_ / "invocations.log").c_str(), 1);
    setenv("FAKE_FRAMES", std::to_string(kLastFrame).c_str(), 1);
    unsetenv("FAKE_FAIL");
    unsetenv("FAKE_SIM_SLEEP");
    unsetenv("FAKE_EMPTY_FRAME");
    setenv("RIME_BLENDER", "none", 1);  // the fake tools stand in for Rime's; a real Blender would render for seconds a frame
  }
  void TearDown() override {
    if (!saved_path_.empty()) setenv("PATH", saved_path_.c_str(), 1);
  }
  /// Puts a fake blender and ffmpeg first on PATH (until TearDown) and lets rime-bake use them.
  void UseFakePreviewTools() {
    test::WriteFakePreviewTools(root_ / "preview_tools");
    saved_path_ = getenv("PATH");
    setenv("PATH", ((root_ / "preview_tools").string() + ":" + saved_path_).c_str(), 1);
    unsetenv("RIME_BLENDER");
  }

  fs::path Out() const { return root_ / "out"; }
  /// Runs rime-bake; returns its exit code, its stdout+stderr in `output_`.
  int RunBake(const std::string& extra = "") {
    fs::remove(root_ / "invocations.log");
    std::string command = std::string("'") + RIME_BINARY_DIR "/bin/rime-bake' '" + scene_.string() + "' --tools '" +
                          (root_ / "tools").string() + "' -o '" + Out().string() + "' " + extra + " > '" +
                          (root_ / "bake_output.txt").string() + "' 2>&1";
    const int status = std::system(command.c_str());
    output_ = ReadFile(root_ / "bake_output.txt");
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
  /// Starts rime-bake (quiet) in the background, its output in `log` under the test's folder.
  pid_t StartBake(const std::string& log) const {
    return test::Spawn(
        {RIME_BINARY_DIR "/bin/rime-bake", scene_.string(), "--tools", (root_ / "tools").string(), "-o", Out().string(), "-q"},
        root_ / log);
  }
  /// Tool name -> number of invocations in the last run.
  std::map<std::string, int> Invocations() const {
    std::map<std::string, int> count;
    std::ifstream in(root_ / "invocations.log");
    std::string line;
    while (std::getline(in, line)) ++count[line.substr(0, line.find(' '))];
    return count;
  }
  std::vector<std::string> InvocationLines() const {
    std::vector<std::string> lines;
    std::ifstream in(root_ / "invocations.log");
    std::string line;
    while (std::getline(in, line)) lines.push_back(line);
    return lines;
  }
  void EditScene(const std::string& from, const std::string& to) {
    std::string text = ReadFile(scene_);
    const auto at = text.find(from);
    ASSERT_NE(at, std::string::npos) << from;
    text.replace(at, from.size(), to);
    WriteFile(scene_, text);
  }
  /// Waits until no process holds the bake lock (the tools of a killed bake keep it until they exit).
  void WaitUntilUnlocked() const {
    const int fd = open((Out() / "cache/.rime-bake/lock").c_str(), O_RDWR | O_CLOEXEC);
    if (fd < 0) return;
    for (int k = 0; k < 200 && flock(fd, LOCK_EX | LOCK_NB) != 0; ++k) std::this_thread::sleep_for(std::chrono::milliseconds(25));
    close(fd);
  }
  /// Moves a file's mtime forward without changing its content (like `touch`).
  static void Touch(const fs::path& p) { fs::last_write_time(p, fs::last_write_time(p) + std::chrono::seconds(5)); }

  rime::test::TempFolder temp_{"bake_test"};
  fs::path root_, scene_;
  std::string output_, saved_path_;
};

using Counts = std::map<std::string, int>;
const Counts kEverything{{"rime-boundary", 1}, {"rime-sim", 1}, {"rime-surface", kLastFrame + 1}, {"rime-clean", kLastFrame + 1}};

TEST_F(Bake, FirstRunBakesEverythingAndSecondRunExecutesNothing) {
  // Where no Blender is installed, the bake looks for one on PATH and must say why it renders none.
  const bool blender_installed = std::system("command -v blender > /dev/null 2>&1") == 0;
  if (!blender_installed) unsetenv("RIME_BLENDER");
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_EQ(Invocations(), kEverything);
  for (int f = 0; f <= kLastFrame; ++f) {
    EXPECT_TRUE(fs::exists(Out() / "cache/sim" / fmt::format("particles.{:04}.h5part", f)));
    EXPECT_TRUE(fs::exists(Out() / "surface" / fmt::format("ice.{:04}.vdb", f)));
    EXPECT_TRUE(fs::exists(Out() / "clean" / fmt::format("ice_clean.{:04}.json", f)));
    EXPECT_TRUE(fs::exists(Out() / "cache/logs" / fmt::format("surface.{:04}.log", f)));
  }
  EXPECT_TRUE(fs::exists(Out() / "cache/.rime-bake/state.json"));
  EXPECT_TRUE(fs::is_empty(Out() / "cache/.rime-bake/incomplete"));
  EXPECT_NE(output_.find("clean"), std::string::npos) << "summary table expected:\n" << output_;
  if (!blender_installed) {
    EXPECT_NE(output_.find("preview stage skipped: blender is not on PATH"), std::string::npos) << output_;
  }

  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_TRUE(Invocations().empty()) << output_;
}

TEST_F(Bake, TouchingFilesWithoutChangingThemRerunsNothing) {
  ASSERT_EQ(RunBake(), 0) << output_;
  Touch(scene_);
  Touch(Out() / "cache/boundary/ground.h5part");
  Touch(Out() / "cache/sim/particles.0002.h5part");
  Touch(Out() / "surface/ice.0001.obj");
  Touch(Out() / "clean/ice_clean.0003.obj");
  Touch(root_ / "tools/rime-clean");
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_TRUE(Invocations().empty()) << output_;
  // Reformatting the scene (comments, spacing) is not a change either: sections are hashed parsed.
  EditScene("omega = 0.5", "omega   =   0.5   # relaxed Jacobi");
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_TRUE(Invocations().empty()) << output_;
}

TEST_F(Bake, ChangingASurfaceParameterRerunsSurfaceAndCleanupOnly) {
  const std::string key = "voxel_ratio = 0.4";
  ASSERT_EQ(RunBake(), 0) << output_;
  WriteFile(scene_, ReadFile(scene_) + "\n[surface]\n" + key + "\n");
  ASSERT_EQ(RunBake("--explain"), 0) << output_;
  EXPECT_EQ(Invocations(), (Counts{{"rime-surface", kLastFrame + 1}, {"rime-clean", kLastFrame + 1}})) << output_;
  EXPECT_NE(output_.find("scene section [surface]"), std::string::npos) << output_;
}

TEST_F(Bake, ChangingACleanupParameterRerunsCleanupOnly) {
  const std::string key = "max_hole_edges = 100";
  ASSERT_EQ(RunBake(), 0) << output_;
  WriteFile(scene_, ReadFile(scene_) + "\n[clean]\n" + key + "\n");
  ASSERT_EQ(RunBake("--explain"), 0) << output_;
  EXPECT_EQ(Invocations(), (Counts{{"rime-clean", kLastFrame + 1}})) << output_;
  EXPECT_NE(output_.find("scene section [clean] changed"), std::string::npos) << output_;
}

TEST_F(Bake, SurfaceOutputsFollowTheSurfacePhaseAndFormats) {
  WriteFile(scene_, ReadFile(scene_) + "\n[surface]\nphase = \"both\"\nformats = [\"obj\", \"vdb\"]\n");
  ASSERT_EQ(RunBake(), 0) << output_;
  ASSERT_TRUE(fs::exists(Out() / "surface/water.0001.obj"));
  fs::remove(Out() / "surface/water.0001.obj");  // a tracked output: its job reruns
  ASSERT_EQ(RunBake("--explain"), 0) << output_;
  EXPECT_EQ(Invocations(), (Counts{{"rime-surface", 1}})) << output_;
  EXPECT_NE(output_.find("water.0001.obj is missing"), std::string::npos) << output_;
  fs::remove(Out() / "surface/ice.0002.ply");  // not among the formats: not an output
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_TRUE(Invocations().empty()) << output_;

  WriteFile(scene_, ReadFile(scene_) + "\n[bake]\n");  // no mesh format at all cannot be cleaned
  std::string text = ReadFile(scene_);
  text.replace(text.find("formats = [\"obj\", \"vdb\"]"), 24, "formats = [\"vdb\"]");
  WriteFile(scene_, text);
  EXPECT_EQ(RunBake(), 3) << output_;
  EXPECT_NE(output_.find("surface.formats"), std::string::npos) << output_;
  EXPECT_EQ(RunBake("surface"), 0) << output_;
}

TEST_F(Bake, FrameWithoutIceHasNothingToClean) {
  setenv("FAKE_EMPTY_FRAME", "0", 1);  // rime-surface writes an empty mesh when a frame has no ice
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_EQ(Invocations(), (Counts{{"rime-boundary", 1}, {"rime-sim", 1}, {"rime-surface", kLastFrame + 1}, {"rime-clean", kLastFrame}}))
      << output_;
  EXPECT_NE(output_.find("clean: 1 of the frames that ran had an empty mesh"), std::string::npos) << output_;
  EXPECT_FALSE(fs::exists(Out() / "clean/ice_clean.0000.obj"));
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_TRUE(Invocations().empty()) << output_;
  EXPECT_EQ(output_.find("empty mesh"), std::string::npos) << output_;
  unsetenv("FAKE_EMPTY_FRAME");  // the frame gets ice: now there is something to clean
  ASSERT_EQ(RunBake("--only surface --frames 0"), 0) << output_;
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_EQ(Invocations(), (Counts{{"rime-clean", 1}})) << output_;
  EXPECT_TRUE(fs::exists(Out() / "clean/ice_clean.0000.obj"));
}

TEST_F(Bake, RerunWithIdenticalOutputCutsOffDownstream) {
  ASSERT_EQ(RunBake(), 0) << output_;
  // The simulation section changes (the fake sim ignores omega): the sim reruns, writes the same
  // bytes, and nothing downstream reruns.
  EditScene("omega = 0.5", "omega = 0.6");
  ASSERT_EQ(RunBake("--explain"), 0) << output_;
  EXPECT_EQ(Invocations(), (Counts{{"rime-sim", 1}})) << output_;
  EXPECT_NE(output_.find("scene section [sim] changed"), std::string::npos) << output_;
  // An edited output reruns the job that wrote it; its restored content cuts cleanup off.
  WriteFile(Out() / "surface/ice.0001.obj", "edited by hand\n");
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_EQ(Invocations(), (Counts{{"rime-surface", 1}})) << output_;
}

TEST_F(Bake, ChangingTheWaterSpacingRerunsEverything) {
  ASSERT_EQ(RunBake(), 0) << output_;
  EditScene("spacing = 0.05", "spacing = 0.04");
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_EQ(Invocations(), kEverything) << output_;
}

TEST_F(Bake, ChangingAToolRerunsItsStage) {
  ASSERT_EQ(RunBake(), 0) << output_;
  WriteFile(root_ / "tools/rime-clean", ReadFile(root_ / "tools/rime-clean") + "# new version\n");
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_EQ(Invocations(), (Counts{{"rime-clean", kLastFrame + 1}})) << output_;
}

TEST_F(Bake, OnlyCleanupRerunsCleanupAlone) {
  ASSERT_EQ(RunBake(), 0) << output_;
  ASSERT_EQ(RunBake("--only clean"), 0) << output_;
  EXPECT_EQ(Invocations(), (Counts{{"rime-clean", kLastFrame + 1}})) << output_;
  ASSERT_EQ(RunBake("--only clean --frames 1-2"), 0) << output_;
  EXPECT_EQ(Invocations(), (Counts{{"rime-clean", 2}})) << output_;
}

TEST_F(Bake, OnlyRefusesMissingOrStaleInputsUnlessForced) {
  EXPECT_EQ(RunBake("--only surface"), 8) << output_;
  EXPECT_TRUE(Invocations().empty());
  EXPECT_NE(output_.find("--only surface refused"), std::string::npos) << output_;
  EXPECT_NE(output_.find("missing"), std::string::npos) << output_;

  ASSERT_EQ(RunBake(), 0) << output_;
  EditScene("spacing = 0.05", "spacing = 0.04");  // boundary and sim are now stale
  EXPECT_EQ(RunBake("--only clean"), 8) << output_;
  EXPECT_NE(output_.find("stale"), std::string::npos) << output_;
  EXPECT_TRUE(Invocations().empty());
  ASSERT_EQ(RunBake("--only clean --force"), 0) << output_;
  EXPECT_EQ(Invocations(), (Counts{{"rime-clean", kLastFrame + 1}})) << output_;
}

TEST_F(Bake, IncompleteMarkerForcesARerun) {
  ASSERT_EQ(RunBake(), 0) << output_;
  WriteFile(Out() / "cache/.rime-bake/incomplete/clean.0002", "interrupted");
  ASSERT_EQ(RunBake("--explain"), 0) << output_;
  EXPECT_EQ(InvocationLines().size(), 1u) << output_;
  EXPECT_EQ(Invocations(), (Counts{{"rime-clean", 1}})) << output_;
  EXPECT_NE(output_.find("incomplete"), std::string::npos) << output_;
  EXPECT_FALSE(fs::exists(Out() / "cache/.rime-bake/incomplete/clean.0002"));
}

TEST_F(Bake, FailingStageReportsStageFrameAndLog) {
  setenv("FAKE_FAIL", "surface:2", 1);
  EXPECT_EQ(RunBake(), 7) << output_;
  EXPECT_NE(output_.find("stage surface failed on frame 2"), std::string::npos) << output_;
  EXPECT_NE(output_.find("cache/logs/surface.0002.log"), std::string::npos) << output_;
  EXPECT_NE(output_.find("no particles in frame (fake)"), std::string::npos) << "the tool's own error line:\n" << output_;
  EXPECT_EQ(Invocations().count("rime-clean") ? Invocations().at("rime-clean") : 0, 2) << "frames 0 and 1 only:\n" << output_;
  unsetenv("FAKE_FAIL");
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_EQ(Invocations(), (Counts{{"rime-surface", 2}, {"rime-clean", 2}})) << output_;
}

TEST_F(Bake, FailedSimulationResumesAndMatchesAnUninterruptedBake) {
  setenv("FAKE_FAIL", "sim:2", 1);
  EXPECT_EQ(RunBake(), 7) << output_;
  EXPECT_NE(output_.find("stage sim failed"), std::string::npos) << output_;
  EXPECT_NE(output_.find("sim.log"), std::string::npos) << output_;
  unsetenv("FAKE_FAIL");
  ASSERT_EQ(RunBake(), 0) << output_;
  const auto lines = InvocationLines();
  ASSERT_FALSE(lines.empty());
  EXPECT_NE(lines.front().find("--resume"), std::string::npos) << lines.front();
  const fs::path interrupted = Out();
  fs::rename(interrupted, root_ / "first");
  ASSERT_EQ(RunBake(), 0) << output_;
  for (int f = 0; f <= kLastFrame; ++f) {
    const std::string name = fmt::format("clean/ice_clean.{:04}.obj", f);
    EXPECT_EQ(ReadFile(root_ / "first" / name), ReadFile(Out() / name)) << name;
  }
}

TEST_F(Bake, ChangedParametersRestartTheSimulationInsteadOfResuming) {
  setenv("FAKE_FAIL", "sim:2", 1);
  EXPECT_EQ(RunBake(), 7) << output_;
  unsetenv("FAKE_FAIL");
  EditScene("omega = 0.5", "omega = 0.7");
  ASSERT_EQ(RunBake(), 0) << output_;
  const auto lines = InvocationLines();
  ASSERT_FALSE(lines.empty());
  EXPECT_EQ(lines.front().find("--resume"), std::string::npos) << lines.front();
}

TEST_F(Bake, KilledDuringSimulationResumes) {
  setenv("FAKE_SIM_SLEEP", "0.4", 1);
  const pid_t pid = StartBake("killed.txt");
  ASSERT_GT(pid, 0);
  const fs::path second_frame = Out() / "cache/sim/particles.0001.h5part";
  for (int k = 0; k < 200 && !fs::exists(second_frame); ++k) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  ASSERT_TRUE(fs::exists(second_frame));
  kill(pid, SIGKILL);  // no chance to clean up; the fake sim dies with it (PR_SET_PDEATHSIG)
  test::WaitExit(pid);
  WaitUntilUnlocked();  // its `sleep` outlives it, holding the inherited lock
  EXPECT_FALSE(fs::exists(Out() / "cache/sim/particles.0003.h5part"));
  EXPECT_TRUE(fs::exists(Out() / "cache/.rime-bake/incomplete/sim"));

  ASSERT_EQ(RunBake("--explain"), 0) << output_;
  const auto lines = InvocationLines();
  ASSERT_FALSE(lines.empty());
  EXPECT_EQ(lines.front().rfind("rime-sim", 0), 0u) << lines.front();
  EXPECT_NE(lines.front().find("--resume"), std::string::npos) << lines.front();
  EXPECT_EQ(Invocations().count("rime-boundary"), 0u);
  for (int f = 0; f <= kLastFrame; ++f)
    EXPECT_EQ(ReadFile(Out() / fmt::format("cache/sim/particles.{:04}.h5part", f)).rfind(fmt::format("frame {}\n", f), 0), 0u);
}

TEST_F(Bake, DryRunPrintsCommandsAndRunsNothing) {
  ASSERT_EQ(RunBake("--dry-run"), 0) << output_;
  EXPECT_TRUE(Invocations().empty());
  EXPECT_NE(output_.find("rime-sim"), std::string::npos) << output_;
  EXPECT_NE(output_.find("particles.0003.h5part"), std::string::npos) << output_;
  EXPECT_FALSE(fs::exists(Out() / "surface"));
  ASSERT_EQ(RunBake(), 0) << output_;
  EditScene("omega = 0.5", "omega = 0.6");
  ASSERT_EQ(RunBake("--dry-run --explain"), 0) << output_;
  EXPECT_TRUE(Invocations().empty());
  EXPECT_NE(output_.find("# sim: scene section [sim] changed"), std::string::npos) << output_;
  EXPECT_NE(output_.find("# surface.0000: after sim reruns"), std::string::npos) << output_;
}

TEST_F(Bake, TargetStopsAtItsStageAndCleanRemovesEverything) {
  ASSERT_EQ(RunBake("sim"), 0) << output_;
  EXPECT_EQ(Invocations(), (Counts{{"rime-boundary", 1}, {"rime-sim", 1}})) << output_;
  EXPECT_FALSE(fs::exists(Out() / "surface"));
  ASSERT_EQ(RunBake("--clean"), 0) << output_;
  EXPECT_FALSE(fs::exists(Out()));
  EXPECT_EQ(RunBake("nonsense"), 2) << output_;
}

TEST_F(Bake, FormerStageNamesAreRefusedNamingTheCurrentOne) {
  EXPECT_EQ(RunBake("cleanup"), 2) << output_;
  EXPECT_NE(output_.find("stage 'cleanup' is now called 'clean'"), std::string::npos) << output_;
  EXPECT_EQ(RunBake("--only simulate"), 2) << output_;
  EXPECT_NE(output_.find("stage 'simulate' is now called 'sim'"), std::string::npos) << output_;
  EXPECT_EQ(Invocations(), Counts{}) << output_;
}

TEST_F(Bake, PreviewRendersEveryCleanedFrameWhenBlenderIsOnPath) {
  UseFakePreviewTools();
  const int code = RunBake();
  ASSERT_EQ(code, 0) << output_;
  EXPECT_EQ(Invocations()["blender"], kLastFrame + 1) << output_;
  EXPECT_EQ(Invocations()["ffmpeg"], 2) << "contact sheet and MP4:\n" << output_;
  for (int f = 0; f <= kLastFrame; ++f) EXPECT_TRUE(fs::exists(Out() / fmt::format("preview/frame.{:04}.png", f))) << f;
  EXPECT_TRUE(fs::exists(Out() / "preview/contact_sheet.png"));
  EXPECT_TRUE(fs::exists(Out() / "preview/preview.mp4"));
  EXPECT_TRUE(fs::exists(Out() / "cache/preview/render_preview.py"));
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_TRUE(Invocations().empty()) << output_;
  WriteFile(scene_, ReadFile(scene_) + "[bake]\npreview_width = 640\n");  // only the preview reads [bake]
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_EQ(Invocations(), (Counts{{"blender", kLastFrame + 1}, {"ffmpeg", 2}})) << output_;
  // The camera's direction reaches the render script's setup and rerenders every frame.
  WriteFile(scene_, ReadFile(scene_) + "preview_view = [1.0, -1.0, 0.25]\n");
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_EQ(Invocations()["blender"], kLastFrame + 1) << output_;
  EXPECT_NE(ReadFile(Out() / "cache/preview/preview_scene.json").find("0.25"), std::string::npos);
  // A close-up box replaces the domain as what the camera frames.
  WriteFile(scene_, ReadFile(scene_) + "preview_frame_min = [0.125, -0.5, 0.0]\npreview_frame_max = [0.375, 0.5, 0.625]\n");
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_EQ(Invocations()["blender"], kLastFrame + 1) << output_;
  const std::string setup = ReadFile(Out() / "cache/preview/preview_scene.json");
  EXPECT_NE(setup.find("0.125"), std::string::npos) << setup;
  EXPECT_NE(setup.find("0.625"), std::string::npos) << setup;
}

// RIME_BLENDER names a Blender outside PATH; "none" skips the preview stage.
TEST_F(Bake, RimeBlenderPicksTheBlenderOrTurnsPreviewsOff) {
  UseFakePreviewTools();
  setenv("RIME_BLENDER", "none", 1);
  ASSERT_EQ(RunBake("-v"), 0) << output_;
  EXPECT_EQ(Invocations().count("blender"), 0u) << output_;
  EXPECT_NE(output_.find("preview stage skipped: RIME_BLENDER=none"), std::string::npos) << output_;
  setenv("RIME_BLENDER", (root_ / "preview_tools/blender").c_str(), 1);
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_EQ(Invocations()["blender"], kLastFrame + 1) << output_;
  setenv("RIME_BLENDER", (root_ / "no_such_blender").c_str(), 1);
  EXPECT_EQ(RunBake(), 3) << output_;
  EXPECT_NE(output_.find("RIME_BLENDER names"), std::string::npos) << output_;
}

TEST_F(Bake, InterruptStopsTheBakeAndTheRerunResumes) {
  setenv("FAKE_SIM_SLEEP", "0.4", 1);
  const pid_t pid = StartBake("interrupted.txt");
  ASSERT_GT(pid, 0);
  const fs::path second_frame = Out() / "cache/sim/particles.0001.h5part";
  for (int k = 0; k < 200 && !fs::exists(second_frame); ++k) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  kill(pid, SIGINT);  // like Ctrl-C, but only to rime-bake: it must stop the running tool itself
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 130);
  EXPECT_FALSE(fs::exists(Out() / "surface"));
  unsetenv("FAKE_SIM_SLEEP");
  ASSERT_EQ(RunBake(), 0) << output_;
  const auto lines = InvocationLines();
  ASSERT_FALSE(lines.empty());
  EXPECT_NE(lines.front().find("--resume"), std::string::npos) << lines.front();
}

std::string HostName() {
  char name[256] = {};
  gethostname(name, sizeof name - 1);
  return name;
}

// The pid of a process that has just exited (and been reaped).
pid_t DeadPid() {
  const pid_t pid = fork();
  if (pid == 0) _exit(0);
  waitpid(pid, nullptr, 0);
  return pid;
}

TEST_F(Bake, SecondBakeIntoTheSameFolderIsRefusedNamingTheHolder) {
  setenv("FAKE_SIM_SLEEP", "0.5", 1);
  const pid_t first = StartBake("first.txt");
  ASSERT_GT(first, 0);
  for (int k = 0; k < 200 && !fs::exists(Out() / "cache/sim/particles.0000.h5part"); ++k)
    std::this_thread::sleep_for(std::chrono::milliseconds(25));
  EXPECT_EQ(RunBake(), 5) << output_;
  // One line: who holds the lock (pid, host, start time) and which lock it is.
  EXPECT_NE(output_.find(fmt::format("rime-bake: error: another rime-bake is baking into {} (pid {} on host {}, started ", Out().string(),
                                     first, HostName())),
            std::string::npos)
      << output_;
  EXPECT_NE(output_.find("UTC) (" + (Out() / "cache/.rime-bake/lock").string() + ")"), std::string::npos) << output_;
  EXPECT_EQ(std::count(output_.begin(), output_.end(), '\n'), 1) << output_;
  EXPECT_EQ(Invocations().count("rime-surface"), 0u) << "the refused bake must run nothing";
  EXPECT_EQ(rime::test::WaitExit(first), 0) << ReadFile(root_ / "first.txt");
  EXPECT_EQ(ReadFile(Out() / "cache/.rime-bake/lock"), "") << "a bake that ends normally clears its holder line";
  unsetenv("FAKE_SIM_SLEEP");
  EXPECT_EQ(RunBake(), 0) << output_;
  EXPECT_EQ(output_.find("stale lock"), std::string::npos) << output_;
}

TEST_F(Bake, StaleLockOfADeadBakeIsReportedAndRecovered) {
  fs::create_directories(Out() / "cache/.rime-bake");
  const pid_t dead = DeadPid();
  WriteFile(Out() / "cache/.rime-bake/lock", fmt::format("pid={} host={} started=2026-01-02T03:04:05Z\n", dead, HostName()));
  // A temporary a killed writer left beside a final file goes too.
  fs::create_directories(Out() / "surface");
  WriteFile(Out() / "surface/ice.0001.obj.tmp.999999.0", "half a mesh");
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_NE(output_.find(fmt::format("stale lock from pid {} ({}, started 2026-01-02 03:04:05 UTC) recovered", dead, HostName())),
            std::string::npos)
      << output_;
  EXPECT_FALSE(fs::exists(Out() / "surface/ice.0001.obj.tmp.999999.0")) << output_;
  EXPECT_NE(output_.find("removed 1 temporary files left by an interrupted run"), std::string::npos) << output_;
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_EQ(output_.find("stale lock"), std::string::npos) << "the holder line is cleared once recovered:\n" << output_;
}

// On a filesystem shared by several hosts flock may be node-local, so a lock that names a process
// on another host cannot be told stale from here: it is refused with what to do about it.
TEST_F(Bake, LockNamingAnotherHostIsRefusedNotTakenOver) {
  fs::create_directories(Out() / "cache/.rime-bake");
  WriteFile(Out() / "cache/.rime-bake/lock", "pid=4242 host=render-node-17 started=2026-01-02T03:04:05Z\n");
  EXPECT_EQ(RunBake(), 5) << output_;
  EXPECT_NE(
      output_.find("the bake lock names pid 4242 on host render-node-17, started 2026-01-02 03:04:05 UTC, which cannot be checked from "
                   "host " +
                   HostName() + "; if no rime-bake runs there any more, delete the lock file and rerun"),
      std::string::npos)
      << output_;
  EXPECT_TRUE(Invocations().empty());
}

// The stage tools inherit the lock: a bake killed with SIGKILL keeps its folder locked until the
// last of its tools has exited, so a rerun cannot race a tool that is still writing.
TEST_F(Bake, ToolsOfAKilledBakeHoldTheLockUntilTheyExit) {
  setenv("FAKE_SIM_SLEEP", "3", 1);  // the fake simulation's `sleep 3` outlives the killed bake
  const pid_t bake = StartBake("killed.txt");
  ASSERT_GT(bake, 0);
  for (int k = 0; k < 200 && ReadFile(root_ / "invocations.log").find("rime-sim") == std::string::npos; ++k)
    std::this_thread::sleep_for(std::chrono::milliseconds(25));
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  kill(bake, SIGKILL);
  rime::test::WaitExit(bake);
  unsetenv("FAKE_SIM_SLEEP");
  EXPECT_EQ(RunBake(), 5) << output_;
  EXPECT_NE(output_.find(fmt::format("stage tools started by a killed rime-bake (pid {} on host {}", bake, HostName())), std::string::npos)
      << output_;
  WaitUntilUnlocked();
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_NE(output_.find(fmt::format("stale lock from pid {} ({}", bake, HostName())), std::string::npos) << output_;
}

TEST_F(Bake, StageToolThatCannotWriteMakesTheBakeExit5NamingTheFile) {
  setenv("FAKE_FAIL", "surface:2", 1);
  setenv("FAKE_FAIL_CODE", "5", 1);
  EXPECT_EQ(RunBake(), 5) << output_;
  unsetenv("FAKE_FAIL");
  unsetenv("FAKE_FAIL_CODE");
  EXPECT_NE(
      output_.find(fmt::format("rime-bake: error: stage surface failed on frame 2 (rime-surface exited with code 5: rime-surface: error: "
                               "cannot write VDB file: No space left on device ({}/ice.0002.vdb)); log: ",
                               (Out() / "surface").string())),
      std::string::npos)
      << output_;
  EXPECT_EQ(RunBake(), 0) << output_;
}

TEST_F(Bake, MemoryBudgetReachesEveryToolAsItsShareAndChangesNoKey) {
  ASSERT_EQ(RunBake("clean -j 2 --memory-budget 4G"), 0) << output_;
  int surfaces = 0, cleanups = 0;
  for (const std::string& line : InvocationLines()) {
    const std::string tool = line.substr(0, line.find(' '));
    // Boundary and simulation run alone with the whole budget; two frames at once share it.
    const std::string expected =
        tool == "rime-boundary" || tool == "rime-sim" ? "--memory-budget 4294967296" : "--memory-budget 2147483648";
    EXPECT_NE(line.find(expected), std::string::npos) << line;
    surfaces += tool == "rime-surface", cleanups += tool == "rime-clean";
  }
  EXPECT_EQ(surfaces, kLastFrame + 1);
  EXPECT_EQ(cleanups, kLastFrame + 1);
  // A budget does not change what a tool computes: another one, or none, reruns nothing.
  ASSERT_EQ(RunBake("clean --memory-budget 1G"), 0) << output_;
  EXPECT_TRUE(Invocations().empty()) << output_;
  ASSERT_EQ(RunBake("clean"), 0) << output_;
  EXPECT_TRUE(Invocations().empty()) << output_;
  EXPECT_EQ(RunBake("clean --memory-budget 4X"), 2) << output_;
  EXPECT_NE(output_.find("--memory-budget 4X"), std::string::npos) << output_;
}

TEST_F(Bake, StageToolOverItsMemoryBudgetMakesTheBakeExit10) {
  setenv("FAKE_FAIL", "surface:1", 1);
  setenv("FAKE_FAIL_CODE", "10", 1);
  EXPECT_EQ(RunBake("clean --memory-budget 1G"), 10) << output_;
  unsetenv("FAKE_FAIL");
  unsetenv("FAKE_FAIL_CODE");
  EXPECT_NE(output_.find("rime-bake: error: stage surface failed on frame 1 (rime-surface exited with code 10: rime-surface: error: "
                         "needs about 2 GiB for 100 M voxels"),
            std::string::npos)
      << output_;
  EXPECT_EQ(RunBake("clean"), 0) << output_;
}

TEST_F(Bake, SandboxRefusesPathsOutsideItBeforeWritingAnything) {
  const fs::path outside = root_.parent_path() / (root_.filename().string() + "_outside");
  fs::create_directories(outside);
  WriteFile(outside / "rock.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  WriteFile(root_ / "rock.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  // Up to the cleanup: the preview stage would run a real Blender where one is installed.
  const std::string sandbox = "clean --sandbox '" + root_.string() + "'";
  const auto expect_refused = [&](int code, const std::string& names) {
    EXPECT_EQ(RunBake(sandbox), code) << output_;
    EXPECT_NE(output_.find(names), std::string::npos) << output_;
    EXPECT_NE(output_.find("outside the sandbox " + root_.string()), std::string::npos) << output_;
    EXPECT_TRUE(Invocations().empty()) << output_;
    EXPECT_FALSE(fs::exists(Out() / "cache" / ".rime-bake")) << output_;
  };
  // Scene mesh paths: a "../" escape, an absolute path, a symlink that leads out.
  fs::create_directory_symlink(outside, root_ / "linked");
  const std::string mesh_field = scene_.string() + ": solid 'rock' mesh ";
  for (const std::string& mesh :
       {"../" + outside.filename().string() + "/rock.obj", (outside / "rock.obj").string(), std::string("linked/rock.obj")}) {
    SCOPED_TRACE(mesh);
    WriteFile(scene_, std::string(kScene) + "\n[[solid]]\nname = \"rock\"\nshape = \"mesh\"\nmesh = \"" + mesh + "\"\n");
    expect_refused(3, mesh_field + (scene_.parent_path() / mesh).string());
  }
  WriteFile(scene_, std::string(kScene) + "\n[[solid]]\nname = \"rock\"\nshape = \"mesh\"\nmesh = \"rock.obj\"\n");
  // The cache folder a symlink out of the sandbox.
  fs::create_directories(Out());
  fs::create_directory_symlink(outside, Out() / "cache");
  expect_refused(2, "-o " + (Out() / "cache").string());
  fs::remove(Out() / "cache");
  // The output folder given with "../".
  const std::string escape = std::string("'") + RIME_BINARY_DIR "/bin/rime-bake' '" + scene_.string() + "' --tools '" +
                             (root_ / "tools").string() + "' -o '" + root_.string() + "/../" + outside.filename().string() + "/out' " +
                             sandbox + " > /dev/null 2>&1";
  const int status = std::system(escape.c_str());
  EXPECT_EQ(WIFEXITED(status) ? WEXITSTATUS(status) : -1, 2);
  EXPECT_FALSE(fs::exists(outside / "out"));
  // Inside: the bake runs, and every tool gets the sandbox too.
  ASSERT_EQ(RunBake(sandbox), 0) << output_;
  for (const std::string& line : InvocationLines()) EXPECT_NE(line.find("--sandbox " + root_.string()), std::string::npos) << line;
  EXPECT_EQ(Invocations(), kEverything);
  fs::remove_all(outside);
}

// The preview's contact sheet and movie run ffmpeg through /bin/sh: the output folder reaches
// that shell as an argument, never as part of the script, whatever characters it holds.
TEST_F(Bake, OutputFolderFullOfShellSyntaxReachesNoShell) {
  UseFakePreviewTools();
  const std::string marker = (root_ / "pwned").string();
  const fs::path out = root_ / fmt::format("out 'q'; touch {0}1; '\"$(touch {0}2)`touch {0}3` %d\n❄ é", marker);
  std::string output;
  const int code =
      rime::test::Run({RIME_BINARY_DIR "/bin/rime-bake", scene_.string(), "--tools", (root_ / "tools").string(), "-o", out.string()},
                      root_ / "hostile.txt", output);
  ASSERT_EQ(code, 0) << output;
  for (int k = 1; k <= 3; ++k) EXPECT_FALSE(fs::exists(fmt::format("{}{}", marker, k))) << "an injected command ran";
  EXPECT_TRUE(fs::exists(out / "preview/contact_sheet.png")) << output;
  EXPECT_TRUE(fs::exists(out / "preview/preview.mp4")) << output;
}

// The farm's batch script runs its arguments as they are: a task command line full of shell
// syntax runs nothing else, and a site `#SBATCH` entry cannot smuggle in a line of script.
TEST_F(Bake, FarmTaskScriptPassesArgumentsThroughUnchanged) {
  FarmSettings settings;
  settings.sbatch_lines = {"--constraint=avx2"};
  const std::string text = TaskScriptText(settings);
  EXPECT_NE(text.find("\n#SBATCH --constraint=avx2\n"), std::string::npos) << text;
  WriteFile(root_ / "task.sh", text);
  WriteFile(root_ / "print_args", "#!/bin/sh\nfor a; do printf '%s\\0' \"$a\"; done\n");
  chmod((root_ / "print_args").c_str(), 0755);
  const std::string marker = (root_ / "pwned").string();
  const std::vector<std::string> hostile = {"a;b", fmt::format("$(touch {})", marker), fmt::format("`touch {}`", marker), "'\"\\", "x\ny ❄",
                                            "*"};
  std::vector<std::string> args = {"/bin/sh", (root_ / "task.sh").string(), (root_ / "print_args").string()};
  args.insert(args.end(), hostile.begin(), hostile.end());
  std::string printed;
  ASSERT_EQ(rime::test::Run(args, root_ / "printed.txt", printed), 0) << printed;
  std::string expected;
  for (const auto& a : hostile) expected += a + '\0';
  EXPECT_EQ(printed, expected);
  EXPECT_FALSE(fs::exists(marker)) << "an injected command ran";

  WriteFile(root_ / "site.toml", "[farm]\nsbatch = [\"--comment=x\\ntouch " + marker + "\"]\n");
  try {
    LoadFarmSettings(root_ / "site.toml", scene_);
    ADD_FAILURE() << "an sbatch entry with a line break was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("is not one sbatch option"), std::string::npos) << e.what();
  }
}

// `[farm.time]` / `[farm.memory]`: the scene's table over the site file's, its `default` filling
// the stages it does not name; every stage has a key.
TEST_F(Bake, FarmPerStageValuesLayerSiteAndScene) {
  WriteFile(root_ / "site.toml", "[farm]\n[farm.time]\nsim = \"12:00:00\"\nclean = \"20\"\n[farm.memory]\ndefault = \"4G\"\n");
  WriteFile(root_ / "farm_scene.toml", "[farm.time]\nsurface = \"5\"\n[farm.memory]\ndefault = \"8G\"\nsim = \"64G\"\n");
  const FarmSettings settings = LoadFarmSettings(root_ / "site.toml", root_ / "farm_scene.toml");
  for (int s = 0; s < kStageCount; ++s) {
    const Stage stage = static_cast<Stage>(s);
    const std::string time = stage == Stage::kSim ? "12:00:00" : stage == Stage::kClean ? "20" : stage == Stage::kSurface ? "5" : "";
    EXPECT_EQ(settings.time[s], time) << StageName(stage);
    EXPECT_EQ(settings.memory[s], stage == Stage::kSim ? "64G" : "8G") << StageName(stage);
  }
  int keys = 0;
  const io::FarmTimes declared;
  io::FarmTimes::Visit(declared, [&](const io::Param& p, const std::string&) {
    if (p.name == "default") return;
    EXPECT_TRUE(ParseStage(std::string(p.name)).has_value()) << p.name;
    ++keys;
  });
  EXPECT_EQ(keys, kStageCount);

  WriteFile(root_ / "bad_site.toml", "[farm]\n[farm.memory]\npreview = \"lots\"\n");
  try {
    LoadFarmSettings(root_ / "bad_site.toml", root_ / "farm_scene.toml");
    ADD_FAILURE() << "a memory size 'lots' was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("farm.memory.preview"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("'lots' is not a Slurm memory size"), std::string::npos) << e.what();
  }
}

TEST_F(Bake, CorruptStateRebuildsEverythingWithAWarning) {
  ASSERT_EQ(RunBake(), 0) << output_;
  WriteFile(Out() / "cache/.rime-bake/state.json", "{ not json");
  ASSERT_EQ(RunBake(), 0) << output_;
  EXPECT_NE(output_.find("ignoring corrupt state file"), std::string::npos) << output_;
  EXPECT_EQ(Invocations(), kEverything) << output_;
}

TEST_F(Bake, MissingStageToolIsNamedAndOnlyNeededForItsStage) {
  fs::remove(root_ / "tools/rime-clean");
  EXPECT_EQ(RunBake(), 3) << output_;
  EXPECT_NE(output_.find("stage tool rime-clean not found"), std::string::npos) << output_;
  EXPECT_TRUE(Invocations().empty());
  EXPECT_EQ(RunBake("surface"), 0) << output_;
  EXPECT_EQ(Invocations()["rime-surface"], kLastFrame + 1) << output_;
}

TEST_F(Bake, BadBakeTableNamesFileLineAndField) {
  const std::string text = ReadFile(scene_) + "[bake]\npreview_widht = 640\n";
  WriteFile(scene_, text);
  const auto line = std::count(text.begin(), text.end(), '\n');  // the misspelled key is on the last line
  EXPECT_EQ(RunBake(), 3) << output_;
  EXPECT_NE(output_.find(fmt::format("scene.toml:{}: bake.preview_widht", line)), std::string::npos) << output_;
}

TEST_F(Bake, EmptyPreviewFrameBoxIsRefusedNamingTheField) {
  WriteFile(scene_, ReadFile(scene_) + "[bake]\npreview_frame_min = [0, 0, 0]\npreview_frame_max = [1, 1, 0]\n");
  EXPECT_EQ(RunBake(), 3) << output_;
  EXPECT_NE(output_.find("bake.preview_frame_max"), std::string::npos) << output_;
}

TEST_F(Bake, ZeroPreviewViewIsRefusedNamingTheField) {
  WriteFile(scene_, ReadFile(scene_) + "[bake]\npreview_view = [0, 0, 0]\n");
  EXPECT_EQ(RunBake(), 3) << output_;
  EXPECT_NE(output_.find("bake.preview_view"), std::string::npos) << output_;
}

}  // namespace
}  // namespace rime::bake
