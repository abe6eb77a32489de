#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "rime/core/atomic_file.h"
#include "rime/core/error.h"
#include "rime/core/hash.h"
#include "rime/core/progress.h"
#include "rime/test/temp_folder.h"

namespace fs = std::filesystem;

namespace rime {
namespace {

TEST(AtomicFile, NoFinalFileWithoutCommit) {
  const rime::test::TempFolder dir("core_atomic");
  {
    AtomicFile f(dir / "out.txt");
    std::ofstream(f.temp_path()) << "partial";
  }
  EXPECT_FALSE(fs::exists(dir / "out.txt"));
  EXPECT_TRUE(fs::is_empty(dir)) << "temporary file left behind";
  WriteFileAtomically(dir / "out.txt", "done");
  std::ifstream in(dir / "out.txt");
  std::string s;
  in >> s;
  EXPECT_EQ(s, "done");
}

// A process killed while writing never leaves a file under its final name.
TEST(AtomicFile, KilledWriterLeavesNoFinalFile) {
  const rime::test::TempFolder dir("core_killed");
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    AtomicFile f(dir / "frame.dat");
    std::ofstream out(f.temp_path());
    for (;;) out << "data data data\n";  // killed mid-write
  }
  for (int i = 0; i < 200 && fs::is_empty(dir); ++i) usleep(5000);
  usleep(20000);
  kill(child, SIGKILL);
  int status = 0;
  waitpid(child, &status, 0);
  EXPECT_FALSE(fs::exists(dir / "frame.dat"));
}

TEST(Hash, StableAndContentSensitive) {
  EXPECT_EQ(Hash64("abc"), Hash64("abc"));
  EXPECT_NE(Hash64("abc"), Hash64("abd"));
  EXPECT_EQ(HexHash(0xabcULL), "0000000000000abc");
  const rime::test::TempFolder dir("core_hash");
  WriteFileAtomically(dir / "a", "hello");
  EXPECT_EQ(HashFile(dir / "a"), Hash64("hello"));
  EXPECT_THROW(HashFile(dir / "missing"), Error);
}

TEST(Error, MessageNamesWhere) {
  const Error e = InputError("negative radius", "scene.toml:12: fluid.spacing");
  EXPECT_EQ(std::string(e.what()), "negative radius (scene.toml:12: fluid.spacing)");
  EXPECT_EQ(e.code(), ExitCode::kBadInput);
}

TEST(Progress, FormatsDurations) {
  EXPECT_EQ(FormatDuration(0.045), "45ms");
  EXPECT_EQ(FormatDuration(12.34), "12.3s");
  EXPECT_EQ(FormatDuration(185), "3m05s");
  EXPECT_EQ(FormatDuration(3720), "1h02m");
}

}  // namespace
}  // namespace rime
