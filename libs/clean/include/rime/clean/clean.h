/// @file clean.h
/// @brief Production cleanup of a marching-cubes ice mesh with CGAL 5.5 (one frame).
///
/// @code
///   io::CleanupSettings settings;              // defaults, or scene.cleanup
///   clean::CleanResult r = clean::Clean(io::ReadMesh(in), settings);
///   io::WriteMesh(out, r.mesh);                // r.report: what changed, what is left
/// @endcode
/// Operations run in the order of io::CleanupSettings; each can be switched off. Per-vertex
/// velocities of the input are carried to every output vertex from the nearest point of the input
/// surface (barycentric interpolation), so motion blur survives remeshing and decimation.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "rime/io/mesh.h"
#include "rime/io/scene_cleanup.h"
#include "rime/clean/quality.h"

namespace rime::clean {

struct OperationRecord {
  std::string name;  // "repair", "degenerate", "components", "holes", "remesh", "smooth", ...
  double seconds = 0;
  double cpu_seconds = 0;  // CPU time of the whole process meanwhile (all threads): the fair cost on a shared machine
  std::string detail;      // what it did, in words ("removed 12 components (340 faces)")
};

struct CleanReport {
  MeshStats before, after;
  std::string repair_path;                // "direct" (faces formed a manifold mesh) or "soup"
  std::size_t faces_dropped_on_load = 0;  // faces that could not be added ("never" repair)
  std::size_t degenerate_faces_removed = 0;
  std::size_t components_removed = 0, component_faces_removed = 0;
  std::size_t holes_filled = 0, holes_left = 0;
  double target_edge = 0;                     // m, remeshing target (0 when remeshing is off)
  std::int64_t self_intersecting_pairs = -1;  // -1: not checked
  bool self_intersections_removed = false;    // "remove" ran and none are left
  bool velocities = false;                    // output carries velocities
  std::vector<OperationRecord> operations;
  std::vector<std::string> warnings;
  double seconds = 0;  // whole chain

  bool manifold() const { return after.manifold(); }
  bool closed() const { return after.closed(); }
};

struct CleanResult {
  io::TriMesh mesh;  // normals left empty: io::WriteMesh computes area-weighted ones
  CleanReport report;
};

/// Cleans one mesh. Throws rime::Error(kBadInput) for an empty mesh or NaN coordinates; a mesh that
/// cannot be made manifold is returned anyway with a warning in the report.
CleanResult Clean(const io::TriMesh& input, const io::CleanupSettings& settings);

/// Velocity of every `targets` point, interpolated at its nearest point on `source`'s surface.
std::vector<Vec3f> TransferVelocities(const io::TriMesh& source, const std::vector<Vec3f>& targets);

nlohmann::json ToJson(const MeshStats& stats);
nlohmann::json ToJson(const CleanReport& report);
/// One line: "82k -> 41k faces, 7 -> 1 components, closed manifold, volume -0.12%, min angle 21.3°, 1.2 s".
std::string SummaryLine(const CleanReport& report);

}  // namespace rime::clean
