#pragma once

namespace rime::test {

// Under AddressSanitizer a process's resident memory holds shadow memory, redzones and the
// quarantine of freed blocks besides the program's own, so tests that hold a memory estimate
// against the measured peak skip in that build (g++ and clang define __SANITIZE_ADDRESS__ or
// __has_feature(address_sanitizer)).
#if defined(__SANITIZE_ADDRESS__)
inline constexpr bool kAddressSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
inline constexpr bool kAddressSanitizer = true;
#else
inline constexpr bool kAddressSanitizer = false;
#endif
#else
inline constexpr bool kAddressSanitizer = false;
#endif

inline constexpr const char* kMemorySkipReason =
    "AddressSanitizer's shadow memory and quarantine inflate the measured peak; the estimate is for builds without it";

}  // namespace rime::test
