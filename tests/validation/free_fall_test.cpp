// Validation against analytic motion, and first stability extremes.
#include <gtest/gtest.h>

#include <cmath>

#include "rime/exec/device.h"
#include "rime/sph/simulation.h"
#include "rime/test/sph_scenes.h"

namespace rime {
namespace {

constexpr double kDp = 0.02;

io::Scene Empty() {
  io::Scene scene;
  scene.fluid.spacing = kDp;
  scene.modules = {"gravity", "viscosity", "surface_tension"};
  io::SolidObject box;
  box.name = "box";
  scene.solids.push_back(box);
  return scene;
}

std::unique_ptr<sph::Simulation<double>> Make(const io::Scene& scene) {
  auto sim = std::make_unique<sph::Simulation<double>>(scene, exec::Device::Cpu());
  sim->AddBoundaryObject(sph::test::BoxBoundary(kDp, 0.5, 0.5, 1.2), "box");
  sim->Initialize();
  return sim;
}

// A block falling freely follows z(t) = z0 + v0 t − g t²/2 until it nears the floor (pairwise
// forces cancel in the uniformly moving lattice). Symplectic Euler is first order: its centroid
// error is g Δt t / 2 for constant Δt, so halving Δt must halve the error.
double FreeFallError(double dt) {
  io::Scene scene = Empty();
  scene.solver.time_step = rime::io::TimeStep::kFixed;
  scene.solver.dt = dt;
  io::FluidBlock b;
  b.min = {0.15, 0.15, 0.8};
  b.max = {0.25, 0.25, 0.9};
  b.velocity = {0, 0, 0.5};
  scene.fluid_blocks.push_back(b);
  auto sim = Make(scene);
  const auto x0 = sim->Positions();
  double z0 = 0;
  for (const auto& p : x0) z0 += p.z / x0.size();
  const double t = 0.3;
  while (sim->time() < t - 1e-12) sim->Step(sim->NextTimeStep(t));
  double z = 0;
  for (const auto& p : sim->Positions()) z += p.z / sim->fluid_count();
  return std::fabs(z - (z0 + 0.5 * t - 0.5 * 9.81 * t * t));
}

TEST(Validation, FreeFallMatchesTheAnalyticTrajectory) {
  const double coarse = FreeFallError(0.004), fine = FreeFallError(0.002);
  const double bound = 0.5 * 9.81 * 0.004 * 0.3;  // g Δt t / 2
  std::printf("free fall, 0.3 s: centroid error %.3g m at dt = 4 ms (bound %.3g), %.3g m at 2 ms: ratio %.2f (first order: 2)\n", coarse,
              bound, fine, coarse / fine);
  EXPECT_LT(coarse, 1.05 * bound);
  EXPECT_NEAR(coarse / fine, 2.0, 0.1);
}

TEST(Extremes, EmptySceneRunsAndReportsNoWater) {
  auto sim = Make(Empty());
  EXPECT_EQ(sim->fluid_count(), 0);
  for (int i = 0; i < 5; ++i) sim->Step(sim->NextTimeStep(0.05));
  EXPECT_GT(sim->time(), 0.0);
  EXPECT_EQ(sim->fluid_count(), 0);
}

TEST(Extremes, SingleParticleFallsFreelyWithoutNaN) {
  io::Scene scene = Empty();
  io::FluidBlock b;
  b.shape = rime::io::BlockShape::kSphere;
  b.center = {0.25, 0.25, 0.6};
  b.radius = 0.001;  // one lattice point
  scene.fluid_blocks.push_back(b);
  scene.solver.time_step = rime::io::TimeStep::kFixed;
  scene.solver.dt = 0.002;
  auto sim = Make(scene);
  ASSERT_EQ(sim->fluid_count(), 1);
  while (sim->time() < 0.2 - 1e-12) sim->Step(sim->NextTimeStep(0.2));
  const Vec3d x = sim->Positions()[0];
  EXPECT_TRUE(IsFinite(x));
  // An isolated particle feels only gravity: symplectic Euler gives z = z0 − g Δt² n(n+1)/2 exactly.
  const double n = 100;
  EXPECT_NEAR(x.z, 0.6 - 9.81 * 0.002 * 0.002 * n * (n + 1) / 2, 1e-9);
}

TEST(Extremes, CoincidentParticlesSeparateWithoutNaN) {
  auto sim = Make(Empty());
  std::vector<Vec3d> x{{0.25, 0.25, 0.3}, {0.25, 0.25, 0.3}, {0.26, 0.25, 0.3}};
  sim->SetFluidState(x, std::vector<Vec3d>(3));
  for (int i = 0; i < 50; ++i) sim->Step(sim->NextTimeStep(1.0));
  for (const auto& p : sim->Positions()) EXPECT_TRUE(IsFinite(p));
  for (const auto& v : sim->Velocities()) EXPECT_TRUE(IsFinite(v));
}

}  // namespace
}  // namespace rime
