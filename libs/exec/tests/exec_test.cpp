// The execution layer against serial references, on every backend present.
#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <random>

#include "rime/core/error.h"
#include "rime/exec/kernels.h"
#include "rime/exec/memory.h"
#include "rime/exec/parallel.h"

namespace rime::exec {
namespace {

const Index kSizes[] = {0, 1, 2, 7, 255, 256, 257, 1000, 16385, 100003, 300000};

std::vector<Device> DevicesPresent() {
  std::vector<Device> devices{Device::Cpu()};
  if (QueryCuda().usable) devices.push_back(SelectDevice("cuda"));
  return devices;
}

TEST(Exec, ParallelForMatchesSerial) {
  for (const Device& device : DevicesPresent())
    for (Index n : kSizes) {
      std::vector<double> in(n);
      std::iota(in.begin(), in.end(), 0.5);
      DeviceArray<double> d_in(device, in), d_out(device, n);
      ParallelFor(device, n, AffineKernel{d_in.data(), d_out.data(), 3.0, -1.0});
      const std::vector<double> out = d_out.ToHost();
      for (Index i = 0; i < n; ++i) ASSERT_EQ(out[i], 3.0 * in[i] - 1.0) << device.description << " n=" << n;
    }
}

TEST(Exec, SortPairsMatchesStableSort) {
  std::mt19937_64 rng(42);
  for (const Device& device : DevicesPresent())
    for (Index n : kSizes)
      for (int bits : {64, 20}) {
        std::vector<std::uint64_t> keys(n);
        for (auto& k : keys) k = rng() & (bits == 64 ? ~0ULL : ((1ULL << bits) - 1)) & (n > 1000 ? ~0ULL : 0xff);
        std::vector<std::uint32_t> values(n);
        std::iota(values.begin(), values.end(), 0u);
        std::vector<std::pair<std::uint64_t, std::uint32_t>> expected(n);
        for (Index i = 0; i < n; ++i) expected[i] = {keys[i], values[i]};
        std::stable_sort(expected.begin(), expected.end(), [](auto& a, auto& b) { return a.first < b.first; });
        DeviceArray<std::uint64_t> d_keys(device, keys);
        DeviceArray<std::uint32_t> d_values(device, values);
        SortPairs(device, d_keys.data(), d_values.data(), n, bits);
        const auto k = d_keys.ToHost();
        const auto v = d_values.ToHost();
        for (Index i = 0; i < n; ++i) {
          ASSERT_EQ(k[i], expected[i].first) << "n=" << n << " i=" << i;
          ASSERT_EQ(v[i], expected[i].second) << "stability, n=" << n << " i=" << i;
        }
      }
}

TEST(Exec, ExclusiveScanMatchesSerial) {
  std::mt19937 rng(3);
  for (const Device& device : DevicesPresent())
    for (Index n : kSizes) {
      std::vector<std::uint32_t> in(n);
      for (auto& x : in) x = rng() % 50;
      DeviceArray<std::uint32_t> d_in(device, in), d_out(device, n);
      const std::uint64_t total = ExclusiveScan(device, d_in.data(), d_out.data(), n);
      const auto out = d_out.ToHost();
      std::uint64_t s = 0;
      for (Index i = 0; i < n; ++i) {
        ASSERT_EQ(out[i], s) << "n=" << n << " i=" << i;
        s += in[i];
      }
      EXPECT_EQ(total, s);
      // in place
      ExclusiveScan(device, d_in.data(), d_in.data(), n);
      EXPECT_EQ(d_in.ToHost(), out);
    }
}

TEST(Exec, ReductionsMatchSerialAndIgnoreThreadCount) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1, 1);
  for (Index n : kSizes) {
    std::vector<float> values(n);
    for (auto& x : values) x = u(rng);
    double serial = 0;
    float serial_max = -INFINITY;
    for (float x : values) {
      serial += x;
      serial_max = std::max(serial_max, x);
    }
    const Device cpu = Device::Cpu();
    SetCpuThreads(1);
    const double one_thread = Sum(cpu, values.data(), n);
    SetCpuThreads(2);
    const double two_threads = Sum(cpu, values.data(), n);
    SetCpuThreads(0);
    EXPECT_EQ(one_thread, two_threads) << "sum must not depend on the thread count";
    EXPECT_NEAR(one_thread, serial, 1e-9 * std::max<double>(1, n));
    EXPECT_EQ(Max(cpu, values.data(), n), serial_max);
  }
  std::vector<double> with_nan{1.0, NAN, 2.0};
  EXPECT_TRUE(std::isnan(Max(Device::Cpu(), with_nan.data(), 3)));
}

TEST(Exec, DeviceArrayResizeKeepsContents) {
  DeviceArray<std::uint32_t> a(Device::Cpu(), 5);
  ParallelFor(Device::Cpu(), 5, IotaKernel{a.data()});
  a.resize(1000);
  const auto host = a.ToHost();
  EXPECT_EQ(host[4], 4u);
  EXPECT_EQ(host[999], 0u);
}

TEST(Exec, DeviceSelection) {
  EXPECT_EQ(SelectDevice("cpu").backend, Backend::kCpu);
  try {
    SelectDevice("gpu0");
    FAIL() << "unknown device accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kUsage);
  }
  const CudaStatus cuda = QueryCuda();
  if (cuda.usable) {
    EXPECT_EQ(SelectDevice("auto").backend, Backend::kCuda);
    return;
  }
  EXPECT_FALSE(cuda.reason.empty());
  EXPECT_EQ(SelectDevice("auto").backend, Backend::kCpu);
  try {
    SelectDevice("cuda");
    FAIL() << "--device cuda accepted without a GPU";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kNoDevice);
    EXPECT_NE(std::string(e.what()).find(cuda.reason), std::string::npos);
  }
}

}  // namespace
}  // namespace rime::exec
