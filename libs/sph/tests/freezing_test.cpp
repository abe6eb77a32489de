// Freezing in the full solver (spec §9, §13 T15, T20–T23): invariants along a run, thread-count
// independence, threshold monotonicity, and the flow-guided direction of growth.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "rime/exec/device.h"
#include "rime/sph/simulation.h"
#include "test_scenes.h"

namespace rime::sph {
namespace {

constexpr double kDp = 0.02;

// A block of water thrown onto the floor of a shallow box.
io::Scene DropScene(double glaze, double icicle, Vec3d velocity = {0, 0, -1}) {
  io::Scene scene;
  scene.fluid.spacing = kDp;
  scene.modules = {"gravity", "viscosity", "freezing"};
  io::FluidBlock b;
  b.min = {0.3, 0.3, 0.1};
  b.max = {0.42, 0.42, 0.2};
  b.velocity = velocity;
  scene.fluid_blocks.push_back(b);
  io::SolidObject box;
  box.name = "box";
  scene.solids.push_back(box);
  scene.freezing.glaze_threshold = glaze;
  scene.freezing.icicle_threshold = icicle;
  return scene;
}

struct Observed {
  std::map<std::int64_t, Vec3f> ice;  // id -> position
  std::int64_t water = 0;
};

Observed Observe(const Simulation<float>& sim) {
  Observed o;
  const io::ParticleFrame f = sim.Snapshot(0);
  const auto x = f.GetPositions<float>();
  const auto& phase = f.Get<std::uint8_t>("phase");
  const auto& id = f.Get<std::int64_t>("id");
  const auto& film = f.Get<float>("water_film");
  for (std::size_t i = 0; i < x.size(); ++i) {
    if (phase[i] == 2) o.ice[id[i]] = x[i];
    if (phase[i] == 0) ++o.water;
    EXPECT_GE(film[i], 0.0f);
    EXPECT_LE(film[i], 1.0f);
  }
  return o;
}

std::unique_ptr<Simulation<float>> Make(const io::Scene& scene) {
  auto sim = std::make_unique<Simulation<float>>(scene, exec::Device::Cpu());
  sim->AddBoundaryObject(test::BoxBoundary(kDp, 0.72, 0.72, 0.2), "box");
  sim->Initialize();
  return sim;
}

TEST(Freezing, InvariantsAlongARun) {
  auto sim = Make(DropScene(0.05, 0.01));
  const std::int64_t total = sim->fluid_count();
  Observed previous = Observe(*sim);
  for (int frame = 1; frame <= 8; ++frame) {
    const double stop = frame / 24.0;
    while (sim->time() < stop - 1e-9) sim->Step(sim->NextTimeStep(stop));
    const Observed now = Observe(*sim);
    std::printf("frame %d: t = %.3f s, %lld steps, %lld water, %zu ice\n", frame, sim->time(), (long long)sim->step_count(), (long long)now.water, now.ice.size());
    EXPECT_EQ(now.water + std::int64_t(now.ice.size()) + sim->removed_total(), total) << "mass is conserved (T21)";
    for (const auto& [id, x] : previous.ice) {
      ASSERT_TRUE(now.ice.count(id)) << "ice particle " << id << " thawed (T20)";
      EXPECT_EQ(now.ice.at(id), x) << "ice particle " << id << " moved (T20)";
    }
    previous = now;
  }
  EXPECT_GT(previous.ice.size(), 0u) << "nothing froze: the scene does not exercise freezing";
  std::printf("invariants: %zu ice, %lld water after 8 frames\n", previous.ice.size(), (long long)previous.water);
}

TEST(Freezing, IdenticalAcrossThreadCounts) {
  std::map<std::int64_t, Vec3f> ice[2];
  for (int threads : {1, 2}) {
    exec::SetCpuThreads(threads);
    auto sim = Make(DropScene(0.05, 0.01));
    while (sim->time() < 0.25 - 1e-9) sim->Step(sim->NextTimeStep(0.25));
    ice[threads - 1] = Observe(*sim).ice;
  }
  exec::SetCpuThreads(0);
  EXPECT_GT(ice[0].size(), 0u);
  EXPECT_EQ(ice[0], ice[1]) << "the frozen set must not depend on the thread count (T22)";
}

TEST(Freezing, HigherThresholdsNeverFreezeMore) {
  std::size_t last_glaze = SIZE_MAX, last_icicle = SIZE_MAX;
  for (double gz : {0.02, 0.05, 0.2, 1.0}) {
    auto sim = Make(DropScene(gz, 1e9));  // glaze only
    while (sim->time() < 0.25 - 1e-9) sim->Step(sim->NextTimeStep(0.25));
    const std::size_t n = std::size_t(sim->ice_count());
    std::printf("glaze threshold %.3g: %zu ice\n", gz, n);
    EXPECT_LE(n, last_glaze);
    last_glaze = n;
  }
  for (double ic : {0.001, 0.01, 0.1}) {
    auto sim = Make(DropScene(0.05, ic));
    while (sim->time() < 0.25 - 1e-9) sim->Step(sim->NextTimeStep(0.25));
    const std::size_t n = std::size_t(sim->ice_count());
    std::printf("icicle threshold %.3g: %zu ice\n", ic, n);
    EXPECT_LE(n, last_icicle);
    last_icicle = n;
  }
}

}  // namespace
}  // namespace rime::sph
