// The surface stage's filters against rime-inspect's measures, on a glaze of ice particles over a
// sphere: the filtered surface is one smooth coat, the unfiltered union of particles is not.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "rime/io/scene_surface.h"
#include "rime/clean/ice_metrics.h"
#include "rime/surface/reconstruct.h"

namespace rime {
namespace {

constexpr double kSpacing = 0.02;  // d_p
constexpr double kRadius = 0.2;    // the solid sphere, 10 d_p
constexpr double kPi = 3.14159265358979323846;

struct Glaze {
  std::vector<Vec3d> solid, ice;
};

/// Solid particles on the sphere (d_p/2 apart), wet on the upper half; two layers of ice particles
/// over the upper cap, on a Fibonacci lattice with jitter of a fifth of a spacing, as frozen water is.
Glaze GlazeOnASphere() {
  Glaze g;
  const auto fibonacci = [](double r, double spacing, double z_min, std::vector<Vec3d>& out, std::mt19937* jitter) {
    const int n = int(4 * kPi * r * r / (spacing * spacing));
    std::uniform_real_distribution<double> u(-0.2 * kSpacing, 0.2 * kSpacing);
    for (int i = 0; i < n; ++i) {
      const double z = 1 - 2 * (i + 0.5) / n, rho = std::sqrt(1 - z * z), phi = i * kPi * (3 - std::sqrt(5.0));
      if (r * z < z_min) continue;
      Vec3d p(r * rho * std::cos(phi), r * rho * std::sin(phi), r * z);
      if (jitter) p += Vec3d(u(*jitter), u(*jitter), u(*jitter));
      out.push_back(p);
    }
  };
  std::mt19937 rng(5);
  fibonacci(kRadius, kSpacing / 2, -kRadius, g.solid, nullptr);
  fibonacci(kRadius + 0.6 * kSpacing, kSpacing, 0.3 * kRadius, g.ice, &rng);
  fibonacci(kRadius + 1.5 * kSpacing, kSpacing, 0.35 * kRadius, g.ice, &rng);
  return g;
}

clean::IceMetrics Measure(const Glaze& g, const surface::Settings& settings) {
  surface::ParticleSet set;
  set.positions = g.ice;
  set.spacing = kSpacing;
  const surface::Result result = surface::Reconstruct(set, settings);
  io::ParticleFrame frame;
  frame.spacing = kSpacing;
  std::vector<Vec3d> x = g.solid;
  x.insert(x.end(), g.ice.begin(), g.ice.end());
  std::vector<std::uint8_t> phase(g.solid.size(), 1);
  phase.resize(x.size(), 2);
  std::vector<float> film(x.size(), 0.0f);
  for (std::size_t i = 0; i < g.solid.size(); ++i) film[i] = g.solid[i].z > 0.3 * kRadius ? 1.0f : 0.0f;
  frame.SetPositions(x);
  frame.Set("phase", phase);
  frame.Set("water_film", film);
  frame.Set("object_id", std::vector<std::uint32_t>(x.size(), 0));
  return clean::MeasureIce(result.mesh, frame, {0, 0, -9.81}, {}, {});
}

TEST(IceLook, FilteredGlazeOnASphereIsOneSmoothCoat) {
  const Glaze glaze = GlazeOnASphere();
  const surface::Settings raw;  // the union of particle shapes, unfiltered
  // The scene defaults rime-surface and rime-bake use.
  const surface::Settings filtered = surface::FromScene(io::SurfaceSettings{}, surface::Field::kEllipsoids);
  const clean::IceMetrics before = Measure(glaze, raw), after = Measure(glaze, filtered);
  std::printf(
      "raw: %zu pieces, noise %.3f d_p, sharp %.1f %%, %lld handles; filtered: %zu pieces, noise %.3f d_p, sharp %.1f %%, %lld handles\n",
      before.components, before.noise_rms, 100 * before.sharp_area_fraction, (long long)before.handles, after.components, after.noise_rms,
      100 * after.sharp_area_fraction, (long long)after.handles);
  // Every wetted solid particle under the cap is covered, by a coat about two particles thick.
  EXPECT_GT(after.glaze_coverage, 0.9);
  EXPECT_NEAR(after.thickness_mean, 2.0, 0.5);
  EXPECT_TRUE(after.icicles.empty());
  // The filtered coat is one piece, without specks or pores, and smooth at the particle scale.
  EXPECT_EQ(after.components, 1u);
  EXPECT_EQ(after.specks, 0u);
  EXPECT_EQ(after.handles, 0);
  // The RMS distance to a smoothed copy also counts the coat's rim and the sphere's own curvature
  // (0.072 -> 0.056 d_p here), so the curvature measure is the sharper test of particle bumps.
  EXPECT_LT(after.noise_rms, 0.85 * before.noise_rms);
  EXPECT_LT(after.sharp_area_fraction, 0.5 * before.sharp_area_fraction);
  EXPECT_LT(after.sharp_area_fraction, 0.05);
}

}  // namespace
}  // namespace rime
