/// @file frame_input.h
/// @brief Picks one phase (ice or water) out of a rime-sim particle frame (H5Part) for reconstruction.
#pragma once

#include <string>
#include <vector>

#include "rime/io/particles.h"
#include "rime/surface/reconstruct.h"

namespace rime::surface {

struct SelectOptions {
  bool strict = false;  // refuse ice without `anisotropy_0..5` instead of falling back to isotropic
};

/// Particles of `phase` with their velocities and, for ice, the stored anisotropy D. Reads the
/// root attributes `spacing` (required, > 0) and `smoothing_length` (optional, default spacing).
/// Problems the user should know about (isotropic fallback) are appended to `warnings`.
/// Throws rime::Error(kBadInput) naming the file and dataset for missing or invalid data.
ParticleSet SelectPhase(const io::ParticleFrame& frame, io::Phase phase, const SelectOptions& options, std::vector<std::string>& warnings);

}  // namespace rime::surface
