#include "rime/neighbors/grid.h"

#include <fmt/format.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <bit>
#include <cmath>
#include <limits>
#include <vector>

#if defined(__AVX2__)
#include <immintrin.h>
#endif

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
      [](Box a, const Box& b) {
        return Box{Min(a.lo, b.lo), Max(a.hi, b.hi), a.finite && b.finite};
      });
  const T nan = std::numeric_limits<T>::quiet_NaN();
  lo = box.finite ? box.lo : Vec3<T>(nan, nan, nan);
  hi = box.finite ? box.hi : Vec3<T>(nan, nan, nan);
}

// The candidates of one query cell (the points of its up to 27 neighbor cells, in the order the
// kernels visit them) as padded structure-of-arrays, and one query point's matches. Padding
// points lie far away, so blocks of kLanes candidates need no tail handling.
constexpr int kLanes = 8;

#if defined(__AVX2__)
// Left-packing permutations: row m moves the lanes whose bit is set in m to the front.
struct LeftPackTable {
  std::uint32_t lanes[256][kLanes];
  constexpr LeftPackTable() : lanes{} {
    for (int m = 0; m < 256; ++m) {
      int k = 0;
      for (int l = 0; l < kLanes; ++l)
        if (m >> l & 1) lanes[m][k++] = std::uint32_t(l);
    }
  }
};
constexpr LeftPackTable kLeftPack;
#endif

template <class T>
struct CellCandidates {
  std::vector<T> x, y, z;
  std::vector<std::uint32_t> j;
  std::size_t count = 0, padded = 0;
  std::vector<std::uint32_t> match_j;  // kLanes longer than the candidates: whole blocks are stored
  std::vector<T> rx, ry, rz;

  void Gather(const GridView<T>& target, const GridView<T>& source, std::uint32_t cell) {
    const kernels::CellNeighborhood<T> hood(target, source, cell);
    count = 0;
    for (int k = 0; k < hood.count; ++k) count += hood.end[k] - hood.begin[k];
    padded = (count + kLanes - 1) / kLanes * kLanes;
    if (x.size() < padded) {
      for (auto* a : {&x, &y, &z}) a->resize(padded);
      j.resize(padded);
      match_j.resize(padded + kLanes);
      for (auto* a : {&rx, &ry, &rz}) a->resize(padded + kLanes);
    }
    std::size_t c = 0;
    for (int k = 0; k < hood.count; ++k)
      for (std::uint32_t t = hood.begin[k]; t < hood.end[k]; ++t, ++c) {
        const std::uint32_t idx = target.sorted_index[t];
        const Vec3<T> p = target.points[idx];
        x[c] = p.x, y[c] = p.y, z[c] = p.z, j[c] = idx;
      }
    const T far = std::numeric_limits<T>::max() / 4;  // its squared distance overflows to +inf: never a neighbor
    for (; c < padded; ++c) x[c] = y[c] = z[c] = far, j[c] = 0;
  }

  /// What Match keeps of the candidates within range: their number only, their indices (into
  /// match_j), or also their offsets r = q − x_j (into rx, ry, rz).
  enum class Keep { kCount, kIndices, kOffsets };

  /// The number of candidates within sqrt(r2max) of q, except `self`, keeping what `kKeep` says.
  /// The squared distance is the kernels' Dot(r, r) expression, so exactly the same pairs are found.
  template <Keep kKeep>
  std::size_t Match(const Vec3<T>& q, T r2max, std::uint32_t self) {
#if defined(__AVX2__)
    if constexpr (std::is_same_v<T, float>) {
      typedef float Block __attribute__((vector_size(32)));
      const Block qx = q.x - Block{}, qy = q.y - Block{}, qz = q.z - Block{};
      const __m256 limit = _mm256_set1_ps(r2max);
      const __m256i self_id = _mm256_set1_epi32(int(self));
      std::size_t k = 0;
      for (std::size_t c = 0; c < padded; c += kLanes) {
        Block bx, by, bz;
        __builtin_memcpy(&bx, &x[c], sizeof bx);
        __builtin_memcpy(&by, &y[c], sizeof by);
        __builtin_memcpy(&bz, &z[c], sizeof bz);
        const Block dx = qx - bx, dy = qy - by, dz = qz - bz;
        const Block d2 = dx * dx + dy * dy + dz * dz;
        const __m256i ids = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(&j[c]));
        const __m256 is_self = _mm256_castsi256_ps(_mm256_cmpeq_epi32(ids, self_id));
        const int mask = _mm256_movemask_ps(_mm256_andnot_ps(is_self, _mm256_cmp_ps(__m256(d2), limit, _CMP_LT_OQ)));
        if constexpr (kKeep != Keep::kCount) {
          if (mask == 0) continue;
          const __m256i pack = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(kLeftPack.lanes[mask]));
          _mm256_storeu_si256(reinterpret_cast<__m256i*>(&match_j[k]), _mm256_permutevar8x32_epi32(ids, pack));
          if constexpr (kKeep == Keep::kOffsets) {
            _mm256_storeu_ps(&rx[k], _mm256_permutevar8x32_ps(__m256(dx), pack));
            _mm256_storeu_ps(&ry[k], _mm256_permutevar8x32_ps(__m256(dy), pack));
            _mm256_storeu_ps(&rz[k], _mm256_permutevar8x32_ps(__m256(dz), pack));
          }
        }
        k += std::size_t(__builtin_popcount(unsigned(mask)));
      }
      return k;
    }
#endif
    std::size_t k = 0;
    for (std::size_t c = 0; c < count; ++c) {
      const Vec3<T> r(q.x - x[c], q.y - y[c], q.z - z[c]);
      if constexpr (kKeep != Keep::kCount) match_j[k] = j[c];
      if constexpr (kKeep == Keep::kOffsets) rx[k] = r.x, ry[k] = r.y, rz[k] = r.z;
      k += (Dot(r, r) < r2max) & (j[c] != self);  // branch-free: store always, advance on a match
    }
    return k;
  }

  /// W and ∇W of the first `found` matches kept with Keep::kOffsets: the values of
  /// kernels::PairValues, bit for bit. With AVX2, kLanes pairs at a time: W's and B''s pieces are
  /// clamped instead of branched on (a clamped piece is exactly zero), and every operation rounds
  /// as the compiled scalar kernel does: q is rounded before use (the barrier stops it being
  /// fused into 2 − q), the cubes and squares are rounded, and only the last term of B and B' is
  /// fused. CpuQueryGridMatchesTheKernelsExactly checks it.
  void Values(std::size_t found, const CubicSpline<T>& kernel, T* w, Vec3<T>* grad) {
#if defined(__AVX2__)
    if constexpr (std::is_same_v<T, float>) {
      typedef float Block __attribute__((vector_size(32)));
      const Block zero{}, one = zero + T(1), two = zero + T(2), tiny = zero + T(1e-9) * kernel.h;
      T wk[kLanes], gx[kLanes], gy[kLanes], gz[kLanes];
      for (std::size_t k = 0; k < found; k += kLanes) {
        Block x, y, z;
        __builtin_memcpy(&x, &rx[k], sizeof x);
        __builtin_memcpy(&y, &ry[k], sizeof y);
        __builtin_memcpy(&z, &rz[k], sizeof z);
        const Block len = Block(_mm256_sqrt_ps(__m256(x * x + y * y + z * z)));
        Block q = len * kernel.inv_h;
        asm("" : "+x"(q));
        const Block a = q < two ? two - q : zero, b = q < one ? one - q : zero;
        const Block cube = a * a * a, b4 = T(4) * b * b, a3 = T(-3) * a * a, b12 = T(12) * b;
        const Block shape = Block(_mm256_fnmadd_ps(__m256(b4), __m256(b), __m256(cube)));
        const Block derivative = Block(_mm256_fmadd_ps(__m256(b12), __m256(b), __m256(a3)));
        const Block factor = len < tiny ? zero : kernel.grad_norm * derivative / len;
        const Block value = kernel.w_norm * shape;
        const Block px = x * factor, py = y * factor, pz = z * factor;
        __builtin_memcpy(wk, &value, sizeof wk);
        __builtin_memcpy(gx, &px, sizeof gx);
        __builtin_memcpy(gy, &py, sizeof gy);
        __builtin_memcpy(gz, &pz, sizeof gz);
        for (std::size_t l = 0, e = std::min<std::size_t>(kLanes, found - k); l < e; ++l) {
          w[k + l] = wk[l];
          grad[k + l] = Vec3<T>(gx[l], gy[l], gz[l]);
        }
      }
      return;
    }
#endif
    for (std::size_t k = 0; k < found; ++k) {
      const Vec3<T> r(rx[k], ry[k], rz[k]);
      const T len = Norm(r);
      w[k] = kernel.W(len);
      grad[k] = r * kernel.GradientFactor(len);
    }
  }
};

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
  dense_cells_.clear();
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
  view_.origin = use_fixed
                     ? *fixed_origin
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
                    kernels::InsertCells{keys_.data(), flags_.data(), cell_of_slot_.data(), cell_start_.data(), table_keys_.data(),
                                         table_cells_.data(), table_size - 1});

  view_.table_keys = table_keys_.data();
  view_.table_cells = table_cells_.data();
  view_.table_mask = table_size - 1;
  view_.cell_start = cell_start_.data();
  view_.sorted_index = sorted_index_.data();
  if (!device_.is_cuda()) BuildDenseCells();
}

template <class T>
void UniformGrid<T>::BuildDenseCells() {
  GridView<T>& v = view_;
  const auto coords = [&](std::uint32_t cell, std::int64_t c[3]) {
    const Vec3<T> p = v.points[v.sorted_index[v.cell_start[cell]]];
    c[0] = v.CellCoord(p.x, v.origin.x), c[1] = v.CellCoord(p.y, v.origin.y), c[2] = v.CellCoord(p.z, v.origin.z);
  };
  std::int64_t lo[3], hi[3], c[3];
  coords(0, lo);
  coords(0, hi);
  for (std::uint32_t cell = 1; cell < cells_; ++cell) {
    coords(cell, c);
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], c[a]), hi[a] = std::max(hi[a], c[a]);
  }
  // Dense only while the box costs at most a few words per point (sparse or far-flung clouds hash).
  const double box = double(hi[0] - lo[0] + 1) * double(hi[1] - lo[1] + 1) * double(hi[2] - lo[2] + 1);
  if (box > 4.0 * double(v.count) + 65536.0) return;
  for (int a = 0; a < 3; ++a) v.dense_lo[a] = lo[a], v.dense_dims[a] = hi[a] - lo[a] + 1;
  dense_cells_.assign(std::size_t(box), GridView<T>::kNoCell);
  for (std::uint32_t cell = 0; cell < cells_; ++cell) {
    coords(cell, c);
    dense_cells_[std::size_t(((c[2] - lo[2]) * v.dense_dims[1] + (c[1] - lo[1])) * v.dense_dims[0] + (c[0] - lo[0]))] = cell;
  }
  v.dense_cells = dense_cells_.data();
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
  if (!device_.is_cuda()) {
    CpuQueryByCell(queries, radius, exclude_self, out, nullptr);
    return;
  }
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

template <class T>
void UniformGrid<T>::QueryGrid(const UniformGrid& queries, T radius, bool exclude_self, NeighborList& out,
                               const PairKernelArrays<T>& values) const {
  const Index m = queries.size();
  if (!device_.is_cuda() && aligned_with(queries) && view_.count > 0 && m > 0) {
    if (radius > cell_size_ * T(1.0000001)) throw Error(ExitCode::kFailure, "neighbor grid: query radius exceeds the cell size");
    CpuQueryByCell(queries, radius, exclude_self, out, &values);
    return;
  }
  QueryGrid(queries, radius, exclude_self, out);
  values.w.resize(out.pairs());
  values.grad.resize(out.pairs());
  exec::ParallelFor(device_, m,
                    kernels::PairValues<T>{.xi = queries.view_.points,
                                           .xj = view_.points,
                                           .offsets = out.offsets.data(),
                                           .index = out.indices.data(),
                                           .kernel = values.kernel,
                                           .w = values.w.data(),
                                           .grad = values.grad.data()});
}

// Two passes over the query cells, as the device kernels: count, scan, fill. Each cell copies its
// candidates once into contiguous arrays that every point of the cell scans kLanes at a time.
template <class T>
void UniformGrid<T>::CpuQueryByCell(const UniformGrid& queries, T radius, bool exclude_self, NeighborList& out,
                                    const PairKernelArrays<T>* values) const {
  const Index m = queries.size();
  const GridView<T> target = view_, source = queries.view_;
  const T r2max = radius * radius;
  const std::size_t cells = queries.cell_count();
  static tbb::enumerable_thread_specific<CellCandidates<T>> scratch;
  using Keep = typename CellCandidates<T>::Keep;
  out.offsets.resize(m + 1);
  counts_.resize(m + 1);
  counts_.SetZero();
  // visit(candidates, i, self) for every query point i, its cell's candidates gathered.
  const auto for_each_query = [&](auto&& visit) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cells, 8), [&](const tbb::blocked_range<std::size_t>& range) {
      CellCandidates<T>& cand = scratch.local();
      for (std::size_t cell = range.begin(); cell != range.end(); ++cell) {
        cand.Gather(target, source, std::uint32_t(cell));
        for (std::uint32_t s = source.cell_start[cell], e = source.cell_start[cell + 1]; s < e; ++s) {
          const std::uint32_t i = source.sorted_index[s];
          visit(cand, i, exclude_self ? i : ~0u);
        }
      }
    });
  };
  std::uint32_t* counts = counts_.data();
  for_each_query([&](CellCandidates<T>& cand, std::uint32_t i, std::uint32_t self) {
    counts[i] = std::uint32_t(cand.template Match<Keep::kCount>(source.points[i], r2max, self));
  });
  const std::uint64_t total = exec::ExclusiveScan(device_, counts_.data(), out.offsets.data(), m + 1);
  if (total > 0xffffffffULL) throw Error(ExitCode::kFailure, "neighbor grid: more than 2^32 neighbor pairs");
  out.indices.resize(total);
  if (values) {
    values->w.resize(total);
    values->grad.resize(total);
  }
  const std::uint32_t* offsets = out.offsets.data();
  std::uint32_t* indices = out.indices.data();
  T* w = values ? values->w.data() : nullptr;
  Vec3<T>* grad = values ? values->grad.data() : nullptr;
  for_each_query([&](CellCandidates<T>& cand, std::uint32_t i, std::uint32_t self) {
    const std::uint32_t first = offsets[i];
    const std::size_t found = values ? cand.template Match<Keep::kOffsets>(source.points[i], r2max, self)
                                     : cand.template Match<Keep::kIndices>(source.points[i], r2max, self);
    std::copy_n(cand.match_j.data(), found, indices + first);
    if (values) cand.Values(found, values->kernel, w + first, grad + first);
  });
}

template class UniformGrid<float>;
template class UniformGrid<double>;

}  // namespace rime::neighbors
