// rime-surface command line: outputs per frame and phase, bad input, nothing half-written.
#include <gtest/gtest.h>
#include <unistd.h>
#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "rime/io/mesh.h"
#include "rime/io/particles.h"
#include "rime/test/files.h"
#include "rime/test/run_command.h"
#include "rime/test/sanitizers.h"
#include "rime/test/temp_folder.h"

namespace {

namespace fs = std::filesystem;
const std::string kTool = std::string(RIME_BINARY_DIR) + "/bin/rime-surface";

using RunResult = rime::test::CommandResult;

RunResult Execute(const std::string& args) { return rime::test::RunCommand(kTool + " " + args); }

// A ball of ice (with stored isotropic anisotropy unless `anisotropy` is false) and a ball of water.
rime::io::ParticleFrame MakeFrame(std::int64_t number, bool ice, bool anisotropy = true) {
  rime::io::ParticleFrame frame;
  frame.spacing = 0.02;
  frame.frame = number;
  std::vector<rime::Vec3f> positions;
  std::vector<std::uint8_t> phase;
  for (int i = -4; i <= 4; ++i)
    for (int j = -4; j <= 4; ++j)
      for (int k = -4; k <= 4; ++k) {
        if (i * i + j * j + k * k > 16) continue;
        if (ice) positions.push_back(rime::Vec3f(i, j, k) * 0.02f), phase.push_back(2);
        positions.push_back(rime::Vec3f(i + 20, j, k) * 0.02f), phase.push_back(0);
      }
  const std::size_t n = positions.size();
  frame.SetPositions(positions);
  frame.Set("vx", std::vector<float>(n, 0.5f));
  frame.Set("vy", std::vector<float>(n, 0.0f));
  frame.Set("vz", std::vector<float>(n, 0.0f));
  frame.Set("phase", phase);
  std::vector<std::int64_t> id(n);
  for (std::size_t i = 0; i < n; ++i) id[i] = std::int64_t(i);
  frame.Set("id", id);
  if (anisotropy)
    for (int c = 0; c < 6; ++c) frame.Set("anisotropy_" + std::to_string(c), std::vector<float>(n, c < 3 ? 1.0f : 0.0f));
  return frame;
}

class Cli : public ::testing::Test {
 protected:
  void SetUp() override { fs::create_directories(dir_ / "sim"); }
  fs::path Frame(std::int64_t n) const { return rime::io::FramePath(dir_ / "sim", "particles", n, "h5part"); }
  std::string Sim() const { return (dir_ / "sim").string(); }
  std::string Out() const { return (dir_ / "out").string(); }
  std::size_t OutputFiles() const {
    if (!fs::exists(dir_ / "out")) return 0;
    return std::size_t(std::distance(fs::directory_iterator(dir_ / "out"), fs::directory_iterator()));
  }
  rime::test::TempFolder temp_{"surface_cli"};
  fs::path dir_ = temp_.path();
};

TEST_F(Cli, WritesEveryFormatForBothPhases) {
  for (int f : {1, 2}) rime::io::WriteParticleFrame(Frame(f), MakeFrame(f, true));
  const std::string json = (dir_ / "summary.json").string();
  const RunResult run = Execute(Sim() + " -o " + Out() + " --phase both --format obj,ply,vdb --vel --density --json-summary " + json);
  ASSERT_EQ(run.code, 0) << run.output;
  for (const char* prefix : {"ice", "water"})
    for (int f : {1, 2})
      for (const char* ext : {"vdb", "obj", "ply"})
        EXPECT_TRUE(fs::exists(rime::io::FramePath(Out(), prefix, f, ext))) << prefix << f << ext;
  const rime::io::TriMesh ply = rime::io::ReadMesh(rime::io::FramePath(Out(), "water", 2, "ply"));
  ASSERT_FALSE(ply.empty());
  ASSERT_EQ(ply.velocities.size(), ply.positions.size());
  EXPECT_NEAR(ply.velocities[0].x, 0.5f, 1e-5f);
  const rime::io::TriMesh obj = rime::io::ReadMesh(rime::io::FramePath(Out(), "ice", 1, "obj"));
  EXPECT_EQ(obj.normals.size(), obj.positions.size());
  EXPECT_TRUE(fs::exists(json));
  EXPECT_NE(run.output.find("particles read"), std::string::npos) << run.output;
}

TEST_F(Cli, SceneSectionGivesDefaultsAndFlagsOverride) {
  rime::io::WriteParticleFrame(Frame(3), MakeFrame(3, true));
  const fs::path scene = dir_ / "scene.toml";
  std::ofstream(scene) << "[surface]\nphase = \"water\"\nformats = [\"ply\"]\n";
  const RunResult run = Execute(Frame(3).string() + " -o " + Out() + " --scene " + scene.string());
  ASSERT_EQ(run.code, 0) << run.output;
  EXPECT_TRUE(fs::exists(rime::io::FramePath(Out(), "water", 3, "ply")));
  EXPECT_FALSE(fs::exists(rime::io::FramePath(Out(), "ice", 3, "ply")));
  EXPECT_FALSE(fs::exists(rime::io::FramePath(Out(), "water", 3, "obj")));
  const RunResult flags = Execute(Frame(3).string() + " -o " + Out() + " --scene " + scene.string() + " --phase ice --format obj");
  ASSERT_EQ(flags.code, 0) << flags.output;
  EXPECT_TRUE(fs::exists(rime::io::FramePath(Out(), "ice", 3, "obj")));
}

TEST_F(Cli, MissingFramesInARangeFailBeforeWriting) {
  for (int f : {1, 2, 4}) rime::io::WriteParticleFrame(Frame(f), MakeFrame(f, true));
  const RunResult run = Execute(Sim() + " -o " + Out() + " --frames 1-4");
  EXPECT_EQ(run.code, 3) << run.output;
  EXPECT_NE(run.output.find("missing frame 3"), std::string::npos) << run.output;
  EXPECT_EQ(OutputFiles(), 0u);
  const RunResult ok = Execute(Sim() + " -o " + Out() + " --frames 1-2");
  EXPECT_EQ(ok.code, 0) << ok.output;
  EXPECT_FALSE(fs::exists(rime::io::FramePath(Out(), "ice", 4, "obj")));
}

TEST_F(Cli, FrameWithoutIceGivesEmptyValidOutputsAndAWarning) {
  rime::io::WriteParticleFrame(Frame(5), MakeFrame(5, false));
  const RunResult run = Execute(Frame(5).string() + " -o " + Out());
  ASSERT_EQ(run.code, 0) << run.output;
  EXPECT_NE(run.output.find("no ice particles"), std::string::npos) << run.output;
  EXPECT_TRUE(fs::exists(rime::io::FramePath(Out(), "ice", 5, "vdb")));
  EXPECT_TRUE(rime::io::ReadMesh(rime::io::FramePath(Out(), "ice", 5, "obj")).empty());
}

TEST_F(Cli, MissingAnisotropyFallsBackOrFailsUnderStrict) {
  rime::io::WriteParticleFrame(Frame(1), MakeFrame(1, true, false));
  const RunResult strict = Execute(Frame(1).string() + " -o " + Out() + " --strict");
  EXPECT_EQ(strict.code, 3) << strict.output;
  EXPECT_NE(strict.output.find("anisotropy"), std::string::npos) << strict.output;
  EXPECT_EQ(OutputFiles(), 0u);
  const RunResult lenient = Execute(Frame(1).string() + " -o " + Out());
  EXPECT_EQ(lenient.code, 0) << lenient.output;
  EXPECT_NE(lenient.output.find("isotropic"), std::string::npos) << lenient.output;
}

// A 24 x 24 x 24 block of ice: 13,824 particles, several MB to surface.
rime::io::ParticleFrame MakeBlock(std::int64_t number) {
  rime::io::ParticleFrame frame;
  frame.spacing = 0.02;
  frame.frame = number;
  std::vector<rime::Vec3f> positions;
  for (int i = 0; i < 24; ++i)
    for (int j = 0; j < 24; ++j)
      for (int k = 0; k < 24; ++k) positions.push_back(rime::Vec3f(i, j, k) * 0.02f);
  frame.SetPositions(positions);
  frame.Set("phase", std::vector<std::uint8_t>(positions.size(), 2));
  for (int c = 0; c < 6; ++c) frame.Set("anisotropy_" + std::to_string(c), std::vector<float>(positions.size(), c < 3 ? 1.0f : 0.0f));
  return frame;
}

TEST_F(Cli, RefusesAboveTheMemoryBudgetBeforeWritingAnyFrame) {
  // Frame 0 is small and would fit; frame 1 is not: neither is written.
  rime::io::WriteParticleFrame(Frame(0), MakeFrame(0, true));
  rime::io::WriteParticleFrame(Frame(1), MakeBlock(1));
  const RunResult refused = Execute(Sim() + " -o " + Out() + " -j 1 --phase ice --memory-budget 1M");
  EXPECT_EQ(refused.code, 10) << refused.output;
  EXPECT_NE(refused.output.find("rime-surface: error: needs about "), std::string::npos) << refused.output;
  EXPECT_NE(refused.output.find(" voxels (frame " + Frame(1).string() + ", voxel 10 mm), budget 1 MiB (--memory-budget)"),
            std::string::npos)
      << refused.output;
  EXPECT_EQ(std::count(refused.output.begin(), refused.output.end(), '\n'), 1) << refused.output;
  EXPECT_FALSE(fs::exists(dir_ / "out"));
  // The same frames under the default budget (the memory available) are surfaced.
  const RunResult fits = Execute(Sim() + " -o " + Out() + " -j 1 --phase ice --format obj");
  EXPECT_EQ(fits.code, 0) << fits.output;
  EXPECT_EQ(OutputFiles(), 2u);
}

// Bytes from "needs about 12.3 MiB" (rime/core/memory_budget.h FormatBytes); 0 when absent.
double NeededBytes(const std::string& refusal) {
  const auto at = refusal.find("needs about ");
  if (at == std::string::npos) return 0;
  std::istringstream in(refusal.substr(at + 12));
  double value = 0;
  std::string unit;
  in >> value >> unit;
  const std::vector<std::string> units = {"B", "KiB", "MiB", "GiB", "TiB"};
  const auto u = std::find(units.begin(), units.end(), unit);
  return u == units.end() ? 0 : value * std::pow(1024.0, double(u - units.begin()));
}

// The estimate must stay above the measured peak where it is loosest: water's kernel sum at a
// fine voxel, whose interior leaves (most of them) carry no mesh. A pool of 48 x 48 x 24 water
// particles at d_p 20 mm, voxel 5 mm; every format and grid, so that all of them count.
TEST_F(Cli, MemoryEstimateBoundsThePeakOfWaterAtAFineVoxel) {
  if (rime::test::kAddressSanitizer) GTEST_SKIP() << rime::test::kMemorySkipReason;
  rime::io::ParticleFrame frame;
  frame.spacing = 0.02;
  frame.frame = 1;
  std::vector<rime::Vec3f> positions;
  for (int i = 0; i < 48; ++i)
    for (int j = 0; j < 48; ++j)
      for (int k = 0; k < 24; ++k) positions.push_back(rime::Vec3f(i, j, k) * 0.02f);
  const std::size_t n = positions.size();
  frame.SetPositions(positions);
  frame.Set("vx", std::vector<float>(n, 0.5f));
  frame.Set("vy", std::vector<float>(n, 0.0f));
  frame.Set("vz", std::vector<float>(n, 0.0f));
  frame.Set("phase", std::vector<std::uint8_t>(n, 0));
  rime::io::WriteParticleFrame(Frame(1), frame);
  const std::string args =
      Frame(1).string() + " -o " + Out() + " -j 1 --phase water --field kernel_sum --voxel-size 0.005 --format obj,ply,vdb --vel --density";
  const RunResult refused = Execute(args + " --memory-budget 1");
  ASSERT_EQ(refused.code, 10) << refused.output;
  const double estimate = NeededBytes(refused.output);
  ASSERT_GT(estimate, 0) << refused.output;
  const RunResult ran = Execute(args + " --json-summary " + (dir_ / "summary.json").string());
  ASSERT_EQ(ran.code, 0) << ran.output;
  const std::string summary = rime::test::ReadFile(dir_ / "summary.json");
  const auto key = summary.find("\"peak_memory_bytes\":");
  ASSERT_NE(key, std::string::npos) << summary;
  const double peak = std::stod(summary.substr(key + 20));
  std::printf("water pool, %zu particles at voxel d_p/4: estimate %.1f MiB, measured peak %.1f MiB (estimate / peak %.2f)\n", n,
              estimate / 1048576, peak / 1048576, estimate / peak);
  EXPECT_GT(estimate, peak);
}

// On a small frame the process's own memory decides the peak: a ball of about 3,300 water
// particles (the default example's count) at its default settings, two threads.
TEST_F(Cli, MemoryEstimateBoundsThePeakOfASmallFrame) {
  if (rime::test::kAddressSanitizer) GTEST_SKIP() << rime::test::kMemorySkipReason;
  rime::io::ParticleFrame frame;
  frame.spacing = 0.02;
  frame.frame = 1;
  std::vector<rime::Vec3f> positions;
  for (int i = -9; i <= 9; ++i)
    for (int j = -9; j <= 9; ++j)
      for (int k = -9; k <= 9; ++k)
        if (i * i + j * j + k * k <= 85) positions.push_back(rime::Vec3f(i, j, k) * 0.02f);
  const std::size_t n = positions.size();
  frame.SetPositions(positions);
  for (const char* v : {"vx", "vy", "vz"}) frame.Set(v, std::vector<float>(n, 0.0f));
  frame.Set("phase", std::vector<std::uint8_t>(n, 0));
  rime::io::WriteParticleFrame(Frame(1), frame);
  const std::string args = Frame(1).string() + " -o " + Out() + " -j 2 --phase water";
  const RunResult refused = Execute(args + " --memory-budget 1");
  ASSERT_EQ(refused.code, 10) << refused.output;
  const double estimate = NeededBytes(refused.output);
  ASSERT_GT(estimate, 0) << refused.output;
  const RunResult ran = Execute(args + " --json-summary " + (dir_ / "summary.json").string());
  ASSERT_EQ(ran.code, 0) << ran.output;
  const std::string summary = rime::test::ReadFile(dir_ / "summary.json");
  const auto key = summary.find("\"peak_memory_bytes\":");
  ASSERT_NE(key, std::string::npos) << summary;
  const double peak = std::stod(summary.substr(key + 20));
  std::printf("water ball, %zu particles: estimate %.1f MiB, measured peak %.1f MiB (estimate / peak %.2f)\n", n, estimate / 1048576,
              peak / 1048576, estimate / peak);
  EXPECT_GT(estimate, peak);
}

TEST_F(Cli, RefusesMalformedMemoryBudgetAndPathsOutsideTheSandbox) {
  rime::io::WriteParticleFrame(Frame(1), MakeFrame(1, true));
  const RunResult bad = Execute(Frame(1).string() + " -o " + Out() + " --memory-budget 4X");
  EXPECT_EQ(bad.code, 2) << bad.output;
  EXPECT_NE(bad.output.find("--memory-budget 4X"), std::string::npos) << bad.output;
  // The sandbox is the frames' folder: an output beside it escapes through "..".
  const RunResult escape = Execute(Frame(1).string() + " -o " + Sim() + "/../out --sandbox " + Sim());
  EXPECT_EQ(escape.code, 2) << escape.output;
  EXPECT_NE(escape.output.find("-o " + Sim() + "/../out resolves to " + Out() + ", outside the sandbox"), std::string::npos)
      << escape.output;
  EXPECT_FALSE(fs::exists(dir_ / "out"));
  const RunResult inside = Execute(Frame(1).string() + " -o " + Sim() + "/out --format obj --sandbox " + Sim());
  EXPECT_EQ(inside.code, 0) << inside.output;
}

TEST_F(Cli, RefusesNewerFormatVersion) {
  rime::io::WriteParticleFrame(Frame(1), MakeFrame(1, true));
  // Pretend a newer Rime wrote the frame.
  const hid_t file = H5Fopen(Frame(1).c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  const hid_t attr = H5Aopen(file, "version", H5P_DEFAULT);
  ASSERT_GE(attr, 0);
  const double version = 99;
  H5Awrite(attr, H5T_NATIVE_DOUBLE, &version);
  H5Aclose(attr);
  H5Fclose(file);
  rime::io::WriteParticleFrame(Frame(0), MakeFrame(0, true));  // a good frame beside it is not written either
  const RunResult newer = Execute(Sim() + " -o " + Out());
  EXPECT_EQ(newer.code, 3) << newer.output;
  EXPECT_NE(newer.output.find("newer"), std::string::npos) << newer.output;
  EXPECT_EQ(OutputFiles(), 0u);
  const RunResult missing = Execute((dir_ / "nope.0001.h5part").string() + " -o " + Out());
  EXPECT_EQ(missing.code, 3) << missing.output;
}

}  // namespace
