#include "rime/neighbors/grid.h"

#include <fmt/format.h>
#include <tbb/parallel_reduce.h>

#include <bit>
#include <cmath>
#include <limits>

#include "rime/core/error.h"
#include "rime/exec/kernel_list.h"
#include "rime/exec/kernels.h"
#include "rime/exec/parallel.h"

RIME_NEIGHBORS_KERNELS(RIME_INSTANTIATE_CPU_KERNEL)

namespace rime::neighbors {
namespace {

// Bounding box in one parallel pass over the points, without the device path's 6n scratch copy.
// Minimum and maximum are exact, so any split gives the same box; a NaN or infinite coordinate
// makes the box NaN, as the device path's NaN-propagating maximum does.
template <class T>
void CpuBounds(const Vec3<T>* points, Index n, Vec3<T>& lo, Vec3<T>& hi) {
  struct Box {
    Vec3<T> lo, hi;
    bool finite = true;
  };
  const Box box = tbb::parallel_reduce(
      tbb::blocked_range<Index>(0, n, 4096), Box{points[0], points[0]},
      [&](const tbb::blocked_range<Index>& r, Box b) {
        for (Index i = r.begin(); i != r.end(); ++i) {
          const Vec3<T> p = points[i];
          b.finite = b.finite && IsFinite(p);
          b.lo = Min(b.lo, p), b.hi = Max(b.hi, p);
        }
        return b;
      },
      [](Box a, const Box& b) { return Box{Min(a.lo, b.lo), Max(a.hi, b.hi), a.finite && b.finite}; });
  const T nan = std::numeric_limits<T>::quiet_NaN();
  lo = box.finite ? box.lo : Vec3<T>(nan, nan, nan);
  hi = box.finite ? box.hi : Vec3<T>(nan, nan, nan);
}

}  // namespace

template <class T>
UniformGrid<T>::UniformGrid(const exec::Device& device)
    : device_(device),
      keys_(device),
      sorted_index_(device),
      flags_(device),
      cell_of_slot_(device),
      cell_start_(device),
      table_keys_(device),
      table_cells_(device),
      bounds_scratch_(device),
      counts_(device) {}

template <class T>
void UniformGrid<T>::Build(const Vec3<T>* points, Index n, T cell_size) {
  BuildImpl(points, n, cell_size, nullptr);
}

template <class T>
void UniformGrid<T>::Build(const Vec3<T>* points, Index n, T cell_size, const Vec3<T>& origin) {
  BuildImpl(points, n, cell_size, &origin);
}

template <class T>
void UniformGrid<T>::BuildImpl(const Vec3<T>* points, Index n, T cell_size, const Vec3<T>* fixed_origin) {
  if (!(cell_size > 0)) throw Error(ExitCode::kFailure, "neighbor grid: cell size must be positive");
  cell_size_ = cell_size;
  view_ = GridView<T>{};
  view_.points = points;
  view_.count = static_cast<std::uint32_t>(n);
  view_.inv_cell = T(1) / cell_size;
  cells_ = 0;
  if (n == 0) return;

  // Bounding box -> origin one cell below the minimum, so every point sits in a cell >= 1.
  Vec3<T> lo, hi;
  if (device_.is_cuda()) {
    bounds_scratch_.resize(6 * n);
    exec::ParallelFor(device_, n, kernels::BoundsComponents<T>{points, n, bounds_scratch_.data()});
    for (int a = 0; a < 3; ++a) {
      lo[a] = -exec::Max(device_, bounds_scratch_.data() + a * n, n);
      hi[a] = exec::Max(device_, bounds_scratch_.data() + (3 + a) * n, n);
    }
  } else {
    CpuBounds(points, n, lo, hi);
  }
  if (!IsFinite(lo) || !IsFinite(hi)) throw Error(ExitCode::kDiverged, "neighbor grid: a particle position is NaN or infinite");
  const T extent = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
  if (extent / cell_size > T(kMaxCellsPerAxis - 4))
    throw Error(ExitCode::kBadInput, fmt::format("particles span {:.4g} m, more than 2^21 neighbor cells of {:.4g} m per axis; "
                                                 "limit the domain or use a larger spacing",
                                                 double(extent), double(cell_size)));
  const bool use_fixed = fixed_origin && lo.x > fixed_origin->x && lo.y > fixed_origin->y && lo.z > fixed_origin->z &&
                         (hi.x - fixed_origin->x) / cell_size < T(kMaxCellsPerAxis - 4) &&
                         (hi.y - fixed_origin->y) / cell_size < T(kMaxCellsPerAxis - 4) &&
                         (hi.z - fixed_origin->z) / cell_size < T(kMaxCellsPerAxis - 4);
  view_.origin = use_fixed ? *fixed_origin
                           : Vec3<T>{std::floor(lo.x / cell_size) * cell_size - cell_size, std::floor(lo.y / cell_size) * cell_size - cell_size,
                                     std::floor(lo.z / cell_size) * cell_size - cell_size};

  keys_.resize(n);
  sorted_index_.resize(n);
  exec::ParallelFor(device_, n, kernels::CellKeys<T>{points, view_.origin, view_.inv_cell, keys_.data(), sorted_index_.data()});
  // Only as many Morton bits as the cloud's extent needs (fewer radix passes).
  const T span = std::max({hi.x - view_.origin.x, hi.y - view_.origin.y, hi.z - view_.origin.z}) / cell_size + T(2);
  const int bits_per_axis = std::min(kMortonBits, static_cast<int>(std::bit_width(static_cast<std::uint64_t>(span) + 1)));
  exec::SortPairs(device_, keys_.data(), sorted_index_.data(), n, 3 * bits_per_axis);

  flags_.resize(n);
  cell_of_slot_.resize(n);
  exec::ParallelFor(device_, n, kernels::MarkCellStarts{keys_.data(), flags_.data()});
  cells_ = exec::ExclusiveScan(device_, flags_.data(), cell_of_slot_.data(), n);

  const std::uint32_t table_size = std::bit_ceil(static_cast<std::uint32_t>(2 * cells_ + 16));
  table_keys_.resize(table_size);
  table_cells_.resize(table_size);
  std::vector<std::uint64_t> empty(table_size, kEmptySlot);  // all-ones fill
  table_keys_.assign(empty);
  cell_start_.resize(cells_ + 1);
  const std::uint32_t end = static_cast<std::uint32_t>(n);
  exec::CopyToDevice(device_, cell_start_.data() + cells_, &end, sizeof end);
  exec::ParallelFor(device_, n,
                    kernels::InsertCells{keys_.data(), flags_.data(), cell_of_slot_.data(), cell_start_.data(),
                                         table_keys_.data(), table_cells_.data(), table_size - 1});

  view_.table_keys = table_keys_.data();
  view_.table_cells = table_cells_.data();
  view_.table_mask = table_size - 1;
  view_.cell_start = cell_start_.data();
  view_.sorted_index = sorted_index_.data();
}

template <class T>
void UniformGrid<T>::AdoptOrder(const Vec3<T>* reordered_points) {
  view_.points = reordered_points;
  exec::ParallelFor(device_, view_.count, exec::IotaKernel{sorted_index_.data()});
}

template <class T>
void UniformGrid<T>::Query(const Vec3<T>* queries, Index m, T radius, bool exclude_self, NeighborList& out) const {
  if (radius > cell_size_ * T(1.0000001) && view_.count > 0)
    throw Error(ExitCode::kFailure, "neighbor grid: query radius exceeds the cell size");
  out.offsets.resize(m + 1);
  counts_.resize(m + 1);
  counts_.SetZero();
  exec::ParallelFor(device_, m, kernels::CountNeighbors<T>{view_, queries, radius, exclude_self, counts_.data()});
  const std::uint64_t total = exec::ExclusiveScan(device_, counts_.data(), out.offsets.data(), m + 1);
  if (total > 0xffffffffULL) throw Error(ExitCode::kFailure, "neighbor grid: more than 2^32 neighbor pairs");
  out.indices.resize(total);
  exec::ParallelFor(device_, m, kernels::FillNeighbors<T>{view_, queries, radius, exclude_self, out.offsets.data(), out.indices.data()});
}

template <class T>
void UniformGrid<T>::QueryGrid(const UniformGrid& queries, T radius, bool exclude_self, NeighborList& out) const {
  const Index m = queries.size();
  if (!aligned_with(queries) || view_.count == 0 || m == 0) {
    Query(queries.view_.points, m, radius, exclude_self, out);
    return;
  }
  if (radius > cell_size_ * T(1.0000001)) throw Error(ExitCode::kFailure, "neighbor grid: query radius exceeds the cell size");
  out.offsets.resize(m + 1);
  counts_.resize(m + 1);
  counts_.SetZero();
  const Index cells = static_cast<Index>(queries.cell_count());
  exec::ParallelFor(device_, cells, kernels::CountNeighborsByCell<T>{view_, queries.view_, radius, exclude_self, counts_.data()});
  const std::uint64_t total = exec::ExclusiveScan(device_, counts_.data(), out.offsets.data(), m + 1);
  if (total > 0xffffffffULL) throw Error(ExitCode::kFailure, "neighbor grid: more than 2^32 neighbor pairs");
  out.indices.resize(total);
  exec::ParallelFor(device_, cells,
                    kernels::FillNeighborsByCell<T>{view_, queries.view_, radius, exclude_self, out.offsets.data(), out.indices.data()});
}

template class UniformGrid<float>;
template class UniformGrid<double>;

}  // namespace rime::neighbors
