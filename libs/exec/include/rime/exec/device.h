/// @file device.h
/// @brief Run-time choice of the execution backend: `--device auto|cpu|cuda`.
#pragma once

#include <string>
#include <string_view>

namespace rime::exec {

enum class Backend { kCpu, kCuda };

struct Device {
  Backend backend = Backend::kCpu;
  int cuda_ordinal = -1;
  std::string description;  // "CPU (2 threads)" or "CUDA device 0: NVIDIA H100 (sm_90)"

  bool is_cuda() const { return backend == Backend::kCuda; }
  static Device Cpu();
};

/// Whether this build contains the CUDA backend (nvcc was found at configure time).
bool CudaCompiledIn();

struct CudaStatus {
  bool usable = false;
  std::string reason;       // why not, when !usable ("no NVIDIA driver", "no CUDA device", ...)
  std::string device_name;  // when usable
  int ordinal = -1;
};
/// Probes the CUDA runtime once (cached). Never throws.
CudaStatus QueryCuda();

/// Resolves a device request. "auto": a usable GPU, otherwise the CPU with one info line saying why;
/// "cpu": the CPU; "cuda": the GPU or rime::Error(kNoDevice) naming the reason.
Device SelectDevice(std::string_view request);

/// Number of CPU worker threads in use (oneTBB's concurrency, honouring RIME_THREADS / -j).
int CpuThreads();
/// Limits CPU worker threads for the life of the process (0 = all cores).
void SetCpuThreads(int threads);

}  // namespace rime::exec
