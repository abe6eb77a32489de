// Internal interface of the CUDA backend, callable from host C++ code. Implemented in
// cuda/cuda_backend.cu when nvcc exists, otherwise by cuda_stub.cpp (every call throws).
#pragma once

#include <cstddef>
#include <cstdint>

#include "rime/exec/device.h"

namespace rime::exec::cuda_impl {

CudaStatus Query();
void Select(int ordinal);
void* Malloc(std::size_t bytes);
void Free(void* pointer);
void CopyHostToDevice(void* dst, const void* src, std::size_t bytes);
void CopyDeviceToHost(void* dst, const void* src, std::size_t bytes);
void CopyDeviceToDevice(void* dst, const void* src, std::size_t bytes);
void Memset0(void* pointer, std::size_t bytes);
void Synchronize();
void SortPairs(std::uint64_t* keys, std::uint32_t* values, std::int64_t n, int key_bits);
std::uint64_t ExclusiveScan(const std::uint32_t* in, std::uint32_t* out, std::int64_t n);
double Sum(const float* values, std::int64_t n);
double Sum(const double* values, std::int64_t n);
float Max(const float* values, std::int64_t n);
double Max(const double* values, std::int64_t n);

}  // namespace rime::exec::cuda_impl
