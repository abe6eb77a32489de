/// @file decimate.h
/// @brief Garland-Heckbert (plane quadric) edge-collapse decimation in batches, without CGAL.
///
/// Same cost and placement as CGAL's GarlandHeckbert_plane_policies (sum of squared distances to
/// the planes of the original faces, optimal point), but the collapses run in passes over a flat
/// array instead of one mutable priority queue over a halfedge structure: each pass computes every
/// edge's cost once, sorts the cheapest, and collapses them in order, skipping an edge whose
/// end-point already moved in this pass (its cost is stale; it is re-costed in the next pass).
/// Every collapse is checked against the mesh as it is at that moment (link condition, no face
/// flip), so the result stays a manifold with the input's topology.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "rime/core/math.h"

namespace rime::clean {

struct DecimateResult {
  std::size_t collapses = 0;
  int passes = 0;
  bool reached_target = false;  // false: stopped by the error bound or no valid collapse left
};

/// Decimates a manifold, consistently oriented triangle mesh in place down to `target_faces`, or
/// until the cheapest collapse would cost more than `max_error`^2 (m^2, sum of squared plane
/// distances; max_error <= 0: no bound). Vertices on a border or at a non-manifold spot never move.
/// `positions` and `triangles` come back compacted (unused vertices removed).
DecimateResult DecimateQuadric(std::vector<Vec3d>& positions, std::vector<std::array<std::uint32_t, 3>>& triangles,
                               std::size_t target_faces, double max_error);

}  // namespace rime::clean
