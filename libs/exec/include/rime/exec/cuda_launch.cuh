/// @file cuda_launch.cuh
/// @brief Definition of the CUDA ParallelFor; included only by the .cu files that instantiate a
/// library's kernel list (see kernel_list.h).
#pragma once

#include <cuda_runtime.h>

#include "rime/exec/parallel.h"

namespace rime::exec::cuda {

void CheckLaunch(cudaError_t error, const char* what);

template <class Kernel>
__global__ void ParallelForEntry(Index n, Kernel kernel) {
  const Index i = static_cast<Index>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < n) kernel(i);
}

template <class Kernel>
void ParallelFor(Index n, const Kernel& kernel) {
  if (n <= 0) return;
  constexpr int kThreads = 256;
  const auto blocks = static_cast<unsigned>((n + kThreads - 1) / kThreads);
  ParallelForEntry<<<blocks, kThreads>>>(n, kernel);
  CheckLaunch(cudaGetLastError(), "kernel launch");
}

}  // namespace rime::exec::cuda
