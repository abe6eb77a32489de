/// @file scene_cleanup.h
/// @brief `[clean]` section of the scene file (rime-clean settings).
///
/// One struct is both the scene section and the options of rime::clean::Clean, so a default
/// lives in exactly one place. Lengths in m, areas in m^2, volumes in m^3. docs/tools.md
/// "rime-clean" explains the operations; the operations run in the order they are numbered here.
#pragma once

#include <span>
#include <string>
#include <string_view>

#include "rime/io/param.h"

namespace rime::io {

class TomlReader;

enum class Repair { kAuto, kAlways, kNever };
inline std::span<const std::string_view> Names(Repair) {
  static constexpr std::string_view names[] = {"auto", "always", "never"};
  return names;
}
enum class DecimateMethod { kBatch, kCgal };
inline std::span<const std::string_view> Names(DecimateMethod) {
  static constexpr std::string_view names[] = {"batch", "cgal"};
  return names;
}
enum class MeshSmoothing { kTangential, kAngle, kNone };
inline std::span<const std::string_view> Names(MeshSmoothing) {
  static constexpr std::string_view names[] = {"tangential", "angle", "none"};
  return names;
}
enum class SelfIntersections { kReport, kRemove, kOff };
inline std::span<const std::string_view> Names(SelfIntersections) {
  static constexpr std::string_view names[] = {"report", "remove", "off"};
  return names;
}

struct CleanupSettings {
  // 1. Polygon soup repair and orientation. "auto": build the mesh directly and fall back to the
  // (slow) soup repair only when the faces do not form a manifold mesh or share no vertices;
  // "always"; "never" (non-manifold faces are then dropped and reported).
  Repair repair = Repair::kAuto;

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
  double target_edge = 0;  // m; 0 = target_edge_factor x mean input edge length
  double target_edge_factor = 1.0;
  int remesh_iterations = 1;

  // 6. Decimation (Garland-Heckbert plane quadrics, edge collapse). Target faces = decimate_faces
  // when > 0, else decimate_ratio x current faces; max_error > 0 also stops as soon as the
  // cheapest collapse would move the surface more than this (m, RMS plane distance).
  // decimate_method "batch": rime's own collapse in sorted passes over flat arrays (about 10x
  // faster than CGAL's, same Hausdorff distance; README "rime-clean"); "cgal": CGAL
  // edge_collapse with GarlandHeckbert_plane_policies (strictly greedy, one priority queue).
  bool decimate = true;
  DecimateMethod decimate_method = DecimateMethod::kBatch;
  double decimate_ratio = 0.5;
  long long decimate_faces = 0;
  double decimate_max_error = 0;  // m

  // 7. Smoothing, after decimation: it evens out the triangles the collapses leave.
  // "tangential": tangential relaxation (moves vertices within the tangent plane, keeps the volume); "angle": angle smoothing (CGAL
  // angle_and_area_smoothing without area term, which needs Ceres); "none". Shape smoothing (mean-curvature flow) is separate, off by
  // default.
  MeshSmoothing smooth = MeshSmoothing::kTangential;
  int smooth_iterations = 2;
  int shape_smooth_iterations = 0;
  double shape_smooth_time = 1e-4;  // time step of the implicit mean-curvature flow, m^2 (CGAL smooth_shape)

  // 8. Self-intersections: "report" (count pairs), "remove" (CGAL 5.5 experimental removal, then
  // count again), "off".
  SelfIntersections self_intersections = SelfIntersections::kReport;

  // Per-vertex velocity: taken from the nearest point of the input surface for every output vertex.
  bool transfer_velocity = true;

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "repair",
            .help = "1. Soup repair: auto (only when the faces are not a manifold mesh), always, never",
            .flag = "--repair"},
      s.repair);
    f(Param{.name = "remove_degenerate", .help = "2. Remove zero-area faces", .flag = "!--no-degenerate"}, s.remove_degenerate);
    f(Param{.name = "remove_almost_degenerate",
            .help = "2. Also remove caps and needles (CGAL experimental, slow)",
            .flag = "--almost-degenerate"},
      s.remove_almost_degenerate);
    f(Param{.name = "cap_angle_deg",
            .unit = "degree",
            .range = Range::Open(90, 180),
            .help = "2. Cap: a triangle with an angle above this",
            .flag = "--cap-angle"},
      s.cap_angle_deg);
    f(Param{.name = "needle_ratio",
            .range = Range::OpenClosed(1, 1e300),
            .help = "2. Needle: longest/shortest edge above this",
            .flag = "--needle-ratio"},
      s.needle_ratio);
    f(Param{.name = "remove_components", .help = "3. Remove small connected components", .flag = "!--no-components"}, s.remove_components);
    f(Param{.name = "min_component_faces",
            .unit = "faces",
            .range = Range::Closed(0, 1e9),
            .help = "3. Remove components with fewer faces (the largest always stays; 0 = off)",
            .flag = "--min-component-faces"},
      s.min_component_faces);
    f(Param{.name = "min_component_area",
            .unit = "m²",
            .range = Range::NonNegative(),
            .help = "3. ... or a smaller area (0 = off)",
            .flag = "--min-component-area"},
      s.min_component_area);
    f(Param{.name = "min_component_volume",
            .unit = "m³",
            .range = Range::NonNegative(),
            .help = "3. ... or a smaller volume, closed components only (0 = off)",
            .flag = "--min-component-volume"},
      s.min_component_volume);
    f(Param{.name = "fill_holes", .help = "4. Fill holes", .flag = "!--no-fill-holes"}, s.fill_holes);
    f(Param{.name = "max_hole_edges",
            .unit = "edges",
            .range = Range::Closed(3, 1e9),
            .help = "4. Fill holes with at most this many border edges",
            .flag = "--max-hole-edges"},
      s.max_hole_edges);
    f(Param{.name = "fair_holes", .help = "4. Fair the filled holes (else triangulate and refine only)", .flag = "!--no-fair"},
      s.fair_holes);
    f(Param{.name = "remesh", .help = "5. Isotropic remeshing (off by default: slow)", .flag = "--remesh,!--no-remesh"}, s.remesh);
    f(Param{.name = "target_edge",
            .unit = "m",
            .range = Range::NonNegative(),
            .help = "5. Remeshing edge length (the flag implies --remesh)",
            .flag = "--target-edge",
            .default_doc = "0 (= factor × mean input edge)"},
      s.target_edge);
    f(Param{.name = "target_edge_factor",
            .range = Range::OpenClosed(0, 100),
            .help = "5. Target edge / mean input edge",
            .flag = "--target-edge-factor"},
      s.target_edge_factor);
    f(Param{.name = "remesh_iterations", .range = Range::Closed(1, 100), .help = "5. Remeshing iterations", .flag = "--remesh-iterations"},
      s.remesh_iterations);
    f(Param{.name = "decimate", .help = "6. Decimate", .flag = "!--no-decimate"}, s.decimate);
    f(Param{.name = "decimate_method",
            .help = "6. batch (rime's quadric collapse in sorted passes, fast) or cgal (CGAL edge_collapse)",
            .flag = "--decimate-method"},
      s.decimate_method);
    f(Param{.name = "decimate_ratio",
            .range = Range::OpenClosed(0, 1),
            .help = "6. Keep this fraction of the faces",
            .flag = "--decimate-ratio"},
      s.decimate_ratio);
    f(Param{.name = "decimate_faces",
            .unit = "faces",
            .range = Range::Closed(0, 1e15),
            .help = "6. Target face count (overrides the ratio)",
            .flag = "--decimate-faces",
            .default_doc = "0 (= use the ratio)"},
      s.decimate_faces);
    f(Param{.name = "decimate_max_error",
            .unit = "m",
            .range = Range::NonNegative(),
            .help = "6. Also stop when a collapse would move the surface more than this (RMS plane distance; 0 = off)",
            .flag = "--decimate-max-error"},
      s.decimate_max_error);
    f(Param{.name = "smooth", .help = "7. tangential (relaxation, keeps volume), angle, none", .flag = "--smooth"}, s.smooth);
    f(Param{.name = "smooth_iterations", .range = Range::Closed(0, 1000), .help = "7. Smoothing iterations", .flag = "--smooth-iterations"},
      s.smooth_iterations);
    f(Param{.name = "shape_smooth_iterations",
            .range = Range::Closed(0, 1000),
            .help = "7. Mean-curvature-flow steps, each piece's volume restored after each (0 = off)",
            .flag = "--shape-smooth-iterations"},
      s.shape_smooth_iterations);
    f(Param{.name = "shape_smooth_time",
            .unit = "m²",
            .range = Range::Positive(),
            .help = "7. Mean-curvature-flow time step (larger smooths more)",
            .flag = "--shape-smooth-time"},
      s.shape_smooth_time);
    f(Param{.name = "self_intersections",
            .help = "8. report (count pairs), remove (CGAL experimental), off",
            .flag = "--self-intersections"},
      s.self_intersections);
    f(Param{.name = "transfer_velocity", .help = "Carry per-vertex velocities from the nearest input point", .flag = "!--no-velocity"},
      s.transfer_velocity);
  }
};

/// Reads the `[clean]` table into `settings` (fields absent from the table keep their defaults).
void ParseCleanupSettings(TomlReader& table, CleanupSettings& settings);

}  // namespace rime::io
