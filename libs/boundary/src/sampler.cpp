#include "rime/boundary/sampler.h"

#include <fmt/format.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>

#include "rime/core/error.h"
#include "rime/core/log.h"
#include "rime/exec/memory.h"
#include "rime/exec/parallel.h"
#include "rime/neighbors/grid.h"

namespace rime::boundary {
namespace {

// Face particles keep this distance from every edge (in units of d_b): more than the 0.5 d_b
// duplicate radius, so face rows never collide with edge particles, and small enough that no
// surface point is farther than d_b from a particle.
constexpr double kFaceMargin = 0.55;
// Particles closer than this (units of d_b) to an earlier particle are removed.
constexpr double kDuplicateRadius = 0.5;

// Points evenly spaced over a segment of `length`, both ends included, at most d apart; a single
// point (the middle) when the segment is shorter than d/2.
std::int64_t RowPointCount(double length, double d) {
  if (length < 0.5 * d) return 1;
  return static_cast<std::int64_t>(std::ceil(length / d - 1e-9)) + 1;
}

// Segments of an edge: the nearest whole number to length/d, so spacing stays within
// [2/3, 3/2) d and a quad's diagonal on a d-lattice gets no midpoint.
std::int64_t EdgeSegments(double length, double d) { return std::max<std::int64_t>(1, std::llround(length / d)); }

struct Triangle {
  Vec3d p[3];
};

// Rows parallel to the longest edge inside the triangle shrunk by kFaceMargin·d towards its
// incenter (the shrunk triangle is exactly the set of points that far from every edge). Calls
// emit(point) for each; returns the count.
template <class Emit>
std::int64_t SampleFaceInterior(const Triangle& t, double d, Emit&& emit) {
  const double la = Norm(t.p[1] - t.p[2]), lb = Norm(t.p[2] - t.p[0]), lc = Norm(t.p[0] - t.p[1]);
  const double perimeter = la + lb + lc;
  const double double_area = Norm(Cross(t.p[1] - t.p[0], t.p[2] - t.p[0]));
  const double inradius = double_area / perimeter;
  const double margin = kFaceMargin * d;
  if (!(inradius > margin)) return 0;
  const Vec3d incenter = (t.p[0] * la + t.p[1] * lb + t.p[2] * lc) / perimeter;
  const double k = (inradius - margin) / inradius;
  // Base = longest edge (q0, q1), apex q2, all of the shrunk triangle.
  int base = 2;  // edge opposite vertex `base` is the longest
  if (la >= lb && la >= lc) base = 0;
  else if (lb >= lc) base = 1;
  const Vec3d q0 = incenter + (t.p[(base + 1) % 3] - incenter) * k;
  const Vec3d q1 = incenter + (t.p[(base + 2) % 3] - incenter) * k;
  const Vec3d q2 = incenter + (t.p[base] - incenter) * k;
  const double base_length = Norm(q1 - q0);
  const double height = double_area / std::max({la, lb, lc}) * k;
  const std::int64_t rows = RowPointCount(height, d);
  std::int64_t count = 0;
  for (std::int64_t r = 0; r < rows; ++r) {
    const double s = rows == 1 ? 0.5 : double(r) / double(rows - 1);
    const Vec3d left = q0 + (q2 - q0) * s, right = q1 + (q2 - q1) * s;
    const std::int64_t points = RowPointCount((1 - s) * base_length, d);
    for (std::int64_t i = 0; i < points; ++i) {
      const double u = points == 1 ? 0.5 : double(i) / double(points - 1);
      emit(left + (right - left) * u);
    }
    count += points;
  }
  return count;
}

Vec3f UnitOr(const Vec3d& v, const Vec3d& fallback) {
  const double n = Norm(v);
  if (n > 0) return Vec3f(v / n);
  const double f = Norm(fallback);
  return f > 0 ? Vec3f(fallback / f) : Vec3f(0, 0, 1);
}

struct Edge {
  std::uint32_t a, b;
  Vec3d normal_sum;      // sum of the adjacent faces' area vectors
  Vec3d first_normal;    // fallback when they cancel (a sheet folded onto itself)
};

void CheckInput(const io::TriMesh& mesh, const SampleOptions& options) {
  if (!(options.spacing > 0) || !std::isfinite(options.spacing))
    throw InputError(fmt::format("boundary spacing must be positive and finite, got {}", options.spacing), options.source);
  if (mesh.triangles.empty()) throw InputError("the mesh has no triangles", options.source);
  for (std::size_t v = 0; v < mesh.positions.size(); ++v)
    if (!IsFinite(mesh.positions[v]))
      throw InputError(fmt::format("vertex {} has a NaN or infinite coordinate", v), options.source);
  const std::size_t nv = mesh.positions.size();
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t)
    for (std::uint32_t v : mesh.triangles[t])
      if (v >= nv) throw InputError(fmt::format("triangle {} uses vertex {} of {}", t, v, nv), options.source);
}

void CheckCount(double count, const SampleOptions& options) {
  if (count > double(options.max_particles))
    throw InputError(fmt::format("spacing {:g} m would make about {:.3g} boundary particles, more than the maximum {} "
                                 "(use a larger spacing or raise --max-particles)",
                                 options.spacing, count, options.max_particles),
                     options.source);
}

}  // namespace

double EstimateSampleCount(const io::TriMesh& mesh, double spacing) {
  double area = 0, edge_length = 0;
  for (const auto& t : mesh.triangles) {
    const Vec3d a(mesh.positions[t[0]]), b(mesh.positions[t[1]]), c(mesh.positions[t[2]]);
    area += 0.5 * Norm(Cross(b - a, c - a));
    edge_length += 0.5 * (Norm(b - a) + Norm(c - b) + Norm(a - c));  // each edge is shared by about two faces
  }
  return area / (spacing * spacing) + edge_length / spacing + double(mesh.positions.size());
}

SurfaceSamples SampleSurface(const io::TriMesh& mesh, const SampleOptions& options) {
  auto phase_start = std::chrono::steady_clock::now();
  const auto phase = [&](const char* name) {  // per-phase timings for --verbose
    const auto now = std::chrono::steady_clock::now();
    log::Debug("sampling {}: {:.1f} ms", name, 1e3 * std::chrono::duration<double>(now - phase_start).count());
    phase_start = now;
  };
  CheckInput(mesh, options);
  CheckCount(EstimateSampleCount(mesh, options.spacing), options);
  const double d = options.spacing;
  SurfaceSamples out;
  SampleStats& stats = out.stats;
  stats.triangles = mesh.triangles.size();

  // 1. Weld vertices with identical positions, so shared edges are found by index.
  const std::size_t nv = mesh.positions.size();
  std::vector<std::uint32_t> order(nv);
  std::iota(order.begin(), order.end(), 0u);
  const auto less = [&](std::uint32_t i, std::uint32_t j) {
    const Vec3f &a = mesh.positions[i], &b = mesh.positions[j];
    if (a.x != b.x) return a.x < b.x;
    if (a.y != b.y) return a.y < b.y;
    if (a.z != b.z) return a.z < b.z;
    return i < j;
  };
  tbb::parallel_sort(order.begin(), order.end(), less);
  std::vector<std::uint32_t> weld(nv);
  std::vector<Vec3d> welded_positions;
  for (std::size_t k = 0; k < nv; ++k) {
    if (k == 0 || !(mesh.positions[order[k]] == mesh.positions[order[k - 1]]))
      welded_positions.push_back(Vec3d(mesh.positions[order[k]]));
    weld[order[k]] = static_cast<std::uint32_t>(welded_positions.size() - 1);
  }
  const std::size_t nw = welded_positions.size();
  phase("check + weld");

  // 2. Valid triangles, their area vectors, and area-weighted vertex normals.
  const std::size_t nt = mesh.triangles.size();
  std::vector<std::array<std::uint32_t, 3>> tris(nt);
  std::vector<Vec3d> area_vectors(nt);
  std::vector<std::uint8_t> valid(nt);
  exec::cpu::ParallelFor(Index(nt), [&](Index t) {
    const auto& src = mesh.triangles[t];
    tris[t] = {weld[src[0]], weld[src[1]], weld[src[2]]};
    const Vec3d &a = welded_positions[tris[t][0]], &b = welded_positions[tris[t][1]], &c = welded_positions[tris[t][2]];
    area_vectors[t] = Cross(b - a, c - a);
    const double longest = std::max({SquaredNorm(b - a), SquaredNorm(c - b), SquaredNorm(a - c)});
    const bool repeated = tris[t][0] == tris[t][1] || tris[t][1] == tris[t][2] || tris[t][0] == tris[t][2];
    valid[t] = !repeated && Norm(area_vectors[t]) > 1e-10 * longest;  // zero area up to round-off
  });
  std::size_t valid_count = 0;
  for (std::size_t t = 0; t < nt; ++t) valid_count += valid[t];
  stats.degenerate_skipped = nt - valid_count;
  if (valid_count == 0)
    throw InputError(fmt::format("all {} triangles are degenerate (zero area)", nt), options.source);

  // Valid triangles around every welded vertex (CSR), so that vertex normals and edges are found
  // per vertex in parallel without sorting.
  std::vector<std::uint32_t> incident_offset(nw + 1, 0);
  for (std::size_t t = 0; t < nt; ++t)
    if (valid[t])
      for (std::uint32_t v : tris[t]) ++incident_offset[v + 1];
  for (std::size_t v = 0; v < nw; ++v) incident_offset[v + 1] += incident_offset[v];
  std::vector<std::uint32_t> incident(incident_offset[nw]), cursor(incident_offset.begin(), incident_offset.end() - 1);
  for (std::size_t t = 0; t < nt; ++t)
    if (valid[t])
      for (std::uint32_t v : tris[t]) incident[cursor[v]++] = static_cast<std::uint32_t>(t);
  std::vector<std::uint32_t>().swap(cursor);
  phase("triangles + incidence");

  // 3. Vertex normals (area-weighted) and distinct edges (a, b > a) with their faces' area vectors,
  // in two passes over the vertices: count, then fill at scanned offsets.
  std::vector<Vec3f> vertex_normals(nw);
  std::vector<std::uint64_t> vertex_edge_offset(nw + 1, 0);
  const auto edges_of = [&](std::uint32_t a, std::vector<Edge>& local) {
    local.clear();
    for (std::uint32_t k = incident_offset[a]; k < incident_offset[a + 1]; ++k) {
      const std::uint32_t t = incident[k];
      for (std::uint32_t b : tris[t]) {
        if (b <= a) continue;
        Edge* found = nullptr;
        for (Edge& e : local)
          if (e.b == b) found = &e;
        if (found) found->normal_sum += area_vectors[t];
        else local.push_back({a, b, area_vectors[t], area_vectors[t]});
      }
    }
  };
  exec::cpu::ParallelFor(Index(nw), [&](Index a) {
    Vec3d sum(0, 0, 0), fallback(0, 0, 0);
    for (std::uint32_t k = incident_offset[a]; k < incident_offset[a + 1]; ++k) {
      sum += area_vectors[incident[k]];
      fallback = area_vectors[incident[k]];
    }
    vertex_normals[a] = UnitOr(sum, fallback);
    thread_local std::vector<Edge> local;
    edges_of(std::uint32_t(a), local);
    vertex_edge_offset[a] = local.size();
  });
  std::exclusive_scan(vertex_edge_offset.begin(), vertex_edge_offset.end(), vertex_edge_offset.begin(), std::uint64_t(0));
  std::vector<Edge> edges(vertex_edge_offset[nw]);
  exec::cpu::ParallelFor(Index(nw), [&](Index a) {
    thread_local std::vector<Edge> local;
    edges_of(std::uint32_t(a), local);
    std::copy(local.begin(), local.end(), edges.begin() + std::ptrdiff_t(vertex_edge_offset[a]));
  });
  stats.edges = edges.size();

  phase("edges");
  // 4. Count, check the total, then fill in parallel at scanned offsets.
  std::vector<std::uint32_t> used_vertices;
  for (std::size_t v = 0; v < nw; ++v)
    if (incident_offset[v + 1] > incident_offset[v]) used_vertices.push_back(std::uint32_t(v));
  stats.welded_vertices = used_vertices.size();
  std::vector<std::uint64_t> edge_offset(edges.size() + 1, 0), face_offset(nt + 1, 0);
  exec::cpu::ParallelFor(Index(edges.size()), [&](Index e) {
    edge_offset[e] = EdgeSegments(Norm(welded_positions[edges[e].b] - welded_positions[edges[e].a]), d) - 1;
  });
  const auto triangle = [&](std::size_t t) {
    return Triangle{{welded_positions[tris[t][0]], welded_positions[tris[t][1]], welded_positions[tris[t][2]]}};
  };
  exec::cpu::ParallelFor(Index(nt), [&](Index t) {
    face_offset[t] = valid[t] ? SampleFaceInterior(triangle(t), d, [](const Vec3d&) {}) : 0;
  });
  std::exclusive_scan(edge_offset.begin(), edge_offset.end(), edge_offset.begin(), std::uint64_t(0));
  std::exclusive_scan(face_offset.begin(), face_offset.end(), face_offset.begin(), std::uint64_t(0));
  stats.vertex_samples = used_vertices.size();
  stats.edge_samples = edge_offset.back();
  stats.face_samples = face_offset.back();
  const std::size_t total = stats.vertex_samples + stats.edge_samples + stats.face_samples;
  CheckCount(double(total), options);

  std::vector<Vec3f> positions(total), normals(total);
  const std::size_t edge_base = stats.vertex_samples, face_base = edge_base + stats.edge_samples;
  exec::cpu::ParallelFor(Index(used_vertices.size()), [&](Index i) {
    const std::uint32_t v = used_vertices[i];
    positions[i] = Vec3f(welded_positions[v]);
    normals[i] = vertex_normals[v];
  });
  exec::cpu::ParallelFor(Index(edges.size()), [&](Index e) {
    const Edge& edge = edges[e];
    const Vec3d a = welded_positions[edge.a], b = welded_positions[edge.b];
    const std::uint64_t first = edge_offset[e], count = edge_offset[e + 1] - first;
    const Vec3f normal = UnitOr(edge.normal_sum, edge.first_normal);
    for (std::uint64_t k = 0; k < count; ++k) {
      positions[edge_base + first + k] = Vec3f(a + (b - a) * (double(k + 1) / double(count + 1)));
      normals[edge_base + first + k] = normal;
    }
  });
  exec::cpu::ParallelFor(Index(nt), [&](Index t) {
    if (face_offset[t + 1] == face_offset[t]) return;
    std::size_t slot = face_base + face_offset[t];
    const Vec3f normal = UnitOr(area_vectors[t], area_vectors[t]);
    SampleFaceInterior(triangle(t), d, [&](const Vec3d& p) {
      positions[slot] = Vec3f(p);
      normals[slot] = normal;
      ++slot;
    });
  });

  phase("count + fill");
  // 5. Remove particles closer than 0.5 d_b to an earlier kept one (greedy in index order:
  // vertices first, then edges, then faces), which is what the sequential loop below computes.
  if (options.remove_near_duplicates && total > 1) {
    // Only particles with an earlier particle within the radius can be removed; find them in
    // parallel, one grid cell at a time (its neighbour cells are looked up once for all of its
    // particles), then run the greedy rule over those alone.
    const float radius = float(kDuplicateRadius * d), radius2 = radius * radius;
    neighbors::UniformGrid<float> grid(exec::Device::Cpu());
    grid.Build(positions.data(), Index(total), float(2 * d));  // a few particles per cell on a surface
    const neighbors::GridView<float> view = grid.view();
    std::vector<std::uint8_t> has_earlier(total, 0), keep(total, 1);
    exec::cpu::ParallelFor(Index(grid.cell_count()), [&](Index cell) {
      const std::uint32_t begin = view.cell_start[cell], end = view.cell_start[cell + 1];
      const Vec3f first = positions[view.sorted_index[begin]];
      const float size = float(2 * d);
      const Vec3f center(view.origin.x + (float(view.CellCoord(first.x, view.origin.x)) + 0.5f) * size,
                         view.origin.y + (float(view.CellCoord(first.y, view.origin.y)) + 0.5f) * size,
                         view.origin.z + (float(view.CellCoord(first.z, view.origin.z)) + 0.5f) * size);
      std::uint32_t range_begin[27], range_end[27];
      int ranges = 0;
      view.ForEachCandidateCell(center, 2 * size, [&](std::uint32_t b, std::uint32_t e) {
        range_begin[ranges] = b, range_end[ranges] = e, ++ranges;
      });
      for (std::uint32_t s = begin; s < end; ++s) {
        const std::uint32_t i = view.sorted_index[s];
        bool earlier = false;
        for (int k = 0; k < ranges && !earlier; ++k)
          for (std::uint32_t t = range_begin[k]; t < range_end[k]; ++t) {
            const std::uint32_t j = view.sorted_index[t];
            if (j < i && SquaredNorm(positions[i] - positions[j]) < radius2) {
              earlier = true;
              break;
            }
          }
        has_earlier[i] = earlier;
      }
    });
    std::size_t removed = 0;
    for (std::size_t i = 0; i < total; ++i) {
      if (!has_earlier[i]) continue;
      bool blocked = false;
      view.ForEachNeighbor(positions[i], radius, [&](std::uint32_t j, const Vec3f&, float) { blocked = blocked || (j < i && keep[j]); });
      if (blocked) keep[i] = 0, ++removed;
    }
    // Kept particles in the grid's Z-curve order: neighbours end up close in memory, which
    // speeds up every later neighbour search over the file (volumes, the simulation).
    std::vector<Vec3f> sorted_positions(total - removed), sorted_normals(total - removed);
    const std::uint32_t* order = grid.order();
    std::size_t w = 0;
    for (std::size_t k = 0; k < total; ++k) {
      const std::uint32_t i = order[k];
      if (!keep[i]) continue;
      sorted_positions[w] = positions[i];
      sorted_normals[w] = normals[i];
      ++w;
    }
    positions.swap(sorted_positions);
    normals.swap(sorted_normals);
    stats.near_duplicates_removed = removed;
  }
  phase("near-duplicate removal");
  out.positions = std::move(positions);
  out.normals = std::move(normals);
  return out;
}

std::vector<float> NearestNeighborDistances(const std::vector<Vec3f>& points, float search_radius) {
  std::vector<float> nearest(points.size(), std::numeric_limits<float>::infinity());
  if (points.empty()) return nearest;
  const exec::Device cpu = exec::Device::Cpu();
  neighbors::UniformGrid<float> grid(cpu);
  grid.Build(points.data(), Index(points.size()), search_radius);
  const neighbors::GridView<float> view = grid.view();
  exec::cpu::ParallelFor(Index(points.size()), [&](Index i) {
    float best = std::numeric_limits<float>::infinity();
    view.ForEachNeighbor(points[i], search_radius, [&](std::uint32_t j, const Vec3f&, float r2) {
      if (j != std::uint32_t(i)) best = std::min(best, r2);
    });
    nearest[i] = std::sqrt(best);
  });
  return nearest;
}

}  // namespace rime::boundary
