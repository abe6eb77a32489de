#include "rime/core/sandbox.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>

#include "rime/test/temp_folder.h"

namespace fs = std::filesystem;

namespace rime {
namespace {

struct SandboxFolders : ::testing::Test {
  rime::test::TempFolder temp{"sandbox"};
  fs::path base = temp.path();
  fs::path root = base / "box";
  void SetUp() override {
    fs::create_directories(root / "meshes");
    fs::create_directories(base / "box-other");
    fs::create_directories(base / "outside");
  }
};

TEST_F(SandboxFolders, AcceptsPathsInsideIncludingOnesNotYetWritten) {
  const Sandbox box(root);
  EXPECT_TRUE(box.Contains(root));
  EXPECT_TRUE(box.Contains(root / "meshes"));
  EXPECT_TRUE(box.Contains(root / "out" / "cache" / "sim" / "particles.0000.h5part"));
  EXPECT_TRUE(box.Contains(root / "meshes" / ".." / "scene.toml"));
  EXPECT_NO_THROW(box.Require(root / "out", "-o", ExitCode::kUsage));
}

TEST_F(SandboxFolders, RefusesEscapesAbsolutePathsSiblingsAndSymlinksOut) {
  const Sandbox box(root);
  EXPECT_FALSE(box.Contains(root / ".." / "outside" / "x.obj"));
  EXPECT_FALSE(box.Contains(root / "meshes" / ".." / ".." / "outside"));
  EXPECT_FALSE(box.Contains("/etc/passwd"));
  EXPECT_FALSE(box.Contains(base / "box-other" / "x"));  // shares the root's name as a prefix only
  fs::create_directory_symlink(base / "outside", root / "link");
  EXPECT_FALSE(box.Contains(root / "link"));
  EXPECT_FALSE(box.Contains(root / "link" / "new_file.h5part"));
  try {
    box.Require(root / "link" / "a.obj", "scene.toml: solid.mesh", ExitCode::kBadInput);
    FAIL() << "not refused";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    const std::string what = e.what();
    EXPECT_NE(what.find("scene.toml: solid.mesh"), std::string::npos) << what;
    EXPECT_NE(what.find((base / "outside" / "a.obj").string()), std::string::npos) << what;
    EXPECT_NE(what.find("outside the sandbox"), std::string::npos) << what;
  }
}

TEST_F(SandboxFolders, SandboxItselfThroughASymlinkAndOff) {
  fs::create_directory_symlink(root, base / "box-link");
  const Sandbox via_link(base / "box-link");
  EXPECT_TRUE(via_link.Contains(root / "meshes"));
  EXPECT_FALSE(via_link.Contains(base / "outside"));
  EXPECT_THROW(Sandbox(base / "missing"), Error);
  EXPECT_TRUE(Sandbox().Contains("/etc/passwd"));
}

}  // namespace
}  // namespace rime
