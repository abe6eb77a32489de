// Replays every committed fuzz input (tests/fuzz/regressions/<target>/, the crashes and hangs found
// and fixed, and tests/fuzz/corpus/<target>/, the seeds) through the fuzz targets' entry points:
// each must be read or refused with a rime::Error, in bounded time.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>

#include "entry_points.h"
#include "rime/core/atomic_file.h"
#include "rime/core/error.h"

namespace fs = std::filesystem;

namespace rime::fuzz {

// In Target's own namespace, where gtest's argument printing finds it.
void PrintTo(const Target& target, std::ostream* out) { *out << target.name; }

namespace {

void Replay(const Target& target, const std::string& kind) {
  const fs::path folder = fs::path(RIME_SOURCE_DIR) / "tests" / "fuzz" / kind / target.name;
  if (!fs::is_directory(folder)) return;
  std::size_t files = 0;
  for (const auto& entry : fs::directory_iterator(folder)) {
    if (!entry.is_regular_file() || entry.path().filename().string().starts_with(".")) continue;
    ++files;
    SCOPED_TRACE(entry.path().string());
    const std::string bytes = ReadFileOrEmpty(entry.path());
    const auto start = std::chrono::steady_clock::now();
    try {
      target.run(bytes);
    } catch (const Error&) {
      // refused cleanly
    } catch (const std::exception& e) {
      ADD_FAILURE() << "not a rime::Error: " << e.what();
    }
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 10.0);
  }
  if (kind == "corpus") {
    EXPECT_GT(files, 0u) << "no seeds in " << folder;
  }
}

class FuzzInputs : public ::testing::TestWithParam<Target> {};

TEST_P(FuzzInputs, RegressionsAreReadOrRefusedCleanly) { Replay(GetParam(), "regressions"); }
TEST_P(FuzzInputs, SeedsAreReadOrRefusedCleanly) { Replay(GetParam(), "corpus"); }

INSTANTIATE_TEST_SUITE_P(Targets, FuzzInputs, ::testing::ValuesIn(Targets()),
                         [](const ::testing::TestParamInfo<Target>& info) { return std::string(info.param.name); });

}  // namespace
}  // namespace rime::fuzz
