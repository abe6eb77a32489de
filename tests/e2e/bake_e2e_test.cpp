// End to end with the real stage tools: bake a tiny procedural scene with rime-bake, then check
// what a second run, a touched file, a changed [surface] value and `--only clean` rerun (from
// rime-bake's JSON summary), and that a bake killed during the simulation resumes and ends with
// the same frames as an uninterrupted one.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fmt/format.h>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "rime/core/error.h"
#include "rime/io/particles.h"
#include "rime/io/scene.h"
#include "rime/test/bake_outputs.h"
#include "rime/test/files.h"
#include "rime/test/small_bake_scene.h"
#include "rime/test/temp_folder.h"

namespace fs = std::filesystem;

namespace rime {
namespace {

constexpr int kLastFrame = 10;
const std::string kScene = test::SmallBakeScene("e2e", kLastFrame);

using test::ReadFile;

class BakeEndToEnd : public ::testing::Test {
 protected:
  void SetUp() override {
    temp_ =
        std::make_unique<rime::test::TempFolder>(fmt::format("e2e_{}", ::testing::UnitTest::GetInstance()->current_test_info()->name()));
    root_ = temp_->path();
    std::ofstream(root_ / "e2e.toml") << kScene;
    setenv("RIME_BLENDER", "none", 1);  // these tests check the stage tools; previews are Blender's work
  }
  void TearDown() override { temp_.reset(); }

  static std::vector<std::string> Args(const fs::path& out, const std::string& extra_flags) {
    std::vector<std::string> args = {
        RIME_BINARY_DIR "/bin/rime-bake", (root_ / "e2e.toml").string(), "-o", out.string(), "-j", "2", "--json-summary",
        (root_ / "summary.json").string()};
    std::istringstream extra(extra_flags);
    for (std::string word; extra >> word;) args.push_back(word);
    return args;
  }
  /// Runs rime-bake to completion; returns its exit code and leaves its JSON summary in summary_.
  static int RunBake(const fs::path& out, const std::string& extra = "") {
    std::string command;
    for (const auto& a : Args(out, extra)) command += "'" + a + "' ";
    command += "> '" + (root_ / "bake.txt").string() + "' 2>&1";
    const int status = std::system(command.c_str());
    output_ = ReadFile(root_ / "bake.txt");
    summary_ = nlohmann::json::parse(ReadFile(root_ / "summary.json"), nullptr, false);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
  static int Ran(const std::string& stage) { return summary_["stages"][stage]["ran"].get<int>(); }
  static int TotalRan() {
    int ran = 0;
    for (const auto& [stage, s] : summary_["stages"].items()) ran += s["ran"].get<int>();
    return ran;
  }
  static fs::path Baked() { return root_ / "out_a"; }

  static inline std::unique_ptr<rime::test::TempFolder> temp_;
  static inline fs::path root_;
  static inline std::string output_;
  static inline nlohmann::json summary_;
};

TEST_F(BakeEndToEnd, RerunsOnlyWhatChanged) {
  // 1. A fresh bake runs every job; a second run executes nothing.
  ASSERT_EQ(RunBake(Baked(), "clean"), 0) << output_;
  EXPECT_EQ(Ran("boundary"), 1);
  EXPECT_EQ(Ran("sim"), 1);
  EXPECT_EQ(Ran("surface"), kLastFrame + 1);
  EXPECT_EQ(Ran("clean"), kLastFrame + 1);
  for (int f = 0; f <= kLastFrame; ++f) {
    EXPECT_TRUE(fs::exists(io::FramePath(Baked() / "cache/sim", "particles", f, "h5part"))) << f;
    EXPECT_TRUE(fs::exists(io::FramePath(Baked() / "surface", "water", f, "vdb"))) << f;
    EXPECT_GT(fs::file_size(io::FramePath(Baked() / "clean", "water_clean", f, "obj")), 0u) << f;
  }
  ASSERT_EQ(RunBake(Baked(), "clean"), 0) << output_;
  EXPECT_EQ(TotalRan(), 0) << output_;

  // 2. Touching files without changing them reruns nothing.
  for (const fs::path& p : {root_ / "e2e.toml", Baked() / "cache/sim/particles.0003.h5part", Baked() / "surface/water.0002.obj",
                            Baked() / "cache/boundary/ball.h5part"})
    fs::last_write_time(p, fs::last_write_time(p) + std::chrono::seconds(3));
  ASSERT_EQ(RunBake(Baked(), "clean"), 0) << output_;
  EXPECT_EQ(TotalRan(), 0) << output_;

  // 3. --only clean reruns cleanup alone.
  ASSERT_EQ(RunBake(Baked(), "--only clean"), 0) << output_;
  EXPECT_EQ(Ran("clean"), kLastFrame + 1);
  EXPECT_EQ(TotalRan(), kLastFrame + 1);

  // 4. A changed [surface] value reruns surface and cleanup only.
  std::ofstream(root_ / "e2e.toml", std::ios::app) << "voxel_ratio = 0.4\n";  // appended to [surface]
  ASSERT_EQ(RunBake(Baked(), "clean --explain"), 0) << output_;
  EXPECT_EQ(Ran("boundary"), 0);
  EXPECT_EQ(Ran("sim"), 0);
  EXPECT_EQ(Ran("surface"), kLastFrame + 1);
  EXPECT_EQ(Ran("clean"), kLastFrame + 1);  // a different voxel size changes every mesh
}

TEST_F(BakeEndToEnd, KilledDuringSimulationResumesToTheSameFrames) {
  ASSERT_EQ(RunBake(Baked(), "clean"), 0) << output_;  // the uninterrupted reference
  const fs::path out = root_ / "out_killed";
  const pid_t pid = test::Spawn(Args(out, "clean -q"), root_ / "killed.txt");
  ASSERT_GT(pid, 0);
  const fs::path first_frames = io::FramePath(out / "cache/sim", "particles", 1, "h5part");
  for (int k = 0; k < 60000 && !fs::exists(first_frames); ++k) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  kill(pid, SIGKILL);  // the running rime-sim gets SIGTERM from the kernel (PR_SET_PDEATHSIG)
  test::WaitExit(pid);
  std::this_thread::sleep_for(std::chrono::seconds(1));
  ASSERT_TRUE(fs::exists(first_frames)) << "the simulation never wrote frame 1";
  if (fs::exists(io::FramePath(out / "cache/sim", "particles", kLastFrame, "h5part")))
    GTEST_SKIP() << "the simulation finished before it could be killed; nothing to resume";

  ASSERT_EQ(RunBake(out, "clean --explain"), 0) << output_;
  EXPECT_NE(ReadFile(out / "cache/logs/sim.log").find("--resume"), std::string::npos) << "the rerun must resume, not restart";
  EXPECT_EQ(Ran("boundary"), 0) << output_;
  for (int f = 0; f <= kLastFrame; ++f) {
    const auto a = io::ReadParticleFrame(io::FramePath(Baked() / "cache/sim", "particles", f, "h5part"));
    const auto b = io::ReadParticleFrame(io::FramePath(out / "cache/sim", "particles", f, "h5part"));
    EXPECT_EQ(a.size(), b.size()) << "frame " << f;
    EXPECT_TRUE(a.attributes == b.attributes) << "frame " << f << " differs after resuming";
    EXPECT_EQ(ReadFile(io::FramePath(Baked() / "clean", "water_clean", f, "obj")),
              ReadFile(io::FramePath(out / "clean", "water_clean", f, "obj")))
        << "frame " << f;
  }
}

}  // namespace
}  // namespace rime
