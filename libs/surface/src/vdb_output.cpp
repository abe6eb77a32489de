// Meshing the level set (OpenVDB volumeToMesh) and VDB file input/output.
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/VolumeToMesh.h>
#include <openvdb/tree/LeafManager.h>
#include <tbb/parallel_reduce.h>

#include <fmt/format.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif

#include <algorithm>
#include <cstring>
#include <fstream>
#include <functional>
#include <numeric>

#include "grids.h"
#include "rime/core/atomic_file.h"
#include "rime/core/error.h"
#include "rime/core/hash.h"
#include "rime/core/union_find.h"
#include "rime/exec/parallel.h"

namespace rime::surface {
namespace {

// Removes closed shells with negative signed volume: the inward-facing surfaces of voids enclosed
// in the body (e.g. the gaps a union of r_iso = 0.75 d_p spheres leaves at cubic cell centres).
std::uint64_t DropVoidShells(io::TriMesh& mesh) {
  const std::size_t nv = mesh.positions.size();
  UnionFind sets(nv);
  for (const auto& t : mesh.triangles) sets.Unite(t[0], t[1]), sets.Unite(t[1], t[2]);
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

// Sign-changing voxel edges with an active end: the number of quads the mesher makes, to size the
// mesh once instead of growing it (a growing vector briefly holds 1.5–3 times its size).
std::uint64_t CountSurfaceEdges(const openvdb::FloatTree& tree) {
  openvdb::tree::LeafManager<const openvdb::FloatTree> leaves(tree);
  return tbb::parallel_reduce(
      leaves.leafRange(), std::uint64_t(0),
      [&](const auto& range, std::uint64_t sum) {
        openvdb::tree::ValueAccessor<const openvdb::FloatTree> acc(tree);
        for (auto leaf = range.begin(); leaf; ++leaf)
          for (auto v = leaf->cbeginValueOn(); v; ++v) {
            const bool inside = *v < 0;
            const openvdb::Coord c = v.getCoord();
            sum += (acc.getValue(c.offsetBy(1, 0, 0)) < 0) != inside;
            sum += (acc.getValue(c.offsetBy(0, 1, 0)) < 0) != inside;
            sum += (acc.getValue(c.offsetBy(0, 0, 1)) < 0) != inside;
          }
        return sum;
      },
      std::plus<>());
}

// A vertex near a slab cut, by the bits of its position (both slabs compute it alike).
struct FaceVertex {
  std::uint32_t key[3];
  std::uint32_t index;  // in the mesh
  bool operator<(const FaceVertex& o) const { return std::lexicographical_compare(key, key + 3, o.key, o.key + 3); }
};

}  // namespace

// Slab by slab along the longest axis: OpenVDB's mesher keeps index and sign trees for every leaf
// plus the whole point and polygon lists, which doubled the peak memory of large frames. A slab
// (at most slab_leaves leaves, cut at leaf planes) is meshed from a copy of its leaves and interior
// tiles with an 8-voxel halo; a polygon belongs to the slab holding its centroid (both slabs compute
// it from the same voxels, bit for bit), and vertices within 3 voxels of the cut are welded to the
// previous slab's by exact position.
std::uint64_t ExtractMesh(const openvdb::FloatGrid& grid, bool keep_voids, io::TriMesh& mesh, std::size_t slab_leaves) {
  using Tree = openvdb::FloatTree;
  constexpr int kLeaf = 8, kHalo = 8, kWeld = 3;
  mesh = {};
  const Tree& tree = grid.tree();
  const openvdb::math::Transform& xform = grid.transform();
  std::vector<const Tree::LeafNodeType*> leaves;
  leaves.reserve(tree.leafCount());
  for (auto leaf = tree.cbeginLeaf(); leaf; ++leaf) leaves.push_back(leaf.getLeaf());
  if (leaves.empty()) return 0;
  openvdb::CoordBBox box;
  tree.evalLeafBoundingBox(box);
  const openvdb::Coord extent = box.dim();
  const int axis = extent.x() >= extent.y() && extent.x() >= extent.z() ? 0 : (extent.y() >= extent.z() ? 1 : 2);
  std::sort(leaves.begin(), leaves.end(), [axis](const auto* a, const auto* b) { return a->origin()[axis] < b->origin()[axis]; });
  std::vector<std::pair<Tree::ValueType, openvdb::CoordBBox>> tiles;  // interior tiles (the mesher needs their sign)
  std::vector<openvdb::Index> tile_levels;
  auto tile = tree.cbeginValueAll();
  tile.setMaxDepth(Tree::ValueAllCIter::LEAF_DEPTH - 1);  // tiles only, not the leaves' voxels
  for (auto& it = tile; it; ++it) {
    if (*it < 0) {
      openvdb::CoordBBox b;
      it.getBoundingBox(b);
      tiles.emplace_back(*it, b);
      tile_levels.push_back(openvdb::Index(it.getLevel()));
    }
  }
  // Cuts at whole leaf planes, at most slab_leaves leaves per slab (one plane may exceed it).
  std::vector<int> cuts{leaves.front()->origin()[axis]};
  for (std::size_t k = 0, in_slab = 0; k < leaves.size();) {
    std::size_t plane_end = k;
    while (plane_end < leaves.size() && leaves[plane_end]->origin()[axis] == leaves[k]->origin()[axis]) ++plane_end;
    if (in_slab > 0 && in_slab + (plane_end - k) > slab_leaves) cuts.push_back(leaves[k]->origin()[axis]), in_slab = 0;
    in_slab += plane_end - k;
    k = plane_end;
  }
  cuts.push_back(leaves.back()->origin()[axis] + kLeaf);

  const std::uint64_t quads_expected = CountSurfaceEdges(tree);
  mesh.positions.reserve(quads_expected + quads_expected / 50 + 64);  // V ≈ F on a closed quad mesh
  mesh.triangles.reserve(2 * quads_expected);
  // World to index space of our grids (uniform scale and translation), without the virtual map call.
  const double inv_dx = 1.0 / xform.voxelSize()[0];
  const openvdb::Vec3d world_origin = xform.indexToWorld(openvdb::Vec3d(0, 0, 0));
  const auto to_index = [&](const openvdb::Vec3d& w) { return (w[axis] - world_origin[axis]) * inv_dx; };

  std::vector<FaceVertex> previous, next;  // vertices near the last cut / near this slab's far cut
  std::vector<std::uint32_t> global;
  for (std::size_t slab = 0; slab + 1 < cuts.size(); ++slab) {
    const int lo = cuts[slab], hi = cuts[slab + 1];
    auto part = std::make_shared<Tree>(tree.background());
    const auto first =
        std::lower_bound(leaves.begin(), leaves.end(), lo - kHalo, [axis](const auto* leaf, int v) { return leaf->origin()[axis] < v; });
    for (auto it = first; it != leaves.end() && (*it)->origin()[axis] < hi + kHalo; ++it) part->addLeaf(new Tree::LeafNodeType(**it));
    for (std::size_t t = 0; t < tiles.size(); ++t)
      if (tiles[t].second.max()[axis] >= lo - kHalo && tiles[t].second.min()[axis] < hi + kHalo)
        part->addTile(tile_levels[t], tiles[t].second.min(), tiles[t].first, false);
    auto part_grid = openvdb::FloatGrid::create(part);
    part_grid->setTransform(xform.copy());
    part_grid->setGridClass(openvdb::GRID_LEVEL_SET);
    openvdb::tools::VolumeToMesh mesher(0.0, 0.0);
    mesher(*part_grid);
    part_grid.reset();
    part.reset();
    const openvdb::Vec3s* points = mesher.pointList().get();
    global.assign(mesher.pointListSize(), ~0u);
    next.clear();
    const auto owned = [&](const openvdb::Vec3d& centroid_world) {
      const double c = std::floor(to_index(centroid_world));
      return c >= lo && c < hi;
    };
    const auto vertex = [&](std::uint32_t local) {
      std::uint32_t& g = global[local];
      if (g != ~0u) return g;
      const openvdb::Vec3s& p = points[local];
      const double c = to_index(openvdb::Vec3d(p));
      FaceVertex fv;
      const float xyz[3] = {p.x(), p.y(), p.z()};
      std::memcpy(fv.key, xyz, sizeof fv.key);
      if (c - lo < kWeld) {
        const auto it = std::lower_bound(previous.begin(), previous.end(), fv);
        if (it != previous.end() && std::equal(fv.key, fv.key + 3, it->key)) return g = it->index;
      }
      g = std::uint32_t(mesh.positions.size());
      mesh.positions.push_back(Vec3f(p.x(), p.y(), p.z()));
      if (hi - c < kWeld) fv.index = g, next.push_back(fv);
      return g;
    };
    auto& pools = mesher.polygonPoolList();
    for (std::size_t n = 0; n < mesher.polygonPoolListSize(); ++n) {
      openvdb::tools::PolygonPool& pool = pools[n];
      // volumeToMesh winds clockwise seen from outside: reverse (LIBRARY_NOTES.md).
      for (std::size_t k = 0; k < pool.numQuads(); ++k) {
        const openvdb::Vec4I& q = pool.quad(k);
        const openvdb::Vec3d centroid =
            (openvdb::Vec3d(points[q[0]]) + openvdb::Vec3d(points[q[1]]) + openvdb::Vec3d(points[q[2]]) + openvdb::Vec3d(points[q[3]])) *
            0.25;
        if (!owned(centroid)) continue;
        const std::uint32_t v0 = vertex(q[0]), v1 = vertex(q[1]), v2 = vertex(q[2]), v3 = vertex(q[3]);
        mesh.triangles.push_back({v2, v1, v0});
        mesh.triangles.push_back({v3, v2, v0});
      }
      for (std::size_t k = 0; k < pool.numTriangles(); ++k) {
        const openvdb::Vec3I& t = pool.triangle(k);
        const openvdb::Vec3d centroid = (openvdb::Vec3d(points[t[0]]) + openvdb::Vec3d(points[t[1]]) + openvdb::Vec3d(points[t[2]])) / 3.0;
        if (!owned(centroid)) continue;
        const std::uint32_t v0 = vertex(t[0]), v1 = vertex(t[1]), v2 = vertex(t[2]);
        mesh.triangles.push_back({v2, v1, v0});
      }
      pool.clearQuads();
      pool.clearTriangles();
    }
    std::sort(next.begin(), next.end());
    previous.swap(next);
#ifdef __GLIBC__
    malloc_trim(0);  // the mesher's scratch, freed by its worker threads, would otherwise stay resident
#endif
  }
  std::vector<FaceVertex>().swap(previous);
  std::vector<FaceVertex>().swap(next);
  std::vector<std::uint32_t>().swap(global);
  const std::uint64_t dropped = keep_voids ? 0 : DropVoidShells(mesh);
  ComputeNormals(mesh);
  return dropped;
}

namespace {

// OpenVDB stamps every file with a random UUID (36 characters after the 21-byte header start).
// Replacing it with one derived from the rest of the file makes the same grids the same bytes on
// every run: bakes are reproducible byte for byte, and rime-bake's early cutoff sees unchanged VDBs.
void DeriveVdbUuidFromContent(const std::filesystem::path& file) {
  constexpr std::streamoff kOffset = 21;
  constexpr std::size_t kLength = 36;
  std::fstream io(file, std::ios::in | std::ios::out | std::ios::binary);
  char uuid[kLength];
  if (!io.seekg(kOffset) || !io.read(uuid, kLength)) return;
  if (uuid[8] != '-' || uuid[13] != '-' || uuid[18] != '-' || uuid[23] != '-') return;  // not the layout this expects
  io.seekp(kOffset);
  io.write("00000000-0000-0000-0000-000000000000", kLength);
  io.flush();
  const std::uint64_t a = HashFile(file), b = Hash64(HexHash(a), 1);
  std::string derived = fmt::format("{:08x}-{:04x}-5{:03x}-{:04x}-{:012x}", a >> 32, (a >> 16) & 0xffff, a & 0xfff,
                                    0x8000 | ((b >> 48) & 0x3fff), b & 0xffffffffffffULL);  // name-based (version 5) form
  io.seekp(kOffset);
  io.write(derived.data(), kLength);
  if (!io.flush()) throw IoError("cannot write VDB file", file.string());
}

}  // namespace

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
    // OpenVDB does not check its stream: a full disk or a file size limit leaves a short file
    // without an error. Reading every grid back is what proves the file complete.
    openvdb::io::File check(atomic.temp_path().string());
    check.open(false);
    for (auto it = check.beginName(); it != check.endName(); ++it) check.readGrid(it.gridName());
    check.close();
  } catch (const std::exception& e) {
    std::string reason = e.what();
    std::replace(reason.begin(), reason.end(), '\n', ' ');  // one error line
    throw IoError(fmt::format("cannot write VDB file (disk full or file size limit?): {}", reason), path.string());
  }
  DeriveVdbUuidFromContent(atomic.temp_path());
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
