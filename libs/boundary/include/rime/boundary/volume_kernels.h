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
/// cell size of at least 2h. With `list`, call k updates only b = list[k] (the simulation's partial
/// update near new ice).
template <class T>
struct BoundaryVolume {
  neighbors::GridView<T> grid;
  CubicSpline<T> kernel;
  T* volumes;
  const std::uint32_t* list = nullptr;
  RIME_HD void operator()(Index k) const {
    const Index b = list ? Index(list[k]) : k;
    const Vec3<T> x = grid.points[b];
    T density_number = kernel.W0();  // the particle itself (spec §3: W(0,h) + Σ_{k≠b})
    grid.ForEachNeighbor(x, kernel.SupportRadius(), [&](std::uint32_t k, const Vec3<T>&, T r2) {
      if (k != static_cast<std::uint32_t>(b)) density_number += kernel.W(std::sqrt(r2));
    });
    volumes[b] = T(1) / density_number;
  }
};

/// The same V_b, one grid cell per call: the (up to 27) neighbour cell ranges are looked up once
/// for all particles of the cell instead of once per particle, which is what costs most on the
/// CPU. Gives bit-identical results to BoundaryVolume (same cells in the same order).
template <class T>
struct BoundaryVolumeByCell {
  neighbors::GridView<T> grid;
  CubicSpline<T> kernel;
  T* volumes;
  RIME_HD void operator()(Index cell) const {
    const std::uint32_t begin = grid.cell_start[cell], end = grid.cell_start[cell + 1];
    const neighbors::kernels::CellNeighborhood<T> hood(grid, grid, static_cast<std::uint32_t>(cell));
    const T r2max = kernel.SupportRadius() * kernel.SupportRadius();
    for (std::uint32_t s = begin; s < end; ++s) {
      const std::uint32_t b = grid.sorted_index[s];
      const Vec3<T> x = grid.points[b];
      T density_number = kernel.W0();
      for (int k = 0; k < hood.count; ++k)
        for (std::uint32_t t = hood.begin[k]; t < hood.end[k]; ++t) {
          const std::uint32_t j = grid.sorted_index[t];
          const Vec3<T> r = x - grid.points[j];
          const T r2 = Dot(r, r);
          if (r2 < r2max && j != b) density_number += kernel.W(std::sqrt(r2));
        }
      volumes[b] = T(1) / density_number;
    }
  }
};

}  // namespace rime::boundary::kernels

#define RIME_BOUNDARY_KERNELS(X)                                                                       \
  X(rime::boundary::kernels::BoundaryVolume<float>) X(rime::boundary::kernels::BoundaryVolume<double>) \
  X(rime::boundary::kernels::BoundaryVolumeByCell<float>) X(rime::boundary::kernels::BoundaryVolumeByCell<double>)
