/// @file mesh.h
/// @brief Triangle meshes exchanged between stages: OBJ (with vertex normals) and binary PLY (with
/// per-vertex normals and velocity for motion blur). Writes are atomic.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <vector>

#include "rime/core/math.h"

namespace rime::io {

struct TriMesh {
  std::vector<Vec3f> positions;                         // m
  std::vector<Vec3f> normals;                           // per vertex, unit; empty = none
  std::vector<Vec3f> velocities;                        // per vertex, m/s; empty = none
  std::vector<std::array<std::uint32_t, 3>> triangles;  // counter-clockwise seen from outside

  std::size_t vertex_count() const { return positions.size(); }
  std::size_t triangle_count() const { return triangles.size(); }
  bool empty() const { return triangles.empty(); }
};

/// Reads .obj or .ply (ASCII or binary little-endian), chosen by extension. Polygons are
/// triangulated as fans. PLY vertex properties vx, vy, vz become velocities; nx, ny, nz normals.
/// Throws rime::Error(kBadInput) naming the file and the problem (missing, unreadable, NaN, bad index).
TriMesh ReadMesh(const std::filesystem::path& path);

/// Writes by extension: .obj (positions, normals) or .ply (binary, positions, normals, velocities).
/// An empty mesh gives a valid empty file. Atomic; throws rime::Error(kIo) on failure.
void WriteMesh(const std::filesystem::path& path, const TriMesh& mesh);

}  // namespace rime::io
