// Mesh files through assimp: OBJ, PLY, STL, glTF/GLB, FBX and the other formats it reads.
#include "rime/io/mesh_import.h"

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <fmt/format.h>

#include <cmath>
#include <system_error>

#include "rime/core/error.h"

namespace rime::io {
namespace {

std::vector<TriMesh> ReadParts(const std::filesystem::path& path, ImportStats* stats) {
  const std::string where = path.string();
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw InputError("mesh file not found", where);
  if (std::filesystem::is_directory(path, ec)) throw InputError("expected a mesh file, found a folder", where);

  Assimp::Importer importer;
  const std::string extension = path.extension().string();
  if (extension.empty() || !importer.IsExtensionSupported(extension))
    throw InputError(
        fmt::format("unsupported mesh format '{}' (OBJ, PLY, STL, glTF/GLB, FBX and the other formats assimp reads)", extension), where);
  // Points and lines are dropped; polygons become triangles; the node hierarchy is baked in.
  importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE, aiPrimitiveType_POINT | aiPrimitiveType_LINE);
  importer.SetPropertyBool(AI_CONFIG_PP_PTV_KEEP_HIERARCHY, true);  // bake transforms, keep meshes apart
  const aiScene* scene = importer.ReadFile(
      path.string(), aiProcess_Triangulate | aiProcess_JoinIdenticalVertices | aiProcess_SortByPType | aiProcess_PreTransformVertices);
  if (scene == nullptr) {
    // Post-processing refuses files without faces; read again without it to tell "no triangles"
    // apart from a file assimp cannot parse.
    const std::string reason = importer.GetErrorString();
    Assimp::Importer plain;
    const aiScene* raw = plain.ReadFile(path.string(), 0);
    bool has_faces = false;
    for (unsigned m = 0; raw != nullptr && m < raw->mNumMeshes; ++m) has_faces = has_faces || raw->mMeshes[m]->mNumFaces > 0;
    if (raw != nullptr && !has_faces) throw InputError("the file has no triangles", where);
    throw InputError(fmt::format("cannot read the mesh: {}", reason), where);
  }

  std::vector<TriMesh> parts;
  ImportStats local;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* mesh = scene->mMeshes[m];
    TriMesh part;
    part.positions.reserve(mesh->mNumVertices);
    for (unsigned v = 0; v < mesh->mNumVertices; ++v) {
      const aiVector3D& p = mesh->mVertices[v];
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
        throw InputError(fmt::format("mesh {} vertex {} has a NaN or infinite coordinate", m, v), where);
      part.positions.push_back(Vec3f(p.x, p.y, p.z));
    }
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
      const aiFace& face = mesh->mFaces[f];
      if (face.mNumIndices != 3) continue;  // removed by SortByPType; kept as a guard
      part.triangles.push_back({face.mIndices[0], face.mIndices[1], face.mIndices[2]});
    }
    if (part.triangles.empty()) continue;
    local.triangles_read += part.triangles.size();
    parts.push_back(std::move(part));
  }
  local.meshes = parts.size();
  if (parts.empty()) throw InputError("the file has no triangles", where);
  if (stats) *stats = local;
  return parts;
}

}  // namespace

std::vector<TriMesh> ImportMeshParts(const std::filesystem::path& path, ImportStats* stats) { return ReadParts(path, stats); }

TriMesh ImportMesh(const std::filesystem::path& path, const ImportOptions& options, ImportStats* stats) {
  std::vector<TriMesh> parts = ReadParts(path, stats);
  if (parts.size() == 1) return std::move(parts.front());
  TriMesh merged;
  for (const TriMesh& part : parts) {
    const auto base = static_cast<std::uint32_t>(merged.positions.size());
    merged.positions.insert(merged.positions.end(), part.positions.begin(), part.positions.end());
    for (const auto& t : part.triangles) merged.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  }
  return merged;
}

}  // namespace rime::io
