/// @file mesh_import.h
/// @brief Loading arbitrary mesh files (OBJ, PLY, STL, glTF/GLB, FBX, ...) through assimp.
#pragma once

#include <filesystem>
#include <vector>

#include "rime/io/mesh.h"

namespace rime::io {

struct ImportOptions {
  bool merge_meshes = true;  // merge every mesh of the file into one object
};

struct ImportStats {
  std::size_t meshes = 0;
  std::size_t triangles_read = 0;
  std::size_t degenerate_skipped = 0;
};

/// Throws rime::Error(kBadInput) naming the file: missing, unsupported format, no triangles,
/// NaN/Inf coordinates.
/// With merge_meshes = false the result is still one mesh (all parts, vertices not shared between
/// parts); use ImportMeshParts to keep the parts apart.
TriMesh ImportMesh(const std::filesystem::path& path, const ImportOptions& options = {}, ImportStats* stats = nullptr);

/// Every mesh of the file as its own TriMesh (node transforms baked in). Same checks and errors as
/// ImportMesh.
std::vector<TriMesh> ImportMeshParts(const std::filesystem::path& path, ImportStats* stats = nullptr);

}  // namespace rime::io
