// CUDA backend of the execution layer: device probing, memory, and CUB algorithms.
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_reduce.cuh>
#include <cub/device/device_scan.cuh>
#include <cuda_runtime.h>

#include <string>

#include "../cuda_backend.h"
#include "rime/core/error.h"
#include "rime/exec/cuda_launch.cuh"

namespace rime::exec {
namespace {

void Check(cudaError_t error, const char* what) {
  if (error != cudaSuccess)
    throw Error(ExitCode::kFailure, std::string("CUDA ") + what + " failed: " + cudaGetErrorName(error) + ": " + cudaGetErrorString(error));
}

// Temporary storage for CUB, grown on demand and kept for the process.
struct Scratch {
  void* data = nullptr;
  std::size_t bytes = 0;
  void* Get(std::size_t needed) {
    if (needed > bytes) {
      if (data) cudaFree(data);
      Check(cudaMalloc(&data, needed), "scratch allocation");
      bytes = needed;
    }
    return data;
  }
};
Scratch& GetScratch() {
  static Scratch scratch;
  return scratch;
}

template <class T>
T* DeviceScalar() {
  static T* value = nullptr;
  if (!value) Check(cudaMalloc(&value, sizeof(double) * 2), "scalar allocation");
  return value;
}

struct MaxWithNan {
  template <class T>
  __host__ __device__ T operator()(const T& a, const T& b) const {
    if (a != a || b != b) return a != a ? a : b;
    return a > b ? a : b;
  }
};

}  // namespace

void cuda::CheckLaunch(cudaError_t error, const char* what) { Check(error, what); }
void cuda::ThrowNotCompiled() { throw Error(ExitCode::kFailure, "internal: CUDA backend misuse"); }

namespace cuda_impl {

CudaStatus Query() {
  CudaStatus status;
  int driver = 0;
  int count = 0;
  const cudaError_t error = cudaGetDeviceCount(&count);
  if (error == cudaErrorInsufficientDriver || error == cudaErrorNoDevice || error != cudaSuccess) {
    cudaDriverGetVersion(&driver);
    if (error == cudaErrorInsufficientDriver)
      status.reason = driver == 0 ? "no NVIDIA driver is installed (cudaErrorInsufficientDriver)"
                                  : "the NVIDIA driver is too old for this CUDA " + std::to_string(CUDART_VERSION / 1000) +
                                        " build (driver supports CUDA " + std::to_string(driver / 1000) + "." +
                                        std::to_string(driver % 1000 / 10) + ")";
    else if (error == cudaErrorNoDevice) status.reason = "the NVIDIA driver reports no CUDA device";
    else status.reason = std::string("the CUDA runtime failed to start: ") + cudaGetErrorName(error);
    cudaGetLastError();
    return status;
  }
  if (count == 0) {
    status.reason = "no CUDA device found";
    return status;
  }
  cudaDeviceProp prop{};
  if (cudaGetDeviceProperties(&prop, 0) != cudaSuccess) {
    status.reason = "cannot read the properties of CUDA device 0";
    return status;
  }
  if (prop.major < 7) {
    status.reason = std::string(prop.name) + " is older than compute capability 7.0";
    return status;
  }
  status.usable = true;
  status.ordinal = 0;
  status.device_name = std::string(prop.name) + " (sm_" + std::to_string(prop.major) + std::to_string(prop.minor) + ", " +
                       std::to_string(prop.totalGlobalMem >> 20) + " MiB)";
  return status;
}

void Select(int ordinal) { Check(cudaSetDevice(ordinal), "device selection"); }
void* Malloc(std::size_t bytes) {
  void* p = nullptr;
  Check(cudaMalloc(&p, bytes), "allocation");
  return p;
}
void Free(void* pointer) { cudaFree(pointer); }
void CopyHostToDevice(void* dst, const void* src, std::size_t bytes) {
  Check(cudaMemcpy(dst, src, bytes, cudaMemcpyHostToDevice), "copy to device");
}
void CopyDeviceToHost(void* dst, const void* src, std::size_t bytes) {
  Check(cudaMemcpy(dst, src, bytes, cudaMemcpyDeviceToHost), "copy to host");
}
void CopyDeviceToDevice(void* dst, const void* src, std::size_t bytes) {
  Check(cudaMemcpy(dst, src, bytes, cudaMemcpyDeviceToDevice), "device copy");
}
void Memset0(void* pointer, std::size_t bytes) { Check(cudaMemset(pointer, 0, bytes), "memset"); }
void Synchronize() { Check(cudaDeviceSynchronize(), "synchronize"); }

void SortPairs(std::uint64_t* keys, std::uint32_t* values, std::int64_t n, int key_bits) {
  if (n < 2) return;
  std::uint64_t* keys_alt = static_cast<std::uint64_t*>(Malloc(n * sizeof(std::uint64_t)));
  std::uint32_t* values_alt = static_cast<std::uint32_t*>(Malloc(n * sizeof(std::uint32_t)));
  cub::DoubleBuffer<std::uint64_t> k(keys, keys_alt);
  cub::DoubleBuffer<std::uint32_t> v(values, values_alt);
  std::size_t bytes = 0;
  Check(cub::DeviceRadixSort::SortPairs(nullptr, bytes, k, v, static_cast<int>(n), 0, key_bits), "sort sizing");
  Check(cub::DeviceRadixSort::SortPairs(GetScratch().Get(bytes), bytes, k, v, static_cast<int>(n), 0, key_bits), "sort");
  if (k.Current() != keys) CopyDeviceToDevice(keys, k.Current(), n * sizeof(std::uint64_t));
  if (v.Current() != values) CopyDeviceToDevice(values, v.Current(), n * sizeof(std::uint32_t));
  Free(keys_alt);
  Free(values_alt);
}

std::uint64_t ExclusiveScan(const std::uint32_t* in, std::uint32_t* out, std::int64_t n) {
  if (n == 0) return 0;
  std::uint32_t last_in = 0;
  CopyDeviceToHost(&last_in, in + n - 1, sizeof(last_in));
  std::size_t bytes = 0;
  Check(cub::DeviceScan::ExclusiveSum(nullptr, bytes, in, out, static_cast<int>(n)), "scan sizing");
  Check(cub::DeviceScan::ExclusiveSum(GetScratch().Get(bytes), bytes, in, out, static_cast<int>(n)), "scan");
  std::uint32_t last_out = 0;
  CopyDeviceToHost(&last_out, out + n - 1, sizeof(last_out));
  return std::uint64_t(last_out) + last_in;
}

template <class In, class Out, class Op>
Out Reduce(const In* values, std::int64_t n, Op op, Out init) {
  if (n == 0) return init;
  Out* result = reinterpret_cast<Out*>(DeviceScalar<double>());
  std::size_t bytes = 0;
  Check(cub::DeviceReduce::Reduce(nullptr, bytes, values, result, static_cast<int>(n), op, init), "reduce sizing");
  Check(cub::DeviceReduce::Reduce(GetScratch().Get(bytes), bytes, values, result, static_cast<int>(n), op, init), "reduce");
  Out host{};
  CopyDeviceToHost(&host, result, sizeof(Out));
  return host;
}

double Sum(const float* v, std::int64_t n) { return Reduce<float, double>(v, n, ::cuda::std::plus<double>{}, 0.0); }
double Sum(const double* v, std::int64_t n) { return Reduce<double, double>(v, n, ::cuda::std::plus<double>{}, 0.0); }
float Max(const float* v, std::int64_t n) { return Reduce<float, float>(v, n, MaxWithNan{}, -INFINITY); }
double Max(const double* v, std::int64_t n) { return Reduce<double, double>(v, n, MaxWithNan{}, -INFINITY); }

}  // namespace cuda_impl
}  // namespace rime::exec
