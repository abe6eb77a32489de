/// @file freezing.h
/// @brief The freezing module's particle state and its step (spec §11 step 8), run after the water
/// moved: contacts between water and boundary, the water's anisotropy, film transfer and growth
/// direction, film diffusion over the wet region, and the phase decisions from one snapshot. The
/// solver owns the water and boundary groups and turns the decided water into ice.
///
/// @code
/// const rime::Index frozen = rime::freeze::FreezeStep(device, scene, particles, dt, pending, film, clocks, work, keep, slot, list);
/// @endcode
#pragma once

#include <cstdint>

#include "rime/exec/attributes.h"
#include "rime/freeze/kernels.h"
#include "rime/io/particles.h"
#include "rime/io/scene.h"
#include "rime/neighbors/grid.h"

namespace rime::exec {

template <class S>
struct Components<freeze::Sym6<S>> {
  using Scalar = S;
  static constexpr int kCount = 6;
  static Scalar Get(const freeze::Sym6<S>& v, int c) { return v.c[c]; }
  static void Set(freeze::Sym6<S>& v, int c, Scalar s) { v.c[c] = s; }
};

}  // namespace rime::exec

namespace rime::freeze {

using exec::AttributeInfo;
using exec::DeviceArray;

static_assert(kIcePhase == std::uint8_t(io::Phase::kIce), "device kernels and files must agree on the ice phase");

/// Freezing state of boundary particles: the water film on solids and ice, and what ice keeps.
template <class T>
struct FreezingBoundary : exec::AttributeGroup<FreezingBoundary<T>> {
  static constexpr const char* kModule = "freezing";
  explicit FreezingBoundary(const exec::Device& d) : film(d), growth(d), growth_valid(d), ice_kind(d), ice_time(d), ice_d(d) {}
  DeviceArray<T> film;  // Γ/Γ_max
  DeviceArray<Vec3<T>> growth;
  DeviceArray<std::uint8_t> growth_valid;
  DeviceArray<std::uint8_t> ice_kind;  // freeze::IceKind; 0 for solids
  DeviceArray<double> ice_time;        // creation time, s
  DeviceArray<Sym6<T>> ice_d;          // anisotropy D frozen with the particle

  template <class Self, class F>
  static void Visit(Self& s, F& f) {
    f(AttributeInfo{.name = "water_film", .checkpointed = true}, s.film);
    f(AttributeInfo{.name = "growth_dir", .checkpointed = true}, s.growth);
    f(AttributeInfo{.name = "growth_valid", .checkpointed = true}, s.growth_valid);
    f(AttributeInfo{.name = "ice_kind", .checkpointed = true}, s.ice_kind);
    f(AttributeInfo{.name = "ice_time", .checkpointed = true}, s.ice_time);
    f(AttributeInfo{.name = "anisotropy", .checkpointed = true}, s.ice_d);
  }
};

/// Nucleation delay (freezing.freeze_delay > 0): seconds each water particle spent above a
/// freezing threshold; persistent, so it moves with the water.
template <class T>
struct FreezingFluid : exec::AttributeGroup<FreezingFluid<T>> {
  static constexpr const char* kModule = "freezing";
  explicit FreezingFluid(const exec::Device& d) : contact_time(d) {}
  DeviceArray<T> contact_time;

  template <class Self, class F>
  static void Visit(Self& s, F& f) {
    f(AttributeInfo{.name = "contact_time", .checkpointed = true}, s.contact_time);
  }
};

/// Work arrays of the freezing step (sized by it: water, boundary or list lengths), and the film
/// diffusion's caches, kept from step to step while the boundary does not move: the region, the
/// wet set it was formed from, and every region particle's Laplacian and stability bound, valid
/// until the film changes within its support (film_touched) or the boundary changes near it
/// (structure_touched: new ice and the volumes it changed, set by the solver).
template <class T>
struct FreezingWork : exec::AttributeGroup<FreezingWork<T>> {
  static constexpr const char* kModule = "freezing";
  explicit FreezingWork(const exec::Device& d)
      : fluid_d(d),
        fluid_flag(d),
        boundary_active(d),
        active_list(d),
        decision(d),
        trigger(d),
        frozen(d),
        wet(d),
        region(d),
        region_list(d),
        energy_solid(d),
        energy_ice(d),
        laplacian(d),
        lambda(d),
        active_x(d),
        active_grid(d),
        bf(d),
        wet_seen(d),
        newly_wet(d),
        dried(d),
        stale(d),
        evaluate(d),
        film_touched(d),
        structure_touched(d),
        change_list(d),
        region_lambda(d),
        row_begin(d),
        row_length(d),
        row_pool(d),
        row_flags(d),
        row_list(d),
        row_x_grad(d),
        row_denominator(d),
        row_x(d),
        new_rows(d) {}
  DeviceArray<Sym6<T>> fluid_d;  // water: anisotropy D of this step
  DeviceArray<std::uint32_t> fluid_flag, boundary_active, active_list, decision, trigger, frozen, wet, region, region_list;
  DeviceArray<T> energy_solid, energy_ice, laplacian, lambda;  // laplacian, lambda: per boundary particle
  DeviceArray<Vec3<T>> active_x;
  neighbors::UniformGrid<T> active_grid;  // active_x binned on the water grid's lattice, to query it cell by cell
  neighbors::NeighborList bf;             // boundary–fluid pairs of the boundary particles touching water
  DeviceArray<std::uint32_t> wet_seen, newly_wet, dried, stale, evaluate, film_touched, structure_touched, change_list;
  DeviceArray<T> region_lambda;
  bool diffusion_cache_valid = false;  // the solver clears it when the boundary moves or is restored
  // The film Laplacian's neighbour rows (kernels::NeighborRows), listed when a particle is first
  // evaluated and kept until the boundary moves or changes near it; row_pool[0, row_pool_used)
  // holds them (rows dropped near new ice leave gaps until the pool is compacted).
  DeviceArray<std::uint32_t> row_begin, row_length, row_pool, row_flags, row_list;
  DeviceArray<T> row_x_grad, row_denominator;  // beside row_pool: kernels::NeighborRows
  DeviceArray<Vec3<T>> row_x;
  neighbors::NeighborList new_rows;
  std::size_t row_pool_used = 0;
  std::size_t row_pool_compacted = 0;  // what the pool held after its first listing or last compaction
  Vec3<T> row_grid_origin{};           // the grid cells the rows were listed in (their order follows them)
  T row_grid_inv_cell = 0;

  template <class Self, class F>
  static void Visit(Self& s, F& f) {
    f(AttributeInfo{.name = "fluid_anisotropy"}, s.fluid_d);
    f(AttributeInfo{.name = "fluid_flag"}, s.fluid_flag);
    f(AttributeInfo{.name = "boundary_active"}, s.boundary_active);
    f(AttributeInfo{.name = "active_list"}, s.active_list);
    f(AttributeInfo{.name = "decision"}, s.decision);
    f(AttributeInfo{.name = "trigger"}, s.trigger);
    f(AttributeInfo{.name = "frozen"}, s.frozen);
    f(AttributeInfo{.name = "wet"}, s.wet);
    f(AttributeInfo{.name = "region"}, s.region);
    f(AttributeInfo{.name = "region_list"}, s.region_list);
    f(AttributeInfo{.name = "energy_solid"}, s.energy_solid);
    f(AttributeInfo{.name = "energy_ice"}, s.energy_ice);
    f(AttributeInfo{.name = "film_laplacian"}, s.laplacian);
    f(AttributeInfo{.name = "film_lambda"}, s.lambda);
    f(AttributeInfo{.name = "active_positions"}, s.active_x);
    f(AttributeInfo{.name = "bf_offsets"}, s.bf.offsets);
    f(AttributeInfo{.name = "bf_indices"}, s.bf.indices);
    f(AttributeInfo{.name = "wet_seen"}, s.wet_seen);
    f(AttributeInfo{.name = "newly_wet"}, s.newly_wet);
    f(AttributeInfo{.name = "dried"}, s.dried);
    f(AttributeInfo{.name = "film_stale"}, s.stale);
    f(AttributeInfo{.name = "film_evaluate"}, s.evaluate);
    f(AttributeInfo{.name = "film_touched"}, s.film_touched);
    f(AttributeInfo{.name = "structure_touched"}, s.structure_touched);
    f(AttributeInfo{.name = "change_list"}, s.change_list);
    f(AttributeInfo{.name = "region_lambda"}, s.region_lambda);
    f(AttributeInfo{.name = "row_begin"}, s.row_begin);
    f(AttributeInfo{.name = "row_length"}, s.row_length);
    f(AttributeInfo{.name = "row_pool"}, s.row_pool);
    f(AttributeInfo{.name = "row_x_grad"}, s.row_x_grad);
    f(AttributeInfo{.name = "row_denominator"}, s.row_denominator);
    f(AttributeInfo{.name = "row_flags"}, s.row_flags);
    f(AttributeInfo{.name = "row_list"}, s.row_list);
    f(AttributeInfo{.name = "row_positions"}, s.row_x);
    f(AttributeInfo{.name = "new_row_offsets"}, s.new_rows.offsets);
    f(AttributeInfo{.name = "new_row_indices"}, s.new_rows.indices);
  }
};

/// What the freezing step reads of the solver's particles (device arrays, valid for one call).
template <class T>
struct Particles {
  Index n = 0, nb = 0;  // water, boundary
  const Vec3<T>* x = nullptr;
  const Vec3<T>* v = nullptr;
  const neighbors::NeighborList* ff = nullptr;  // water–water pairs
  const neighbors::NeighborList* fb = nullptr;  // water–boundary pairs
  const neighbors::UniformGrid<T>* fluid_grid = nullptr;
  const Vec3<T>* boundary_x = nullptr;
  const T* boundary_volume = nullptr;
  const std::uint8_t* boundary_phase = nullptr;
  const neighbors::UniformGrid<T>* boundary_grid = nullptr;
  double viscosity_epsilon = 0;  // the film Laplacian's regularisation, as the viscosity's
  bool boundary_moves = false;   // an animated solid: the diffusion's caches are rebuilt every time
};

/// The freezing kernels' parameters from the scene.
template <class T>
FreezeParams<T> MakeFreezeParams(const io::Scene& scene);

/// One freezing step of length dt: updates the film state and the nucleation clocks, and returns
/// the number of water particles that freeze, listed in `frozen_list` (their kinds in
/// work.decision, the boundary particle that decided in work.trigger, their anisotropy in
/// work.fluid_d). `diffusion_pending` carries the film diffusion time not yet applied from step to
/// step; `keep` and `slot` are per-water work arrays (keep[j] = 0 when j freezes).
template <class T>
Index FreezeStep(const exec::Device& device, const io::Scene& scene, const Particles<T>& particles, double dt, double& diffusion_pending,
                 FreezingBoundary<T>& film, FreezingFluid<T>* clocks, FreezingWork<T>& work, DeviceArray<std::uint32_t>& keep,
                 DeviceArray<std::uint32_t>& slot, DeviceArray<std::uint32_t>& frozen_list);

extern template Index FreezeStep<float>(const exec::Device&, const io::Scene&, const Particles<float>&, double, double&,
                                        FreezingBoundary<float>&, FreezingFluid<float>*, FreezingWork<float>&, DeviceArray<std::uint32_t>&,
                                        DeviceArray<std::uint32_t>&, DeviceArray<std::uint32_t>&);
extern template Index FreezeStep<double>(const exec::Device&, const io::Scene&, const Particles<double>&, double, double&,
                                         FreezingBoundary<double>&, FreezingFluid<double>*, FreezingWork<double>&,
                                         DeviceArray<std::uint32_t>&, DeviceArray<std::uint32_t>&, DeviceArray<std::uint32_t>&);

}  // namespace rime::freeze
