#include "rime/boundary/sampler.h"

#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <ctime>
#include <limits>
#include <memory>
#include <numeric>
#include <type_traits>

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

// Storage for arrays whose elements are all written before they are read: no value-initialisation
// (a vector's zero fill runs on one thread and takes every page fault there; here the first touch
// happens in the parallel loops). Sampling a large mesh touches a few hundred MB of such arrays.
template <class T>
class Scratch {
  static_assert(std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T>);

 public:
  explicit Scratch(std::size_t n) : data_(static_cast<T*>(std::malloc(std::max<std::size_t>(n * sizeof(T), 1)))), n_(n) {
    if (!data_) throw std::bad_alloc();
  }
  T& operator[](std::size_t i) { return data_.get()[i]; }
  const T& operator[](std::size_t i) const { return data_.get()[i]; }
  T* data() { return data_.get(); }
  const T* data() const { return data_.get(); }
  std::size_t size() const { return n_; }

 private:
  struct Free {
    void operator()(T* p) const { std::free(p); }
  };
  std::unique_ptr<T, Free> data_;
  std::size_t n_;
};

// Smallest i < n with bad(i), or n: parallel, and the same answer for any thread count (so the
// error message names the first bad element).
template <class Bad>
std::size_t FirstBad(std::size_t n, Bad&& bad) {
  std::atomic<std::size_t> first{n};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end() && i < first.load(std::memory_order_relaxed); ++i)
      if (bad(i)) {
        std::size_t cur = first.load();
        while (i < cur && !first.compare_exchange_weak(cur, i)) {}
        return;
      }
  });
  return first.load();
}

// Sum of term(i) over i < n in fixed blocks added in block order: parallel and bit-identical for
// any thread count.
template <class Term>
double DeterministicSum(std::size_t n, Term&& term) {
  constexpr std::size_t kBlock = 1 << 14;
  std::vector<double> partial((n + kBlock - 1) / kBlock, 0.0);
  tbb::parallel_for(std::size_t(0), partial.size(), [&](std::size_t b) {
    double sum = 0;
    for (std::size_t i = b * kBlock, end = std::min(n, (b + 1) * kBlock); i < end; ++i) sum += term(i);
    partial[b] = sum;
  });
  return std::accumulate(partial.begin(), partial.end(), 0.0);
}

// In-place exclusive prefix sum (parallel, deterministic); returns the total, which the caller
// checks against 2^32 before using the (32-bit) offsets.
std::uint64_t Scan(Scratch<std::uint32_t>& values) {
  return exec::ExclusiveScan(exec::Device::Cpu(), values.data(), values.data(), Index(values.size()));
}

void CheckInput(const io::TriMesh& mesh, const SampleOptions& options) {
  if (!(options.spacing > 0) || !std::isfinite(options.spacing))
    throw InputError(fmt::format("boundary spacing must be positive and finite, got {}", options.spacing), options.source);
  if (mesh.triangles.empty()) throw InputError("the mesh has no triangles", options.source);
  const std::size_t nv = mesh.positions.size();
  const std::size_t v = FirstBad(nv, [&](std::size_t i) { return !IsFinite(mesh.positions[i]); });
  if (v < nv) throw InputError(fmt::format("vertex {} has a NaN or infinite coordinate", v), options.source);
  const std::size_t nt = mesh.triangles.size();
  const auto out_of_range = [&](std::size_t t) {
    const auto& tri = mesh.triangles[t];
    return tri[0] >= nv || tri[1] >= nv || tri[2] >= nv;
  };
  const std::size_t t = FirstBad(nt, out_of_range);
  if (t < nt) {
    const auto& tri = mesh.triangles[t];
    const std::uint32_t bad = tri[0] >= nv ? tri[0] : (tri[1] >= nv ? tri[1] : tri[2]);
    throw InputError(fmt::format("triangle {} uses vertex {} of {}", t, bad, nv), options.source);
  }
}

void CheckCount(double count, const SampleOptions& options) {
  if (count > double(options.max_particles) || count > double(0xffffffffu))
    throw InputError(fmt::format("spacing {:g} m would make about {:.3g} boundary particles, more than the maximum {} "
                                 "(use a larger spacing or raise --max-particles)",
                                 options.spacing, count, std::min<std::uint64_t>(options.max_particles, 0xffffffffu)),
                     options.source);
}

// Vertices with identical positions share one representative, the smallest original index among
// them, found with a lock-free hash table (an atomic minimum per slot, so the result does not
// depend on which thread inserts first). Writes rep[v] for every vertex.
void WeldRepresentatives(const std::vector<Vec3f>& positions, Scratch<std::uint32_t>& rep) {
  const std::size_t nv = positions.size();
  constexpr std::uint32_t kEmpty = ~0u;
  const auto bits = [&](std::uint32_t v) {  // -0 folded into +0 so that equal floats have equal bits
    const Vec3f& p = positions[v];
    return std::array<std::uint32_t, 3>{std::bit_cast<std::uint32_t>(p.x + 0.0f), std::bit_cast<std::uint32_t>(p.y + 0.0f),
                                        std::bit_cast<std::uint32_t>(p.z + 0.0f)};
  };
  // Load factor 0.375 to 0.75: short probe sequences and a table of at most 8 bytes per vertex.
  const std::uint32_t size = std::bit_ceil(static_cast<std::uint32_t>(nv + nv / 3 + 16)), mask = size - 1;
  Scratch<std::uint32_t> table(size);
  exec::cpu::ParallelFor(Index(size), [&](Index i) { table[i] = kEmpty; });
  exec::cpu::ParallelFor(Index(nv), [&](Index i) {
    const std::uint32_t v = static_cast<std::uint32_t>(i);
    const auto key = bits(v);
    std::uint64_t h =
        (std::uint64_t(key[0]) | std::uint64_t(key[1]) << 32) * 0x9e3779b97f4a7c15ULL ^ std::uint64_t(key[2]) * 0xc2b2ae3d27d4eb4fULL;
    h ^= h >> 31;
    h *= 0xff51afd7ed558ccdULL;
    for (std::uint32_t slot = static_cast<std::uint32_t>(h >> 32) & mask;; slot = (slot + 1) & mask) {
      std::atomic_ref<std::uint32_t> entry(table[slot]);
      std::uint32_t cur = entry.load(std::memory_order_relaxed);
      if (cur == kEmpty && entry.compare_exchange_strong(cur, v, std::memory_order_relaxed)) {
        rep[v] = slot;
        return;
      }
      if (bits(cur) != key) continue;  // cur is the slot's occupant either way
      while (v < cur && !entry.compare_exchange_weak(cur, v, std::memory_order_relaxed)) {}
      rep[v] = slot;
      return;
    }
  });
  exec::cpu::ParallelFor(Index(nv), [&](Index v) { rep[v] = table[rep[v]]; });  // slot -> its final minimum
}

// Points as separate x, y, z arrays, so that the distance loops below vectorise.
struct Points {
  Scratch<float> x, y, z;
  explicit Points(std::size_t n) : x(n), y(n), z(n) {}
  Vec3f operator[](std::size_t i) const { return Vec3f(x[i], y[i], z[i]); }
  void Set(std::size_t i, const Vec3f& p) { x[i] = p.x, y[i] = p.y, z[i] = p.z; }
};

// The (up to 27) cells around one cell of a grid over the sorted particles, with each cell's lower
// corner so that a particle can skip the cells farther from it than the radius.
struct CellHood {
  std::uint32_t begin[27], end[27];
  Vec3f lo[27];
  int count = 0;
  CellHood(const neighbors::GridView<float>& grid, const Points& sorted, float size, std::uint32_t cell) {
    const neighbors::kernels::CellNeighborhood<float> hood(grid, grid, cell);
    count = hood.count;
    for (int k = 0; k < count; ++k) {
      begin[k] = hood.begin[k], end[k] = hood.end[k];
      const Vec3f p = sorted[begin[k]];
      lo[k] = Vec3f(grid.origin.x + float(grid.CellCoord(p.x, grid.origin.x)) * size,
                    grid.origin.y + float(grid.CellCoord(p.y, grid.origin.y)) * size,
                    grid.origin.z + float(grid.CellCoord(p.z, grid.origin.z)) * size);
    }
    // The cell itself first: on a crowded surface most particles have a close one in their own cell.
    for (int k = 1; k < count; ++k)
      if (begin[k] == grid.cell_start[cell]) std::swap(begin[0], begin[k]), std::swap(end[0], end[k]), std::swap(lo[0], lo[k]);
  }
  // Whether a point of points[begin[k], stop(k)) over the cells k, other than slot `self`, lies
  // closer than sqrt(r2) to p (cells farther than that are skipped; each range is counted
  // branch-free, which vectorises).
  template <class Stop>
  bool AnyWithin(const Points& points, float size, const Vec3f& p, std::uint32_t self, float r2, Stop&& stop) const {
    const float slack = 1e-4f * size;  // cell boxes from floor(): never skip a cell by round-off
    const float *x = points.x.data(), *y = points.y.data(), *z = points.z.data();
    for (int k = 0; k < count; ++k) {
      const float gx = std::max(std::max(lo[k].x - p.x, p.x - lo[k].x - size) - slack, 0.0f);
      const float gy = std::max(std::max(lo[k].y - p.y, p.y - lo[k].y - size) - slack, 0.0f);
      const float gz = std::max(std::max(lo[k].z - p.z, p.z - lo[k].z - size) - slack, 0.0f);
      if (gx * gx + gy * gy + gz * gz >= r2) continue;
      std::uint32_t hits = 0;
      for (std::uint32_t t = begin[k], e = stop(k); t < e; ++t) {
        const float dx = x[t] - p.x, dy = y[t] - p.y, dz = z[t] - p.z;
        hits += (dx * dx + dy * dy + dz * dz < r2) & (t != self);
      }
      if (hits) return true;
    }
    return false;
  }
};

// Removes every particle closer than `radius` to a kept one and writes the kept particles, in the
// Z-curve order of a grid of `cell_size` (>= radius), to out_*. The rule, deterministic and
// parallel: particles without any other within the radius are kept; the others are decided class
// by class (vertices [0, edge_base), edges, then faces), and within a class in 8 rounds, one per
// cell parity (x, y, z mod 2). A round processes its cells in parallel (two cells of the same
// parity are at least one cell apart, so they never interact), each cell's particles in sorted
// order, keeping a particle when no kept one is within the radius. Same output for any number
// of threads.
void ThinAndOrder(const Vec3f* positions, const Vec3f* normals, std::size_t total, std::size_t edge_base, std::size_t face_base,
                  float cell_size, float radius, std::vector<Vec3f>& out_positions, std::vector<Vec3f>& out_normals) {
  neighbors::UniformGrid<float> grid(exec::Device::Cpu());
  grid.Build(positions, Index(total), cell_size);
  const neighbors::GridView<float> view = grid.view();
  const std::uint32_t* order = grid.order();
  const std::size_t cells = grid.cell_count();
  Points sorted(total);
  Scratch<std::uint8_t> kind(total), keep(total), undecided(total), cell_parity(cells);
  exec::cpu::ParallelFor(Index(total), [&](Index s) {
    const std::uint32_t i = order[s];
    sorted.Set(s, positions[i]);
    kind[s] = i < edge_base ? 0 : (i < face_base ? 1 : 2);
  });
  const float r2 = radius * radius;
  // keep = 1 for particles alone within the radius, 0 (undecided) for the others.
  exec::cpu::ParallelFor(Index(cells), [&](Index cell) {
    const std::uint32_t begin = view.cell_start[cell], end = view.cell_start[cell + 1];
    const CellHood hood(view, sorted, cell_size, std::uint32_t(cell));
    bool crowded = false;
    for (std::uint32_t s = begin; s < end; ++s) {
      // The next slots first: on a crowded surface they are usually close (same cell, input order).
      const bool near_next =
          (s > 0 && SquaredNorm(sorted[s - 1] - sorted[s]) < r2) || (s + 1 < total && SquaredNorm(sorted[s + 1] - sorted[s]) < r2);
      undecided[s] = near_next || hood.AnyWithin(sorted, cell_size, sorted[s], s, r2, [&](int k) { return hood.end[k]; });
      keep[s] = !undecided[s];
      crowded = crowded || undecided[s];
    }
    const Vec3f p = sorted[begin];
    cell_parity[cell] = !crowded ? 8
                                 : std::uint8_t((view.CellCoord(p.x, view.origin.x) & 1) | (view.CellCoord(p.y, view.origin.y) & 1) << 1 |
                                                (view.CellCoord(p.z, view.origin.z) & 1) << 2);
  });
  std::vector<std::uint32_t> rounds[8];  // crowded cells by parity, in cell order
  std::size_t crowded_cells = 0;
  for (std::uint32_t cell = 0; cell < cells; ++cell)
    if (cell_parity[cell] < 8) rounds[cell_parity[cell]].push_back(cell), ++crowded_cells;
  // Where there is anything to decide: the kept particles of each cell packed at the cell's first
  // slots of kept_at (kept_n of them, stored at the cell's first slot), so that deciding a
  // particle scans kept ones only.
  Points kept_at(crowded_cells ? total : 0);
  Scratch<std::uint32_t> kept_n(crowded_cells ? total : 0);
  if (crowded_cells)
    exec::cpu::ParallelFor(Index(cells), [&](Index cell) {
      const std::uint32_t begin = view.cell_start[cell];
      std::uint32_t n_kept = 0;
      for (std::uint32_t s = begin; s < view.cell_start[cell + 1]; ++s)
        if (keep[s]) kept_at.Set(begin + n_kept++, sorted[s]);
      kept_n[begin] = n_kept;
    });
  for (std::uint8_t cls = 0; cls < 3; ++cls)
    for (const std::vector<std::uint32_t>& round : rounds)
      exec::cpu::ParallelFor(Index(round.size()), [&](Index r) {
        const std::uint32_t cell = round[r], begin = view.cell_start[cell];
        const CellHood hood(view, sorted, cell_size, cell);
        const auto kept_end = [&](int k) { return hood.begin[k] + kept_n[hood.begin[k]]; };
        for (std::uint32_t s = begin; s < view.cell_start[cell + 1]; ++s) {
          if (!undecided[s] || kind[s] != cls) continue;
          keep[s] = !hood.AnyWithin(kept_at, cell_size, sorted[s], ~0u, r2, kept_end);
          if (keep[s]) kept_at.Set(begin + kept_n[begin]++, sorted[s]);
        }
      });
  Scratch<std::uint32_t> slot(total);
  exec::cpu::ParallelFor(Index(total), [&](Index s) { slot[s] = keep[s]; });
  const std::size_t count = Scan(slot);
  out_positions.resize(count);
  out_normals.resize(count);
  exec::cpu::ParallelFor(Index(total), [&](Index s) {
    if (!keep[s]) return;
    out_positions[slot[s]] = sorted[s];
    out_normals[slot[s]] = normals[order[s]];
  });
}

// Distinct edges (a, b) with b > a around welded vertex a, with the sum of their faces' area
// vectors (and the first one, for when the sum cancels: a sheet folded onto itself).
struct LocalEdge {
  std::uint32_t b;
  Vec3d normal_sum, first_normal;
};

}  // namespace

double EstimateSampleCount(const io::TriMesh& mesh, double spacing) {
  const double sum = DeterministicSum(mesh.triangles.size(), [&](std::size_t i) {
    const auto& t = mesh.triangles[i];
    const Vec3d a(mesh.positions[t[0]]), b(mesh.positions[t[1]]), c(mesh.positions[t[2]]);
    // Area over d^2 plus half the perimeter over d (each edge is shared by about two faces).
    return 0.5 * Norm(Cross(b - a, c - a)) / (spacing * spacing) + 0.5 * (Norm(b - a) + Norm(c - b) + Norm(a - c)) / spacing;
  });
  return sum + double(mesh.positions.size());
}

SurfaceSamples SampleSurface(const io::TriMesh& mesh, const SampleOptions& options) {
  // Per-phase timings for --verbose: wall and process CPU time (all threads; the CPU figure stays
  // meaningful on a machine shared with other work).
  auto phase_start = std::chrono::steady_clock::now();
  std::clock_t phase_cpu = std::clock();
  const auto phase = [&](const char* name) {
    const auto now = std::chrono::steady_clock::now();
    const std::clock_t cpu = std::clock();
    log::Debug("sampling {}: {:.1f} ms, {:.1f} ms CPU", name, 1e3 * std::chrono::duration<double>(now - phase_start).count(),
               1e3 * double(cpu - phase_cpu) / CLOCKS_PER_SEC);
    phase_start = now, phase_cpu = cpu;
  };
  CheckInput(mesh, options);
  CheckCount(EstimateSampleCount(mesh, options.spacing), options);
  const double d = options.spacing;
  SurfaceSamples out;
  SampleStats& stats = out.stats;
  stats.triangles = mesh.triangles.size();

  // 1. Weld vertices with identical positions, so shared edges are found by index. Welded
  // vertices are numbered in the order of their first occurrence in the input.
  const std::size_t nv = mesh.positions.size();
  Scratch<std::uint32_t> weld(nv), welded_index(nv);
  WeldRepresentatives(mesh.positions, weld);
  exec::cpu::ParallelFor(Index(nv), [&](Index v) { welded_index[v] = weld[v] == std::uint32_t(v); });
  const std::size_t nw = Scan(welded_index);
  Scratch<Vec3f> welded_positions(nw);  // the input's floats: converted to double where used
  exec::cpu::ParallelFor(Index(nv), [&](Index v) {
    if (weld[v] == std::uint32_t(v)) welded_positions[welded_index[v]] = mesh.positions[v];
  });
  exec::cpu::ParallelFor(Index(nv), [&](Index v) { weld[v] = welded_index[weld[v]]; });  // touches element v only
  const auto wp = [&](std::uint32_t v) { return Vec3d(welded_positions[v]); };
  phase("check + weld");

  // 2. Valid triangles and their area vectors.
  const std::size_t nt = mesh.triangles.size();
  Scratch<std::array<std::uint32_t, 3>> tris(nt);
  Scratch<Vec3f> area_vectors(nt);  // computed in double, kept in float: they only give directions
  Scratch<std::uint8_t> valid(nt);
  exec::cpu::ParallelFor(Index(nt), [&](Index t) {
    const auto& src = mesh.triangles[t];
    const std::array<std::uint32_t, 3> w{weld[src[0]], weld[src[1]], weld[src[2]]};
    tris[t] = w;
    const Vec3d a = wp(w[0]), b = wp(w[1]), c = wp(w[2]);
    const Vec3d area = Cross(b - a, c - a);
    area_vectors[t] = Vec3f(area);
    const double longest = std::max({SquaredNorm(b - a), SquaredNorm(c - b), SquaredNorm(a - c)});
    const bool repeated = w[0] == w[1] || w[1] == w[2] || w[0] == w[2];
    valid[t] = !repeated && Norm(area) > 1e-10 * longest;  // zero area up to round-off
  });
  const std::size_t valid_count = std::size_t(DeterministicSum(nt, [&](std::size_t t) { return double(valid[t]); }));
  stats.degenerate_skipped = nt - valid_count;
  if (valid_count == 0) throw InputError(fmt::format("all {} triangles are degenerate (zero area)", nt), options.source);

  // Valid triangles around every welded vertex (CSR): counted and placed with atomics, then each
  // vertex's short list sorted, so the lists (and every sum over them) do not depend on threads.
  Scratch<std::uint32_t> incident_offset(nw + 1), cursor(nw);
  exec::cpu::ParallelFor(Index(nw + 1), [&](Index v) { incident_offset[v] = 0; });
  exec::cpu::ParallelFor(Index(nt), [&](Index t) {
    if (valid[t])
      for (std::uint32_t v : tris[t]) std::atomic_ref<std::uint32_t>(incident_offset[v]).fetch_add(1, std::memory_order_relaxed);
  });
  Scratch<std::uint32_t> incident(Scan(incident_offset));
  exec::cpu::ParallelFor(Index(nw), [&](Index v) { cursor[v] = incident_offset[v]; });
  exec::cpu::ParallelFor(Index(nt), [&](Index t) {
    if (valid[t])
      for (std::uint32_t v : tris[t])
        incident[std::atomic_ref<std::uint32_t>(cursor[v]).fetch_add(1, std::memory_order_relaxed)] = std::uint32_t(t);
  });
  exec::cpu::ParallelFor(Index(nw),
                         [&](Index v) { std::sort(incident.data() + incident_offset[v], incident.data() + incident_offset[v + 1]); });
  phase("triangles + incidence");

  // 3. Per welded vertex: area-weighted normal, and the distinct edges (a, b > a) it owns, with
  // their samples counted here and written in step 4 from the same list (no edge array).
  const auto edges_of = [&](std::uint32_t a, std::vector<LocalEdge>& local) {
    local.clear();
    for (std::uint32_t k = incident_offset[a]; k < incident_offset[a + 1]; ++k) {
      const std::uint32_t t = incident[k];
      for (std::uint32_t b : tris[t]) {
        if (b <= a) continue;
        LocalEdge* found = nullptr;
        for (LocalEdge& e : local)
          if (e.b == b) found = &e;
        const Vec3d area(area_vectors[t]);
        if (found) found->normal_sum += area;
        else local.push_back({b, area, area});
      }
    }
  };
  Scratch<Vec3f> vertex_normals(nw);
  Scratch<std::uint32_t> edge_count(nw + 1), edge_offset(nw + 1), used_slot(nw + 1);
  exec::cpu::ParallelFor(Index(nw), [&](Index a) {
    Vec3d sum(0, 0, 0), fallback(0, 0, 0);
    for (std::uint32_t k = incident_offset[a]; k < incident_offset[a + 1]; ++k) {
      fallback = Vec3d(area_vectors[incident[k]]);
      sum += fallback;
    }
    vertex_normals[a] = UnitOr(sum, fallback);
    used_slot[a] = incident_offset[a + 1] > incident_offset[a];
    thread_local std::vector<LocalEdge> local;
    edges_of(std::uint32_t(a), local);
    edge_count[a] = std::uint32_t(local.size());
    std::int64_t samples = 0;
    for (const LocalEdge& e : local) samples += EdgeSegments(Norm(wp(e.b) - wp(std::uint32_t(a))), d) - 1;
    edge_offset[a] = std::uint32_t(std::min<std::int64_t>(samples, 0xffffffff));
  });
  edge_count[nw] = edge_offset[nw] = used_slot[nw] = 0;
  stats.edges = Scan(edge_count);
  stats.welded_vertices = stats.vertex_samples = Scan(used_slot);
  stats.edge_samples = Scan(edge_offset);
  Scratch<std::uint32_t> face_offset(nt + 1);
  const auto triangle = [&](std::size_t t) { return Triangle{{wp(tris[t][0]), wp(tris[t][1]), wp(tris[t][2])}}; };
  exec::cpu::ParallelFor(
      Index(nt), [&](Index t) { face_offset[t] = valid[t] ? std::uint32_t(SampleFaceInterior(triangle(t), d, [](const Vec3d&) {})) : 0; });
  face_offset[nt] = 0;
  stats.face_samples = Scan(face_offset);
  const std::uint64_t total = std::uint64_t(stats.vertex_samples) + stats.edge_samples + stats.face_samples;
  CheckCount(double(total), options);
  phase("edges + count");

  // 4. Fill at the scanned offsets: vertices, then edges (by owning vertex), then faces.
  Scratch<Vec3f> positions(total), normals(total);
  const std::size_t edge_base = stats.vertex_samples, face_base = edge_base + stats.edge_samples;
  exec::cpu::ParallelFor(Index(nw), [&](Index a) {
    if (used_slot[a + 1] > used_slot[a]) {
      positions[used_slot[a]] = welded_positions[a];
      normals[used_slot[a]] = vertex_normals[a];
    }
    if (edge_offset[a + 1] == edge_offset[a]) return;
    thread_local std::vector<LocalEdge> local;
    edges_of(std::uint32_t(a), local);
    std::size_t slot = edge_base + edge_offset[a];
    const Vec3d pa = wp(std::uint32_t(a));
    for (const LocalEdge& e : local) {
      const Vec3d pb = wp(e.b);
      const std::int64_t count = EdgeSegments(Norm(pb - pa), d) - 1;
      const Vec3f normal = UnitOr(e.normal_sum, e.first_normal);
      for (std::int64_t k = 0; k < count; ++k, ++slot) {
        positions[slot] = Vec3f(pa + (pb - pa) * (double(k + 1) / double(count + 1)));
        normals[slot] = normal;
      }
    }
  });
  exec::cpu::ParallelFor(Index(nt), [&](Index t) {
    if (face_offset[t + 1] == face_offset[t]) return;
    std::size_t slot = face_base + face_offset[t];
    const Vec3f normal = UnitOr(Vec3d(area_vectors[t]), Vec3d(area_vectors[t]));
    SampleFaceInterior(triangle(t), d, [&](const Vec3d& p) {
      positions[slot] = Vec3f(p);
      normals[slot] = normal;
      ++slot;
    });
  });
  phase("fill");

  // 5. Thinning: remove particles closer than 0.5 d_b to a kept one, vertices first, then edges,
  // then faces, and keep the rest in the Z-curve order of an 8 d_b grid (neighbours close in
  // memory speed up every later neighbour search over the file: volumes, the simulation). Cells
  // of 16 radii hold some 60 surface particles: few hash lookups per particle, and the (SIMD)
  // distance scans stay short.
  if (options.remove_near_duplicates && total > 1) {
    ThinAndOrder(positions.data(), normals.data(), total, edge_base, face_base, float(8 * d), float(kDuplicateRadius * d), out.positions,
                 out.normals);
    stats.near_duplicates_removed = total - out.positions.size();
  } else {
    out.positions.assign(positions.data(), positions.data() + total);
    out.normals.assign(normals.data(), normals.data() + total);
  }
  phase("near-duplicate removal");
  return out;
}

std::vector<float> NearestNeighborDistances(const std::vector<Vec3f>& points, float search_radius) {
  const float inf = std::numeric_limits<float>::infinity();
  std::vector<float> nearest(points.size(), inf);
  if (points.empty()) return nearest;
  // Cell by cell (27 cell lookups per cell, not per point) over sorted x/y/z arrays.
  neighbors::UniformGrid<float> grid(exec::Device::Cpu());
  grid.Build(points.data(), Index(points.size()), search_radius);
  const neighbors::GridView<float> view = grid.view();
  Points sorted(points.size());
  exec::cpu::ParallelFor(Index(points.size()), [&](Index s) { sorted.Set(s, points[view.sorted_index[s]]); });
  const float r2max = search_radius * search_radius;
  const float *x = sorted.x.data(), *y = sorted.y.data(), *z = sorted.z.data();
  exec::cpu::ParallelFor(Index(grid.cell_count()), [&](Index cell) {
    const CellHood hood(view, sorted, search_radius, std::uint32_t(cell));
    for (std::uint32_t s = view.cell_start[cell]; s < view.cell_start[cell + 1]; ++s) {
      float best = inf;
      for (int k = 0; k < hood.count; ++k)
        for (std::uint32_t t = hood.begin[k]; t < hood.end[k]; ++t) {
          const float dx = x[t] - x[s], dy = y[t] - y[s], dz = z[t] - z[s];
          const float r2 = dx * dx + dy * dy + dz * dz;
          best = std::min(best, (r2 < r2max && t != s) ? r2 : inf);
        }
      nearest[view.sorted_index[s]] = std::sqrt(best);
    }
  });
  return nearest;
}

}  // namespace rime::boundary
