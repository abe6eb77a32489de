/// @file scene_cleanup.h
/// @brief `[cleanup]` section of the scene file (rime-clean settings).
///
/// One struct is both the scene section and the options of rime::meshfix::Clean, so a default
/// lives in exactly one place. Lengths in m, areas in m^2, volumes in m^3. README.md
/// "rime-clean" documents every field; the operations run in the order they are numbered here.
#pragma once

#include <string>

namespace rime::io {

class TomlReader;

struct CleanupSettings {
  // 1. Polygon soup repair and orientation. "auto": build the mesh directly and fall back to the
  // (slow) soup repair only when the faces do not form a manifold mesh or share no vertices;
  // "always"; "never" (non-manifold faces are then dropped and reported).
  std::string repair = "auto";

  // 2. Degenerate faces (zero area) and, optionally, almost-degenerate caps/needles.
  bool remove_degenerate = true;
  bool remove_almost_degenerate = false;  // CGAL 5.5 experimental; slow on big meshes
  double cap_angle_deg = 170;             // a triangle with an angle above this is a cap
  double needle_ratio = 8;                // longest/shortest edge above this is a needle

  // 3. Small connected components (stray ice specks). A component is removed when it falls below
  // any threshold that is > 0. The volume threshold applies to closed components only.
  bool remove_components = true;
  int min_component_faces = 64;
  double min_component_area = 0;    // m^2
  double min_component_volume = 0;  // m^3

  // 4. Holes up to this many border edges: triangulate, refine, fair.
  bool fill_holes = true;
  int max_hole_edges = 200;
  bool fair_holes = true;

  // 5. Isotropic remeshing (CGAL isotropic_remeshing). Off by default: it alone costs about
  // 9 us per input triangle, more than the whole default chain (README "rime-clean").
  bool remesh = false;
  double target_edge = 0;           // m; 0 = target_edge_factor x mean input edge length
  double target_edge_factor = 1.0;
  int remesh_iterations = 1;

  // 6. Decimation (Garland-Heckbert plane quadrics, edge collapse). Target faces = decimate_faces
  // when > 0, else decimate_ratio x current faces; max_error > 0 also stops as soon as the
  // cheapest collapse would move the surface more than this (m, RMS plane distance).
  // decimate_method "batch": rime's own collapse in sorted passes over flat arrays (about 10x
  // faster than CGAL's, same Hausdorff distance; README "rime-clean"); "cgal": CGAL
  // edge_collapse with GarlandHeckbert_plane_policies (strictly greedy, one priority queue).
  bool decimate = true;
  std::string decimate_method = "batch";
  double decimate_ratio = 0.5;
  long long decimate_faces = 0;
  double decimate_max_error = 0;  // m

  // 7. Smoothing, after decimation: it evens out the triangles the collapses leave.
  // "tangential": tangential relaxation (moves vertices within the tangent plane, keeps the volume); "angle": angle smoothing (CGAL angle_and_area_smoothing without area
  // term, which needs Ceres); "none". Shape smoothing (mean-curvature flow) is separate, off by default.
  std::string smooth = "tangential";
  int smooth_iterations = 2;
  int shape_smooth_iterations = 0;
  double shape_smooth_time = 1e-4;  // time step of the implicit mean-curvature flow, m^2 (CGAL smooth_shape)

  // 8. Self-intersections: "report" (count pairs), "remove" (CGAL 5.5 experimental removal, then
  // count again), "off".
  std::string self_intersections = "report";

  // Per-vertex velocity: taken from the nearest point of the input surface for every output vertex.
  bool transfer_velocity = true;
};

/// Reads the `[cleanup]` table into `settings` (fields absent from the table keep their defaults).
void ParseCleanupSettings(TomlReader& table, CleanupSettings& settings);

}  // namespace rime::io
