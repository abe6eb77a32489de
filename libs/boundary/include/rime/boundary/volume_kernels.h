/// @file volume_kernels.h
/// @brief Akinci 2012 boundary volumes as a host/device kernel (spec §3).
///
/// V_b = 1 / ( W(0,h) + Σ_{k≠b, r_bk<2h} W(x_b − x_k, h) ) over all boundary particles together
/// (solid and ice). Ψ_b = ρ0 V_b is the "boundary mass" used in the fluid density and pressure sums.
#pragma once

#include <cmath>

#include "rime/core/hd.h"
#include "rime/core/kernel.h"
#include "rime/core/math.h"
#include "rime/neighbors/grid_kernels.h"

namespace rime::boundary::kernels {

/// a*b + c, fused wherever the target has FMA. The volume sums spell out their fused operations so
/// that the CPU's SIMD path and the per-particle kernel round identically: a compiler contracting
/// a*b + c on its own may do so differently in scalar and in vectorised code.
template <class T>
RIME_HDI T MulAdd(T a, T b, T c) {
#if defined(__FMA__) || defined(__CUDA_ARCH__)
  return std::fma(a, b, c);
#else
  return a * b + c;  // no FMA instructions, so no contraction either
#endif
}

/// The term W(r)/w_norm = B(q) of the Akinci sum for r^2 = (dx, dy, dz)^2 (0 at and beyond 2h),
/// branch-free; `r2` receives r^2. Shared by both volume paths.
template <class T>
RIME_HDI T VolumeTerm(T dx, T dy, T dz, T inv_h, T& r2) {
  r2 = MulAdd(dz, dz, MulAdd(dy, dy, dx * dx));
  const T minus_r = -std::sqrt(r2);  // a = 2 - q and b = 1 - q (q = r/h) as explicit FMAs too
  const T a0 = MulAdd(minus_r, inv_h, T(2)), b0 = MulAdd(minus_r, inv_h, T(1));
  const T a = a0 > T(0) ? a0 : T(0), b = b0 > T(0) ? b0 : T(0);
  return MulAdd(T(-4) * b * b, b, a * a * a);
}

/// volumes[b] = V_b for the grid point b; the grid must be built over the boundary positions with a
/// cell size of at least 2h. With `list`, call k updates only b = list[k] (the simulation's partial
/// update near new ice). The GPU runs this for every particle; the CPU's whole-set path in
/// volumes.cpp gives bit-identical values (same terms added in the same order).
template <class T>
struct BoundaryVolume {
  neighbors::GridView<T> grid;
  CubicSpline<T> kernel;
  T* volumes;
  const std::uint32_t* list = nullptr;
  RIME_HD void operator()(Index k) const {
    const Index b = list ? Index(list[k]) : k;
    const Vec3<T> x = grid.points[b];
    const T r2max = kernel.SupportRadius() * kernel.SupportRadius();
    T density_number = kernel.W0();  // the particle itself (spec §3: W(0,h) + Σ_{k≠b})
    grid.ForEachCandidateCell(x, kernel.SupportRadius(), [&](std::uint32_t begin, std::uint32_t end) {
      for (std::uint32_t s = begin; s < end; ++s) {
        const std::uint32_t j = grid.sorted_index[s];
        const Vec3<T> p = grid.points[j];
        T r2;
        const T term = VolumeTerm(x.x - p.x, x.y - p.y, x.z - p.z, kernel.inv_h, r2);
        if (r2 < r2max && j != static_cast<std::uint32_t>(b)) density_number = MulAdd(kernel.w_norm, term, density_number);
      }
    });
    volumes[b] = T(1) / density_number;
  }
};

}  // namespace rime::boundary::kernels

#define RIME_BOUNDARY_KERNELS(X) X(rime::boundary::kernels::BoundaryVolume<float>) X(rime::boundary::kernels::BoundaryVolume<double>)
