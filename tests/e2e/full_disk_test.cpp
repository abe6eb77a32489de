// A full disk, stage by stage, with the real stage tools: each stage in turn runs under a file
// size limit (ulimit -f: its writes fail with EFBIG), then the whole bake runs on a tmpfs too small
// for it (ENOSPC). Each time rime-bake exits 5 with one line naming the stage and the file,
// nothing already written is damaged, and the same command completes once there is room.
#include <gtest/gtest.h>
#include <sys/mount.h>
#include <sys/stat.h>

#include <cstdlib>
#include <filesystem>
#include <fmt/format.h>

#include "rime/test/bake_outputs.h"
#include "rime/test/small_bake_scene.h"
#include "rime/test/temp_folder.h"

namespace fs = std::filesystem;

namespace rime {
namespace {

constexpr int kLastFrame = 3;

// The lines of `output` that are error messages.
std::vector<std::string> ErrorLines(const std::string& output) {
  std::vector<std::string> lines;
  std::istringstream in(output);
  for (std::string line; std::getline(in, line);)
    if (line.find(": error: ") != std::string::npos) lines.push_back(line);
  return lines;
}

class FullDisk : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    temp_ = std::make_unique<rime::test::TempFolder>("full_disk");
    root_ = temp_->path();
    std::ofstream(root_ / "disk.toml") << test::SmallBakeScene("disk", kLastFrame);
    std::string output;
    ASSERT_EQ(test::Run(Args(root_ / "reference", RIME_BINARY_DIR "/bin"), root_ / "reference.txt", output), 0) << output;
    reference_ = test::Outputs(root_ / "reference");
  }
  static void TearDownTestSuite() { temp_.reset(); }
  static constexpr std::pair<const char*, const char*> kStages[] = {
      {"boundary", "rime-boundary"}, {"sim", "rime-sim"}, {"surface", "rime-surface"}, {"clean", "rime-clean"}};
  // Each stage tool behind a wrapper that applies RIME_TEST_FSIZE_<stage> (KiB) when set; the
  // wrappers do not change between runs, so neither do the jobs' keys.
  static fs::path LimitedTools() {
    const fs::path tools = root_ / "limited_tools";
    fs::create_directories(tools);
    for (const auto& [stage, tool] : kStages) {
      std::ofstream(tools / tool) << fmt::format(
          "#!/bin/bash\nlimit=${{RIME_TEST_FSIZE_{}:-unlimited}}\nulimit -f \"$limit\" || exit 1\nexec \"{}/bin/{}\" \"$@\"\n", stage,
          RIME_BINARY_DIR, tool);
      fs::permissions(tools / tool, fs::perms::owner_all | fs::perms::group_read | fs::perms::group_exec);
    }
    return tools;
  }
  static std::vector<std::string> Args(const fs::path& out, const fs::path& tools) {
    return {RIME_BINARY_DIR "/bin/rime-bake", (root_ / "disk.toml").string(), "clean", "-o", out.string(), "--tools", tools.string(), "-q"};
  }
  static void ExpectNothingDamaged(const fs::path& out, const std::string& when) {
    for (const std::string& problem : test::PartialFiles(out, reference_)) ADD_FAILURE() << when << ": " << problem;
  }
  static inline std::unique_ptr<rime::test::TempFolder> temp_;
  static inline fs::path root_;
  static inline std::map<std::string, std::string> reference_;
};

TEST_F(FullDisk, EachStageInTurnHitsAFileSizeLimit) {
  const fs::path tools = LimitedTools();
  const fs::path out = root_ / "limited";
  std::string output;
  for (const auto& [stage, tool] : kStages) {
    // KiB: more than any log a tool writes, less than the first output of every stage (the
    // surface's meshes: its VDB, written first, fits; see VdbWriteFailure below).
    setenv(fmt::format("RIME_TEST_FSIZE_{}", stage).c_str(), std::string(stage) == "surface" ? "128" : "16", 1);
    const int code = test::Run(Args(out, tools), root_ / "limited.txt", output);
    unsetenv(fmt::format("RIME_TEST_FSIZE_{}", stage).c_str());
    EXPECT_EQ(code, 5) << stage << ":\n" << output;
    const auto errors = ErrorLines(output);
    ASSERT_EQ(errors.size(), 1u) << stage << ": one error line expected:\n" << output;
    const std::string& error = errors.front();
    EXPECT_NE(error.find(fmt::format("stage {} failed", stage)), std::string::npos) << error;
    EXPECT_NE(error.find("File too large"), std::string::npos) << error;
    EXPECT_NE(error.find("(" + out.string() + "/"), std::string::npos) << "the message must name the file: " << error;
    std::printf("file size limit on %s: %s\n", stage, error.c_str());
    ExpectNothingDamaged(out, std::string("after the limit on ") + stage);
  }
  ASSERT_EQ(test::Run(Args(out, tools), root_ / "limited.txt", output), 0) << output;
  EXPECT_TRUE(test::Outputs(out) == reference_) << "outputs after the failed runs differ from an uninterrupted bake";
}

// Known bug, disabled until libs/surface checks its VDB stream: openvdb::io::File::write does
// not report a failed write, so a VDB cut short by a full disk is committed under its final name
// (rime-surface then fails on the mesh that follows, but the partial VDB stays).
TEST_F(FullDisk, VdbWriteFailureLeavesNoPartialVdb) {
  const fs::path tools = LimitedTools(), out = root_ / "vdb";
  std::string output;
  setenv("RIME_TEST_FSIZE_surface", "16", 1);
  const int code = test::Run(Args(out, tools), root_ / "vdb.txt", output);
  unsetenv("RIME_TEST_FSIZE_surface");
  EXPECT_EQ(code, 5) << output;
  EXPECT_NE(output.find("cannot write VDB file"), std::string::npos) << output;
  ExpectNothingDamaged(out, "after a VDB write failed");
}

// Bytes a file takes on tmpfs (whole pages).
std::uintmax_t Pages(std::uintmax_t bytes) { return (bytes + 4095) / 4096 * 4096; }

TEST_F(FullDisk, TooSmallFilesystemFailsCleanlyAndTheBakeFinishesOnceThereIsRoom) {
  const fs::path mount_point = root_ / "small";
  fs::create_directories(mount_point);
  if (mount("tmpfs", mount_point.c_str(), "tmpfs", 0, "size=64k") != 0)
    GTEST_SKIP() << "cannot mount a tmpfs here (" << std::strerror(errno)
                 << "; needs root or CAP_SYS_ADMIN): the file size limit test covers "
                 << "each stage's write failures";
  struct Unmount {
    fs::path at;
    ~Unmount() { umount2(at.c_str(), MNT_DETACH); }
  } unmount{mount_point};

  // Filesystem sizes from a quarter of what the finished bake needs to all of it, so that the
  // bake runs out of room in a different stage each time.
  std::uintmax_t needed = 0;
  for (const auto& entry : fs::recursive_directory_iterator(root_ / "reference"))
    if (entry.is_regular_file()) needed += Pages(entry.file_size());
  const fs::path out = mount_point / "out";
  std::string output;
  std::set<std::string> stages_hit;
  for (const double share : {0.05, 0.3, 0.6, 0.9}) {
    const std::string options = fmt::format("size={}", Pages(static_cast<std::uintmax_t>(share * needed)));
    ASSERT_EQ(mount("tmpfs", mount_point.c_str(), "tmpfs", MS_REMOUNT, options.c_str()), 0) << std::strerror(errno);
    const int code = test::Run(Args(out, RIME_BINARY_DIR "/bin"), root_ / "small.txt", output);
    if (code == 0) break;  // enough room already
    EXPECT_EQ(code, 5) << options << ":\n" << output;
    const auto errors = ErrorLines(output);
    ASSERT_EQ(errors.size(), 1u) << options << ": one error line expected:\n" << output;
    EXPECT_NE(errors.front().find("No space left on device"), std::string::npos) << errors.front();
    EXPECT_NE(errors.front().find(mount_point.string() + "/"), std::string::npos) << "the message must name the file: " << errors.front();
    for (const char* stage : {"boundary", "sim", "surface", "clean"})
      if (errors.front().find(fmt::format("stage {} ", stage)) != std::string::npos) stages_hit.insert(stage);
    std::printf("tmpfs %s (%.0f%% of the bake): %s\n", options.c_str(), 100 * share, errors.front().c_str());
    ExpectNothingDamaged(out, options);
  }
  ASSERT_EQ(mount("tmpfs", mount_point.c_str(), "tmpfs", MS_REMOUNT, fmt::format("size={}", 4 * needed + (16 << 20)).c_str()), 0);
  ASSERT_EQ(test::Run(Args(out, RIME_BINARY_DIR "/bin"), root_ / "small.txt", output), 0) << output;
  EXPECT_TRUE(test::Outputs(out) == reference_) << "outputs after running out of room differ from an uninterrupted bake";
  EXPECT_GE(stages_hit.size(), 2u) << "the filesystem filled up in fewer stages than expected";
}

}  // namespace
}  // namespace rime
