// libFuzzer target: see rime::fuzz::BakeState in entry_points.h.
#include <cstddef>
#include <cstdint>

#include "entry_points.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return rime::fuzz::RunOne(rime::fuzz::BakeState, data, size);
}
