/// @file atomic.h
/// @brief Atomics usable in kernel bodies on both backends.
#pragma once

#include <cstdint>

#include "rime/core/hd.h"

namespace rime::exec {

/// Compare-and-swap on a 64-bit word; returns the previous value.
RIME_HDI std::uint64_t AtomicCas(std::uint64_t* address, std::uint64_t expected, std::uint64_t desired) {
#if RIME_DEVICE_CODE
  return atomicCAS(reinterpret_cast<unsigned long long*>(address), static_cast<unsigned long long>(expected),
                   static_cast<unsigned long long>(desired));
#else
  __atomic_compare_exchange_n(address, &expected, desired, false, __ATOMIC_ACQ_REL, __ATOMIC_ACQUIRE);
  return expected;
#endif
}

RIME_HDI std::uint32_t AtomicAdd(std::uint32_t* address, std::uint32_t value) {
#if RIME_DEVICE_CODE
  return atomicAdd(address, value);
#else
  return __atomic_fetch_add(address, value, __ATOMIC_RELAXED);
#endif
}

}  // namespace rime::exec
