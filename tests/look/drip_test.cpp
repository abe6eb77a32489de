// The default example's ledge: water that runs over its lower end hangs there and freezes into
// drips when air pressure holds it to the underside; without air pressure it falls off as a spray.
// With tip_growth, water runs down the ice and freezes at its tip, so more ice hangs, and deeper.
// Surfaced and cleaned as rime-bake does, the last frame is a smooth glaze with an icicle.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>

#include "rime/clean/clean.h"
#include "rime/clean/ice_metrics.h"
#include "rime/exec/device.h"
#include "rime/io/scene.h"
#include "rime/sph/simulation.h"
#include "rime/surface/frame_input.h"
#include "rime/surface/reconstruct.h"
#include "rime/test/scene_solids.h"

namespace rime {
namespace {

struct Drips {
  int hanging = 0;     // ice particles more than 2 d_p below the ledge, clear of the ground
  double deepest = 0;  // d_p below the ledge's lowest solid particle
};

/// The last frame of the scene, simulated as rime-sim does.
io::ParticleFrame Bake(const io::Scene& scene) {
  sph::Simulation<float> sim(scene, exec::Device::Cpu());
  test::AddSceneSolids(sim, scene);
  sim.Initialize();
  while (sim.time() < scene.info.end_time - 1e-9) sim.Step(sim.NextTimeStep(scene.info.end_time));
  return sim.Snapshot(0);
}

Drips Measure(const io::Scene& scene, const io::ParticleFrame& frame, const char* variant) {
  const auto x = frame.GetPositions<double>();
  const auto& phase = frame.Get<std::uint8_t>("phase");
  const double dp = scene.fluid.spacing, clear_of_ground = 5 * dp;
  double ledge_bottom = 1e30;
  for (std::size_t i = 0; i < x.size(); ++i)
    if (phase[i] == 1 && x[i].z > clear_of_ground) ledge_bottom = std::min(ledge_bottom, x[i].z);
  Drips d;
  for (std::size_t i = 0; i < x.size(); ++i) {
    if (phase[i] != 2 || x[i].z < clear_of_ground || x[i].z > ledge_bottom - 2 * dp) continue;
    ++d.hanging;
    d.deepest = std::max(d.deepest, (ledge_bottom - x[i].z) / dp);
  }
  std::printf("%s: %d ice particles hang below the ledge, the deepest %.1f d_p\n", variant, d.hanging, d.deepest);
  return d;
}

io::Scene DefaultScene() { return io::LoadScene(RIME_SOURCE_DIR "/examples/default.toml"); }

Drips BakeAndMeasure(const io::Scene& scene, const char* variant) { return Measure(scene, Bake(scene), variant); }

// The shipped default, simulated once per process (ctest runs each test in a process of its own).
const io::ParticleFrame& DefaultFrame() {
  static const io::ParticleFrame frame = Bake(DefaultScene());
  return frame;
}
const Drips& DefaultDrips() {
  static const Drips drips = Measure(DefaultScene(), DefaultFrame(), "default");
  return drips;
}

/// rime-inspect's measures of the frame's ice, surfaced with `surfacing` and cleaned as the scene says.
clean::IceMetrics InspectIce(const io::Scene& scene, const io::ParticleFrame& frame, const surface::Settings& surfacing) {
  std::vector<std::string> warnings;
  const surface::ParticleSet ice = surface::SelectPhase(frame, io::Phase::kIce, {}, warnings);
  const clean::CleanResult cleaned = clean::Clean(surface::Reconstruct(ice, surfacing).mesh, scene.cleanup);
  std::set<std::uint32_t> objects;  // the ledge, not the ground
  for (std::uint32_t i = 0; i < scene.solids.size(); ++i)
    if (scene.solids[i].shape != io::SolidShape::kPlane) objects.insert(i);
  return clean::MeasureIce(cleaned.mesh, frame, scene.solver.gravity, objects, {});
}

TEST(IceLook, DripsFreezeUnderTheDefaultLedgeOnlyWithAirPressure) {
  const io::Scene scene = DefaultScene();
  ASSERT_TRUE(scene.Enabled("air_pressure"));
  const Drips& held = DefaultDrips();
  // Bounds from four bakes of this ledge with nozzles placed differently: 7-32 hanging, 2.7-4.3 d_p.
  EXPECT_GE(held.hanging, 3);
  EXPECT_GE(held.deepest, 2.5);

  io::Scene without = scene;
  without.modules.erase("air_pressure");
  const Drips fallen = BakeAndMeasure(without, "no air pressure");
  EXPECT_LT(fallen.hanging, held.hanging);
  EXPECT_LE(fallen.hanging, 2);
}

TEST(IceLook, TipGrowthHangsMoreIceDeeperUnderTheDefaultLedge) {
  const io::Scene scene = DefaultScene();
  ASSERT_GT(scene.freezing.tip_growth, 1.0);
  const Drips& tip = DefaultDrips();
  io::Scene paper = scene;
  paper.freezing.tip_growth = 1;
  const Drips sides = BakeAndMeasure(paper, "tip_growth 1");
  EXPECT_GT(tip.hanging, 2 * sides.hanging);
  EXPECT_GT(tip.deepest, sides.deepest + 1.0);
}

TEST(IceLook, DefaultLedgeIsASmoothGlazeWithAHangingIcicle) {
  const io::Scene scene = DefaultScene();
  const surface::Settings filtered = surface::FromScene(scene.surface, scene.surface.ice_field);
  surface::Settings raw = filtered;  // the union of particle shapes, as without the level-set filters
  raw.close_radius = 0;
  raw.smooth_iterations = 0;
  const clean::IceMetrics m = InspectIce(scene, DefaultFrame(), filtered), r = InspectIce(scene, DefaultFrame(), raw);
  std::printf(
      "filtered: glaze %.0f %%, %zu pieces, %zu specks, noise %.3f d_p, sharp %.1f %%, %zu icicles (%zu hanging, longest %.1f d_p)\n",
      100 * m.glaze_coverage, m.components, m.specks, m.noise_rms, 100 * m.sharp_area_fraction, m.icicles.size(), m.hanging_icicles,
      m.icicle_length_max);
  std::printf("raw: noise %.3f d_p, sharp %.1f %%, %zu specks\n", r.noise_rms, 100 * r.sharp_area_fraction, r.specks);
  // No loose ice, a coat over much of the wetted ledge, and at least one icicle hanging from it.
  EXPECT_EQ(m.specks, 0u);
  EXPECT_GT(m.glaze_coverage, 0.3);
  EXPECT_GE(m.hanging_icicles, 1u);
  // Smooth at the particle scale: filtering halves the noise of the particle union, at least.
  EXPECT_LT(m.noise_rms, 0.5 * r.noise_rms);
  EXPECT_LT(m.sharp_area_fraction, 0.5 * r.sharp_area_fraction);
}

}  // namespace
}  // namespace rime
