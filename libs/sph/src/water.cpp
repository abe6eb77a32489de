/// @file water.cpp
/// @brief Where water comes from and where it goes: the scene's water blocks seeded on a lattice
/// (clear of solids and of the inside of closed objects), emitter nozzles adding layers as their
/// jets advance, and the domain box outside which particles are removed. New particles get the
/// fill value of every water attribute; removal compacts every water group.

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <type_traits>

#include "rime/core/error.h"
#include "rime/core/log.h"
#include "rime/sph/enclosure.h"
#include "state.h"

namespace rime::sph {

template <class T>
void Simulation<T>::SeedWater(const Enclosure& enclosure) {
  State& s = *state_;
  const double dp = scene_.fluid.spacing;
  // Fluid blocks on their lattices of spacing d_p. Particles closer than 1.05 d_p to a boundary
  // particle are dropped: fluid must start about 1.1 d_p from walls (spec §3), and nothing may
  // start inside a solid.
  std::vector<Vec3<T>> x;
  std::vector<Vec3<T>> v;
  for (const io::FluidBlock& block : scene_.fluid_blocks) {
    if (block.Particles(dp) > 200'000'000)
      throw InputError("water block would create more than 200 million particles", SceneField(scene_, "water_block"));
    block.ForEachLatticePoint(dp, [&](const Vec3d& p) {
      x.push_back(ToT<T>(p));
      v.push_back(ToT<T>(block.velocity));
    });
  }
  std::size_t dropped = 0, enclosed = 0;
  if (enclosure.enclosed_cells() > 0) {
    std::vector<Vec3<T>> kept_x, kept_v;
    for (std::size_t i = 0; i < x.size(); ++i)
      if (!enclosure.Inside({double(x[i].x), double(x[i].y), double(x[i].z)})) kept_x.push_back(x[i]), kept_v.push_back(v[i]);
    enclosed = x.size() - kept_x.size();
    x.swap(kept_x);
    v.swap(kept_v);
  }
  if (enclosed) log::Warn("dropped {} water particles inside closed solids", enclosed);
  if (!x.empty() && s.nb() > 0) {
    DeviceArray<Vec3<T>> candidates(device_, x);
    neighbors::NeighborList near(device_);
    s.boundary_grid.Query(candidates.data(), Index(x.size()), T(1.05 * dp), false, near);
    const auto offsets = near.offsets.ToHost();
    std::vector<Vec3<T>> kept_x, kept_v;
    for (std::size_t i = 0; i < x.size(); ++i)
      if (offsets[i + 1] == offsets[i]) {
        kept_x.push_back(x[i]);
        kept_v.push_back(v[i]);
      }
    dropped = x.size() - kept_x.size();
    x.swap(kept_x);
    v.swap(kept_v);
  }
  if (dropped) log::Info("dropped {} water particles closer than 1.05 spacings to a solid", dropped);
  if constexpr (std::is_same_v<T, float>) {
    // Single precision resolves 2^-23 of a coordinate: 10 km from the origin that is 1.2 mm, too
    // coarse for centimetre particles. Refuse rather than simulate silently wrong motion.
    double far = 0;
    for (const Vec3<T>& p : x) far = std::max({far, std::fabs(double(p.x)), std::fabs(double(p.y)), std::fabs(double(p.z))});
    for (const Vec3<T>& p : s.boundary.x.ToHost())
      far = std::max({far, std::fabs(double(p.x)), std::fabs(double(p.y)), std::fabs(double(p.z))});
    const double resolution = far * std::ldexp(1.0, -23);
    if (resolution > 0.01 * dp)
      throw InputError(
          fmt::format("the scene reaches {:.4g} m from the origin, where single precision resolves only {:.3g} m ({:.2g} particle "
                      "spacings): set water.precision = \"double\" or move the scene near the origin",
                      far, resolution, resolution / dp),
          SceneField(scene_, "water.precision"));
  }
  if (!scene_.fluid_blocks.empty() && x.empty() && scene_.emitters.empty())
    throw InputError("every water particle lies inside or against a solid: nothing to simulate", SceneField(scene_, "water_block"));
  SetWater(x, v);
}

template <class T>
void Simulation<T>::SetWater(const std::vector<Vec3<T>>& x, const std::vector<Vec3<T>>& v) {
  State& s = *state_;
  std::vector<std::int64_t> ids(x.size());
  for (auto& id : ids) id = next_id_++;
  s.ForEachFluidGroup([&](auto& group) { exec::ResetGroup(device_, group, x.size(), scene_.fluid.rest_density); });
  s.fluid.x.assign(x);
  s.fluid.v.assign(v);
  s.fluid.id.assign(ids);
}

template <class T>
void Simulation<T>::RemoveOutsideDomain(StepStats& stats) {
  State& s = *state_;
  const Index n = s.n();
  if (n == 0) return;
  s.keep.resize(n);
  s.slot.resize(n);
  exec::ParallelFor(device_, n,
                    kernels::InsideDomain<T>{.x = s.fluid.x.data(), .lo = domain_min_, .hi = domain_max_, .keep = s.keep.data()});
  const Index kept = exec::ListFlagged(device_, s.keep, n, s.slot, s.order);
  if (kept == n) return;
  s.GatherFluid(device_, kept);
  stats.removed_particles = n - kept;
  removed_total_ += n - kept;
}

template <class T>
void Simulation<T>::Emit(double dt, StepStats& stats) {
  State& s = *state_;
  const double dp = scene_.fluid.spacing;
  std::vector<Vec3<T>> new_x, new_v;
  for (std::size_t e = 0; e < scene_.emitters.size(); ++e) {
    const io::Emitter& em = scene_.emitters[e];
    // Active part of [time, time + dt) within [start, stop).
    const double t0 = std::max(time_, em.start), t1 = std::min(time_ + dt, em.stop);
    if (t1 <= t0) continue;
    emitter_travel_[e] += em.speed * (t1 - t0);
    const Vec3d dir = em.direction / Norm(em.direction);
    const Vec3d helper = std::fabs(dir.z) < 0.9 ? Vec3d(0, 0, 1) : Vec3d(1, 0, 0);
    const Vec3d u = Cross(dir, helper) / Norm(Cross(dir, helper));
    const Vec3d w = Cross(dir, u);
    while (emitter_travel_[e] >= dp) {
      emitter_travel_[e] -= dp;
      // The layer emitted `travel` ago has moved that far already.
      const Vec3d base = em.center + dir * emitter_travel_[e];
      em.ForEachLayerPoint(dp, [&](double a, double b) {
        new_x.push_back(ToT<T>(base + u * a + w * b));
        new_v.push_back(ToT<T>(dir * em.speed));
      });
    }
  }
  if (new_x.empty()) return;
  const Index n = s.n(), m = Index(new_x.size());
  std::vector<std::int64_t> ids(m);
  for (auto& id : ids) id = next_id_++;
  s.ForEachFluidGroup([&](auto& group) { exec::GrowGroup(device_, group, m, scene_.fluid.rest_density); });
  exec::CopyTail(device_, s.fluid.x, n, new_x);
  exec::CopyTail(device_, s.fluid.v, n, new_v);
  exec::CopyTail(device_, s.fluid.id, n, ids);
  stats.emitted_particles = m;
}

template <class T>
void Simulation<T>::ComputeDomain(const std::vector<Vec3<T>>& fluid) {
  if (scene_.domain.set) {
    domain_min_ = ToT<T>(scene_.domain.min);
    domain_max_ = ToT<T>(scene_.domain.max);
    return;
  }
  // Default: the bounding box of solids, water and emitters, enlarged by max(1 m, half its size).
  Vec3d lo = Vec3d::Splat(1e300), hi = Vec3d::Splat(-1e300);
  auto grow = [&](const Vec3d& p) { lo = Min(lo, p), hi = Max(hi, p); };
  for (const Vec3<T>& p : BoundaryPositions()) grow(Vec3d(p));
  for (const Vec3<T>& p : fluid) grow(Vec3d(p));
  for (const io::Emitter& e : scene_.emitters) grow(e.center);
  if (lo.x > hi.x) lo = hi = Vec3d{};
  const Vec3d margin = Max(Vec3d::Splat(1.0), (hi - lo) * 0.5);
  domain_min_ = ToT<T>(lo - margin);
  domain_max_ = ToT<T>(hi + margin);
}

template void Simulation<float>::SeedWater(const Enclosure&);
template void Simulation<double>::SeedWater(const Enclosure&);
template void Simulation<float>::SetWater(const std::vector<Vec3<float>>&, const std::vector<Vec3<float>>&);
template void Simulation<double>::SetWater(const std::vector<Vec3<double>>&, const std::vector<Vec3<double>>&);
template void Simulation<float>::RemoveOutsideDomain(StepStats&);
template void Simulation<double>::RemoveOutsideDomain(StepStats&);
template void Simulation<float>::Emit(double, StepStats&);
template void Simulation<double>::Emit(double, StepStats&);
template void Simulation<float>::ComputeDomain(const std::vector<Vec3<float>>&);
template void Simulation<double>::ComputeDomain(const std::vector<Vec3<double>>&);

}  // namespace rime::sph
