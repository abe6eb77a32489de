// End-to-end checks of the rime-clean executable: outputs, names, reports and bad input.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "rime/io/mesh.h"
#include "rime/io/particles.h"
#include "rime/clean/procedural.h"
#include "rime/clean/quality.h"
#include "rime/test/files.h"
#include "rime/test/run_command.h"
#include "rime/test/temp_folder.h"

namespace rime {
namespace {
namespace fs = std::filesystem;

const fs::path kTool = fs::path(RIME_BINARY_DIR) / "bin" / "rime-clean";

using ToolRun = test::CommandResult;

ToolRun Clean(const std::string& args) { return test::RunCommand(kTool.string() + " -q " + args, test::Capture::kStderr); }

class CleanTool : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!fs::exists(kTool)) GTEST_SKIP() << "rime-clean not built at " << kTool;
  }
  rime::test::TempFolder temp_{"clean_tool"};
  fs::path dir_ = temp_.path();
};

io::TriMesh NoisyBallWithSpeck() {
  io::TriMesh m = clean::procedural::NoisyBall(8000, 1);
  for (const Vec3f& p : m.positions) m.velocities.push_back(Vec3f(1, 0, 0) + p * 2.0f);
  io::TriMesh speck = clean::procedural::Icosphere(0.01, 0, {0.8, 0, 0});
  for (const Vec3f& p : speck.positions) speck.velocities.push_back(p);
  clean::procedural::Append(m, speck);
  return m;
}

TEST_F(CleanTool, OneMeshToOneFileWithReportAndVelocity) {
  io::WriteMesh(dir_ / "ball.ply", NoisyBallWithSpeck());
  const ToolRun r = Clean((dir_ / "ball.ply").string() + " -o " + (dir_ / "clean.ply").string() + " --report " +
                          (dir_ / "report.json").string() + " --json-summary " + (dir_ / "summary.json").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const io::TriMesh out = io::ReadMesh(dir_ / "clean.ply");
  const clean::MeshStats s = clean::ComputeStats(out);
  EXPECT_EQ(s.components, 1u);
  EXPECT_TRUE(s.closed());
  EXPECT_EQ(out.velocities.size(), out.positions.size());
  // v = (1,0,0) + 2x on the ball: the transferred field stays close to it.
  for (std::size_t i = 0; i < out.positions.size(); i += 97)
    EXPECT_LT(Norm(out.velocities[i] - (Vec3f(1, 0, 0) + out.positions[i] * 2.0f)), 0.02f) << i;
  std::ifstream report(dir_ / "report.json");
  const nlohmann::json j = nlohmann::json::parse(report);
  ASSERT_EQ(j.size(), 1u);
  EXPECT_EQ(j[0]["before"]["components"], 2);
  EXPECT_EQ(j[0]["after"]["components"], 1);
  EXPECT_TRUE(j[0]["closed"].get<bool>());
  std::ifstream summary(dir_ / "summary.json");
  EXPECT_EQ(nlohmann::json::parse(summary)["frames"], 1);
}

TEST_F(CleanTool, SequenceToFolderWithFramesAndFormat) {
  fs::create_directories(dir_ / "in");
  for (int f = 1; f <= 3; ++f) io::WriteMesh(io::FramePath(dir_ / "in", "ice", f, "obj"), clean::procedural::NoisyBall(3000, f));
  ToolRun r = Clean((dir_ / "in").string() + " -o " + (dir_ / "out").string() + " --frames 2-3 -j 2 --format ply");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_FALSE(fs::exists(dir_ / "out" / "ice_clean.0001.ply"));
  EXPECT_TRUE(fs::exists(dir_ / "out" / "ice_clean.0002.ply"));
  EXPECT_TRUE(fs::exists(dir_ / "out" / "ice_clean.0003.ply"));
  EXPECT_FALSE(fs::exists(dir_ / "out" / "ice_clean.0003.obj"));  // --format ply
  EXPECT_TRUE(fs::exists(dir_ / "out" / "ice_clean.0003.json"));  // per-frame report
  EXPECT_GT(io::ReadMesh(dir_ / "out" / "ice_clean.0003.ply").triangle_count(), 0u);
  // The rime-bake call: one frame into a folder gives OBJ, PLY and the report.
  r = Clean((dir_ / "in" / "ice.0001.obj").string() + " -o " + (dir_ / "bake").string());
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* name : {"ice_clean.0001.obj", "ice_clean.0001.ply", "ice_clean.0001.json"})
    EXPECT_TRUE(fs::exists(dir_ / "bake" / name)) << name;
  // Several inputs and a file name: refused as a usage error.
  r = Clean((dir_ / "in").string() + " -o " + (dir_ / "x.obj").string());
  EXPECT_EQ(r.code, 2) << r.output;
}

TEST_F(CleanTool, SceneDefaultsAndFlagsOverride) {
  io::WriteMesh(dir_ / "ball.obj", clean::procedural::NoisyBall(6000, 2));
  std::ofstream(dir_ / "scene.toml") << "[clean]\ndecimate_ratio = 0.25\nsmooth = \"none\"\n";
  ToolRun r = Clean((dir_ / "ball.obj").string() + " -o " + (dir_ / "a.obj").string() + " --scene " + (dir_ / "scene.toml").string());
  ASSERT_EQ(r.code, 0) << r.output;
  r = Clean((dir_ / "ball.obj").string() + " -o " + (dir_ / "b.obj").string() + " --scene " + (dir_ / "scene.toml").string() +
            " --decimate-ratio 0.5");
  ASSERT_EQ(r.code, 0) << r.output;
  const double in = double(io::ReadMesh(dir_ / "ball.obj").triangle_count());
  EXPECT_NEAR(double(io::ReadMesh(dir_ / "a.obj").triangle_count()), 0.25 * in, 0.03 * in);
  EXPECT_NEAR(double(io::ReadMesh(dir_ / "b.obj").triangle_count()), 0.5 * in, 0.03 * in);
  std::ofstream(dir_ / "bad.toml") << "[clean]\ndecimate_ratio = 2\n";
  r = Clean((dir_ / "ball.obj").string() + " -o " + (dir_ / "c.obj").string() + " --scene " + (dir_ / "bad.toml").string());
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("bad.toml"), std::string::npos) << r.output;
}

// Bad input: a clear error naming the file, exit code 3, and no output.
TEST_F(CleanTool, BadInputsExitThreeWithoutOutput) {
  std::ofstream(dir_ / "empty.obj") << "# nothing\n";
  std::ofstream(dir_ / "nan.obj") << "v 0 0 0\nv 1 0 0\nv 0 nan 1\nf 1 2 3\n";
  std::ofstream(dir_ / "garbage.ply") << "not a mesh at all\n";
  std::ofstream(dir_ / "vertices_only.obj") << "v 0 0 0\nv 1 0 0\n";
  for (const char* name : {"empty.obj", "nan.obj", "garbage.ply", "missing.obj", "vertices_only.obj"}) {
    const fs::path out = dir_ / (std::string("out_") + name);
    const ToolRun r = Clean((dir_ / name).string() + " -o " + out.string());
    EXPECT_EQ(r.code, 3) << name << ": " << r.output;
    EXPECT_NE(r.output.find(name), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(out)) << name;
  }
  if (::geteuid() != 0) {  // root reads anything
    io::WriteMesh(dir_ / "locked.obj", clean::procedural::Icosphere(1, 1));
    fs::permissions(dir_ / "locked.obj", fs::perms::none);
    const ToolRun r = Clean((dir_ / "locked.obj").string() + " -o " + (dir_ / "out_locked.obj").string());
    EXPECT_EQ(r.code, 3) << r.output;
    EXPECT_NE(r.output.find("locked.obj"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(dir_ / "out_locked.obj"));
  }
}

}  // namespace
}  // namespace rime

namespace rime {
namespace {

TEST_F(CleanTool, RefusesAboveTheMemoryBudgetBeforeWritingAnyFrame) {
  // Frame 0 is a small icosphere and would fit; frame 1 (about 8k triangles, OBJ and PLY) does not.
  fs::create_directories(dir_ / "surface");
  io::WriteMesh(dir_ / "surface" / "ice.0000.ply", clean::procedural::Icosphere(0.1, 2, {0, 0, 0}));
  for (const char* ext : {"ply", "obj"}) {
    fs::remove_all(dir_ / "surface" / "ice.0001.ply");
    fs::remove_all(dir_ / "surface" / "ice.0001.obj");
    io::WriteMesh(dir_ / "surface" / (std::string("ice.0001.") + ext), NoisyBallWithSpeck());
    const ToolRun r = Clean((dir_ / "surface").string() + " -o " + (dir_ / "clean").string() + " -j 1 --memory-budget 1M");
    EXPECT_EQ(r.code, 10) << ext << ": " << r.output;
    const std::string expected =
        " triangles (mesh " + (dir_ / "surface" / (std::string("ice.0001.") + ext)).string() + "), budget 1 MiB (--memory-budget)";
    EXPECT_NE(r.output.find("rime-clean: error: needs about "), std::string::npos) << r.output;
    EXPECT_NE(r.output.find(expected), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(dir_ / "clean")) << ext;
  }
  // Under the default budget (the memory available) both frames are cleaned.
  const ToolRun fits = Clean((dir_ / "surface").string() + " -o " + (dir_ / "clean").string() + " -j 1");
  EXPECT_EQ(fits.code, 0) << fits.output;
  EXPECT_TRUE(fs::exists(dir_ / "clean" / "ice_clean.0001.ply"));
  EXPECT_TRUE(fs::exists(dir_ / "clean" / "ice_clean.0000.ply"));
}

TEST_F(CleanTool, SandboxRefusesASymlinkOutAndAnEscapingOutput) {
  fs::create_directories(dir_ / "box");
  fs::create_directories(dir_ / "outside");
  io::WriteMesh(dir_ / "outside" / "ice.0001.ply", clean::procedural::Icosphere(0.1, 2, {0, 0, 0}));
  fs::create_symlink(dir_ / "outside" / "ice.0001.ply", dir_ / "box" / "ice.0001.ply");
  const std::string box = (dir_ / "box").string();
  const ToolRun link = Clean(box + "/ice.0001.ply -o " + box + "/clean --sandbox " + box);
  EXPECT_EQ(link.code, 2) << link.output;
  EXPECT_NE(link.output.find("input " + box + "/ice.0001.ply resolves to " + (dir_ / "outside" / "ice.0001.ply").string() +
                             ", outside the sandbox"),
            std::string::npos)
      << link.output;
  fs::remove(dir_ / "box" / "ice.0001.ply");
  fs::copy_file(dir_ / "outside" / "ice.0001.ply", dir_ / "box" / "ice.0001.ply");
  const ToolRun escape = Clean(box + "/ice.0001.ply -o " + (dir_ / "outside" / "clean").string() + " --sandbox " + box);
  EXPECT_EQ(escape.code, 2) << escape.output;
  EXPECT_FALSE(fs::exists(dir_ / "outside" / "clean"));
  const ToolRun inside = Clean(box + "/ice.0001.ply -o " + box + "/clean --sandbox " + box);
  EXPECT_EQ(inside.code, 0) << inside.output;
  EXPECT_TRUE(fs::exists(dir_ / "box" / "clean" / "ice_clean.0001.ply"));
}

}  // namespace
}  // namespace rime
