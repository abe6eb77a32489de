/// @file grid_kernels.h
/// @brief Uniform-grid neighbor search as host/device kernels (spec §2).
///
/// Points are binned in cubic cells of size >= the search radius, keyed by the Morton code of the
/// cell (so sorting by key orders particles along a Z curve for cache locality). Occupied cells are
/// found through an open-addressing hash table, so memory is proportional to the number of points,
/// not to the bounding-box volume. A query visits the 27 cells around a position.
#pragma once

#include <cstdint>

#include "rime/core/hd.h"
#include "rime/core/kernel.h"
#include "rime/core/math.h"
#include "rime/exec/atomic.h"

namespace rime::neighbors {

inline constexpr std::uint64_t kEmptySlot = ~0ULL;
inline constexpr int kMortonBits = 21;  // per axis
inline constexpr std::int64_t kMaxCellsPerAxis = (1LL << kMortonBits) - 2;

RIME_HDI std::uint64_t SpreadBits(std::uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffULL;
  v = (v | v << 16) & 0x1f0000ff0000ffULL;
  v = (v | v << 8) & 0x100f00f00f00f00fULL;
  v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
  v = (v | v << 2) & 0x1249249249249249ULL;
  return v;
}
RIME_HDI std::uint64_t MortonKey(std::int64_t ix, std::int64_t iy, std::int64_t iz) {
  return SpreadBits(std::uint64_t(ix)) | SpreadBits(std::uint64_t(iy)) << 1 | SpreadBits(std::uint64_t(iz)) << 2;
}
RIME_HDI std::uint32_t HashSlot(std::uint64_t key, std::uint32_t mask) {
  key ^= key >> 33;
  key *= 0xff51afd7ed558ccdULL;
  key ^= key >> 33;
  return static_cast<std::uint32_t>(key) & mask;
}

/// Read-only view of a built grid, passed by value into kernels.
template <class T>
struct GridView {
  Vec3<T> origin;  // world position of cell (1,1,1)'s lower corner minus one cell (cells start at 1)
  T inv_cell = 0;
  const std::uint64_t* table_keys = nullptr;   // hash slot -> cell key (kEmptySlot = empty); none with dense_cells
  const std::uint32_t* table_cells = nullptr;  // hash slot -> cell index
  std::uint32_t table_mask = 0;
  const std::uint32_t* cell_start = nullptr;    // cell index -> first sorted slot; cell_start[cells] = n
  const std::uint32_t* sorted_index = nullptr;  // sorted slot -> original point index
  const Vec3<T>* points = nullptr;              // original point positions
  std::uint32_t count = 0;
  // CPU only, optional: the cell index of every lattice position of a box (kNoCell where empty),
  // read instead of probing the hash table (neighbouring cells are neighbouring words).
  const std::uint32_t* dense_cells = nullptr;
  std::int64_t dense_lo[3] = {0, 0, 0}, dense_dims[3] = {0, 0, 0};
  static constexpr std::uint32_t kNoCell = ~0u;

  /// The cell at lattice coordinates (ix, iy, iz) from the dense box (kNoCell when empty or outside it).
  RIME_HDI std::uint32_t DenseCell(std::int64_t ix, std::int64_t iy, std::int64_t iz) const {
    ix -= dense_lo[0], iy -= dense_lo[1], iz -= dense_lo[2];
    if (ix < 0 || iy < 0 || iz < 0 || ix >= dense_dims[0] || iy >= dense_dims[1] || iz >= dense_dims[2]) return kNoCell;
    return dense_cells[(iz * dense_dims[1] + iy) * dense_dims[0] + ix];
  }

  RIME_HDI std::int64_t CellCoord(T x, T o) const { return static_cast<std::int64_t>(std::floor((x - o) * inv_cell)); }

  /// Calls visit(begin, end) for the sorted-slot range of every occupied cell that can hold a
  /// point within `radius` of x (cells whose box is farther than the radius are skipped).
  template <class V>
  RIME_HDI void ForEachCandidateCell(const Vec3<T>& x, T radius, V&& visit) const {
    if (count == 0) return;
    const T cell = T(1) / inv_cell, r2max = radius * radius;
    const std::int64_t cx = CellCoord(x.x, origin.x), cy = CellCoord(x.y, origin.y), cz = CellCoord(x.z, origin.z);
    // Distance from x to the lower/upper faces of its own cell, per axis.
    const Vec3<T> lo_gap{x.x - (origin.x + T(cx) * cell), x.y - (origin.y + T(cy) * cell), x.z - (origin.z + T(cz) * cell)};
    const Vec3<T> hi_gap{cell - lo_gap.x, cell - lo_gap.y, cell - lo_gap.z};
    for (std::int64_t dz = -1; dz <= 1; ++dz) {
      const T gz = dz < 0 ? lo_gap.z : (dz > 0 ? hi_gap.z : T(0));
      for (std::int64_t dy = -1; dy <= 1; ++dy) {
        const T gy = dy < 0 ? lo_gap.y : (dy > 0 ? hi_gap.y : T(0));
        for (std::int64_t dx = -1; dx <= 1; ++dx) {
          const T gx = dx < 0 ? lo_gap.x : (dx > 0 ? hi_gap.x : T(0));
          if (gx * gx + gy * gy + gz * gz >= r2max) continue;  // the whole cell is out of range
          const std::int64_t ix = cx + dx, iy = cy + dy, iz = cz + dz;
          if (ix < 0 || iy < 0 || iz < 0 || ix > kMaxCellsPerAxis || iy > kMaxCellsPerAxis || iz > kMaxCellsPerAxis) continue;
          if (dense_cells) {
            const std::uint32_t c = DenseCell(ix, iy, iz);
            if (c != kNoCell) visit(cell_start[c], cell_start[c + 1]);
            continue;
          }
          const std::uint64_t key = MortonKey(ix, iy, iz);
          std::uint32_t slot = HashSlot(key, table_mask);
          while (true) {
            const std::uint64_t k = table_keys[slot];
            if (k == kEmptySlot) break;
            if (k == key) {
              const std::uint32_t c = table_cells[slot];
              visit(cell_start[c], cell_start[c + 1]);
              break;
            }
            slot = (slot + 1) & table_mask;
          }
        }
      }
    }
  }

  /// Calls f(j, r_ij = x - points[j], r2) for every point j with |x - points[j]| < radius.
  template <class F>
  RIME_HDI void ForEachNeighbor(const Vec3<T>& x, T radius, F&& f) const {
    const T r2max = radius * radius;
    ForEachCandidateCell(x, radius, [&](std::uint32_t begin, std::uint32_t end) {
      for (std::uint32_t s = begin; s < end; ++s) {
        const std::uint32_t j = sorted_index[s];
        const Vec3<T> r = x - points[j];
        const T r2 = Dot(r, r);
        if (r2 < r2max) f(j, r, r2);
      }
    });
  }

  /// Number of points within radius of x (branch-free inner loop), optionally excluding `self`.
  RIME_HDI std::uint32_t CountWithin(const Vec3<T>& x, T radius, std::uint32_t self) const {
    const T r2max = radius * radius;
    std::uint32_t c = 0;
    ForEachCandidateCell(x, radius, [&](std::uint32_t begin, std::uint32_t end) {
      for (std::uint32_t s = begin; s < end; ++s) {
        const std::uint32_t j = sorted_index[s];
        const Vec3<T> r = x - points[j];
        c += (Dot(r, r) < r2max) & (j != self);
      }
    });
    return c;
  }
};

namespace kernels {

/// keys[i] = Morton key of point i's cell; values[i] = i.
template <class T>
struct CellKeys {
  const Vec3<T>* points;
  Vec3<T> origin;
  T inv_cell;
  std::uint64_t* keys;
  std::uint32_t* values;
  RIME_HD void operator()(Index i) const {
    const Vec3<T> p = points[i];
    const auto c = [&](T x, T o) {
      std::int64_t v = static_cast<std::int64_t>(std::floor((x - o) * inv_cell));
      return v < 0 ? 0 : (v > kMaxCellsPerAxis ? kMaxCellsPerAxis : v);
    };
    keys[i] = MortonKey(c(p.x, origin.x), c(p.y, origin.y), c(p.z, origin.z));
    values[i] = static_cast<std::uint32_t>(i);
  }
};

/// flags[i] = 1 where sorted slot i starts a new cell.
struct MarkCellStarts {
  const std::uint64_t* sorted_keys;
  std::uint32_t* flags;
  RIME_HD void operator()(Index i) const { flags[i] = (i == 0 || sorted_keys[i] != sorted_keys[i - 1]) ? 1u : 0u; }
};

/// For every cell start: record the start slot and insert the cell into the hash table (when
/// there is one: the CPU reads a dense box instead where it can).
struct InsertCells {
  const std::uint64_t* sorted_keys;
  const std::uint32_t* flags;
  const std::uint32_t* cell_of_slot;  // exclusive scan of flags
  std::uint32_t* cell_start;
  std::uint64_t* table_keys;
  std::uint32_t* table_cells;
  std::uint32_t table_mask;
  RIME_HD void operator()(Index i) const {
    if (!flags[i]) return;
    const std::uint32_t cell = cell_of_slot[i];
    cell_start[cell] = static_cast<std::uint32_t>(i);
    if (!table_keys) return;
    const std::uint64_t key = sorted_keys[i];
    std::uint32_t slot = HashSlot(key, table_mask);
    while (exec::AtomicCas(&table_keys[slot], kEmptySlot, key) != kEmptySlot) slot = (slot + 1) & table_mask;
    table_cells[slot] = cell;
  }
};

/// counts[i] = number of grid points within radius of queries[i] (excluding i itself if asked).
template <class T>
struct CountNeighbors {
  GridView<T> grid;
  const Vec3<T>* queries;
  T radius;
  bool exclude_self;
  std::uint32_t* counts;
  RIME_HD void operator()(Index i) const {
    counts[i] = grid.CountWithin(queries[i], radius, exclude_self ? static_cast<std::uint32_t>(i) : ~0u);
  }
};

/// Writes the neighbor indices of queries[i] at offsets[i] (in cell order, then sorted order, so
/// lists are deterministic).
template <class T>
struct FillNeighbors {
  GridView<T> grid;
  const Vec3<T>* queries;
  T radius;
  bool exclude_self;
  const std::uint32_t* offsets;
  std::uint32_t* indices;
  RIME_HD void operator()(Index i) const {
    std::uint32_t k = offsets[i];
    const std::uint32_t end = offsets[i + 1];
    const std::uint32_t self = exclude_self ? static_cast<std::uint32_t>(i) : ~0u;
    const Vec3<T> x = queries[i];
    const T r2max = radius * radius;
    grid.ForEachCandidateCell(x, radius, [&](std::uint32_t begin, std::uint32_t stop) {
      for (std::uint32_t s = begin; s < stop; ++s) {
        const std::uint32_t j = grid.sorted_index[s];
        const Vec3<T> r = x - grid.points[j];
        // Branch-free: always store, advance only for a neighbor (the guard is almost always true).
        if (k < end) indices[k] = j;
        k += (Dot(r, r) < r2max) & (j != self);
      }
    });
  }
};

/// The up to 27 occupied cells of `target` around one cell of `source` (grids of the same cell
/// size on the same origin), gathered once for all points of the source cell.
template <class T>
struct CellNeighborhood {
  std::uint32_t begin[27], end[27];
  int count = 0;
  CellNeighborhood() = default;
  RIME_HDI CellNeighborhood(const GridView<T>& target, const GridView<T>& source, std::uint32_t cell) {
    const T size = T(1) / source.inv_cell;
    const Vec3<T> p = source.points[source.sorted_index[source.cell_start[cell]]];
    if (target.dense_cells) {  // the 27 cells straight from the dense box, in the same order
      const std::int64_t cx = source.CellCoord(p.x, source.origin.x), cy = source.CellCoord(p.y, source.origin.y),
                         cz = source.CellCoord(p.z, source.origin.z);
      for (std::int64_t z = cz - 1; z <= cz + 1; ++z)
        for (std::int64_t y = cy - 1; y <= cy + 1; ++y)
          for (std::int64_t x = cx - 1; x <= cx + 1; ++x) {
            const std::uint32_t c = target.DenseCell(x, y, z);
            if (c == GridView<T>::kNoCell) continue;
            begin[count] = target.cell_start[c];
            end[count] = target.cell_start[c + 1];
            ++count;
          }
      return;
    }
    const Vec3<T> center(source.origin.x + (T(source.CellCoord(p.x, source.origin.x)) + T(0.5)) * size,
                         source.origin.y + (T(source.CellCoord(p.y, source.origin.y)) + T(0.5)) * size,
                         source.origin.z + (T(source.CellCoord(p.z, source.origin.z)) + T(0.5)) * size);
    // Neighbor cells are at most half a cell from the centre, the next ring 1.5 cells: keep 27.
    target.ForEachCandidateCell(center, size, [&](std::uint32_t b, std::uint32_t e) {
      begin[count] = b;
      end[count] = e;
      ++count;
    });
  }
};

/// counts[i] for every point i of one source cell (see CountNeighbors; same results).
template <class T>
struct CountNeighborsByCell {
  GridView<T> target, source;
  T radius;
  bool exclude_self;
  std::uint32_t* counts;
  RIME_HD void operator()(Index cell) const {
    const CellNeighborhood<T> hood(target, source, static_cast<std::uint32_t>(cell));
    const T r2max = radius * radius;
    for (std::uint32_t s = source.cell_start[cell], e = source.cell_start[cell + 1]; s < e; ++s) {
      const std::uint32_t i = source.sorted_index[s];
      const Vec3<T> x = source.points[i];
      const std::uint32_t self = exclude_self ? i : ~0u;
      std::uint32_t c = 0;
      for (int k = 0; k < hood.count; ++k)
        for (std::uint32_t t = hood.begin[k]; t < hood.end[k]; ++t) {
          const std::uint32_t j = target.sorted_index[t];
          const Vec3<T> r = x - target.points[j];
          c += (Dot(r, r) < r2max) & (j != self);
        }
      counts[i] = c;
    }
  }
};

/// Neighbor indices for every point of one source cell (same order as FillNeighbors).
template <class T>
struct FillNeighborsByCell {
  GridView<T> target, source;
  T radius;
  bool exclude_self;
  const std::uint32_t* offsets;
  std::uint32_t* indices;
  RIME_HD void operator()(Index cell) const {
    const CellNeighborhood<T> hood(target, source, static_cast<std::uint32_t>(cell));
    const T r2max = radius * radius;
    for (std::uint32_t s = source.cell_start[cell], e = source.cell_start[cell + 1]; s < e; ++s) {
      const std::uint32_t i = source.sorted_index[s];
      const Vec3<T> x = source.points[i];
      const std::uint32_t self = exclude_self ? i : ~0u;
      std::uint32_t k_out = offsets[i];
      const std::uint32_t end = offsets[i + 1];
      for (int k = 0; k < hood.count; ++k)
        for (std::uint32_t t = hood.begin[k]; t < hood.end[k]; ++t) {
          const std::uint32_t j = target.sorted_index[t];
          const Vec3<T> r = x - target.points[j];
          if (k_out < end) indices[k_out] = j;
          k_out += (Dot(r, r) < r2max) & (j != self);
        }
    }
  }
};

/// w and ∇W of every listed pair (i, j): r = xi[i] − xj[j].
template <class T>
struct PairValues {
  const Vec3<T>* xi;
  const Vec3<T>* xj;
  const std::uint32_t* offsets;
  const std::uint32_t* index;
  CubicSpline<T> kernel;
  T* w;
  Vec3<T>* grad;
  RIME_HD void operator()(Index i) const {
    const Vec3<T> x = xi[i];
    for (std::uint32_t k = offsets[i], e = offsets[i + 1]; k < e; ++k) {
      const Vec3<T> r = x - xj[index[k]];
      const T len = Norm(r);
      w[k] = kernel.W(len);
      grad[k] = r * kernel.GradientFactor(len);
    }
  }
};

/// Component-wise copy for bounding-box reductions: out[a*n + i] = -points[i][a] (a < 3) and
/// points[i][a-3] (a >= 3), so one Max over each third gives -min and max.
template <class T>
struct BoundsComponents {
  const Vec3<T>* points;
  Index n;
  T* out;
  RIME_HD void operator()(Index i) const {
    const Vec3<T> p = points[i];
    out[i] = -p.x, out[n + i] = -p.y, out[2 * n + i] = -p.z;
    out[3 * n + i] = p.x, out[4 * n + i] = p.y, out[5 * n + i] = p.z;
  }
};

}  // namespace kernels
}  // namespace rime::neighbors

// One kernel per line: clang-format 14 keeps that layout but rewraps a line of several on every run.
#define RIME_NEIGHBORS_KERNELS(X)                           \
  X(rime::neighbors::kernels::CellKeys<float>)              \
  X(rime::neighbors::kernels::CellKeys<double>)             \
  X(rime::neighbors::kernels::MarkCellStarts)               \
  X(rime::neighbors::kernels::InsertCells)                  \
  X(rime::neighbors::kernels::CountNeighbors<float>)        \
  X(rime::neighbors::kernels::CountNeighbors<double>)       \
  X(rime::neighbors::kernels::FillNeighbors<float>)         \
  X(rime::neighbors::kernels::FillNeighbors<double>)        \
  X(rime::neighbors::kernels::BoundsComponents<float>)      \
  X(rime::neighbors::kernels::BoundsComponents<double>)     \
  X(rime::neighbors::kernels::CountNeighborsByCell<float>)  \
  X(rime::neighbors::kernels::CountNeighborsByCell<double>) \
  X(rime::neighbors::kernels::FillNeighborsByCell<float>)   \
  X(rime::neighbors::kernels::FillNeighborsByCell<double>)  \
  X(rime::neighbors::kernels::PairValues<float>)            \
  X(rime::neighbors::kernels::PairValues<double>)
