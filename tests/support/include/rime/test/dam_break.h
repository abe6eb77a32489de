// The dam break that rime-bench-sim and rime-gpu-check time (PERFORMANCE.md's scene): a cube of
// water particles 1.1 d_p from the corner of an open 4 × 3 × 1.5 m box sampled at half spacing,
// d_p = 0.0264 m, fixed Δt = 1 ms, η = 0.1 %, the examples' freezing thresholds.
#pragma once

#include <memory>
#include <set>
#include <string>

#include "rime/exec/device.h"
#include "rime/io/scene.h"
#include "rime/sph/simulation.h"
#include "rime/test/sph_scenes.h"

namespace rime::test {

inline constexpr double kDamBreakSpacing = 0.0264;

/// The scene with `edge`³ water particles and these modules.
inline io::Scene DamBreakScene(int edge, std::set<std::string> modules) {
  const double dp = kDamBreakSpacing;
  io::Scene scene;
  scene.fluid.spacing = dp;
  scene.modules = std::move(modules);
  scene.solver.time_step = io::TimeStep::kFixed;
  scene.solver.dt = 0.001;
  scene.solver.eta = 0.001;
  scene.freezing.glaze_threshold = 0.05;
  scene.freezing.icicle_threshold = 0.01;
  io::FluidBlock block;
  block.min = {1.1 * dp, 1.1 * dp, 1.1 * dp};
  block.max = block.min + Vec3d(edge - 1, edge - 1, edge - 1) * dp;
  scene.fluid_blocks.push_back(block);
  io::SolidObject box;
  box.name = "box";
  scene.solids.push_back(box);
  return scene;
}

/// The solver for a dam-break scene in its box (`box_scale` times 4 × 3 × 1.5 m), initialised.
inline std::unique_ptr<sph::Simulation<float>> MakeDamBreak(const io::Scene& scene, const exec::Device& device, double box_scale = 1.0) {
  auto sim = std::make_unique<sph::Simulation<float>>(scene, device);
  sim->AddBoundaryObject(sph::test::BoxBoundary(scene.fluid.spacing, 4.0 * box_scale, 3.0 * box_scale, 1.5 * box_scale), "box");
  sim->Initialize();
  return sim;
}

}  // namespace rime::test
