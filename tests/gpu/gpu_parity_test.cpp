// GPU parity in the normal suite: skipped, visibly, where no GPU is usable.
#include <gtest/gtest.h>

#include <unordered_map>

#include "gpu_check.h"

namespace rime {
namespace {

TEST(GpuParity, ShortDamBreakMatchesTheCpu) {
  const exec::CudaStatus cuda = exec::QueryCuda();
  if (!cuda.usable) GTEST_SKIP() << "no usable GPU (" << cuda.reason << "): CPU/GPU parity not checked";
  const io::Scene scene = gpu_check::DamBreak(12, true);
  auto a = gpu_check::Make(scene, exec::Device::Cpu(), 0.2);
  auto b = gpu_check::Make(scene, exec::SelectDevice("cuda"), 0.2);
  for (int s = 0; s < 30; ++s) {
    a->Step(0.001);
    b->Step(0.001);
  }
  const auto d = gpu_check::Compare(*a, *b, scene.fluid.spacing);
  EXPECT_LT(d.rms_position, 0.01);
  EXPECT_LT(d.max_density, 0.005);
  EXPECT_EQ(d.unmatched, 0);
}

}  // namespace
}  // namespace rime
