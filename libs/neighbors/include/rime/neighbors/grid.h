/// @file grid.h
/// @brief Host-side owner of a uniform grid and CSR neighbor lists on one device.
///
/// @code
/// rime::neighbors::UniformGrid<float> grid(device);
/// grid.Build(points, n, support_radius);            // points stay where they are
/// rime::neighbors::NeighborList list(device);
/// grid.Query(queries, m, support_radius, /*exclude_self=*/false, list);
/// // neighbors of query i: list.indices[list.offsets[i] .. list.offsets[i+1])
/// @endcode
#pragma once

#include <cstdint>
#include <vector>

#include "rime/core/kernel.h"
#include "rime/exec/memory.h"
#include "rime/neighbors/grid_kernels.h"

namespace rime::neighbors {

/// Per-pair kernel values stored beside a neighbor list: for pair k = (i, j),
/// w[k] = W(|x_i − x_j|) and grad[k] = ∇_i W(x_i − x_j).
template <class T>
struct PairKernelArrays {
  CubicSpline<T> kernel;
  exec::DeviceArray<T>& w;
  exec::DeviceArray<Vec3<T>>& grad;
};

/// Compressed sparse rows: offsets has queries+1 entries.
struct NeighborList {
  explicit NeighborList(const exec::Device& device) : offsets(device), indices(device) {}
  exec::DeviceArray<std::uint32_t> offsets;
  exec::DeviceArray<std::uint32_t> indices;
  std::uint64_t pairs() const { return indices.size(); }
};

template <class T>
class UniformGrid {
 public:
  explicit UniformGrid(const exec::Device& device);

  /// Bins `points` (device pointer, must stay valid while the grid is used) in cells of
  /// size `cell_size`. Throws rime::Error if the cloud spans more than 2^21 cells per axis.
  void Build(const Vec3<T>* points, Index n, T cell_size);
  /// The same on a fixed cell lattice: grids built on the same origin and cell size share their
  /// cells, which lets QueryGrid work cell by cell. Falls back to a computed origin (and says so
  /// through aligned_with) when a point lies below `origin`.
  void Build(const Vec3<T>* points, Index n, T cell_size, const Vec3<T>& origin);
  /// After points were appended to the array binned last (points [0, size()) unchanged, at
  /// `points` now), bins [size(), n) too: the same grid as Build(points, n, cell_size(), origin),
  /// merged into the sorted cells rather than sorted anew when the new points are few.
  void Append(const Vec3<T>* points, Index n, const Vec3<T>& origin);
  /// The grid Build(points, count, cell_size, origin) makes of a subset of `parent`'s points
  /// (flags[b] != 0 for its members, slot[b] the place of member b in `points`, in increasing b),
  /// taken from the parent's sorted cells rather than sorted anew.
  void BuildSubset(const UniformGrid& parent, const std::uint32_t* flags, const std::uint32_t* slot, const Vec3<T>* points, Index count,
                   T cell_size, const Vec3<T>& origin);
  bool aligned_with(const UniformGrid& other) const { return view_.origin == other.view_.origin && cell_size_ == other.cell_size_; }

  /// sorted slot -> original index: the Z-curve order, for callers that reorder their arrays.
  const std::uint32_t* order() const { return sorted_index_.data(); }
  GridView<T> view() const { return view_; }
  Index size() const { return view_.count; }
  T cell_size() const { return cell_size_; }
  std::size_t cell_count() const { return cells_; }

  /// After the caller gathered its arrays into order() (point k of the new array is old point
  /// order()[k]), re-points the grid at the reordered array so no rebuild is needed.
  void AdoptOrder(const Vec3<T>* reordered_points);

  /// CSR lists of grid points within `radius` (<= cell size) of each query position.
  void Query(const Vec3<T>* queries, Index m, T radius, bool exclude_self, NeighborList& out) const;
  /// The same for the points of another grid as queries (row i = its point i). When both grids
  /// share their cell lattice the search runs per query cell, looking up the 27 neighbor cells
  /// once for all points of the cell (several times faster on the CPU); identical lists either way
  /// while the grid's points are where they were binned (after they moved, it also finds those that
  /// moved into range from a cell the per-point search skips).
  void QueryGrid(const UniformGrid& queries, T radius, bool exclude_self, NeighborList& out) const;
  /// The same, also filling `values` for every pair. On the CPU the cell-by-cell search tests
  /// 8 candidates at a time and the values are computed from its matches once they are in place;
  /// lists and values are bit-identical to QueryGrid followed by kernels::PairValues.
  void QueryGrid(const UniformGrid& queries, T radius, bool exclude_self, NeighborList& out, const PairKernelArrays<T>& values) const;

 private:
  void BuildImpl(const Vec3<T>* points, Index n, T cell_size, const Vec3<T>* fixed_origin);
  void CpuQueryByCell(const UniformGrid& queries, T radius, bool exclude_self, NeighborList& out, const PairKernelArrays<T>* values) const;
  void Clear(const Vec3<T>* points, Index n, T cell_size);  // an empty grid over `points`, before its cells are indexed
  void IndexCells(Index n);                                 // cell starts, then a dense box (CPU) or a hash table
  bool OnLattice(const Vec3<T>& lo, const Vec3<T>& hi, const Vec3<T>& origin) const;
  void BuildDenseCells();

  exec::Device device_;
  T cell_size_ = 0;
  std::size_t cells_ = 0;
  GridView<T> view_;
  exec::DeviceArray<std::uint64_t> keys_;
  exec::DeviceArray<std::uint32_t> sorted_index_;
  exec::DeviceArray<std::uint32_t> flags_;
  exec::DeviceArray<std::uint32_t> cell_of_slot_;
  exec::DeviceArray<std::uint32_t> cell_start_;
  exec::DeviceArray<std::uint64_t> table_keys_;
  exec::DeviceArray<std::uint32_t> table_cells_;
  exec::DeviceArray<T> bounds_scratch_;
  mutable exec::DeviceArray<std::uint32_t> counts_;
  // CPU: blocks of the first pass's matches (kept between queries), and where each query's lie.
  mutable std::vector<std::vector<std::uint32_t>> staged_;
  mutable std::vector<const std::uint32_t*> staged_at_;
  std::vector<std::uint32_t> dense_cells_;  // CPU: GridView::dense_cells
  bool in_order_ = false;                   // sorted slot k holds point k (after AdoptOrder)
};

extern template class UniformGrid<float>;
extern template class UniformGrid<double>;

}  // namespace rime::neighbors
