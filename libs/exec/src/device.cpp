#include "rime/exec/device.h"

#include <tbb/global_control.h>
#include <tbb/info.h>

#include <cstdlib>
#include <fmt/format.h>
#include <memory>
#include <mutex>

#include "cuda_backend.h"
#include "rime/core/error.h"
#include "rime/core/log.h"

namespace rime::exec {
namespace {
std::unique_ptr<tbb::global_control> g_thread_limit;
int g_threads = 0;
}  // namespace

bool CudaCompiledIn() {
#ifdef RIME_HAVE_CUDA
  return true;
#else
  return false;
#endif
}

CudaStatus QueryCuda() {
  static std::once_flag once;
  static CudaStatus status;
  std::call_once(once, [] { status = cuda_impl::Query(); });
  return status;
}

void SetCpuThreads(int threads) {
  g_thread_limit.reset();
  g_threads = 0;
  if (threads > 0) {
    g_thread_limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, threads);
    g_threads = threads;
  }
}

int CpuThreads() {
  if (g_threads > 0) return g_threads;
  return static_cast<int>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
}

Device Device::Cpu() { return Device{Backend::kCpu, -1, fmt::format("CPU ({} threads)", CpuThreads())}; }

Device SelectDevice(std::string_view request) {
  if (request == "cpu") return Device::Cpu();
  if (request != "auto" && request != "cuda")
    throw Error(ExitCode::kUsage, fmt::format("unknown device '{}' (expected auto, cpu or cuda)", request), "--device");
  const CudaStatus cuda = QueryCuda();
  if (cuda.usable) {
    cuda_impl::Select(cuda.ordinal);
    Device d{Backend::kCuda, cuda.ordinal, fmt::format("CUDA device {}: {}", cuda.ordinal, cuda.device_name)};
    log::Info("using {}", d.description);
    return d;
  }
  if (request == "cuda") throw Error(ExitCode::kNoDevice, "--device cuda: no usable GPU: " + cuda.reason);
  Device d = Device::Cpu();
  log::Info("no usable GPU ({}); running on the {}", cuda.reason, d.description);
  return d;
}

}  // namespace rime::exec
