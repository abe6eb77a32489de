#include "rime/exec/memory.h"

#include <cstdlib>
#include <cstring>
#include <new>

#include <sys/mman.h>

#include "cuda_backend.h"
#include "rime/core/error.h"

namespace rime::exec {

void* AllocateBytes(const Device& device, std::size_t bytes) {
  if (bytes == 0) return nullptr;
  if (device.is_cuda()) return cuda_impl::Malloc(bytes);
  // 64-byte alignment for vector loads; aligned_alloc needs a multiple of the alignment. Arrays of
  // 2 MiB or more ask for transparent huge pages: first touching fresh 4 KiB pages costs up to
  // 3 ms per MiB on virtual machines (a pool of 100 MiB: 0.4 s), 2 MiB pages about a fortieth.
  constexpr std::size_t kHugePage = std::size_t(2) << 20;
  const std::size_t alignment = bytes >= kHugePage ? kHugePage : 64;
  void* p = std::aligned_alloc(alignment, (bytes + alignment - 1) / alignment * alignment);
  if (!p) throw Error(ExitCode::kFailure, "out of memory allocating " + std::to_string(bytes >> 20) + " MiB");
#ifdef MADV_HUGEPAGE
  if (alignment == kHugePage) madvise(p, bytes, MADV_HUGEPAGE);  // advice only: ignored where THP is off
#endif
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
