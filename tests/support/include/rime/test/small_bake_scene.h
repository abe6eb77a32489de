/// @file small_bake_scene.h
/// @brief The one small scene the end-to-end, farm and farm-benchmark bakes share: about 1,700 water
/// particles falling onto a sphere above the ground, at 20 fps.
#pragma once

#include <string>

#include <fmt/format.h>

namespace rime::test {

/// Scene text named `name` that simulates frames 0..last_frame. The water is surfaced: it exists from
/// frame 0, so every stage has real work on every frame (ice appears only once water has frozen,
/// and frames without ice have nothing to clean).
inline std::string SmallBakeScene(const std::string& name, int last_frame) {
  return fmt::format(R"([scene]
name = "{}"
fps = 20
end_time = {:.3f}

[water]
spacing = 0.025

[sim]
modules = ["gravity", "viscosity", "surface_tension", "freezing"]

[domain]
min = [-0.5, -0.5, -0.05]
max = [0.5, 0.5, 0.8]

[[solid]]
name = "ground"
shape = "plane"
size = [1.0, 1.0, 1.0]

[[solid]]
name = "ball"
shape = "sphere"
radius = 0.12
translate = [0.0, 0.0, 0.2]

[[water_block]]
min = [-0.15, -0.15, 0.4]
max = [0.15, 0.15, 0.55]

[surface]
phase = "water"
)",
                     name, last_frame / 20.0 + 0.001);
}

}  // namespace rime::test
