// The default example's ledge: water that runs over its lower end hangs there and freezes into
// drips when air pressure holds it to the underside; without air pressure it falls off as a spray.
// With tip_growth, water runs down the ice and freezes at its tip, so more ice hangs, and deeper.
// Surfaced and cleaned as rime-bake does, the last frame is a smooth glaze, with an icicle in most takes.
// The eave example's drips freeze into slender icicles, which the surface keeps with smooth_limit.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <span>
#include <vector>

#include "rime/clean/clean.h"
#include "rime/clean/ice_metrics.h"
#include "rime/exec/device.h"
#include "rime/io/scene.h"
#include "rime/sph/simulation.h"
#include "rime/surface/frame_input.h"
#include "rime/surface/reconstruct.h"
#include "rime/test/measure.h"
#include "rime/test/scene_solids.h"

namespace rime {
namespace {

struct Drips {
  double hanging = 0;  // ice particles more than 2 d_p below the ledge, clear of the ground
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

// Drips are chaotic: nudging the first nozzle's speed by 2.5e-4 of itself, or building with other
// rounding (the sanitizer preset), moves where water leaves the edge and the icicles with it
// (docs/ice-look.md). Bounds on how much ice hangs therefore hold for the median of nudged takes.
constexpr double kLedgeNudges[] = {0, -2.5e-4, 2.5e-4, -5e-4, 5e-4, -7.5e-4, 7.5e-4};
constexpr double kEaveNudges[] = {0, -2.5e-4, 2.5e-4, -5e-4, 5e-4};

std::vector<io::Scene> Nudged(const io::Scene& scene, std::span<const double> nudges) {
  std::vector<io::Scene> takes(nudges.size(), scene);
  for (std::size_t k = 0; k < nudges.size(); ++k) takes[k].emitters.at(0).speed *= 1 + nudges[k];
  return takes;
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

Drips Measure(const io::Scene& scene, const io::ParticleFrame& frame) {
  double bottom = 0;
  const auto hanging = HangingIce(scene, frame, bottom);
  Drips d;
  d.hanging = double(hanging.size());
  for (const Vec3d& p : hanging) d.deepest = std::max(d.deepest, (bottom - p.z) / scene.fluid.spacing);
  return d;
}

/// The medians of the takes' drips, each take printed.
Drips MedianDrips(const std::vector<io::Scene>& takes, const std::vector<io::ParticleFrame>& frames, const char* variant) {
  std::vector<double> hanging, deepest;
  for (std::size_t k = 0; k < takes.size(); ++k) {
    const Drips d = Measure(takes[k], frames[k]);
    std::printf("%s, speed %.5f m/s: %.0f ice particles hang below the ledge, the deepest %.1f d_p\n", variant, takes[k].emitters[0].speed,
                d.hanging, d.deepest);
    hanging.push_back(d.hanging), deepest.push_back(d.deepest);
  }
  const Drips median{test::Median(hanging), test::Median(deepest)};
  std::printf("%s, median of %zu takes: %.0f hanging, the deepest %.1f d_p\n", variant, takes.size(), median.hanging, median.deepest);
  return median;
}

std::vector<io::ParticleFrame> BakeAll(const std::vector<io::Scene>& takes) {
  std::vector<io::ParticleFrame> frames;
  for (const io::Scene& take : takes) frames.push_back(Bake(take));
  return frames;
}

Drips BakeAndMeasure(const io::Scene& scene, const char* variant) {
  const auto takes = Nudged(scene, kLedgeNudges);
  return MedianDrips(takes, BakeAll(takes), variant);
}

io::Scene DefaultScene() { return io::LoadScene(RIME_SOURCE_DIR "/examples/default.toml"); }

// The shipped default's takes, simulated once per process (ctest runs each test in a process of its own).
const std::vector<io::Scene>& DefaultTakes() {
  static const std::vector<io::Scene> takes = Nudged(DefaultScene(), kLedgeNudges);
  return takes;
}
const std::vector<io::ParticleFrame>& DefaultFrames() {
  static const std::vector<io::ParticleFrame> frames = BakeAll(DefaultTakes());
  return frames;
}
const Drips& DefaultDrips() {
  static const Drips drips = MedianDrips(DefaultTakes(), DefaultFrames(), "default");
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
  std::vector<double> glaze, hanging_icicles;
  for (std::size_t k = 0; k < DefaultTakes().size(); ++k) {
    const io::ParticleFrame& frame = DefaultFrames()[k];
    const clean::IceMetrics m = InspectIce(scene, frame, filtered), r = InspectIce(scene, frame, raw);
    std::printf(
        "speed %.5f m/s: glaze %.0f %%, %zu pieces, %zu specks, noise %.3f d_p (raw %.3f), sharp %.1f %% (raw %.1f %%), %zu icicles "
        "(%zu hanging, longest %.1f d_p), volume / (ice particles x d_p^3) %.2f\n",
        DefaultTakes()[k].emitters[0].speed, 100 * m.glaze_coverage, m.components, m.specks, m.noise_rms, r.noise_rms,
        100 * m.sharp_area_fraction, 100 * r.sharp_area_fraction, m.icicles.size(), m.hanging_icicles, m.icicle_length_max, m.volume_ratio);
    // Every take: no loose ice; smooth at the particle scale (filtering halves the noise of the
    // particle union, at least); and the smoothing neither dissolves the glaze nor inflates it (the
    // mesh holds about the volume the ice particles stand for, d_p^3 each).
    EXPECT_EQ(m.specks, 0u);
    EXPECT_LT(m.noise_rms, 0.5 * r.noise_rms);
    EXPECT_LT(m.sharp_area_fraction, 0.5 * r.sharp_area_fraction);
    EXPECT_GT(m.volume_ratio, 0.8);
    EXPECT_LT(m.volume_ratio, 1.25);
    glaze.push_back(m.glaze_coverage), hanging_icicles.push_back(double(m.hanging_icicles));
  }
  // Most takes: a coat over much of the wetted ledge and at least one icicle hanging from it.
  EXPECT_GT(test::Median(glaze), 0.3);
  EXPECT_GE(test::Median(hanging_icicles), 1);
}

// The eave example's drips freeze into slender icicles one or two particles thick. Mean-curvature
// flow would pinch them off the eave or dissolve them; with the scene's smooth_limit the cleaned
// surface still holds the hanging ice.
TEST(IceLook, EaveGrowsSlenderIciclesThatTheSurfaceKeeps) {
  const io::Scene eaves = io::LoadScene(RIME_SOURCE_DIR "/examples/eaves.toml");
  ASSERT_GT(eaves.surface.smooth_limit, 0.0);
  const surface::Settings limited = surface::FromScene(eaves.surface, eaves.surface.ice_field);
  surface::Settings free = limited;
  free.smooth_limit = 0;
  std::vector<double> hanging_icicles, longest, kept_shares, loose_shares;
  for (const io::Scene& scene : Nudged(eaves, kEaveNudges)) {
    const io::ParticleFrame frame = Bake(scene);
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
        "speed %.5f m/s: %zu icicles (%zu hanging, longest %.1f d_p), %zu pieces, %zu specks; hanging ice particles inside the "
        "surface: %.0f %% of %zu with smooth_limit %.2f, %.0f %% without (%zu pieces, %zu specks)\n",
        scene.emitters[0].speed, m.icicles.size(), m.hanging_icicles, m.icicle_length_max, m.components, m.specks, 100 * kept_share,
        hanging.size(), scene.surface.smooth_limit, 100 * loose_share, f.components, f.specks);
    hanging_icicles.push_back(double(m.hanging_icicles)), longest.push_back(m.icicle_length_max);
    kept_shares.push_back(kept_share), loose_shares.push_back(loose_share);
  }
  // Slender ice (at least 1.5 times longer than wide) hanging 4 cm or more under the edge.
  EXPECT_GE(test::Median(hanging_icicles), 2);
  EXPECT_GE(test::Median(longest), 8.0);
  // The surface shows most of the ice that hangs there; unlimited smoothing dissolves most of it.
  EXPECT_GE(test::Median(kept_shares), 0.8);
  EXPECT_LT(test::Median(loose_shares), 0.5 * test::Median(kept_shares));
}

}  // namespace
}  // namespace rime
