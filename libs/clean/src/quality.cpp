// Mesh measures for the cleanup report (see rime/clean/quality.h). Plain C++: no CGAL here, so
// the report is computed the same way for the input (possibly non-manifold) and the output.
#include "rime/clean/quality.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <numbers>
#include <numeric>

#include "rime/core/union_find.h"
#include "rime/exec/parallel.h"

namespace rime::clean {
namespace {

/// Vertex -> incident triangles, compressed rows.
struct VertexFaces {
  std::vector<std::uint32_t> offsets, faces;
  explicit VertexFaces(const io::TriMesh& mesh) : offsets(mesh.positions.size() + 1, 0) {
    for (const auto& t : mesh.triangles)
      for (std::uint32_t v : t) ++offsets[v + 1];
    std::partial_sum(offsets.begin(), offsets.end(), offsets.begin());
    faces.resize(offsets.back());
    std::vector<std::uint32_t> fill(offsets.begin(), offsets.end() - 1);
    for (std::uint32_t f = 0; f < mesh.triangles.size(); ++f)
      for (std::uint32_t v : mesh.triangles[f]) faces[fill[v]++] = f;
  }
};

struct VertexCounts {
  std::size_t boundary_edges = 0, non_manifold_edges = 0, non_manifold_vertex = 0;
};

/// Edges (v, u > v) around v and whether v's triangles form a single fan. Triangles with repeated
/// vertices are skipped (counted as degenerate elsewhere).
VertexCounts CountAroundVertex(const io::TriMesh& mesh, const VertexFaces& vf, std::uint32_t v) {
  // Small local tables: a vertex of a marching-cubes mesh has about six neighbors.
  std::uint32_t neighbors[64];
  std::uint32_t counts[64];
  std::uint32_t link_parent[64];
  std::vector<std::uint32_t> big_neighbors, big_counts, big_parent;
  std::uint32_t* nb = neighbors;
  std::uint32_t* cnt = counts;
  std::uint32_t* parent = link_parent;
  const std::uint32_t begin = vf.offsets[v], end = vf.offsets[v + 1];
  if (2 * (end - begin) > 64) {
    big_neighbors.resize(2 * (end - begin)), big_counts.resize(2 * (end - begin)), big_parent.resize(2 * (end - begin));
    nb = big_neighbors.data(), cnt = big_counts.data(), parent = big_parent.data();
  }
  std::uint32_t n = 0;
  auto slot = [&](std::uint32_t u) {
    for (std::uint32_t k = 0; k < n; ++k)
      if (nb[k] == u) return k;
    nb[n] = u, cnt[n] = 0, parent[n] = n;
    return n++;
  };
  auto find = [&](std::uint32_t a) {
    while (parent[a] != a) a = parent[a] = parent[parent[a]];
    return a;
  };
  for (std::uint32_t i = begin; i < end; ++i) {
    const auto& t = mesh.triangles[vf.faces[i]];
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) continue;
    const int corner = t[0] == v ? 0 : (t[1] == v ? 1 : 2);
    const std::uint32_t a = slot(t[(corner + 1) % 3]), b = slot(t[(corner + 2) % 3]);
    ++cnt[a], ++cnt[b];
    const std::uint32_t ra = find(a), rb = find(b);
    if (ra != rb) parent[std::max(ra, rb)] = std::min(ra, rb);
  }
  VertexCounts out;
  std::uint32_t fans = 0;
  for (std::uint32_t k = 0; k < n; ++k) {
    if (find(k) == k) ++fans;
    if (nb[k] > v) {
      if (cnt[k] == 1) ++out.boundary_edges;
      if (cnt[k] > 2) ++out.non_manifold_edges;
    }
  }
  out.non_manifold_vertex = fans > 1 ? 1 : 0;
  return out;
}

}  // namespace

MeshStats ComputeStats(const io::TriMesh& mesh) {
  MeshStats s;
  s.faces = mesh.triangles.size();
  if (mesh.triangles.empty()) return s;
  const VertexFaces vf(mesh);
  const std::size_t nv = mesh.positions.size();

  std::atomic<std::size_t> boundary{0}, nm_edges{0}, nm_vertices{0}, used{0};
  constexpr Index kChunk = 4096;
  const Index chunks = Index((nv + kChunk - 1) / kChunk);
  exec::cpu::ParallelFor(chunks, [&](Index c) {
    VertexCounts sum;
    std::size_t referenced = 0;
    for (std::size_t v = std::size_t(c) * kChunk; v < std::min(nv, std::size_t(c + 1) * kChunk); ++v) {
      if (vf.offsets[v] == vf.offsets[v + 1]) continue;
      ++referenced;
      const VertexCounts k = CountAroundVertex(mesh, vf, std::uint32_t(v));
      sum.boundary_edges += k.boundary_edges, sum.non_manifold_edges += k.non_manifold_edges;
      sum.non_manifold_vertex += k.non_manifold_vertex;
    }
    boundary += sum.boundary_edges, nm_edges += sum.non_manifold_edges, nm_vertices += sum.non_manifold_vertex;
    used += referenced;
  });
  s.vertices = used, s.boundary_edges = boundary, s.non_manifold_edges = nm_edges, s.non_manifold_vertices = nm_vertices;

  UnionFind components(nv);
  for (const auto& t : mesh.triangles) components.Unite(t[0], t[1]), components.Unite(t[1], t[2]);
  for (std::size_t v = 0; v < nv; ++v)
    if (vf.offsets[v] != vf.offsets[v + 1] && components.Find(std::uint32_t(v)) == v) ++s.components;

  // Volume about the centroid of the vertices: fewer cancelling digits for meshes far from the origin.
  Vec3d center(0, 0, 0);
  for (const Vec3f& p : mesh.positions) center += Vec3d(p);
  center /= double(std::max<std::size_t>(nv, 1));
  double area = 0, volume = 0, edge_sum = 0;
  double min_angle = std::numbers::pi;
  for (const auto& t : mesh.triangles) {
    const Vec3d a = Vec3d(mesh.positions[t[0]]) - center, b = Vec3d(mesh.positions[t[1]]) - center,
                c = Vec3d(mesh.positions[t[2]]) - center;
    const Vec3d cross = Cross(b - a, c - a);
    const double twice_area = Norm(cross);
    area += 0.5 * twice_area;
    volume += Dot(a, Cross(b, c)) / 6.0;
    const double ab = Norm(b - a), bc = Norm(c - b), ca = Norm(a - c);
    edge_sum += ab + bc + ca;
    if (twice_area == 0) {
      ++s.degenerate_faces;
      min_angle = 0;
      continue;
    }
    // Angle at each corner from atan2(|cross|, dot): accurate for slivers, unlike acos.
    const double angles[3] = {std::atan2(twice_area, Dot(b - a, c - a)), std::atan2(twice_area, Dot(c - b, a - b)),
                              std::atan2(twice_area, Dot(a - c, b - c))};
    min_angle = std::min({min_angle, angles[0], angles[1], angles[2]});
  }
  s.area = area, s.volume = volume;
  s.min_angle_deg = min_angle * 180.0 / std::numbers::pi;
  s.mean_edge_length = edge_sum / (3.0 * double(mesh.triangles.size()));
  return s;
}

}  // namespace rime::clean
