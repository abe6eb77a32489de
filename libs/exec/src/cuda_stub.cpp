// The CUDA backend when this build has no nvcc: probing says why, every other call throws.
#include "cuda_backend.h"
#include "rime/core/error.h"
#include "rime/exec/parallel.h"

namespace rime::exec {

void cuda::ThrowNotCompiled() {
  throw Error(ExitCode::kNoDevice, "this build of Rime has no CUDA backend (nvcc was not found when it was configured)");
}

namespace cuda_impl {
CudaStatus Query() { return {false, "this build has no CUDA backend (nvcc was not found at configure time)", {}, -1}; }
void Select(int) { cuda::ThrowNotCompiled(); }
void* Malloc(std::size_t) { cuda::ThrowNotCompiled(); }
void Free(void*) { cuda::ThrowNotCompiled(); }
void CopyHostToDevice(void*, const void*, std::size_t) { cuda::ThrowNotCompiled(); }
void CopyDeviceToHost(void*, const void*, std::size_t) { cuda::ThrowNotCompiled(); }
void CopyDeviceToDevice(void*, const void*, std::size_t) { cuda::ThrowNotCompiled(); }
void Memset0(void*, std::size_t) { cuda::ThrowNotCompiled(); }
void Synchronize() { cuda::ThrowNotCompiled(); }
void SortPairs(std::uint64_t*, std::uint32_t*, std::int64_t, int) { cuda::ThrowNotCompiled(); }
std::uint64_t ExclusiveScan(const std::uint32_t*, std::uint32_t*, std::int64_t) { cuda::ThrowNotCompiled(); }
double Sum(const float*, std::int64_t) { cuda::ThrowNotCompiled(); }
double Sum(const double*, std::int64_t) { cuda::ThrowNotCompiled(); }
float Max(const float*, std::int64_t) { cuda::ThrowNotCompiled(); }
double Max(const double*, std::int64_t) { cuda::ThrowNotCompiled(); }
}  // namespace cuda_impl
}  // namespace rime::exec
