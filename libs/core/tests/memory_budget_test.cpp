#include "rime/core/memory_budget.h"

#include <gtest/gtest.h>

#include "rime/core/error.h"

namespace rime {
namespace {

TEST(MemoryBudget, ParsesSizesAsPowersOf1024) {
  EXPECT_EQ(ParseByteSize("100000"), 100000u);
  EXPECT_EQ(ParseByteSize("512B"), 512u);
  EXPECT_EQ(ParseByteSize("1K"), 1024u);
  EXPECT_EQ(ParseByteSize("512M"), 512ull << 20);
  EXPECT_EQ(ParseByteSize("512m"), 512ull << 20);
  EXPECT_EQ(ParseByteSize("4G"), 4ull << 30);
  EXPECT_EQ(ParseByteSize("4GB"), 4ull << 30);
  EXPECT_EQ(ParseByteSize("1.5GiB"), 3ull << 29);
  EXPECT_EQ(ParseByteSize("2Ti"), 2ull << 40);
  EXPECT_EQ(ParseByteSize(".5K"), 512u);
}

TEST(MemoryBudget, RefusesWhatIsNotASize) {
  for (const char* bad :
       {"", "G", "-1G", "1..5G", "1.5.G", "4X", "4GiBs", "4 G", "0", "0.1", "1e9", "nan", "inf", "0x10", "9000000000G", "4BB", "4iG"}) {
    try {
      ParseByteSize(bad);
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ExitCode::kUsage) << bad;
      EXPECT_NE(std::string(e.what()).find("--memory-budget"), std::string::npos) << e.what();
    }
  }
}

TEST(MemoryBudget, FormatsBytesAndCounts) {
  EXPECT_EQ(FormatBytes(900), "900 B");
  EXPECT_EQ(FormatBytes(14.2 * (1ull << 30)), "14.2 GiB");
  EXPECT_EQ(FormatBytes(512.0 * (1 << 20)), "512 MiB");
  EXPECT_EQ(FormatCount(310e6), "310 M");
  EXPECT_EQ(FormatCount(12500), "12.5 k");
  EXPECT_EQ(FormatCount(800), "800");
}

TEST(MemoryBudget, ConcurrentPeakSumsTheLargestThatMeet) {
  std::size_t largest = 99;
  EXPECT_EQ(ConcurrentPeak({1, 5, 3, 4}, 2, &largest), 9);
  EXPECT_EQ(largest, 1u);
  EXPECT_EQ(ConcurrentPeak({1, 5, 3}, 8), 9);
  EXPECT_EQ(ConcurrentPeak({}, 2, &largest), 0);
  EXPECT_EQ(largest, 0u);
}

TEST(MemoryBudget, RefusalIsOneLineWithEstimateBudgetAndInput) {
  const MemoryBudget budget{8ull << 30, "--memory-budget"};
  // What the test process holds already counts: 7 GiB more fits in 8, 8 GiB more does not.
  EXPECT_GT(ResidentBytes(), 0u);
  EXPECT_NO_THROW(CheckMemoryBudget(budget, double(7ull << 30), "310 M voxels", "frame f.h5part"));
  EXPECT_THROW(CheckMemoryBudget(budget, double(8ull << 30), "310 M voxels", "frame f.h5part"), Error);
  try {
    CheckMemoryBudget(budget, 14.2 * (1ull << 30), "310 M voxels", "frame particles.0012.h5part, voxel 2 mm");
    FAIL() << "not refused";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kOverBudget);
    EXPECT_STREQ(e.what(),
                 "needs about 14.2 GiB for 310 M voxels (frame particles.0012.h5part, voxel 2 mm), budget 8 GiB (--memory-budget)");
  }
}

TEST(MemoryBudget, DefaultIsTheMachinesAvailableMemory) {
  // Every Linux since 3.14 has MemAvailable; the default must be a real, positive figure.
  const auto available = AvailableMemory();
  ASSERT_TRUE(available.has_value());
  EXPECT_GT(available->bytes, 0u);
  EXPECT_LT(available->bytes, UINT64_MAX);
  const MemoryBudget resolved = ResolveMemoryBudget("");
  EXPECT_FALSE(resolved.source.empty());
  EXPECT_LT(resolved.bytes, UINT64_MAX);
  EXPECT_EQ(ResolveMemoryBudget("1M").bytes, 1u << 20);
  EXPECT_EQ(ResolveMemoryBudget("1M").source, "--memory-budget");
}

}  // namespace
}  // namespace rime
