/// @file volume_kernels.h
/// @brief Akinci 2012 boundary volumes as a host/device kernel (spec §3).
///
/// V_b = 1 / ( W(0,h) + Σ_{k≠b, r_bk<2h} W(x_b − x_k, h) ) over all boundary particles together
/// (solid and ice). Ψ_b = ρ0 V_b is the "boundary mass" used in the fluid density and pressure sums.
#pragma once

#include "rime/core/hd.h"
#include "rime/core/kernel.h"
#include "rime/core/math.h"
#include "rime/neighbors/grid_kernels.h"

namespace rime::boundary::kernels {

/// volumes[b] = V_b for the grid point b; the grid must be built over the boundary positions with a
/// cell size of at least 2h.
template <class T>
struct BoundaryVolume {
  neighbors::GridView<T> grid;
  CubicSpline<T> kernel;
  T* volumes;
  RIME_HD void operator()(Index b) const {
    const Vec3<T> x = grid.points[b];
    T density_number = kernel.W0();  // the particle itself (spec §3: W(0,h) + Σ_{k≠b})
    grid.ForEachNeighbor(x, kernel.SupportRadius(), [&](std::uint32_t k, const Vec3<T>&, T r2) {
      if (k != static_cast<std::uint32_t>(b)) density_number += kernel.W(std::sqrt(r2));
    });
    volumes[b] = T(1) / density_number;
  }
};

}  // namespace rime::boundary::kernels

#define RIME_BOUNDARY_KERNELS(X) \
  X(rime::boundary::kernels::BoundaryVolume<float>) X(rime::boundary::kernels::BoundaryVolume<double>)
