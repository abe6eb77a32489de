/// @file kernel_list.h
/// @brief How a library declares the kernels both backends must compile.
///
/// Each library with kernels has one header `<lib>/kernels.h` defining
/// `#define RIME_<LIB>_KERNELS(X) X(KernelA) X(KernelB<float>) ...`, then
/// `RIME_<LIB>_KERNELS(RIME_DECLARE_KERNEL)` in that header (an extern declaration for the CUDA
/// instantiation: host code that launches a kernel not on the list fails to link), and one .cu file
/// with `RIME_<LIB>_KERNELS(RIME_INSTANTIATE_CUDA_KERNEL)`. A CPU translation unit expands the
/// same list with RIME_INSTANTIATE_CPU_KERNEL so the list itself is compiled on machines without
/// nvcc too. Kernel types containing commas must be wrapped in a typedef.
#pragma once

#include "rime/exec/parallel.h"

#define RIME_DECLARE_KERNEL(K) extern template void rime::exec::cuda::ParallelFor<K>(rime::Index, const K&);
#define RIME_INSTANTIATE_CUDA_KERNEL(K) template void rime::exec::cuda::ParallelFor<K>(rime::Index, const K&);
#define RIME_INSTANTIATE_CPU_KERNEL(K) template void rime::exec::cpu::ParallelFor<K>(rime::Index, const K&);
