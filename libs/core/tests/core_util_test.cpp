#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "rime/core/atomic_file.h"
#include "rime/core/error.h"
#include "rime/core/hash.h"
#include "rime/core/progress.h"

namespace fs = std::filesystem;

namespace rime {
namespace {

fs::path TempDir(const std::string& name) {
  fs::path dir = fs::temp_directory_path() / ("rime_core_" + name + "_" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

TEST(AtomicFile, NoFinalFileWithoutCommit) {
  const fs::path dir = TempDir("atomic");
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
  fs::remove_all(dir);
}

// A process killed while writing never leaves a file under its final name.
TEST(AtomicFile, KilledWriterLeavesNoFinalFile) {
  const fs::path dir = TempDir("killed");
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
  fs::remove_all(dir);
}

TEST(Hash, StableAndContentSensitive) {
  EXPECT_EQ(Hash64("abc"), Hash64("abc"));
  EXPECT_NE(Hash64("abc"), Hash64("abd"));
  EXPECT_EQ(HexHash(0xabcULL), "0000000000000abc");
  const fs::path dir = TempDir("hash");
  WriteFileAtomically(dir / "a", "hello");
  EXPECT_EQ(HashFile(dir / "a"), Hash64("hello"));
  EXPECT_THROW(HashFile(dir / "missing"), Error);
  fs::remove_all(dir);
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
