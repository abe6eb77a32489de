/// @file memory_estimate.h
/// @brief rime-sim's peak memory, estimated from particle counts before any array is allocated.
#pragma once

#include "rime/io/scene.h"

namespace rime {

struct SimulationCounts {
  double fluid = 0;       // water particles at their most (blocks plus everything the emitters add)
  double boundary = 0;    // boundary particles of every solid
  bool freezing = false;  // the freezing module's per-particle state
  int scalar_bytes = 4;   // [water] precision: 4 (float) or 8 (double)
};

/// Peak resident bytes: per-particle arrays, neighbour lists (and the search's staged matches) at
/// about 40 fluid and 20 boundary neighbours per water particle, and the frame snapshot being written. Calibrated against
/// measured peaks in docs/reliability.md.
double EstimateSimulationBytes(const SimulationCounts& counts);

}  // namespace rime
