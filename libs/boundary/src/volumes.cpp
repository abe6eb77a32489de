// CPU instantiation of the boundary kernel list and the host entry point of the volume computation.
#include "rime/boundary/volumes.h"

#include <algorithm>
#include <chrono>
#include <vector>

#include "rime/boundary/volume_kernels.h"
#include "rime/core/hd.h"
#include "rime/core/log.h"
#include "rime/exec/kernel_list.h"
#include "rime/exec/memory.h"
#include "rime/exec/parallel.h"
#include "rime/neighbors/grid.h"

RIME_BOUNDARY_KERNELS(RIME_INSTANTIATE_CPU_KERNEL)

namespace rime::boundary {
namespace {

// CPU path, one grid cell per task: its (up to 27) neighbour cell ranges are looked up once, the
// points are gathered into sorted order as x, y, z arrays so that every range is contiguous, and
// up to kLanes particles of the cell are summed side by side (SIMD across particles, candidates in
// sequence). Each particle's sum thus adds the same terms in the same order as the per-particle
// kernel (cells as ForEachCandidateCell visits them, slots in sorted order; a skipped term adds an
// exact 0), so the values are bit-identical to BoundaryVolume's and independent of thread count.
template <class T>
void BoundaryVolumesCpu(const neighbors::GridView<T>& grid, std::size_t cells, const CubicSpline<T>& kernel, T* volumes) {
  constexpr int kLanes = 64 / sizeof(T);  // one AVX-512 register
  const Index n = grid.count;
  std::vector<T> sx(n), sy(n), sz(n);
  exec::cpu::ParallelFor(n, [&](Index s) {
    const Vec3<T> p = grid.points[grid.sorted_index[s]];
    sx[s] = p.x, sy[s] = p.y, sz[s] = p.z;
  });
  const T r2max = kernel.SupportRadius() * kernel.SupportRadius(), w0 = kernel.W0(), inv_h = kernel.inv_h, w_norm = kernel.w_norm;
  const T far = T(1e30);  // padding lanes: r2 overflows to +inf, outside the support
  exec::cpu::ParallelFor(Index(cells), [&](Index cell) {
    const neighbors::kernels::CellNeighborhood<T> hood(grid, grid, static_cast<std::uint32_t>(cell));
    const std::uint32_t begin = grid.cell_start[cell], end = grid.cell_start[cell + 1];
    for (std::uint32_t s0 = begin; s0 < end; s0 += kLanes) {
      const std::uint32_t m = std::min<std::uint32_t>(kLanes, end - s0);
      alignas(64) T xi[kLanes], yi[kLanes], zi[kLanes], acc[kLanes];
      for (std::uint32_t l = 0; l < kLanes; ++l) {
        xi[l] = l < m ? sx[s0 + l] : far;
        yi[l] = l < m ? sy[s0 + l] : far;
        zi[l] = l < m ? sz[s0 + l] : far;
        acc[l] = w0;
      }
      for (int k = 0; k < hood.count; ++k)
        for (std::uint32_t t = hood.begin[k]; t < hood.end[k]; ++t) {
          const T xj = sx[t], yj = sy[t], zj = sz[t];
          const std::uint32_t self = t - s0;  // lane t would be (wraps to a huge value when t < s0)
          RIME_IVDEP
          for (std::uint32_t l = 0; l < kLanes; ++l) {
            T r2;
            const T term = kernels::VolumeTerm(xi[l] - xj, yi[l] - yj, zi[l] - zj, inv_h, r2);
            acc[l] = kernels::MulAdd(w_norm, ((r2 < r2max) & (l != self)) ? term : T(0), acc[l]);
          }
        }
      for (std::uint32_t l = 0; l < m; ++l) volumes[grid.sorted_index[s0 + l]] = T(1) / acc[l];
    }
  });
}

}  // namespace

template <class T>
void ComputeBoundaryVolumes(const exec::Device& device, const Vec3<T>* positions, Index n, T h, T* volumes) {
  if (n <= 0) return;
  const CubicSpline<T> kernel(h);
  neighbors::UniformGrid<T> grid(device);
  const auto t0 = std::chrono::steady_clock::now();
  grid.Build(positions, n, kernel.SupportRadius());
  const auto t1 = std::chrono::steady_clock::now();
  if (device.is_cuda()) exec::ParallelFor(device, n, kernels::BoundaryVolume<T>{grid.view(), kernel, volumes});
  else BoundaryVolumesCpu(grid.view(), grid.cell_count(), kernel, volumes);
  exec::Synchronize(device);
  const auto t2 = std::chrono::steady_clock::now();
  log::Debug("boundary volumes of {} particles: grid {:.1f} ms, kernel {:.1f} ms", n, 1e3 * std::chrono::duration<double>(t1 - t0).count(),
             1e3 * std::chrono::duration<double>(t2 - t1).count());
}

template <class T>
std::vector<T> ComputeBoundaryVolumes(const exec::Device& device, const std::vector<Vec3<T>>& positions, T h) {
  if (!device.is_cuda()) {  // host memory is device memory: no copies
    std::vector<T> volumes(positions.size());
    ComputeBoundaryVolumes(device, positions.data(), static_cast<Index>(positions.size()), h, volumes.data());
    return volumes;
  }
  exec::DeviceArray<Vec3<T>> d_positions(device, positions);
  exec::DeviceArray<T> d_volumes(device, positions.size());
  ComputeBoundaryVolumes(device, d_positions.data(), static_cast<Index>(positions.size()), h, d_volumes.data());
  return d_volumes.ToHost();
}

template void ComputeBoundaryVolumes<float>(const exec::Device&, const Vec3<float>*, Index, float, float*);
template void ComputeBoundaryVolumes<double>(const exec::Device&, const Vec3<double>*, Index, double, double*);
template std::vector<float> ComputeBoundaryVolumes<float>(const exec::Device&, const std::vector<Vec3<float>>&, float);
template std::vector<double> ComputeBoundaryVolumes<double>(const exec::Device&, const std::vector<Vec3<double>>&, double);

}  // namespace rime::boundary
