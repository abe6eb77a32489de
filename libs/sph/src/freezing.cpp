/// @file freezing.cpp
/// @brief The solver's side of freezing: runs libs/freeze's step on the water and boundary groups,
/// then turns the water that froze into ice particles attached to the object it touched (rows move
/// from the water groups to the boundary groups) and updates the boundary volumes near new ice.

#include <cmath>

#include "rime/boundary/volume_kernels.h"
#include "rime/core/kernel.h"
#include "rime/exec/parallel.h"
#include "rime/freeze/freezing.h"
#include "state.h"

namespace rime::sph {

template <class T>
void Simulation<T>::Freeze(double dt) {
  State& s = *state_;
  const Index n = s.n(), nb = s.nb();
  if (n == 0 || nb == 0) return;
  modules_.CountLaunch("freezing");
  const freeze::Particles<T> particles{.n = n,
                                       .nb = nb,
                                       .x = s.fluid.x.data(),
                                       .v = s.fluid.v.data(),
                                       .ff = &s.pairs.ff,
                                       .fb = &s.pairs.fb,
                                       .fluid_grid = &s.fluid_grid,
                                       .boundary_x = s.boundary.x.data(),
                                       .boundary_volume = s.boundary.volume.data(),
                                       .boundary_phase = s.boundary.phase.data(),
                                       .boundary_grid = &s.boundary_grid,
                                       .viscosity_epsilon = scene_.viscosity.epsilon,
                                       .boundary_moves = s.any_animated};
  DeviceArray<std::uint32_t> frozen_list(device_);
  const Index frozen = freeze::FreezeStep(device_, scene_, particles, dt, diffusion_pending_, *s.freezing,
                                          s.freezing_fluid ? &*s.freezing_fluid : nullptr, *s.freezing_work, s.keep, s.slot, frozen_list);
  if (frozen > 0) ConvertToIce(frozen_list, frozen, time_ + dt);
}

template <class T>
void Simulation<T>::ConvertToIce(const DeviceArray<std::uint32_t>& frozen_list, Index frozen, double when) {
  State& s = *state_;
  FreezingWork<T>& w = *s.freezing_work;
  const Index n = s.n();
  // Gather what the new ice needs (few particles per step: the host does the bookkeeping).
  DeviceArray<Vec3<T>> fx(device_, frozen);
  DeviceArray<std::uint32_t> kind(device_, frozen), trig(device_, frozen), object(device_, frozen);
  DeviceArray<std::int64_t> ids(device_, frozen);
  DeviceArray<freeze::Sym6<T>> d(device_, frozen);
  const std::uint32_t* list = frozen_list.data();
  exec::ParallelFor(device_, frozen, exec::Gather<Vec3<T>>{s.fluid.x.data(), list, fx.data()});
  exec::ParallelFor(device_, frozen, exec::Gather<std::uint32_t>{w.decision.data(), list, kind.data()});
  exec::ParallelFor(device_, frozen, exec::Gather<std::uint32_t>{w.trigger.data(), list, trig.data()});
  exec::ParallelFor(device_, frozen, exec::Gather<std::uint32_t>{s.boundary.object.data(), trig.data(), object.data()});
  exec::ParallelFor(device_, frozen, exec::Gather<std::int64_t>{s.fluid.id.data(), list, ids.data()});
  exec::ParallelFor(device_, frozen, exec::Gather<freeze::Sym6<T>>{w.fluid_d.data(), list, d.data()});
  const auto hx = fx.ToHost();
  const auto hkind = kind.ToHost();
  const auto hobject = object.ToHost();
  std::vector<Vec3<T>> local(frozen);
  for (Index k = 0; k < frozen; ++k) {
    // Ice is attached to the object it froze onto: store its rest-pose (local) position.
    Mat3<double> r;
    Vec3d t;
    s.object_motions[hobject[k]].Pose(time_, r, t);
    const Vec3d l = Transpose(r) * (Vec3d(hx[k]) - t);
    local[k] = ToT<T>(l);
  }
  std::vector<std::uint8_t> kinds(frozen);
  for (Index k = 0; k < frozen; ++k) kinds[k] = static_cast<std::uint8_t>(hkind[k]);
  // New boundary rows start at every attribute's fill value; these are the ones ice sets.
  const Index first = s.nb();
  s.ForEachBoundaryGroup([&](auto& group) { exec::GrowGroup(device_, group, frozen, scene_.fluid.rest_density); });
  exec::CopyTail(device_, s.boundary.x, first, hx);
  exec::CopyTail(device_, s.boundary.local, first, local);
  exec::CopyTail(device_, s.boundary.object, first, hobject);
  exec::CopyTail(device_, s.boundary.phase, first, std::vector<std::uint8_t>(frozen, static_cast<std::uint8_t>(io::Phase::kIce)));
  exec::CopyTail(device_, s.boundary.id, first, ids.ToHost());
  exec::CopyTail(device_, s.freezing->ice_kind, first, kinds);
  exec::CopyTail(device_, s.freezing->ice_time, first, std::vector<double>(frozen, when));
  exec::CopyTail(device_, s.freezing->ice_d, first, d.ToHost());
  s.ice_count += frozen;
  // Remove the frozen particles from the fluid.
  const Index kept = n - frozen;
  exec::ListFlagged(device_, s.keep, n, s.slot, s.order);
  s.GatherFluid(device_, kept);
  // The boundary set changed: merge the new ice into its grid and recompute the volumes of every
  // boundary particle within 2h of new ice, the new ice included (spec §3, §9.7).
  const T support = T(2 * scene_.fluid.smoothing_length());
  s.boundary_grid.Append(s.boundary.x.data(), s.nb(), lattice_origin_);
  neighbors::NeighborList near(device_);
  s.boundary_grid.Query(fx.data(), frozen, support, false, near);
  w.wet.resize(s.nb());
  w.wet.SetZero();
  exec::ParallelFor(device_, frozen,
                    kernels::MarkListed{.offsets = near.offsets.data(), .index = near.indices.data(), .flags = w.wet.data()});
  const Index dirty = exec::ListFlagged(device_, w.wet, s.nb(), s.slot, w.change_list);
  exec::ParallelFor(device_, dirty,
                    boundary::kernels::BoundaryVolume<T>{.grid = s.boundary_grid.view(),
                                                         .kernel = CubicSpline<T>(support / 2),
                                                         .volumes = s.boundary.volume.data(),
                                                         .list = w.change_list.data()});
  FinishBoundaryVolumes();
  // The film diffusion re-evaluates around them (its caches hold until the boundary changes).
  w.structure_touched.resize(s.nb());
  exec::ParallelFor(device_, dirty,
                    freeze::kernels::SetListed{.list = w.change_list.data(), .value = 1u, .flags = w.structure_touched.data()});
}

template void Simulation<float>::Freeze(double);
template void Simulation<double>::Freeze(double);
template void Simulation<float>::ConvertToIce(const DeviceArray<std::uint32_t>&, Index, double);
template void Simulation<double>::ConvertToIce(const DeviceArray<std::uint32_t>&, Index, double);

}  // namespace rime::sph
