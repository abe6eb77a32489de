/// @file freezing.cpp
/// @brief The freezing step's order of operations (spec §11 step 8a–8e); see freezing.h.

#include "rime/freeze/freezing.h"

#include <algorithm>
#include <cmath>
#include <type_traits>

#include "rime/core/kernel.h"
#include "rime/exec/parallel.h"

namespace rime::freeze {

template <class T>
FreezeParams<T> MakeFreezeParams(const io::Scene& scene) {
  const io::FreezingSettings& f = scene.freezing;
  FreezeParams<T> p{};
  p.h = T(scene.fluid.smoothing_length());
  p.mass = T(scene.fluid.particle_mass());
  p.film_max = T(f.film_max_ratio * scene.fluid.particle_mass());
  p.alpha_solid = T(f.alpha_solid);
  p.alpha_ice = T(f.alpha_ice);
  p.dt_ref = T(f.dt_ref);
  p.glaze_threshold = T(f.glaze_threshold);
  p.icicle_threshold = T(f.icicle_threshold);
  p.growth_sign = T(f.growth_sign);
  p.gravity_growth = T(f.gravity_growth);
  p.tip_growth = T(f.tip_growth);
  const double g = Norm(scene.solver.gravity);
  p.gravity_dir = g > 0 && scene.Enabled("gravity") ? Vec3<T>(scene.solver.gravity / g) : Vec3<T>{};
  p.fr_clamp = f.fr_mode == io::FrMode::kClamp;
  p.ce_raw = f.ce_mode == io::CeMode::kRaw;
  p.ce_sum = f.ce_aggregation == io::CeAggregation::kSum;
  p.isotropic = f.growth == io::Growth::kIsotropic;
  p.pca.k_s = T(f.k_s);
  p.pca.k_r = T(f.k_r);
  p.pca.k_n = T(f.k_n);
  p.pca.n_eps = f.n_eps;
  p.pca.s_min = T(f.s_min);
  p.pca.s_max = T(f.s_max);
  p.pca.center_on_particle = f.pca_center == io::PcaCenter::kParticle;
  return p;
}

namespace {

// Drops the Laplacian rows that changes of the boundary made wrong: all of them when it moved,
// its caches were dropped or its grid changed cells; else those of the particles within the
// support of new ice (structure_touched). A row farther from new ice keeps its neighbours and
// their order: new ice is appended, and the grid's stable sort bins it after the older particles.
template <class T>
void DropChangedRows(const exec::Device& device, const Particles<T>& particles, FreezingWork<T>& work, DeviceArray<std::uint32_t>& slot) {
  const Index nb = particles.nb;
  work.row_begin.resize(nb);
  work.row_length.resize(nb);  // new particles have no row (length 0)
  const neighbors::GridView<T> grid = particles.boundary_grid->view();
  if (!work.diffusion_cache_valid || particles.boundary_moves || !(grid.origin == work.row_grid_origin) ||
      grid.inv_cell != work.row_grid_inv_cell) {
    work.row_length.SetZero();
    work.row_pool_used = work.row_pool_compacted = 0;
    work.row_grid_origin = grid.origin;
    work.row_grid_inv_cell = grid.inv_cell;
    return;
  }
  const Index changed = exec::ListFlagged(device, work.structure_touched, nb, slot, work.change_list);
  exec::ParallelFor(device, changed, kernels::SetListed{.list = work.change_list.data(), .value = 0u, .flags = work.row_length.data()});
}

// The pool's size at which it is compacted: twice what it held after its last compaction (rows
// dropped near new ice leave gaps), plus a margin for small pools.
inline std::size_t CompactionPoint(std::size_t compacted) { return 2 * compacted + (std::size_t(1) << 16); }

// Moves the kept rows into fresh pools without the gaps, with room for `room` more pairs now and
// capacity up to the next compaction. Copying is several times cheaper than listing the rows again
// and keeps them and their values bit for bit; the pools move one at a time to bound the peak.
template <class T>
void CompactRows(const exec::Device& device, FreezingWork<T>& work, std::size_t room) {
  const Index nb = Index(work.row_length.size());
  DeviceArray<std::uint32_t> begin(device, nb);
  const std::size_t kept = exec::ExclusiveScan(device, work.row_length.data(), begin.data(), nb);
  const auto move = [&](auto& pool) {
    using E = std::remove_reference_t<decltype(*pool.data())>;
    DeviceArray<E> fresh(device);
    fresh.reserve(CompactionPoint(kept + room));
    fresh.resize(kept);
    exec::ParallelFor(device, nb,
                      kernels::MoveRows<E>{.from_begin = work.row_begin.data(),
                                           .length = work.row_length.data(),
                                           .to_begin = begin.data(),
                                           .from = pool.data(),
                                           .to = fresh.data()});
    pool.swap(fresh);
  };
  move(work.row_pool);
  move(work.row_x_grad);
  move(work.row_denominator);
  work.row_begin.swap(begin);
  work.row_pool_used = kept;
}

// Lists the rows of the `count` particles of `list` that have none, appending them to the pool
// (compacted first when it reaches its compaction point).
template <class T>
void ListRows(const exec::Device& device, const Particles<T>& particles, const CubicSpline<T>& kernel, const std::uint32_t* list,
              Index count, FreezingWork<T>& work, DeviceArray<std::uint32_t>& slot) {
  work.row_flags.resize(count);
  exec::ParallelFor(device, count, kernels::MarkRowless{.list = list, .length = work.row_length.data(), .flags = work.row_flags.data()});
  const Index rowless = exec::ListFlagged(device, work.row_flags, count, slot, work.row_list);
  if (rowless == 0) return;
  exec::ParallelFor(device, rowless,
                    exec::Gather<std::uint32_t>{list, work.row_list.data(), work.row_list.data()});  // in place: i reads and writes i
  work.row_x.resize(rowless);
  exec::ParallelFor(device, rowless, exec::Gather<Vec3<T>>{particles.boundary_x, work.row_list.data(), work.row_x.data()});
  particles.boundary_grid->Query(work.row_x.data(), rowless, kernel.SupportRadius(), false, work.new_rows);
  const std::size_t pairs = work.new_rows.indices.size();
  const bool compact = work.row_pool_used > 0 && work.row_pool_used + pairs > CompactionPoint(work.row_pool_compacted);
  if (compact) CompactRows(device, work, pairs);
  const std::size_t used = work.row_pool_used + pairs;
  // An empty pool (the first listing) gets its room up to the compaction point at once too.
  if (work.row_pool_compacted == 0) {
    work.row_pool.reserve(CompactionPoint(used));
    work.row_x_grad.reserve(CompactionPoint(used));
    work.row_denominator.reserve(CompactionPoint(used));
  }
  work.row_pool.resize(used);
  work.row_x_grad.resize(used);
  work.row_denominator.resize(used);
  exec::ParallelFor(device, rowless,
                    kernels::StoreRows<T>{.list = work.row_list.data(),
                                          .offsets = work.new_rows.offsets.data(),
                                          .indices = work.new_rows.indices.data(),
                                          .base = std::uint32_t(work.row_pool_used),
                                          .x = particles.boundary_x,
                                          .kernel = kernel,
                                          .epsilon = T(particles.viscosity_epsilon),
                                          .begin = work.row_begin.data(),
                                          .length = work.row_length.data(),
                                          .pool = work.row_pool.data(),
                                          .x_grad = work.row_x_grad.data(),
                                          .denominator = work.row_denominator.data()});
  work.row_pool_used = used;
  work.new_rows.indices.release();  // scratch that may hold a whole listing
  if (work.row_pool_compacted == 0 || compact) work.row_pool_compacted = used;
}

// The film diffusion's region (spec §9.3: the wet particles and their one-ring) in
// work.region_list; returns its size. With valid caches only what changed since the last call is
// looked at: the particles that became wet grow it, the boundary changed by new ice joins it, and
// a particle that dried rebuilds it (it may shrink).
template <class T>
Index UpdateDiffusionRegion(const exec::Device& device, const Particles<T>& particles, T support, FreezingBoundary<T>& film,
                            FreezingWork<T>& work, DeviceArray<std::uint32_t>& slot) {
  const Index nb = particles.nb;
  const neighbors::GridView<T> grid = particles.boundary_grid->view();
  DropChangedRows(device, particles, work, slot);
  work.wet.resize(nb);
  exec::ParallelFor(device, nb, kernels::MarkWet<T>{.film = film.film.data(), .wet = work.wet.data()});
  work.newly_wet.resize(nb);
  work.dried.resize(nb);
  exec::ParallelFor(
      device, nb,
      kernels::WetChanges{
          .wet = work.wet.data(), .wet_seen = work.wet_seen.data(), .newly_wet = work.newly_wet.data(), .dried = work.dried.data()});
  const bool rebuild =
      !work.diffusion_cache_valid || particles.boundary_moves || exec::ListFlagged(device, work.dried, nb, slot, work.change_list) > 0;
  if (rebuild) {
    work.region.SetZero();
    exec::ParallelFor(device, nb,
                      kernels::DilateWet<T>{.grid = grid, .wet = work.wet.data(), .radius = support, .region = work.region.data()});
    exec::FillValue(device, work.stale, 0, 1u);  // every Laplacian is evaluated anew
    work.film_touched.SetZero();
    work.structure_touched.SetZero();
    work.diffusion_cache_valid = !particles.boundary_moves;
  } else {
    const Index grown = exec::ListFlagged(device, work.newly_wet, nb, slot, work.change_list);
    exec::ParallelFor(
        device, grown,
        kernels::GrowRegion<T>{
            .grid = grid, .list = work.change_list.data(), .radius = support, .region = work.region.data(), .stale = work.stale.data()});
    const Index changed = exec::ListFlagged(device, work.structure_touched, nb, slot, work.change_list);
    exec::ParallelFor(device, changed,
                      kernels::JoinRegion<T>{.grid = grid,
                                             .list = work.change_list.data(),
                                             .wet = work.wet.data(),
                                             .radius = support,
                                             .region = work.region.data(),
                                             .stale = work.stale.data()});
  }
  return exec::ListFlagged(device, work.region, nb, slot, work.region_list);
}

// The region particles whose Laplacian (and stability bound) must be evaluated before the next
// diffusion step, listed in `list` (work.change_list or work.region_list); returns how many. A
// Laplacian depends on the films, volumes and positions within its support, so those around a
// changed film or a changed boundary particle are evaluated, and those that entered the region;
// the others keep theirs. Marking around a changed film costs about what evaluating a Laplacian
// does, so when the changed films are many the whole region is evaluated instead (evaluation is
// deterministic: the values are the same).
template <class T>
Index EvaluationList(const exec::Device& device, const Particles<T>& particles, T support, Index region, FreezingWork<T>& work,
                     DeviceArray<std::uint32_t>& slot, const std::uint32_t*& list) {
  const Index nb = particles.nb;
  const neighbors::GridView<T> grid = particles.boundary_grid->view();
  work.evaluate.resize(nb);
  work.evaluate.SetZero();
  const Index film_changes = exec::ListFlagged(device, work.film_touched, nb, slot, work.change_list);
  if (2 * film_changes >= region) {
    work.film_touched.SetZero();
    work.structure_touched.SetZero();
    exec::ParallelFor(device, nb,
                      kernels::AddStale{.region = work.region.data(), .stale = work.stale.data(), .evaluate = work.evaluate.data()});
    list = work.region_list.data();
    return region;
  }
  for (DeviceArray<std::uint32_t>* changed : {&work.film_touched, &work.structure_touched}) {
    const Index count = changed == &work.film_touched ? film_changes : exec::ListFlagged(device, *changed, nb, slot, work.change_list);
    exec::ParallelFor(device, count,
                      kernels::MarkAffected<T>{.grid = grid,
                                               .list = work.change_list.data(),
                                               .region = work.region.data(),
                                               .radius = support,
                                               .evaluate = work.evaluate.data()});
    changed->SetZero();
  }
  exec::ParallelFor(device, nb,
                    kernels::AddStale{.region = work.region.data(), .stale = work.stale.data(), .evaluate = work.evaluate.data()});
  const Index count = exec::ListFlagged(device, work.evaluate, nb, slot, work.change_list);
  list = work.change_list.data();
  return count;
}

}  // namespace

template <class T>
Index FreezeStep(const exec::Device& device, const io::Scene& scene, const Particles<T>& particles, double dt, double& diffusion_pending,
                 FreezingBoundary<T>& film, FreezingFluid<T>* clocks, FreezingWork<T>& work, DeviceArray<std::uint32_t>& keep,
                 DeviceArray<std::uint32_t>& slot, DeviceArray<std::uint32_t>& frozen_list) {
  const Index n = particles.n, nb = particles.nb;
  const FreezeParams<T> p = MakeFreezeParams<T>(scene);
  const CubicSpline<T> kernel(p.h);
  const T support = kernel.SupportRadius();

  // Per-boundary caches of the diffusion; new rows (new ice) start at zero, and the solver flags
  // them and the volumes they changed in structure_touched.
  for (auto* a : {&work.wet_seen, &work.stale, &work.film_touched, &work.structure_touched, &work.region}) a->resize(nb);
  work.laplacian.resize(nb);
  work.lambda.resize(nb);

  // Who touches whom: fluid with boundary neighbors, and boundary particles with fluid neighbors
  // (their B–F lists at the new positions, spec §11 step 8).
  work.fluid_flag.resize(n);
  work.boundary_active.resize(nb);
  work.boundary_active.SetZero();
  exec::ParallelFor(device, n,
                    kernels::MarkContacts<T>{.fb_offsets = particles.fb->offsets.data(),
                                             .fb_index = particles.fb->indices.data(),
                                             .fluid_flag = work.fluid_flag.data(),
                                             .boundary_active = work.boundary_active.data()});
  const Index active = exec::ListFlagged(device, work.boundary_active, nb, slot, work.active_list);
  work.active_x.resize(active);
  exec::ParallelFor(device, active, exec::Gather<Vec3<T>>{particles.boundary_x, work.active_list.data(), work.active_x.data()});
  // The water moved since its grid was binned; searching cell by cell scans all 27 cells around
  // each boundary cell, so it also finds water that moved into the support from a cell that the
  // per-point search would skip as out of range.
  work.active_grid.BuildSubset(*particles.boundary_grid, work.boundary_active.data(), slot.data(), work.active_x.data(), active,
                               particles.fluid_grid->cell_size(), particles.fluid_grid->view().origin);
  particles.fluid_grid->QueryGrid(work.active_grid, support, false, work.bf);
  exec::ParallelFor(device, active,
                    kernels::MarkFluidFromBoundary{
                        .bf_offsets = work.bf.offsets.data(), .bf_index = work.bf.indices.data(), .fluid_flag = work.fluid_flag.data()});

  // 8a fluid anisotropy, 8b film transfer + 8d growth direction.
  work.fluid_d.resize(n);
  exec::ParallelFor(device, n,
                    kernels::FluidAnisotropy<T>{.flag = work.fluid_flag.data(),
                                                .ff_offsets = particles.ff->offsets.data(),
                                                .ff_index = particles.ff->indices.data(),
                                                .x = particles.x,
                                                .kernel = kernel,
                                                .params = p,
                                                .d = work.fluid_d.data()});
  exec::ParallelFor(device, active,
                    kernels::FilmAndGrowth<T>{.active = work.active_list.data(),
                                              .bf_offsets = work.bf.offsets.data(),
                                              .bf_index = work.bf.indices.data(),
                                              .boundary_x = particles.boundary_x,
                                              .boundary_volume = particles.boundary_volume,
                                              .boundary_phase = particles.boundary_phase,
                                              .x = particles.x,
                                              .v = particles.v,
                                              .d = work.fluid_d.data(),
                                              .kernel = kernel,
                                              .params = p,
                                              .dt = T(dt),
                                              .film = film.film.data(),
                                              .growth = film.growth.data(),
                                              .growth_valid = film.growth_valid.data(),
                                              .film_touched = work.film_touched.data()});
  if (scene.freezing.drying_rate > 0)
    exec::ParallelFor(
        device, nb,
        kernels::DryFilm<T>{
            .factor = T(std::exp(-scene.freezing.drying_rate * dt)), .film = film.film.data(), .film_touched = work.film_touched.data()});

  // 8c film diffusion over the wet region and its one-ring. Operator splitting: the diffusion
  // time accumulates until one explicit step of it would use half the stability budget (the
  // plane reference λ h² ≈ 5, spec §9.3), then it is applied with its accumulated time step and
  // sub-stepped if the actual λ_max needs it. At small Δt this saves most diffusion passes.
  const double diffusivity = scene.freezing.film_diffusion * scene.fluid.spacing * scene.fluid.spacing / scene.freezing.dt_ref;
  diffusion_pending += dt;
  const double h = scene.fluid.smoothing_length();
  if (diffusivity > 0 && diffusion_pending * diffusivity * 5.0 / (h * h) >= 0.5) {
    const double dt_diffusion = diffusion_pending;
    diffusion_pending = 0;
    const Index region = UpdateDiffusionRegion(device, particles, support, film, work, slot);
    if (region > 0) {
      // Laplacians where they may have changed (the list is rebuilt first: it may move in memory).
      const auto evaluate = [&] {
        const std::uint32_t* list = nullptr;
        const Index count = EvaluationList(device, particles, support, region, work, slot, list);
        ListRows(device, particles, kernel, list, count, work, slot);
        exec::ParallelFor(device, count,
                          kernels::FilmLaplacian<T>{.list = list,
                                                    .rows = {.begin = work.row_begin.data(),
                                                             .length = work.row_length.data(),
                                                             .pool = work.row_pool.data(),
                                                             .x_grad = work.row_x_grad.data(),
                                                             .denominator = work.row_denominator.data()},
                                                    .volume = particles.boundary_volume,
                                                    .film = film.film.data(),
                                                    .laplacian = work.laplacian.data(),
                                                    .lambda = work.lambda.data()});
      };
      evaluate();
      work.region_lambda.resize(region);
      exec::ParallelFor(
          device, region,
          kernels::GatherListed<T>{.list = work.region_list.data(), .values = work.lambda.data(), .out = work.region_lambda.data()});
      const double lambda_max = exec::Max(device, work.region_lambda.data(), region);
      const int substeps = std::max(1, int(std::ceil(dt_diffusion * diffusivity * lambda_max)));
      for (int sub = 0; sub < substeps; ++sub) {
        if (sub > 0) evaluate();
        exec::ParallelFor(device, region,
                          kernels::ApplyFilmDiffusion<T>{.list = work.region_list.data(),
                                                         .laplacian = work.laplacian.data(),
                                                         .step = T(dt_diffusion * diffusivity / substeps),
                                                         .film = film.film.data(),
                                                         .film_touched = work.film_touched.data()});
      }
    }
  }

  // 8e decisions from one snapshot, 8f conversions applied together.
  for (auto* a : {&work.decision, &work.trigger, &keep, &work.frozen}) a->resize(n);
  work.energy_solid.resize(n);
  work.energy_ice.resize(n);
  exec::ParallelFor(device, n,
                    kernels::PhaseDecision<T>{.fb_offsets = particles.fb->offsets.data(),
                                              .fb_index = particles.fb->indices.data(),
                                              .x = particles.x,
                                              .d = work.fluid_d.data(),
                                              .boundary_x = particles.boundary_x,
                                              .boundary_phase = particles.boundary_phase,
                                              .film = film.film.data(),
                                              .growth = film.growth.data(),
                                              .growth_valid = film.growth_valid.data(),
                                              .kernel = kernel,
                                              .params = p,
                                              .decision = work.decision.data(),
                                              .trigger = work.trigger.data(),
                                              .energy_solid = work.energy_solid.data(),
                                              .energy_ice = work.energy_ice.data()});
  if (clocks)
    exec::ParallelFor(device, n,
                      kernels::NucleationDelay<T>{.dt = T(dt),
                                                  .delay = T(scene.freezing.freeze_delay),
                                                  .decision = work.decision.data(),
                                                  .contact_time = clocks->contact_time.data()});
  exec::ParallelFor(device, n, kernels::KeepUnfrozen{.decision = work.decision.data(), .keep = keep.data(), .frozen = work.frozen.data()});
  return exec::ListFlagged(device, work.frozen, n, slot, frozen_list);
}

template FreezeParams<float> MakeFreezeParams<float>(const io::Scene&);
template FreezeParams<double> MakeFreezeParams<double>(const io::Scene&);
template Index FreezeStep<float>(const exec::Device&, const io::Scene&, const Particles<float>&, double, double&, FreezingBoundary<float>&,
                                 FreezingFluid<float>*, FreezingWork<float>&, DeviceArray<std::uint32_t>&, DeviceArray<std::uint32_t>&,
                                 DeviceArray<std::uint32_t>&);
template Index FreezeStep<double>(const exec::Device&, const io::Scene&, const Particles<double>&, double, double&,
                                  FreezingBoundary<double>&, FreezingFluid<double>*, FreezingWork<double>&, DeviceArray<std::uint32_t>&,
                                  DeviceArray<std::uint32_t>&, DeviceArray<std::uint32_t>&);

}  // namespace rime::freeze
