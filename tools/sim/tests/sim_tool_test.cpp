// rime-sim as a user runs it: exit codes, messages, valid frames after a failure, resume.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

#include "rime/io/particles.h"
#include "rime/test/bake_outputs.h"
#include "rime/test/files.h"
#include "rime/test/run_command.h"
#include "rime/test/sanitizers.h"
#include "rime/test/temp_folder.h"

namespace fs = std::filesystem;

namespace {

const fs::path kBin = fs::path(RIME_BINARY_DIR) / "bin";

using Result = rime::test::CommandResult;

Result Exec(const std::string& command) { return rime::test::RunCommand(command); }

class SimTool : public ::testing::Test {
 protected:
  fs::path WriteScene(const std::string& simulation_extra, double end_time = 0.2, double fps = 30) {
    const fs::path scene = dir_ / "scene.toml";
    std::ofstream(scene)
        << "[scene]\nfps = " << fps << "\nend_time = " << end_time << "\n"
        << "[water]\nspacing = 0.04\n"
        << "[sim]\nmodules = [\"gravity\", \"viscosity\", \"freezing\"]\n"
        << simulation_extra << "\n"
        << "[freezing]\nglaze_threshold = 0.01\nicicle_threshold = 0.002\n"
        << "[[solid]]\nname = \"tank\"\nshape = \"box\"\ncontainer = true\nsize = [0.6, 0.6, 0.4]\ntranslate = [0, 0, 0.2]\n"
        << "[[water_block]]\nmin = [-0.15, -0.15, 0.15]\nmax = [0.1, 0.1, 0.3]\nvelocity = [0.5, 0, -1]\n";
    return scene;
  }
  void MakeBoundary(const fs::path& scene) {
    const Result r = Exec((kBin / "rime-boundary").string() + " " + scene.string() + " -o " + (dir_ / "boundary").string() + " -q");
    ASSERT_EQ(r.code, 0) << r.output;
  }
  std::string Sim(const fs::path& scene, const std::string& out, const std::string& extra = "") {
    return (kBin / "rime-sim").string() + " " + scene.string() + " --boundary " + (dir_ / "boundary").string() + " -o " +
           (dir_ / out).string() + " -q " + extra;
  }
  void ExpectEstimateBoundsThePeak(const fs::path& scene);
  rime::test::TempFolder temp_{"sim_tool"};
  fs::path dir_ = temp_.path();
};

TEST_F(SimTool, MissingBoundaryFileIsABadInput) {
  const fs::path scene = WriteScene("");
  const Result r = Exec(Sim(scene, "sim"));
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("tank.h5part"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("rime-boundary"), std::string::npos) << "the message says what to run: " << r.output;
}

TEST_F(SimTool, InvalidSceneValueNamesFileLineAndField) {
  const fs::path scene = WriteScene("omega = 1.5");
  const Result r = Exec(Sim(scene, "sim"));
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("scene.toml:8: sim.omega"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir_ / "sim" / "particles.0000.h5part"));
}

TEST_F(SimTool, DivergenceStopsWithAClearMessageAndKeepsEarlierFrames) {
  const fs::path scene = WriteScene("time_step = \"fixed\"\ndt = 0.5\nmax_iterations = 10", 3.0, 2);
  MakeBoundary(scene);
  const Result r = Exec(Sim(scene, "sim"));
  EXPECT_EQ(r.code, 4) << r.output;
  EXPECT_NE(r.output.find("diverged"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("frame "), std::string::npos) << r.output;
  // Every frame on disk is complete and readable; no temporary file is left.
  int frames = 0;
  for (const auto& entry : fs::directory_iterator(dir_ / "sim")) {
    EXPECT_EQ(entry.path().string().find(".tmp."), std::string::npos) << entry.path();
    if (entry.path().extension() == ".h5part" && entry.path().filename() != "particles.h5part") {
      EXPECT_NO_THROW(rime::io::ReadParticleFrame(entry.path(), "particles"));
      ++frames;
    }
  }
  EXPECT_GE(frames, 1);
}

// Frames are written in the background while the next frame simulates: a write that fails (here a
// directory stands where frame 2 must go; disk full behaves alike) still stops the run with the
// file named and an I/O exit code, and the frames before it are complete.
TEST_F(SimTool, FailedBackgroundFrameWriteStopsTheRunWithTheFileNamed) {
  const fs::path scene = WriteScene("", 0.2, 30);
  MakeBoundary(scene);
  fs::create_directories(dir_ / "sim" / "particles.0002.h5part" / "occupied");
  const Result r = Exec(Sim(scene, "sim"));
  EXPECT_EQ(r.code, 5) << r.output;
  EXPECT_NE(r.output.find("particles.0002.h5part"), std::string::npos) << r.output;
  EXPECT_NO_THROW(rime::io::ReadParticleFrame(dir_ / "sim" / "particles.0001.h5part", "particles"));
  EXPECT_FALSE(fs::exists(dir_ / "sim" / "particles.0006.h5part")) << "the run went on after the failed write";
}

TEST_F(SimTool, ResumeReproducesTheUninterruptedFrames) {
  const fs::path scene = WriteScene("");
  MakeBoundary(scene);
  ASSERT_EQ(Exec(Sim(scene, "full", "-j 2")).code, 0);
  // Interrupted run: stop after frame 1, then resume to the end.
  ASSERT_EQ(Exec(Sim(scene, "resumed", "-j 2 --end-time 0.1")).code, 0);
  ASSERT_TRUE(fs::exists(dir_ / "resumed" / "particles.0003.h5part"));
  ASSERT_FALSE(fs::exists(dir_ / "resumed" / "particles.0004.h5part"));
  const Result r = Exec(Sim(scene, "resumed", "-j 2 --resume"));
  ASSERT_EQ(r.code, 0) << r.output;
  const auto a = rime::io::ReadParticleFrame(dir_ / "full" / "particles.0006.h5part");
  const auto b = rime::io::ReadParticleFrame(dir_ / "resumed" / "particles.0006.h5part");
  EXPECT_EQ(a.time, b.time);
  ASSERT_EQ(a.attributes.size(), b.attributes.size());
  for (const auto& [name, data] : a.attributes) EXPECT_TRUE(b.attributes.at(name) == data) << name << " differs after resume";
  EXPECT_GT(a.numbers.at("ice_particles"), 0) << "the scene must exercise freezing so that its state is part of the check";
}

// A kill can land after a frame's stats line is written and before the frame itself: the resume
// starts from the last frame on disk, drops the newer line and writes it again, so the log keeps
// exactly one line per frame, equal to an uninterrupted run's.
TEST_F(SimTool, ResumeAfterAKillBeforeTheFrameKeepsOneStatsLinePerFrame) {
  const fs::path scene = WriteScene("");
  MakeBoundary(scene);
  ASSERT_EQ(Exec(Sim(scene, "full", "-j 2")).code, 0);
  ASSERT_EQ(Exec(Sim(scene, "resumed", "-j 2 --end-time 0.1")).code, 0);
  ASSERT_TRUE(fs::remove(dir_ / "resumed" / "particles.0003.h5part"));
  const Result r = Exec(Sim(scene, "resumed", "-j 2 --resume"));
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string full = rime::test::ComparableBytes(dir_ / "full" / "stats.jsonl", dir_ / "full");
  EXPECT_EQ(std::count(full.begin(), full.end(), '\n'), 6) << full;
  EXPECT_EQ(rime::test::ComparableBytes(dir_ / "resumed" / "stats.jsonl", dir_ / "resumed"), full);
}

TEST_F(SimTool, CudaWithoutGpuIsRefused) {
  const Result probe = Exec("nvidia-smi -L");
  if (probe.code == 0) GTEST_SKIP() << "a GPU is present: the refusal path cannot be exercised here";
  const fs::path scene = WriteScene("");
  MakeBoundary(scene);
  const Result r = Exec(Sim(scene, "sim", "--device cuda"));
  EXPECT_EQ(r.code, 6) << r.output;
  EXPECT_NE(r.output.find("--device cuda"), std::string::npos) << r.output;
  const Result fallback = Exec(Sim(scene, "auto", "--device auto --end-time 0.034"));
  EXPECT_EQ(fallback.code, 0) << fallback.output;
}

// ParaView 5.11's H5Part reader opens a frame on its own and the index as a timed sequence.
TEST_F(SimTool, ParaViewOpensFramesAndTheSequence) {
  if (Exec("command -v pvpython").code != 0)
    GTEST_SKIP() << "pvpython not installed (Debian packages paraview + python3-paraview): not checked";
  const fs::path scene = WriteScene("", 0.1);
  MakeBoundary(scene);
  ASSERT_EQ(Exec(Sim(scene, "sim")).code, 0);
  const fs::path script = dir_ / "check.py";
  std::ofstream(script) << "from paraview.simple import *\n"
                        << "r = H5PartReader(FileName='" << (dir_ / "sim" / "particles.0002.h5part").string() << "')\n"
                        << "r.UpdatePipeline()\n"
                        << "print('points', r.GetDataInformation().GetNumberOfPoints())\n"
                        << "print('arrays', sorted(r.PointData.keys()))\n"
                        << "s = H5PartReader(FileName='" << (dir_ / "sim" / "particles.h5part").string() << "')\n"
                        << "s.UpdatePipelineInformation()\n"
                        << "print('times', ' '.join('%.6f' % t for t in s.TimestepValues))\n";
  const Result r = Exec("timeout 120 pvpython " + script.string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto frame = rime::io::ReadParticleFrame(dir_ / "sim" / "particles.0002.h5part");
  EXPECT_NE(r.output.find("points " + std::to_string(frame.size())), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("'phase'"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("'pressure'"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("times 0.000000 0.033333 0.066667 0.100000"), std::string::npos) << r.output;
}

}  // namespace

namespace {

TEST_F(SimTool, RefusesAboveTheMemoryBudgetBeforeWritingAFrame) {
  fs::path scene = WriteScene("");
  {
    // The same scene at a 1 cm spacing: about 10.8 k water and 53 k boundary particles.
    std::string text = rime::test::ReadFile(scene);
    text.replace(text.find("spacing = 0.04"), 14, "spacing = 0.01");
    rime::test::WriteFile(scene, text);
  }
  MakeBoundary(scene);
  const Result r = Exec(Sim(scene, "sim", "--memory-budget 1M"));
  EXPECT_EQ(r.code, 10) << r.output;
  EXPECT_NE(r.output.find("rime-sim: error: needs about "), std::string::npos) << r.output;
  // 0.25 x 0.25 x 0.15 m of water on a 1 cm lattice, its far faces included: 26 x 26 x 16 points.
  EXPECT_NE(r.output.find(" for 10.8 k water"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(" k water and "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(" boundary particles (scene " + scene.string() + ", spacing 10 mm), budget 1 MiB (--memory-budget)"),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(dir_ / "sim"));
}

// The estimate must bound the measured peak where the process's own memory weighs most: a small
// dense scene (about 10.8 k water and 53 k boundary particles at 1 cm), freezing on, two threads.
// The estimate from the refusal at a 1-byte budget, then the peak of the whole run.
void SimTool::ExpectEstimateBoundsThePeak(const fs::path& scene) {
  MakeBoundary(scene);
  const Result refused = Exec(Sim(scene, "refused", "-j 2 --memory-budget 1"));
  ASSERT_EQ(refused.code, 10) << refused.output;
  const auto at = refused.output.find("needs about ");
  ASSERT_NE(at, std::string::npos) << refused.output;
  const double estimate_mib = std::stod(refused.output.substr(at + 12));
  ASSERT_NE(refused.output.find(" MiB for "), std::string::npos) << refused.output;
  const Result ran = Exec(Sim(scene, "sim", "-j 2 --json-summary " + (dir_ / "summary.json").string()));
  ASSERT_EQ(ran.code, 0) << ran.output;
  const std::string summary = rime::test::ReadFile(dir_ / "summary.json");
  const auto key = summary.find("\"peak_memory_bytes\":");
  ASSERT_NE(key, std::string::npos) << summary;
  const double peak_mib = std::stod(summary.substr(key + 20)) / 1048576;
  std::printf("estimate %.1f MiB, measured peak %.1f MiB (measured / estimated %.2f)\n", estimate_mib, peak_mib, peak_mib / estimate_mib);
  EXPECT_GT(estimate_mib, peak_mib);
}

TEST_F(SimTool, MemoryEstimateBoundsThePeakOfASmallScene) {
  if (rime::test::kAddressSanitizer) GTEST_SKIP() << rime::test::kMemorySkipReason;
  fs::path scene = WriteScene("", 0.004, 500);
  std::string text = rime::test::ReadFile(scene);
  text.replace(text.find("spacing = 0.04"), 14, "spacing = 0.01");
  rime::test::WriteFile(scene, text);
  ExpectEstimateBoundsThePeak(scene);
}

// Emitted water, and a film that wets nearly the whole boundary, so freezing keeps a film row for
// most boundary particles by the end.
TEST_F(SimTool, MemoryEstimateBoundsThePeakOfTheDefaultExample) {
  if (rime::test::kAddressSanitizer) GTEST_SKIP() << rime::test::kMemorySkipReason;
  ExpectEstimateBoundsThePeak(RIME_SOURCE_DIR "/examples/default.toml");
}

TEST_F(SimTool, SandboxRefusesBoundaryAndOutputOutsideIt) {
  const fs::path scene = WriteScene("");
  MakeBoundary(scene);
  fs::create_directories(dir_ / "box");
  fs::copy_file(scene, dir_ / "box" / "scene.toml");
  const std::string box = (dir_ / "box").string();
  // The boundary files are outside the sandbox.
  const Result boundary = Exec(Sim(dir_ / "box" / "scene.toml", "box/sim", "--sandbox " + box));
  EXPECT_EQ(boundary.code, 2) << boundary.output;
  EXPECT_NE(boundary.output.find("--boundary " + (dir_ / "boundary").string()), std::string::npos) << boundary.output;
  EXPECT_NE(boundary.output.find("outside the sandbox"), std::string::npos) << boundary.output;
  EXPECT_FALSE(fs::exists(dir_ / "box" / "sim"));
  const Result output = Exec(Sim(dir_ / "box" / "scene.toml", "sim", "--sandbox " + box));
  EXPECT_EQ(output.code, 2) << output.output;
  EXPECT_FALSE(fs::exists(dir_ / "sim"));
}

}  // namespace
