/// @file kernels.h
/// @brief The execution layer's own kernels (used by its tests and by other libraries).
#pragma once

#include <cstdint>

#include "rime/core/hd.h"
#include "rime/core/math.h"
#include "rime/exec/kernel_list.h"

namespace rime::exec {

/// out[i] = a * in[i] + b  (also the parity probe of the GPU check).
struct AffineKernel {
  const double* in;
  double* out;
  double a, b;
  RIME_HD void operator()(Index i) const { out[i] = a * in[i] + b; }
};

/// values[i] = i
struct IotaKernel {
  std::uint32_t* values;
  RIME_HD void operator()(Index i) const { values[i] = static_cast<std::uint32_t>(i); }
};

/// dst[i] = src[order[i]] (reordering along a grid's Z curve, compaction).
template <class V>
struct Gather {
  const V* src;
  const std::uint32_t* order;
  V* dst;
  RIME_HD void operator()(Index i) const { dst[i] = src[order[i]]; }
};

/// For every kept i: order[slot[i]] = i (slot = exclusive scan of keep): the compaction map.
struct CompactionOrder {
  const std::uint32_t* keep;
  const std::uint32_t* slot;
  std::uint32_t* order;
  RIME_HD void operator()(Index i) const {
    if (keep[i]) order[slot[i]] = static_cast<std::uint32_t>(i);
  }
};

}  // namespace rime::exec

// Gather for the element types of every library's attributes (a library adds its own types).
// One kernel per line: clang-format 14 keeps that layout but rewraps a line of several on every run.
#define RIME_EXEC_KERNELS(X)                \
  X(rime::exec::AffineKernel)               \
  X(rime::exec::IotaKernel)                 \
  X(rime::exec::CompactionOrder)            \
  X(rime::exec::Gather<float>)              \
  X(rime::exec::Gather<double>)             \
  X(rime::exec::Gather<rime::Vec3<float>>)  \
  X(rime::exec::Gather<rime::Vec3<double>>) \
  X(rime::exec::Gather<std::int64_t>)       \
  X(rime::exec::Gather<std::uint32_t>)      \
  X(rime::exec::Gather<std::uint8_t>)
