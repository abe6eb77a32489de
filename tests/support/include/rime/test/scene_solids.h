/// @file scene_solids.h
/// @brief Samples a scene's solids as rime-boundary does and hands them to a simulation, for tests
/// and benchmarks that simulate a scene in-process. Link rime_sph and rime_boundary.
#pragma once

#include <cstdint>

#include "rime/boundary/object.h"
#include "rime/io/scene.h"
#include "rime/sph/simulation.h"

namespace rime::test {

template <class T>
void AddSceneSolids(sph::Simulation<T>& sim, const io::Scene& scene) {
  boundary::BoundarySettings settings;
  settings.UseWater(scene.fluid);
  for (std::size_t k = 0; k < scene.solids.size(); ++k)
    sim.AddBoundaryObject(boundary::ToParticleFrame(boundary::BuildBoundaryObject(scene.solids[k], std::uint32_t(k), {}, settings)),
                          scene.solids[k].name);
}

}  // namespace rime::test
