#include "rime/exec/memory.h"

#include <cstdlib>
#include <cstring>
#include <new>

#include "cuda_backend.h"
#include "rime/core/error.h"

namespace rime::exec {

void* AllocateBytes(const Device& device, std::size_t bytes) {
  if (bytes == 0) return nullptr;
  if (device.is_cuda()) return cuda_impl::Malloc(bytes);
  // 64-byte alignment for vector loads; aligned_alloc needs a multiple of the alignment.
  void* p = std::aligned_alloc(64, (bytes + 63) / 64 * 64);
  if (!p) throw Error(ExitCode::kFailure, "out of memory allocating " + std::to_string(bytes >> 20) + " MiB");
  return p;
}

void FreeBytes(const Device& device, void* pointer) {
  if (!pointer) return;
  if (device.is_cuda()) cuda_impl::Free(pointer);
  else std::free(pointer);
}

void CopyToDevice(const Device& device, void* dst, const void* src, std::size_t bytes) {
  if (!bytes) return;
  if (device.is_cuda()) cuda_impl::CopyHostToDevice(dst, src, bytes);
  else std::memcpy(dst, src, bytes);
}

void CopyToHost(const Device& device, void* dst, const void* src, std::size_t bytes) {
  if (!bytes) return;
  if (device.is_cuda()) cuda_impl::CopyDeviceToHost(dst, src, bytes);
  else std::memcpy(dst, src, bytes);
}

void CopyOnDevice(const Device& device, void* dst, const void* src, std::size_t bytes) {
  if (!bytes) return;
  if (device.is_cuda()) cuda_impl::CopyDeviceToDevice(dst, src, bytes);
  else std::memmove(dst, src, bytes);
}

void FillZero(const Device& device, void* pointer, std::size_t bytes) {
  if (!bytes) return;
  if (device.is_cuda()) cuda_impl::Memset0(pointer, bytes);
  else std::memset(pointer, 0, bytes);
}

void Synchronize(const Device& device) {
  if (device.is_cuda()) cuda_impl::Synchronize();
}

}  // namespace rime::exec
