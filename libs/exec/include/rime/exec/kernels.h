/// @file kernels.h
/// @brief The execution layer's own kernels (used by its tests and by other libraries).
#pragma once

#include <cstdint>

#include "rime/core/hd.h"
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

}  // namespace rime::exec

#define RIME_EXEC_KERNELS(X) X(rime::exec::AffineKernel) X(rime::exec::IotaKernel)
