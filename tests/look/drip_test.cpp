// The default example's ledge: water that runs over its lower end hangs there and freezes into
// drips when air pressure holds it to the underside; without air pressure it falls off as a spray.
// With tip_growth, water runs down the ice and freezes at its tip, so more ice hangs, and deeper.
// Surfaced and cleaned as rime-bake does, the last frame is a smooth glaze with an icicle.
// The eave example's drips freeze into slender icicles, which the surface keeps with smooth_limit.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>

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

/// Ice particles more than 2 d_p below the lowest solid particle above the ground (the ledge's or
/// the eave's), clear of the ground; `bottom` receives that solid's lowest height.
std::vector<Vec3d> HangingIce(const io::Scene& scene, const io::ParticleFrame& frame, double& bottom) {
  const auto x = frame.GetPositions<double>();
  const auto& phase = frame.Get<std::uint8_t>("phase");
  const double dp = scene.fluid.spacing, clear_of_ground = 5 * dp;
  bottom = 1e30;
  for (std::size_t i = 0; i < x.size(); ++i)
    if (phase[i] == 1 && x[i].z > clear_of_ground) bottom = std::min(bottom, x[i].z);
  std::vector<Vec3d> hanging;
  for (std::size_t i = 0; i < x.size(); ++i)
    if (phase[i] == 2 && x[i].z > clear_of_ground && x[i].z < bottom - 2 * dp) hanging.push_back(x[i]);
  return hanging;
}

Drips Measure(const io::Scene& scene, const io::ParticleFrame& frame, const char* variant) {
  double bottom = 0;
  const auto hanging = HangingIce(scene, frame, bottom);
  Drips d;
  d.hanging = int(hanging.size());
  for (const Vec3d& p : hanging) d.deepest = std::max(d.deepest, (bottom - p.z) / scene.fluid.spacing);
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

/// The frame's ice surfaced with `surfacing` and cleaned as the scene says (what rime-bake writes).
io::TriMesh CleanIce(const io::Scene& scene, const io::ParticleFrame& frame, const surface::Settings& surfacing) {
  std::vector<std::string> warnings;
  const surface::ParticleSet ice = surface::SelectPhase(frame, io::Phase::kIce, {}, warnings);
  return clean::Clean(surface::Reconstruct(ice, surfacing).mesh, scene.cleanup).mesh;
}

/// rime-inspect's measures of a cleaned ice mesh of the frame.
clean::IceMetrics InspectIce(const io::Scene& scene, const io::ParticleFrame& frame, const io::TriMesh& mesh) {
  std::set<std::uint32_t> objects;  // the ledge, not the ground
  for (std::uint32_t i = 0; i < scene.solids.size(); ++i)
    if (scene.solids[i].shape != io::SolidShape::kPlane) objects.insert(i);
  return clean::MeasureIce(mesh, frame, scene.solver.gravity, objects, {});
}
clean::IceMetrics InspectIce(const io::Scene& scene, const io::ParticleFrame& frame, const surface::Settings& surfacing) {
  return InspectIce(scene, frame, CleanIce(scene, frame, surfacing));
}

/// Whether p lies inside the closed mesh: the parity of a ray's crossings (Möller–Trumbore), along
/// a direction no lattice or axis-aligned edge lies on.
bool InsideMesh(const io::TriMesh& mesh, const Vec3d& p) {
  const Vec3d dir = Vec3d(0.1234, 0.2345, 1.0) / Norm(Vec3d(0.1234, 0.2345, 1.0));
  int crossings = 0;
  for (const auto& t : mesh.triangles) {
    const Vec3d a(mesh.positions[t[0]]), e1 = Vec3d(mesh.positions[t[1]]) - a, e2 = Vec3d(mesh.positions[t[2]]) - a;
    const Vec3d q = Cross(dir, e2);
    const double det = Dot(e1, q);
    if (std::abs(det) < 1e-18) continue;
    const Vec3d s = p - a;
    const double u = Dot(s, q) / det;
    if (u < 0 || u > 1) continue;
    const Vec3d r = Cross(s, e1);
    const double v = Dot(dir, r) / det;
    if (v < 0 || u + v > 1) continue;
    if (Dot(e2, r) / det > 0) ++crossings;
  }
  return crossings % 2 == 1;
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
  // The smoothing neither dissolves the glaze nor inflates it: the mesh holds about the volume
  // the ice particles stand for (d_p³ each).
  std::printf("cleaned ice mesh volume / (ice particles x d_p^3) = %.2f\n", m.volume_ratio);
  EXPECT_GT(m.volume_ratio, 0.8);
  EXPECT_LT(m.volume_ratio, 1.25);
}

// The eave example's drips freeze into slender icicles one or two particles thick. Mean-curvature
// flow would pinch them off the eave or dissolve them; with the scene's smooth_limit the cleaned
// surface still holds the hanging ice.
TEST(IceLook, EaveGrowsSlenderIciclesThatTheSurfaceKeeps) {
  const io::Scene scene = io::LoadScene(RIME_SOURCE_DIR "/examples/eaves.toml");
  ASSERT_GT(scene.surface.smooth_limit, 0.0);
  const io::ParticleFrame frame = Bake(scene);
  const surface::Settings limited = surface::FromScene(scene.surface, scene.surface.ice_field);
  surface::Settings free = limited;
  free.smooth_limit = 0;
  const io::TriMesh kept = CleanIce(scene, frame, limited), loose = CleanIce(scene, frame, free);
  const clean::IceMetrics m = InspectIce(scene, frame, kept), f = InspectIce(scene, frame, loose);
  double bottom = 0;
  const auto hanging = HangingIce(scene, frame, bottom);
  const auto inside = [&](const io::TriMesh& mesh) {
    const auto n = std::count_if(hanging.begin(), hanging.end(), [&](const Vec3d& p) { return InsideMesh(mesh, p); });
    return double(n) / double(std::max<std::size_t>(hanging.size(), 1));
  };
  const double kept_share = inside(kept), loose_share = inside(loose);
  std::printf(
      "%zu icicles (%zu hanging, longest %.1f d_p), %zu pieces, %zu specks; hanging ice particles inside the surface: %.0f %% "
      "of %zu with smooth_limit %.2f, %.0f %% without (%zu pieces, %zu specks)\n",
      m.icicles.size(), m.hanging_icicles, m.icicle_length_max, m.components, m.specks, 100 * kept_share, hanging.size(),
      scene.surface.smooth_limit, 100 * loose_share, f.components, f.specks);
  // Slender ice (at least 1.5 times longer than wide) hanging 4 cm or more under the edge.
  EXPECT_GE(m.hanging_icicles, 2u);
  EXPECT_GE(m.icicle_length_max, 8.0);
  // The surface shows most of the ice that hangs there; unlimited smoothing dissolves most of it.
  EXPECT_GE(kept_share, 0.8);
  EXPECT_LT(loose_share, 0.5 * kept_share);
}

}  // namespace
}  // namespace rime
