/// @file volumes.h
/// @brief Boundary volumes V_b of any set of boundary particles, on any device (spec §3).
///
/// The boundary stage calls this per object; the simulation calls it again over the union of all
/// objects (and after ice forms), since V_b depends on every boundary neighbour.
#pragma once

#include <vector>

#include "rime/core/math.h"
#include "rime/exec/device.h"

namespace rime::boundary {

/// `positions` and `volumes` are device pointers of `device` (n elements each). h = smoothing length.
template <class T>
void ComputeBoundaryVolumes(const exec::Device& device, const Vec3<T>* positions, Index n, T h, T* volumes);

/// Host convenience: copies to the device, computes, copies back.
template <class T>
std::vector<T> ComputeBoundaryVolumes(const exec::Device& device, const std::vector<Vec3<T>>& positions, T h);

extern template void ComputeBoundaryVolumes<float>(const exec::Device&, const Vec3<float>*, Index, float, float*);
extern template void ComputeBoundaryVolumes<double>(const exec::Device&, const Vec3<double>*, Index, double, double*);
extern template std::vector<float> ComputeBoundaryVolumes<float>(const exec::Device&, const std::vector<Vec3<float>>&, float);
extern template std::vector<double> ComputeBoundaryVolumes<double>(const exec::Device&, const std::vector<Vec3<double>>&, double);

}  // namespace rime::boundary
