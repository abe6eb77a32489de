/// @file freezing.cpp
/// @brief The freezing step after the water moved (spec §11 step 8): contacts between water and
/// boundary, the water's anisotropy, film transfer and growth direction, film diffusion over the
/// wet region, the phase decisions from one snapshot, and the conversion of the water that froze
/// into ice particles on the object it touched, with the boundary volumes near new ice updated.

#include <cmath>

#include "rime/boundary/volume_kernels.h"
#include "rime/core/kernel.h"
#include "rime/exec/parallel.h"
#include "rime/freeze/kernels.h"
#include "state.h"

namespace rime::sph {

namespace {

template <class T>
freeze::FreezeParams<T> MakeFreezeParams(const io::Scene& scene) {
  const io::FreezingSettings& f = scene.freezing;
  freeze::FreezeParams<T> p{};
  p.h = T(scene.fluid.smoothing_length());
  p.mass = T(scene.fluid.particle_mass());
  p.film_max = T(f.film_max_ratio * scene.fluid.particle_mass());
  p.alpha_solid = T(f.alpha_solid);
  p.alpha_ice = T(f.alpha_ice);
  p.dt_ref = T(f.dt_ref);
  p.glaze_threshold = T(f.glaze_threshold);
  p.icicle_threshold = T(f.icicle_threshold);
  p.growth_sign = T(f.growth_sign);
  p.fr_clamp = f.fr_mode == "clamp";
  p.ce_raw = f.ce_mode == "raw";
  p.ce_sum = f.ce_aggregation == "sum";
  p.isotropic = f.growth == "isotropic";
  p.pca.k_s = T(f.k_s);
  p.pca.k_r = T(f.k_r);
  p.pca.k_n = T(f.k_n);
  p.pca.n_eps = f.n_eps;
  p.pca.s_min = T(f.s_min);
  p.pca.s_max = T(f.s_max);
  p.pca.center_on_particle = f.pca_center == "particle";
  return p;
}

}  // namespace

static_assert(freeze::kIcePhase == std::uint8_t(io::Phase::kIce), "device kernels and files must agree on the ice phase");

template <class T>
void Simulation<T>::Freeze(double dt) {
  State& s = *state_;
  const Index n = s.n(), nb = s.nb();
  if (n == 0 || nb == 0) return;
  modules_.CountLaunch("freezing");
  const freeze::FreezeParams<T> p = MakeFreezeParams<T>(scene_);
  const CubicSpline<T> kernel(p.h);
  const T support = kernel.SupportRadius();
  namespace fk = freeze::kernels;
  FreezingBoundary<T>& fz = *s.freezing;
  FreezingStep<T>& w = *s.freezing_step;
  const Neighborhoods<T>& pairs = s.pairs;

  // Who touches whom: fluid with boundary neighbors, and boundary particles with fluid neighbors
  // (their B–F lists at the new positions, spec §11 step 8).
  w.fluid_flag.resize(n);
  w.boundary_active.resize(nb);
  w.boundary_active.SetZero();
  exec::ParallelFor(device_, n,
                    fk::MarkContacts<T>{.fb_offsets = pairs.fb.offsets.data(), .fb_index = pairs.fb.indices.data(),
                                        .fluid_flag = w.fluid_flag.data(), .boundary_active = w.boundary_active.data()});
  const Index active = ListFlagged(device_, w.boundary_active, nb, s.slot, w.active_list);
  w.active_x.resize(active);
  exec::ParallelFor(device_, active, kernels::Gather<Vec3<T>>{s.boundary.x.data(), w.active_list.data(), w.active_x.data()});
  s.fluid_grid.Query(w.active_x.data(), active, support, false, w.bf);
  exec::ParallelFor(device_, active,
                    fk::MarkFluidFromBoundary{.bf_offsets = w.bf.offsets.data(), .bf_index = w.bf.indices.data(), .fluid_flag = w.fluid_flag.data()});

  // 8a fluid anisotropy, 8b film transfer + 8d growth direction.
  w.fluid_d.resize(n);
  exec::ParallelFor(device_, n,
                    fk::FluidAnisotropy<T>{.flag = w.fluid_flag.data(), .ff_offsets = pairs.ff.offsets.data(), .ff_index = pairs.ff.indices.data(),
                                           .x = s.fluid.x.data(), .kernel = kernel, .params = p, .d = w.fluid_d.data()});
  exec::ParallelFor(device_, active,
                    fk::FilmAndGrowth<T>{.active = w.active_list.data(), .bf_offsets = w.bf.offsets.data(), .bf_index = w.bf.indices.data(),
                                         .boundary_x = s.boundary.x.data(), .boundary_volume = s.boundary.volume.data(),
                                         .boundary_phase = s.boundary.phase.data(), .x = s.fluid.x.data(), .v = s.fluid.v.data(),
                                         .d = w.fluid_d.data(), .kernel = kernel, .params = p, .dt = T(dt), .film = fz.film.data(),
                                         .growth = fz.growth.data(), .growth_valid = fz.growth_valid.data()});
  if (scene_.freezing.drying_rate > 0)
    exec::ParallelFor(device_, nb, fk::DryFilm<T>{.factor = T(std::exp(-scene_.freezing.drying_rate * dt)), .film = fz.film.data()});

  // 8c film diffusion over the wet region and its one-ring. Operator splitting: the diffusion
  // time accumulates until one explicit step of it would use half the stability budget (the
  // plane reference λ h² ≈ 5, spec §9.3), then it is applied with its accumulated time step and
  // sub-stepped if the actual λ_max needs it. At small Δt this saves most diffusion passes.
  const double diffusivity = scene_.freezing.film_diffusion * scene_.fluid.spacing * scene_.fluid.spacing / scene_.freezing.dt_ref;
  diffusion_pending_ += dt;
  const double h = scene_.fluid.smoothing_length();
  if (diffusivity > 0 && diffusion_pending_ * diffusivity * 5.0 / (h * h) >= 0.5) {
    const double dt_diffusion = diffusion_pending_;
    diffusion_pending_ = 0;
    w.wet.resize(nb);
    w.region.resize(nb);
    w.region.SetZero();
    exec::ParallelFor(device_, nb, fk::MarkWet<T>{.film = fz.film.data(), .wet = w.wet.data()});
    exec::ParallelFor(device_, nb,
                      fk::DilateWet<T>{.grid = s.boundary_grid.view(), .wet = w.wet.data(), .radius = support, .region = w.region.data()});
    const Index region = ListFlagged(device_, w.region, nb, s.slot, w.region_list);
    if (region > 0) {
      w.laplacian.resize(region);
      w.lambda.resize(region);
      const fk::FilmLaplacian<T> laplacian{.list = w.region_list.data(), .grid = s.boundary_grid.view(), .volume = s.boundary.volume.data(),
                                           .film = fz.film.data(), .kernel = kernel, .epsilon = T(scene_.viscosity.epsilon),
                                           .laplacian = w.laplacian.data(), .lambda = w.lambda.data()};
      exec::ParallelFor(device_, region, laplacian);
      const double lambda_max = exec::Max(device_, w.lambda.data(), region);
      const int substeps = std::max(1, int(std::ceil(dt_diffusion * diffusivity * lambda_max)));
      for (int sub = 0; sub < substeps; ++sub) {
        if (sub > 0) exec::ParallelFor(device_, region, laplacian);
        exec::ParallelFor(device_, region,
                          fk::ApplyFilmDiffusion<T>{.list = w.region_list.data(), .laplacian = w.laplacian.data(),
                                                    .step = T(dt_diffusion * diffusivity / substeps), .film = fz.film.data()});
      }
    }
  }

  // 8e decisions from one snapshot, 8f conversions applied together.
  for (auto* a : {&w.decision, &w.trigger, &s.keep, &w.frozen}) a->resize(n);
  w.energy_solid.resize(n);
  w.energy_ice.resize(n);
  exec::ParallelFor(device_, n,
                    fk::PhaseDecision<T>{.fb_offsets = pairs.fb.offsets.data(), .fb_index = pairs.fb.indices.data(), .x = s.fluid.x.data(),
                                         .d = w.fluid_d.data(), .boundary_x = s.boundary.x.data(), .boundary_phase = s.boundary.phase.data(),
                                         .film = fz.film.data(), .growth = fz.growth.data(), .growth_valid = fz.growth_valid.data(),
                                         .kernel = kernel, .params = p, .decision = w.decision.data(), .trigger = w.trigger.data(),
                                         .energy_solid = w.energy_solid.data(), .energy_ice = w.energy_ice.data()});
  if (s.freezing_fluid)
    exec::ParallelFor(device_, n,
                      fk::NucleationDelay<T>{.dt = T(dt), .delay = T(scene_.freezing.freeze_delay), .decision = w.decision.data(),
                                             .contact_time = s.freezing_fluid->contact_time.data()});
  exec::ParallelFor(device_, n, fk::KeepUnfrozen{.decision = w.decision.data(), .keep = s.keep.data(), .frozen = w.frozen.data()});
  DeviceArray<std::uint32_t> frozen_list(device_);
  const Index frozen = ListFlagged(device_, w.frozen, n, s.slot, frozen_list);
  if (frozen > 0) ConvertToIce(frozen_list, frozen, time_ + dt);
}

template <class T>
void Simulation<T>::ConvertToIce(const DeviceArray<std::uint32_t>& frozen_list, Index frozen, double when) {
  State& s = *state_;
  FreezingStep<T>& w = *s.freezing_step;
  const Index n = s.n();
  // Gather what the new ice needs (few particles per step: the host does the bookkeeping).
  DeviceArray<Vec3<T>> fx(device_, frozen);
  DeviceArray<std::uint32_t> kind(device_, frozen), trig(device_, frozen), object(device_, frozen);
  DeviceArray<std::int64_t> ids(device_, frozen);
  DeviceArray<freeze::Sym6<T>> d(device_, frozen);
  const std::uint32_t* list = frozen_list.data();
  exec::ParallelFor(device_, frozen, kernels::Gather<Vec3<T>>{s.fluid.x.data(), list, fx.data()});
  exec::ParallelFor(device_, frozen, kernels::Gather<std::uint32_t>{w.decision.data(), list, kind.data()});
  exec::ParallelFor(device_, frozen, kernels::Gather<std::uint32_t>{w.trigger.data(), list, trig.data()});
  exec::ParallelFor(device_, frozen, kernels::Gather<std::uint32_t>{s.boundary.object.data(), trig.data(), object.data()});
  exec::ParallelFor(device_, frozen, kernels::Gather<std::int64_t>{s.fluid.id.data(), list, ids.data()});
  exec::ParallelFor(device_, frozen, kernels::Gather<freeze::Sym6<T>>{w.fluid_d.data(), list, d.data()});
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
  s.ForEachBoundaryGroup([&](auto& group) { Grow(device_, group, frozen, scene_.fluid.rest_density); });
  CopyTail(device_, s.boundary.x, first, hx);
  CopyTail(device_, s.boundary.local, first, local);
  CopyTail(device_, s.boundary.object, first, hobject);
  CopyTail(device_, s.boundary.phase, first, std::vector<std::uint8_t>(frozen, static_cast<std::uint8_t>(io::Phase::kIce)));
  CopyTail(device_, s.boundary.id, first, ids.ToHost());
  CopyTail(device_, s.freezing->ice_kind, first, kinds);
  CopyTail(device_, s.freezing->ice_time, first, std::vector<double>(frozen, when));
  CopyTail(device_, s.freezing->ice_d, first, d.ToHost());
  s.ice_count += frozen;
  // Remove the frozen particles from the fluid.
  const Index kept = n - frozen;
  ListFlagged(device_, s.keep, n, s.slot, s.order);
  s.GatherFluid(device_, kept);
  // The boundary set changed: re-index it and recompute the volumes of every boundary particle
  // within 2h of new ice, the new ice included (spec §3, §9.7).
  const T support = T(2 * scene_.fluid.smoothing_length());
  s.boundary_grid.Build(s.boundary.x.data(), s.nb(), support, lattice_origin_);
  neighbors::NeighborList near(device_);
  s.boundary_grid.Query(fx.data(), frozen, support, false, near);
  w.region.resize(s.nb());
  w.region.SetZero();
  exec::ParallelFor(device_, frozen, kernels::MarkListed{near.offsets.data(), near.indices.data(), w.region.data()});
  const Index dirty = ListFlagged(device_, w.region, s.nb(), s.slot, w.region_list);
  exec::ParallelFor(device_, dirty,
                    boundary::kernels::BoundaryVolume<T>{s.boundary_grid.view(), CubicSpline<T>(support / 2), s.boundary.volume.data(),
                                                         w.region_list.data()});
  FinishBoundaryVolumes();
}

template void Simulation<float>::Freeze(double);
template void Simulation<double>::Freeze(double);
template void Simulation<float>::ConvertToIce(const DeviceArray<std::uint32_t>&, Index, double);
template void Simulation<double>::ConvertToIce(const DeviceArray<std::uint32_t>&, Index, double);

}  // namespace rime::sph
