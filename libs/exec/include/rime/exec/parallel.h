/// @file parallel.h
/// @brief ParallelFor, key/value sort, exclusive scan and reductions over both backends.
///
/// Kernel bodies are named functors with `RIME_HD void operator()(Index i) const` that capture
/// views (raw pointers and sizes), never containers. The CPU backend runs them with oneTBB; the
/// CUDA backend launches them from the instantiations listed in each library's kernel list
/// (see RIME_EXEC_KERNELS in rime/exec/kernel_list.h): a kernel missing from a list does not link.
///
/// @code
/// struct Scale { float* v; float s; RIME_HD void operator()(rime::Index i) const { v[i] *= s; } };
/// rime::exec::ParallelFor(device, n, Scale{data, 2.0f});
/// @endcode
#pragma once

#include <cstdint>

#include "rime/core/hd.h"
#include "rime/exec/device.h"

#if !RIME_NVCC
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#endif

namespace rime::exec {

namespace cpu {
#if !RIME_NVCC
/// CPU backend: any callable, including lambdas (host-only code may call this directly).
template <class Kernel>
void ParallelFor(Index n, const Kernel& kernel) {
  if (n <= 0) return;
  tbb::parallel_for(tbb::blocked_range<Index>(0, n, 256), [&](const tbb::blocked_range<Index>& r) {
    for (Index i = r.begin(); i != r.end(); ++i) kernel(i);
  });
}
#endif
}  // namespace cpu

namespace cuda {
/// CUDA backend: defined in cuda_launch.cuh and explicitly instantiated per kernel in a .cu file.
template <class Kernel>
void ParallelFor(Index n, const Kernel& kernel);
[[noreturn]] void ThrowNotCompiled();
}  // namespace cuda

#if !RIME_NVCC
template <class Kernel>
void ParallelFor(const Device& device, Index n, const Kernel& kernel) {
  if (device.is_cuda()) {
#ifdef RIME_HAVE_CUDA
    cuda::ParallelFor(n, kernel);
#else
    cuda::ThrowNotCompiled();
#endif
  } else {
    cpu::ParallelFor(n, kernel);
  }
}
#endif

/// Sorts (key, value) pairs by key, in place, stably; only key bits [0, key_bits) are compared.
/// Deterministic on both backends.
void SortPairs(const Device& device, std::uint64_t* keys, std::uint32_t* values, Index n, int key_bits = 64);

/// out[i] = sum of in[0..i); returns the total. `out` may alias `in`.
std::uint64_t ExclusiveScan(const Device& device, const std::uint32_t* in, std::uint32_t* out, Index n);

/// Deterministic reductions (bit-identical for any thread count on the CPU).
double Sum(const Device& device, const float* values, Index n);
double Sum(const Device& device, const double* values, Index n);
float Max(const Device& device, const float* values, Index n);
double Max(const Device& device, const double* values, Index n);

}  // namespace rime::exec
