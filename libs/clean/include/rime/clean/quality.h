/// @file quality.h
/// @brief Topology and shape measures of a triangle mesh (no CGAL): what the cleanup report shows
/// before and after.
#pragma once

#include <cstddef>

#include "rime/io/mesh.h"

namespace rime::clean {

struct MeshStats {
  std::size_t vertices = 0;  // referenced by at least one triangle
  std::size_t faces = 0;
  std::size_t components = 0;             // edge-connected groups of triangles
  std::size_t boundary_edges = 0;         // edges with one incident triangle
  std::size_t non_manifold_edges = 0;     // edges with more than two incident triangles
  std::size_t non_manifold_vertices = 0;  // vertices whose triangles form more than one fan
  std::size_t degenerate_faces = 0;       // repeated vertex index or zero area
  double area = 0;                        // m^2
  double volume = 0;                      // m^3, signed (divergence theorem; exact only when closed)
  double min_angle_deg = 0;               // smallest triangle angle (0 for an empty mesh)
  double mean_edge_length = 0;            // m

  bool closed() const { return boundary_edges == 0 && non_manifold_edges == 0; }
  bool manifold() const { return non_manifold_edges == 0 && non_manifold_vertices == 0; }
};

/// Measures `mesh` in O(faces) (parallel over vertices).
MeshStats ComputeStats(const io::TriMesh& mesh);

}  // namespace rime::clean
