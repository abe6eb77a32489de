// CPU instantiation of the boundary kernel list and the host entry point of the volume computation.
#include "rime/boundary/volumes.h"

#include <chrono>

#include "rime/boundary/volume_kernels.h"
#include "rime/core/log.h"
#include "rime/exec/kernel_list.h"
#include "rime/exec/memory.h"
#include "rime/exec/parallel.h"
#include "rime/neighbors/grid.h"

RIME_BOUNDARY_KERNELS(RIME_INSTANTIATE_CPU_KERNEL)

namespace rime::boundary {

template <class T>
void ComputeBoundaryVolumes(const exec::Device& device, const Vec3<T>* positions, Index n, T h, T* volumes) {
  if (n <= 0) return;
  const CubicSpline<T> kernel(h);
  neighbors::UniformGrid<T> grid(device);
  const auto t0 = std::chrono::steady_clock::now();
  grid.Build(positions, n, kernel.SupportRadius());
  const auto t1 = std::chrono::steady_clock::now();
  // One thread per particle on the GPU; on the CPU one task per cell shares the cell lookups.
  if (device.is_cuda())
    exec::ParallelFor(device, n, kernels::BoundaryVolume<T>{grid.view(), kernel, volumes});
  else
    exec::ParallelFor(device, Index(grid.cell_count()), kernels::BoundaryVolumeByCell<T>{grid.view(), kernel, volumes});
  exec::Synchronize(device);
  const auto t2 = std::chrono::steady_clock::now();
  log::Debug("boundary volumes of {} particles: grid {:.1f} ms, kernel {:.1f} ms", n,
             1e3 * std::chrono::duration<double>(t1 - t0).count(), 1e3 * std::chrono::duration<double>(t2 - t1).count());
}

template <class T>
std::vector<T> ComputeBoundaryVolumes(const exec::Device& device, const std::vector<Vec3<T>>& positions, T h) {
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
