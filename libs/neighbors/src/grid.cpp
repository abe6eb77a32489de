#include "rime/neighbors/grid.h"

#include <fmt/format.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include <bit>
#include <cmath>
#include <limits>
#include <mutex>
#include <vector>

#if defined(__AVX2__)
#include <immintrin.h>
#endif

#include "rime/core/error.h"
#include "rime/exec/attributes.h"
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

template <class T>
void RequireFinite(const Vec3<T>& lo, const Vec3<T>& hi) {
  if (!IsFinite(lo) || !IsFinite(hi)) throw Error(ExitCode::kDiverged, "neighbor grid: a particle position is NaN or infinite");
}

// The candidates of one query cell (the points of its up to 27 neighbor cells, in the order the
// kernels visit them) as padded structure-of-arrays. Padding points lie far away, so blocks of
// kLanes candidates need no tail handling.
constexpr int kLanes = 8;
constexpr std::size_t kStagedBlock = std::size_t(1) << 16;  // matches per block of the first pass's buffers

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

typedef float FloatBlock __attribute__((vector_size(32)));

/// W and ∇W of kLanes pairs of offsets (x, y, z): the values of kernels::PairValues, bit for bit.
/// W's and B''s pieces are clamped instead of branched on (a clamped piece is exactly zero), and
/// every operation rounds as the compiled scalar kernel does: q is rounded before use (the barrier
/// stops it being fused into 2 − q), the cubes and squares are rounded, and only the last term of
/// B and B' is fused. CpuQueryGridMatchesTheKernelsExactly checks it.
struct PairBlock {
  FloatBlock w, gx, gy, gz;
};
inline PairBlock KernelValues(FloatBlock x, FloatBlock y, FloatBlock z, const CubicSpline<float>& kernel) {
  const FloatBlock zero{}, one = zero + 1.0f, two = zero + 2.0f, tiny = zero + 1e-9f * kernel.h;
  const FloatBlock len = FloatBlock(_mm256_sqrt_ps(__m256(x * x + y * y + z * z)));
  FloatBlock q = len * kernel.inv_h;
  asm("" : "+x"(q));
  const FloatBlock a = q < two ? two - q : zero, b = q < one ? one - q : zero;
  const FloatBlock cube = a * a * a, b4 = 4.0f * b * b, a3 = -3.0f * a * a, b12 = 12.0f * b;
  const FloatBlock shape = FloatBlock(_mm256_fnmadd_ps(__m256(b4), __m256(b), __m256(cube)));
  const FloatBlock derivative = FloatBlock(_mm256_fmadd_ps(__m256(b12), __m256(b), __m256(a3)));
  const FloatBlock factor = len < tiny ? zero : kernel.grad_norm * derivative / len;
  return {kernel.w_norm * shape, x * factor, y * factor, z * factor};
}

/// Stores kLanes vectors given by their components as 3 kLanes consecutive floats (x0 y0 z0 x1 ...).
inline void StoreInterleaved(FloatBlock x, FloatBlock y, FloatBlock z, float* out) {
  const __m256 xy = _mm256_shuffle_ps(__m256(x), __m256(y), _MM_SHUFFLE(2, 0, 2, 0));  // x0 x2 y0 y2 | x4 x6 y4 y6
  const __m256 yz = _mm256_shuffle_ps(__m256(y), __m256(z), _MM_SHUFFLE(3, 1, 3, 1));  // y1 y3 z1 z3 | y5 y7 z5 z7
  const __m256 zx = _mm256_shuffle_ps(__m256(z), __m256(x), _MM_SHUFFLE(3, 1, 2, 0));  // z0 z2 x1 x3 | z4 z6 x5 x7
  const __m256 v03 = _mm256_shuffle_ps(xy, zx, _MM_SHUFFLE(2, 0, 2, 0));               // x0 y0 z0 x1 | x4 y4 z4 x5
  const __m256 v14 = _mm256_shuffle_ps(yz, xy, _MM_SHUFFLE(3, 1, 2, 0));               // y1 z1 x2 y2 | y5 z5 x6 y6
  const __m256 v25 = _mm256_shuffle_ps(zx, yz, _MM_SHUFFLE(3, 1, 3, 1));               // z2 x3 y3 z3 | z6 x7 y7 z7
  _mm256_storeu_ps(out, _mm256_permute2f128_ps(v03, v14, 0x20));
  _mm256_storeu_ps(out + 8, _mm256_permute2f128_ps(v25, v03, 0x30));
  _mm256_storeu_ps(out + 16, _mm256_permute2f128_ps(v14, v25, 0x31));
}
#endif

template <class T>
struct CellCandidates {
  std::vector<T> x, y, z;
  std::vector<std::uint32_t> j;
  std::size_t count = 0, padded = 0;

  /// `in_order`: the target's sorted slot k holds point k, so a cell's points are read as a block.
  void Gather(const GridView<T>& target, const GridView<T>& source, std::uint32_t cell, bool in_order) {
    const kernels::CellNeighborhood<T> hood(target, source, cell);
    const int cells = hood.count;
    const std::uint32_t *begin = hood.begin, *end = hood.end;
    count = 0;
    for (int k = 0; k < cells; ++k) count += end[k] - begin[k];
    padded = (count + kLanes - 1) / kLanes * kLanes;
    if (x.size() < padded + kLanes) {
      for (auto* a : {&x, &y, &z}) a->resize(padded + kLanes);
      j.resize(padded + kLanes);
    }
    T* const px = x.data();
    T* const py = y.data();
    T* const pz = z.data();
    std::uint32_t* const pj = j.data();
    std::size_t c = 0;
    bool gathered = false;
#if defined(__AVX2__)
    if constexpr (std::is_same_v<T, float>) {
      if (in_order) {
        gathered = true;
        // kLanes points at a time, de-interleaved; a cell's last block may run past its end (into
        // slots the next cell overwrites) but not past the last point.
        const float* base = &target.points[0].x;
        const __m256i lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        for (int k = 0; k < cells; ++k) {
          std::uint32_t t = begin[k];
          for (; t < end[k] && t + kLanes <= target.count; t += kLanes, c += kLanes) {
            const __m256 m0 = _mm256_loadu_ps(base + 3 * std::size_t(t)), m1 = _mm256_loadu_ps(base + 3 * std::size_t(t) + 8),
                         m2 = _mm256_loadu_ps(base + 3 * std::size_t(t) + 16);
            const __m256 v03 = _mm256_permute2f128_ps(m0, m1, 0x30);                 // x0 y0 z0 x1 | x4 y4 z4 x5
            const __m256 v14 = _mm256_permute2f128_ps(m0, m2, 0x21);                 // y1 z1 x2 y2 | y5 z5 x6 y6
            const __m256 v25 = _mm256_permute2f128_ps(m1, m2, 0x30);                 // z2 x3 y3 z3 | z6 x7 y7 z7
            const __m256 xy = _mm256_shuffle_ps(v14, v25, _MM_SHUFFLE(2, 1, 3, 2));  // x2 y2 x3 y3
            const __m256 yz = _mm256_shuffle_ps(v03, v14, _MM_SHUFFLE(1, 0, 2, 1));  // y0 z0 y1 z1
            _mm256_storeu_ps(px + c, _mm256_shuffle_ps(v03, xy, _MM_SHUFFLE(2, 0, 3, 0)));
            _mm256_storeu_ps(py + c, _mm256_shuffle_ps(yz, xy, _MM_SHUFFLE(3, 1, 2, 0)));
            _mm256_storeu_ps(pz + c, _mm256_shuffle_ps(yz, v25, _MM_SHUFFLE(3, 0, 3, 1)));
            _mm256_storeu_si256(reinterpret_cast<__m256i*>(pj + c), _mm256_add_epi32(_mm256_set1_epi32(int(t)), lanes));
          }
          if (t > end[k]) c -= t - end[k];  // the overrun
          for (; t < end[k]; ++t, ++c) {
            const Vec3<T> p = target.points[t];
            px[c] = p.x, py[c] = p.y, pz[c] = p.z, pj[c] = t;
          }
        }
      }
    }
#endif
    if (!gathered)
      for (int k = 0; k < cells; ++k)
        for (std::uint32_t t = begin[k]; t < end[k]; ++t, ++c) {
          const std::uint32_t idx = target.sorted_index[t];
          const Vec3<T> p = target.points[idx];
          px[c] = p.x, py[c] = p.y, pz[c] = p.z, pj[c] = idx;
        }
    const T far = std::numeric_limits<T>::max() / 4;  // its squared distance overflows to +inf: never a neighbor
    for (; c < padded; ++c) px[c] = py[c] = pz[c] = far, pj[c] = 0;
  }

  /// Writes the indices of the candidates within sqrt(r2max) of q, except `self` (if kSkipSelf), to
  /// `out` (room for kLanes more than the candidates: whole blocks are stored) and returns their
  /// number. The squared distance is the kernels' Dot(r, r) expression, so exactly the same pairs
  /// are found.
  template <bool kSkipSelf>
  std::size_t Match(const Vec3<T>& q, T r2max, std::uint32_t self, std::uint32_t* out) const {
    const T* const px = x.data();
    const T* const py = y.data();
    const T* const pz = z.data();
    const std::uint32_t* const pj = j.data();
#if defined(__AVX2__)
    if constexpr (std::is_same_v<T, float>) {
      const FloatBlock qx = q.x - FloatBlock{}, qy = q.y - FloatBlock{}, qz = q.z - FloatBlock{};
      const __m256 limit = _mm256_set1_ps(r2max);
      const __m256i self_id = _mm256_set1_epi32(int(self));
      std::size_t k = 0;
      for (std::size_t c = 0; c < padded; c += kLanes) {
        FloatBlock bx, by, bz;
        __builtin_memcpy(&bx, px + c, sizeof bx);
        __builtin_memcpy(&by, py + c, sizeof by);
        __builtin_memcpy(&bz, pz + c, sizeof bz);
        const FloatBlock dx = qx - bx, dy = qy - by, dz = qz - bz;
        const FloatBlock d2 = dx * dx + dy * dy + dz * dz;
        __m256 within = _mm256_cmp_ps(__m256(d2), limit, _CMP_LT_OQ);
        const __m256i ids = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(pj + c));
        if constexpr (kSkipSelf) within = _mm256_andnot_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(ids, self_id)), within);
        const int mask = _mm256_movemask_ps(within);
        const __m256i pack = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(kLeftPack.lanes[mask]));
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(out + k), _mm256_permutevar8x32_epi32(ids, pack));
        k += std::size_t(__builtin_popcount(unsigned(mask)));
      }
      return k;
    }
#endif
    std::size_t k = 0;
    for (std::size_t c = 0; c < count; ++c) {
      const Vec3<T> r(q.x - px[c], q.y - py[c], q.z - pz[c]);
      out[k] = pj[c];
      k += (Dot(r, r) < r2max) & (!kSkipSelf || pj[c] != self);  // branch-free: store always, advance on a match
    }
    return k;
  }
};

/// W and ∇W of the pairs (q, points[j]) for the `found` indices j: kernels::PairValues's values,
/// r = q − x_j rounded as the list search rounds it.
template <class T>
void PairValuesOf(const Vec3<T>& q, const std::uint32_t* j, std::size_t found, const Vec3<T>* points, std::size_t count,
                  const CubicSpline<T>& kernel, T* w, Vec3<T>* grad) {
#if defined(__AVX2__)
  if constexpr (std::is_same_v<T, float>) {
    static_assert(sizeof(Vec3<T>) == 3 * sizeof(T));
    const float* base = &points[0].x;
    const FloatBlock qx = q.x - FloatBlock{}, qy = q.y - FloatBlock{}, qz = q.z - FloatBlock{};
    const std::uint32_t last = std::uint32_t(count - 1);
    for (std::size_t k = 0; k < found; k += kLanes) {
      const std::size_t live = std::min<std::size_t>(kLanes, found - k);
      // Lanes past the end read point 0. Each point is read as 4 floats, so a block holding the
      // array's last point (whose 4th float may lie past the allocation) is gathered instead.
      std::uint32_t id[kLanes];
      bool has_last = false;
      for (std::size_t l = 0; l < kLanes; ++l) {
        id[l] = l < live ? j[k + l] : 0;
        has_last |= id[l] == last;
      }
      FloatBlock px, py, pz;
      if (!has_last) {
        const __m256 r0 = _mm256_loadu2_m128(base + 3 * std::size_t(id[4]), base + 3 * std::size_t(id[0]));
        const __m256 r1 = _mm256_loadu2_m128(base + 3 * std::size_t(id[5]), base + 3 * std::size_t(id[1]));
        const __m256 r2 = _mm256_loadu2_m128(base + 3 * std::size_t(id[6]), base + 3 * std::size_t(id[2]));
        const __m256 r3 = _mm256_loadu2_m128(base + 3 * std::size_t(id[7]), base + 3 * std::size_t(id[3]));
        const __m256 t0 = _mm256_unpacklo_ps(r0, r1), t1 = _mm256_unpacklo_ps(r2, r3);  // x0 x1 y0 y1, x2 x3 y2 y3
        const __m256 t2 = _mm256_unpackhi_ps(r0, r1), t3 = _mm256_unpackhi_ps(r2, r3);  // z0 z1 . ., z2 z3 . .
        px = FloatBlock(_mm256_shuffle_ps(t0, t1, _MM_SHUFFLE(1, 0, 1, 0)));
        py = FloatBlock(_mm256_shuffle_ps(t0, t1, _MM_SHUFFLE(3, 2, 3, 2)));
        pz = FloatBlock(_mm256_shuffle_ps(t2, t3, _MM_SHUFFLE(1, 0, 1, 0)));
      } else {
        __m256i ids;
        __builtin_memcpy(&ids, id, sizeof ids);
        const __m256i at = _mm256_add_epi32(_mm256_add_epi32(ids, ids), ids);
        px = FloatBlock(_mm256_i32gather_ps(base, at, 4));
        py = FloatBlock(_mm256_i32gather_ps(base + 1, at, 4));
        pz = FloatBlock(_mm256_i32gather_ps(base + 2, at, 4));
      }
      const PairBlock v = KernelValues(qx - px, qy - py, qz - pz, kernel);
      if (live == kLanes) {
        _mm256_storeu_ps(w + k, __m256(v.w));
        StoreInterleaved(v.gx, v.gy, v.gz, &grad[k].x);
        continue;
      }
      float wk[kLanes], gx[kLanes], gy[kLanes], gz[kLanes];
      __builtin_memcpy(wk, &v.w, sizeof wk);
      __builtin_memcpy(gx, &v.gx, sizeof gx);
      __builtin_memcpy(gy, &v.gy, sizeof gy);
      __builtin_memcpy(gz, &v.gz, sizeof gz);
      for (std::size_t l = 0; l < live; ++l) {
        w[k + l] = wk[l];
        grad[k + l] = Vec3<T>(gx[l], gy[l], gz[l]);
      }
    }
    return;
  }
#endif
  for (std::size_t k = 0; k < found; ++k) {
    const Vec3<T> p = points[j[k]];
    const Vec3<T> r(q.x - p.x, q.y - p.y, q.z - p.z);
    const T len = Norm(r);
    w[k] = kernel.W(len);
    grad[k] = r * kernel.GradientFactor(len);
  }
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
  Clear(points, n, cell_size);
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
  RequireFinite(lo, hi);
  const T extent = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
  if (extent / cell_size > T(kMaxCellsPerAxis - 4))
    throw Error(ExitCode::kBadInput, fmt::format("particles span {:.4g} m, more than 2^21 neighbor cells of {:.4g} m per axis; "
                                                 "limit the domain or use a larger spacing",
                                                 double(extent), double(cell_size)));
  const bool use_fixed = fixed_origin && OnLattice(lo, hi, *fixed_origin);
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
  IndexCells(n);
}

template <class T>
void UniformGrid<T>::Clear(const Vec3<T>* points, Index n, T cell_size) {
  cell_size_ = cell_size;
  view_ = GridView<T>{};
  view_.points = points;
  view_.count = static_cast<std::uint32_t>(n);
  view_.inv_cell = T(1) / cell_size;
  cells_ = 0;
  dense_cells_.clear();
  in_order_ = false;
}

template <class T>
void UniformGrid<T>::IndexCells(Index n) {
  dense_cells_.clear();
  view_.dense_cells = nullptr;
  flags_.resize(n);
  cell_of_slot_.resize(n);
  exec::ParallelFor(device_, n, kernels::MarkCellStarts{keys_.data(), flags_.data()});
  cells_ = exec::ExclusiveScan(device_, flags_.data(), cell_of_slot_.data(), n);
  cell_start_.resize(cells_ + 1);
  const std::uint32_t end = static_cast<std::uint32_t>(n);
  exec::CopyToDevice(device_, cell_start_.data() + cells_, &end, sizeof end);
  view_.cell_start = cell_start_.data();
  view_.sorted_index = sorted_index_.data();
  view_.table_keys = nullptr;
  view_.table_cells = nullptr;
  view_.table_mask = 0;
  kernels::InsertCells insert{keys_.data(), flags_.data(), cell_of_slot_.data(), cell_start_.data(), nullptr, nullptr, 0};
  if (!device_.is_cuda()) {  // cell starts first: a dense box needs no hash table
    exec::ParallelFor(device_, n, insert);
    BuildDenseCells();
    if (view_.dense_cells) return;
  }

  const std::uint32_t table_size = std::bit_ceil(static_cast<std::uint32_t>(2 * cells_ + 16));
  table_keys_.resize(table_size);
  table_cells_.resize(table_size);
  exec::FillValue(device_, table_keys_, 0, kEmptySlot);
  insert.table_keys = table_keys_.data();
  insert.table_cells = table_cells_.data();
  insert.table_mask = table_size - 1;
  exec::ParallelFor(device_, n, insert);
  view_.table_keys = insert.table_keys;
  view_.table_cells = insert.table_cells;
  view_.table_mask = insert.table_mask;
}

template <class T>
bool UniformGrid<T>::OnLattice(const Vec3<T>& lo, const Vec3<T>& hi, const Vec3<T>& origin) const {
  const T limit = T(kMaxCellsPerAxis - 4);
  return lo.x > origin.x && lo.y > origin.y && lo.z > origin.z && (hi.x - origin.x) / cell_size_ < limit &&
         (hi.y - origin.y) / cell_size_ < limit && (hi.z - origin.z) / cell_size_ < limit;
}

template <class T>
void UniformGrid<T>::Append(const Vec3<T>* points, Index n, const Vec3<T>& origin) {
  const Index first = view_.count, added = n - first;
  // Merging pays while the new points are few; the device and a reordered grid build anew.
  if (device_.is_cuda() || in_order_ || first == 0 || added <= 0 || added > first / 4 || !(view_.origin == origin))
    return BuildImpl(points, n, cell_size_, &origin);
  Vec3<T> lo, hi;
  CpuBounds(points + first, added, lo, hi);
  RequireFinite(lo, hi);
  if (!OnLattice(lo, hi, origin)) return BuildImpl(points, n, cell_size_, &origin);
  view_.points = points;
  view_.count = static_cast<std::uint32_t>(n);
  std::vector<std::uint64_t> new_keys(added);
  std::vector<std::uint32_t> new_index(added);
  exec::ParallelFor(device_, added, kernels::CellKeys<T>{points + first, origin, view_.inv_cell, new_keys.data(), new_index.data()});
  exec::SortPairs(device_, new_keys.data(), new_index.data(), added, 3 * kMortonBits);
  // Merged from the back; a new point goes after the old ones of its cell, as a stable sort puts it.
  keys_.resize(n);
  sorted_index_.resize(n);
  std::uint64_t* keys = keys_.data();
  std::uint32_t* index = sorted_index_.data();
  Index old = first - 1, fresh = added - 1;
  for (Index k = n - 1; fresh >= 0; --k) {
    if (old >= 0 && keys[old] > new_keys[fresh]) {
      keys[k] = keys[old];
      index[k] = index[old--];
    } else {
      keys[k] = new_keys[fresh];
      index[k] = new_index[fresh--] + static_cast<std::uint32_t>(first);
    }
  }
  IndexCells(n);
}

template <class T>
void UniformGrid<T>::BuildSubset(const UniformGrid& parent, const std::uint32_t* flags, const std::uint32_t* slot, const Vec3<T>* points,
                                 Index count, T cell_size, const Vec3<T>& origin) {
  if (device_.is_cuda() || parent.in_order_ || count == 0 || parent.cell_size_ != cell_size || !(parent.view_.origin == origin))
    return BuildImpl(points, count, cell_size, &origin);
  Clear(points, count, cell_size);
  view_.origin = origin;
  // The parent's slots in order, keeping the flagged points: already sorted by cell, and by index
  // within a cell (the parent's are ascending, and so are their places in the subset).
  keys_.resize(count);
  sorted_index_.resize(count);
  const std::uint64_t* parent_keys = parent.keys_.data();
  const std::uint32_t* parent_index = parent.sorted_index_.data();
  Index k = 0;
  for (Index s = 0; s < parent.size(); ++s) {
    const std::uint32_t b = parent_index[s];
    if (!flags[b]) continue;
    keys_.data()[k] = parent_keys[s];
    sorted_index_.data()[k++] = slot[b];
  }
  if (k != count) throw Error(ExitCode::kFailure, "neighbor grid: the subset's count does not match its flags");
  IndexCells(count);
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
  // Dense while the box costs at most a few words per point or 4 MiB in all (far-flung clouds hash):
  // water spread thin over a large floor has 20 cells per point, and probing the hash table for
  // each of a cell's 27 neighbours costs far more than filling such a box once per build.
  const double box = double(hi[0] - lo[0] + 1) * double(hi[1] - lo[1] + 1) * double(hi[2] - lo[2] + 1);
  if (box > 4.0 * double(v.count) + double(1 << 20)) return;
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
  in_order_ = true;
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

// Two passes, as the device kernels, but only the first searches: cell by cell, each cell copies its
// candidates once into contiguous arrays that every point of the cell scans kLanes at a time, and
// the matches are staged in blocks of the grid's pool. After the scan the second pass copies each
// query's matches into place and computes their W and ∇W from the points they name.
template <class T>
void UniformGrid<T>::CpuQueryByCell(const UniformGrid& queries, T radius, bool exclude_self, NeighborList& out,
                                    const PairKernelArrays<T>* values) const {
  const Index m = queries.size();
  const GridView<T> target = view_, source = queries.view_;
  const T r2max = radius * radius;
  const std::size_t cells = queries.cell_count();
  static tbb::enumerable_thread_specific<CellCandidates<T>> scratch;
  out.offsets.resize(m + 1);
  counts_.resize(m + 1);
  counts_.SetZero();
  staged_at_.resize(std::size_t(m));
  // Each worker fills a block at a time, taken from the grid's pool (kept between queries), so
  // the pool holds about the pairs plus a block per worker whichever worker finds them.
  struct Cursor {
    std::uint32_t* block = nullptr;
    std::size_t size = 0, used = 0;
  };
  std::vector<Cursor> cursors(static_cast<std::size_t>(tbb::this_task_arena::max_concurrency()));
  std::size_t next_block = 0;
  std::mutex pool_mutex;
  const auto take_block = [&](std::size_t room, Cursor& at) {
    const std::lock_guard<std::mutex> lock(pool_mutex);
    if (next_block == staged_.size()) staged_.emplace_back(std::max(kStagedBlock, room));
    std::vector<std::uint32_t>& block = staged_[next_block++];
    if (block.size() < room) block.resize(room);
    at = {block.data(), block.size(), 0};
  };
  std::uint32_t* counts = counts_.data();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cells, 8), [&](const tbb::blocked_range<std::size_t>& range) {
    CellCandidates<T>& cand = scratch.local();
    Cursor& at = cursors[std::size_t(tbb::this_task_arena::current_thread_index())];
    for (std::size_t cell = range.begin(); cell != range.end(); ++cell) {
      cand.Gather(target, source, std::uint32_t(cell), in_order_);
      const std::size_t room = cand.padded + kLanes;  // what Match may store
      for (std::uint32_t s = source.cell_start[cell], e = source.cell_start[cell + 1]; s < e; ++s) {
        const std::uint32_t i = source.sorted_index[s];
        if (at.size - at.used < room) take_block(room, at);
        std::uint32_t* staged = at.block + at.used;
        const std::size_t found = exclude_self ? cand.template Match<true>(source.points[i], r2max, i, staged)
                                               : cand.template Match<false>(source.points[i], r2max, ~0u, staged);
        counts[i] = std::uint32_t(found);
        staged_at_[i] = staged;
        at.used += found;
      }
    }
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
  tbb::parallel_for(tbb::blocked_range<Index>(0, m, 256), [&](const tbb::blocked_range<Index>& range) {
    for (Index i = range.begin(); i != range.end(); ++i) {
      const std::uint32_t first = offsets[i], found = offsets[i + 1] - first;
      if (found == 0) continue;
      const std::uint32_t* matches = staged_at_[i];
      std::copy_n(matches, found, indices + first);
      if (values) PairValuesOf(source.points[i], matches, found, target.points, target.count, values->kernel, w + first, grad + first);
    }
  });
}

template class UniformGrid<float>;
template class UniformGrid<double>;

}  // namespace rime::neighbors
