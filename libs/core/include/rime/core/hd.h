/// @file hd.h
/// @brief Host/device annotation shared by every kernel body.
///
/// Physics is written once as inline functions over plain data. Under nvcc RIME_HD expands to
/// `__host__ __device__`; with a plain C++ compiler it is empty, so the same code runs on the CPU.
#pragma once

#if defined(__CUDACC__)
#define RIME_HD __host__ __device__
#define RIME_NVCC 1  // this translation unit is compiled by nvcc (host or device pass)
#else
#define RIME_HD
#define RIME_NVCC 0
#endif

#if defined(__CUDA_ARCH__)
#define RIME_DEVICE_CODE 1  // the device pass of nvcc
#else
#define RIME_DEVICE_CODE 0
#endif

#define RIME_HDI RIME_HD inline

// Before a loop over independent lanes: lets the compiler vectorise it without alias checks.
#if defined(__clang__)
#define RIME_IVDEP _Pragma("clang loop vectorize(assume_safety)")
#elif defined(__GNUC__)
#define RIME_IVDEP _Pragma("GCC ivdep")
#else
#define RIME_IVDEP
#endif

#include <cstdint>

namespace rime {
using Index = std::int64_t;
}  // namespace rime
