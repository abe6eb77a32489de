// Meshing the level set (OpenVDB volumeToMesh) and VDB file input/output.
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <fmt/format.h>

#include <algorithm>
#include <numeric>

#include "grids.h"
#include "rime/core/atomic_file.h"
#include "rime/core/error.h"
#include "rime/exec/parallel.h"

namespace rime::surface {
namespace {

struct DisjointSets {
  std::vector<std::uint32_t> parent;
  explicit DisjointSets(std::size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  std::uint32_t Find(std::uint32_t a) {
    while (parent[a] != a) a = parent[a] = parent[parent[a]];
    return a;
  }
  void Join(std::uint32_t a, std::uint32_t b) {
    a = Find(a), b = Find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
};

// Removes closed shells with negative signed volume: the inward-facing surfaces of voids enclosed
// in the body (e.g. the gaps a union of r_iso = 0.75 d_p spheres leaves at cubic cell centres).
std::uint64_t DropVoidShells(io::TriMesh& mesh) {
  const std::size_t nv = mesh.positions.size();
  DisjointSets sets(nv);
  for (const auto& t : mesh.triangles) sets.Join(t[0], t[1]), sets.Join(t[1], t[2]);
  std::vector<double> volume(nv, 0.0);
  for (const auto& t : mesh.triangles) {
    const Vec3d a(mesh.positions[t[0]]), b(mesh.positions[t[1]]), c(mesh.positions[t[2]]);
    volume[sets.Find(t[0])] += Dot(a, Cross(b, c)) / 6;
  }
  // Volumes are taken about the origin; shift-invariant only for closed shells, which these are.
  std::uint64_t dropped = 0;
  for (std::size_t v = 0; v < nv; ++v)
    if (sets.Find(std::uint32_t(v)) == v && volume[v] < 0) ++dropped;
  if (dropped == 0) return 0;
  // Filter and compact in place (these meshes can hold tens of millions of triangles).
  auto& tris = mesh.triangles;
  tris.erase(std::remove_if(tris.begin(), tris.end(), [&](const auto& t) { return volume[sets.Find(t[0])] < 0; }), tris.end());
  std::vector<double>().swap(volume);
  std::vector<std::uint32_t>& remap = sets.parent;  // reuse: old vertex -> new vertex
  std::fill(remap.begin(), remap.end(), ~0u);
  std::uint32_t next = 0;
  for (auto& t : tris)
    for (auto& v : t) {
      if (remap[v] == ~0u) remap[v] = next++;
      v = remap[v];
    }
  std::vector<Vec3f> positions(next);
  for (std::size_t v = 0; v < nv; ++v)
    if (remap[v] != ~0u) positions[remap[v]] = mesh.positions[v];
  mesh.positions = std::move(positions);
  tris.shrink_to_fit();
  return dropped;
}

void ComputeNormals(io::TriMesh& mesh) {
  std::vector<Vec3f> normals(mesh.positions.size(), Vec3f(0, 0, 0));
  for (const auto& t : mesh.triangles) {
    const Vec3f& a = mesh.positions[t[0]];
    const Vec3f n = Cross(mesh.positions[t[1]] - a, mesh.positions[t[2]] - a);  // area weighted
    for (auto v : t) normals[v] += n;
  }
  exec::cpu::ParallelFor(Index(normals.size()), [&](Index v) {
    const float len = Norm(normals[v]);
    normals[v] = len > 0 ? normals[v] / len : Vec3f(0, 0, 1);
  });
  mesh.normals = std::move(normals);
}

}  // namespace

std::uint64_t ExtractMesh(const openvdb::FloatGrid& grid, bool keep_voids, io::TriMesh& mesh) {
  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> triangles;
  std::vector<openvdb::Vec4I> quads;
  openvdb::tools::volumeToMesh(grid, points, triangles, quads, 0.0, 0.0);
  mesh = {};
  mesh.positions.resize(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) mesh.positions[i] = Vec3f(points[i].x(), points[i].y(), points[i].z());
  std::vector<openvdb::Vec3s>().swap(points);  // free as we go: meshes of tens of millions of triangles
  mesh.triangles.reserve(triangles.size() + 2 * quads.size());
  // volumeToMesh winds clockwise seen from outside: reverse (LIBRARY_NOTES.md).
  for (const auto& t : triangles) mesh.triangles.push_back({t[2], t[1], t[0]});
  std::vector<openvdb::Vec3I>().swap(triangles);
  for (const auto& q : quads) {
    mesh.triangles.push_back({q[2], q[1], q[0]});
    mesh.triangles.push_back({q[3], q[2], q[0]});
  }
  std::vector<openvdb::Vec4I>().swap(quads);
  const std::uint64_t dropped = keep_voids ? 0 : DropVoidShells(mesh);
  ComputeNormals(mesh);
  return dropped;
}

void WriteVdb(const std::filesystem::path& path, const Result& result) {
  InitializeOpenVdb();
  openvdb::GridPtrVec grids;
  if (result.grids && result.grids->surface) grids.push_back(result.grids->surface);
  else grids.push_back(EmptyLevelSet(result.stats.voxel_size > 0 ? result.stats.voxel_size : 1.0, 3));
  if (result.grids && result.grids->velocity) grids.push_back(result.grids->velocity);
  if (result.grids && result.grids->density) grids.push_back(result.grids->density);
  AtomicFile atomic(path);
  try {
    openvdb::io::File file(atomic.temp_path().string());
    file.setCompression(openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK);
    file.write(grids);
    file.close();
  } catch (const openvdb::Exception& e) {
    throw IoError(fmt::format("cannot write VDB file: {}", e.what()), path.string());
  }
  atomic.Commit();
}

std::vector<VdbGridInfo> InspectVdb(const std::filesystem::path& path) {
  InitializeOpenVdb();
  std::vector<VdbGridInfo> out;
  try {
    openvdb::io::File file(path.string());
    file.open();
    for (auto it = file.beginName(); it != file.endName(); ++it) {
      openvdb::GridBase::Ptr grid = file.readGrid(it.gridName());
      VdbGridInfo info;
      info.name = grid->getName();
      info.grid_class = grid->getGridClass() == openvdb::GRID_LEVEL_SET    ? "level set"
                        : grid->getGridClass() == openvdb::GRID_FOG_VOLUME ? "fog volume"
                                                                            : "unknown";
      info.voxel_size = grid->voxelSize()[0];
      info.active_voxels = grid->activeVoxelCount();
      if (auto f = openvdb::gridPtrCast<openvdb::FloatGrid>(grid)) info.background = f->background();
      out.push_back(info);
    }
    file.close();
  } catch (const openvdb::Exception& e) {
    throw InputError(fmt::format("cannot read VDB file: {}", e.what()), path.string());
  }
  return out;
}

}  // namespace rime::surface
