/// @file kernels.h
/// @brief The paper's anisotropic freezing (spec §8–9) as RIME_HD kernels: fluid PCA, virtual water
/// film transfer and diffusion, growth direction, freezing fraction, nucleation energy and the
/// phase-shift decision. All decisions of a step read one snapshot (Jacobi-style), so the set of
/// frozen particles does not depend on thread order (spec §9.7, T22).
#pragma once

#include <cstdint>

#include "rime/core/anisotropy.h"
#include "rime/core/hd.h"
#include "rime/core/kernel.h"
#include "rime/core/math.h"
#include "rime/exec/kernel_list.h"
#include "rime/neighbors/grid_kernels.h"

namespace rime::freeze {

/// Boundary phase of ice (io::Phase::kIce; io is host-only, checked in freezing.h).
inline constexpr std::uint8_t kIcePhase = 2;

/// A symmetric 3x3 matrix as six components (xx, yy, zz, xy, xz, yz): the stored anisotropy D.
template <class T>
struct Sym6 {
  T c[6];
};

enum IceKind : std::uint8_t { kNotIce = 0, kGlaze = 1, kIcicle = 2 };

/// Parameters of the freezing kernels, in the solver's precision.
template <class T>
struct FreezeParams {
  T h, mass, film_max;  // Γ_max (kg)
  T alpha_solid, alpha_ice;
  T dt_ref;
  T glaze_threshold, icicle_threshold;
  T growth_sign;        // +1 paper, −1 flipped
  T gravity_growth;     // weight of gravity's direction added to the flow's (0: Eq. 26 alone)
  T tip_growth = T(1);  // power of fr on ice (1: Eq. 31 alone)
  Vec3<T> gravity_dir;  // unit vector along gravity (zero without gravity)
  bool fr_clamp;        // fr_mode = "clamp"
  bool ce_raw;          // ce_mode = "raw" (kg/m³) instead of dimensionless
  bool ce_sum;          // ce_aggregation = "sum"
  bool isotropic;       // growth = "isotropic" (baseline: G = I/h)
  anisotropy::Params<T> pca;
};

namespace kernels {

/// flag[j] = 1 for fluid particles with a boundary neighbor; marks those boundary particles active.
template <class T>
struct MarkContacts {
  const std::uint32_t* fb_offsets;
  const std::uint32_t* fb_index;
  std::uint32_t* fluid_flag;
  std::uint32_t* boundary_active;
  RIME_HD void operator()(Index j) const {
    const std::uint32_t begin = fb_offsets[j], end = fb_offsets[j + 1];
    fluid_flag[j] = begin != end ? 1u : 0u;
    for (std::uint32_t k = begin; k < end; ++k) boundary_active[fb_index[k]] = 1u;  // benign race: same value
  }
};

/// Marks every fluid particle that appears in a boundary particle's fluid list (the B–F lists).
struct MarkFluidFromBoundary {
  const std::uint32_t* bf_offsets;
  const std::uint32_t* bf_index;
  std::uint32_t* fluid_flag;
  RIME_HD void operator()(Index k) const {
    for (std::uint32_t e = bf_offsets[k + 1], m = bf_offsets[k]; m < e; ++m) fluid_flag[bf_index[m]] = 1u;
  }
};

/// Fluid anisotropy for flagged particles (spec §8): W-weighted covariance over the fluid
/// neighbors at the current positions, stretches, and D = R diag(1/s) Rᵀ (G = D/h).
template <class T>
struct FluidAnisotropy {
  const std::uint32_t* flag;
  const std::uint32_t* ff_offsets;
  const std::uint32_t* ff_index;
  const Vec3<T>* x;
  CubicSpline<T> kernel;
  FreezeParams<T> params;
  Sym6<T>* d;
  RIME_HD void operator()(Index j) const {
    if (!flag[j]) return;
    Mat3<T> D = Mat3<T>::Identity();
    if (!params.isotropic) {
      anisotropy::CovarianceAccumulator<T> acc;
      acc.AddSelf(kernel.W0());
      const Vec3<T> xj = x[j];
      for (std::uint32_t k = ff_offsets[j], e = ff_offsets[j + 1]; k < e; ++k) {
        const Vec3<T> r = x[ff_index[k]] - xj;
        const T w = kernel.W(Norm(r));
        if (w > T(0)) acc.Add(r, w);
      }
      D = anisotropy::Compute(acc.Covariance(params.pca.center_on_particle), acc.neighbors, kernel.h, params.pca).D();
    }
    anisotropy::ToComponents(D, d[j].c);
  }
};

/// Film transfer (spec §9.2, bounded rate form) and growth direction (spec §9.4) for one active
/// boundary particle b = active[k] with fluid neighbors bf(k).
template <class T>
struct FilmAndGrowth {
  const std::uint32_t* active;
  const std::uint32_t* bf_offsets;
  const std::uint32_t* bf_index;
  const Vec3<T>* boundary_x;
  const T* boundary_volume;
  const std::uint8_t* boundary_phase;  // 1 solid, 2 ice
  const Vec3<T>* x;
  const Vec3<T>* v;
  const Sym6<T>* d;
  CubicSpline<T> kernel;
  FreezeParams<T> params;
  T dt;
  T* film;  // Γ/Γ_max ∈ [0,1]
  Vec3<T>* growth;
  std::uint8_t* growth_valid;
  std::uint32_t* film_touched;  // set where the film changed (the diffusion re-evaluates around it)
  RIME_HD void operator()(Index k) const {
    const std::uint32_t b = active[k];
    const std::uint32_t begin = bf_offsets[k], end = bf_offsets[k + 1];
    if (begin == end) return;  // N_f(b) = ∅: keep the film and the last growth direction
    const Vec3<T> xb = boundary_x[b];
    T density_sum = T(0);
    Vec3<T> gv{};
    const T inv_h = T(1) / params.h;
    for (std::uint32_t m = begin; m < end; ++m) {
      const std::uint32_t j = bf_index[m];
      const Vec3<T> r = xb - x[j];
      density_sum += params.mass * kernel.W(Norm(r));
      const Mat3<T> G = anisotropy::FromComponents(d[j].c) * inv_h;
      gv += v[j] * anisotropy::Kernel(r, G);
    }
    const T alpha = boundary_phase[b] == kIcePhase ? params.alpha_ice : params.alpha_solid;
    const T s = alpha * boundary_volume[b] * density_sum / params.film_max;
    const T keep = std::pow(T(1) - (s < T(1) ? s : T(1)), dt / params.dt_ref);
    const T wetted = T(1) - (T(1) - film[b]) * keep;
    if (wetted != film[b]) film_touched[b] = 1u;
    film[b] = wetted;
    gv /= T(end - begin);
    growth[b] = gv;
    growth_valid[b] = Norm(gv) > T(1e-9) * kernel.W0() ? 1 : 0;
  }
};

/// wet[b] = 1 where the film is positive (seeds of the diffusion region).
template <class T>
struct MarkWet {
  const T* film;
  std::uint32_t* wet;
  RIME_HD void operator()(Index b) const { wet[b] = film[b] > T(0) ? 1u : 0u; }
};

/// region[k] = 1 for every boundary neighbor k of a wet particle (the one-ring dilation, so that
/// flux into dry neighbors is counted on both sides).
template <class T>
struct DilateWet {
  neighbors::GridView<T> grid;  // over boundary particles
  const std::uint32_t* wet;
  T radius;
  std::uint32_t* region;
  RIME_HD void operator()(Index b) const {
    if (!wet[b]) return;
    region[b] = 1u;
    grid.ForEachNeighbor(grid.points[b], radius, [&](std::uint32_t k, const Vec3<T>&, T) { region[k] = 1u; });
  }
};

/// The diffusion's caches between steps (the boundary does not move): which particles became wet
/// or dry since the region was last formed; remembers the wet set.
struct WetChanges {
  const std::uint32_t* wet;
  std::uint32_t* wet_seen;
  std::uint32_t* newly_wet;
  std::uint32_t* dried;
  RIME_HD void operator()(Index b) const {
    newly_wet[b] = wet[b] & (1u - wet_seen[b]);
    dried[b] = wet_seen[b] & (1u - wet[b]);
    wet_seen[b] = wet[b];
  }
};

/// Adds the listed newly wet particles and their neighbors to the region; those that enter it
/// have no valid Laplacian yet (stale).
template <class T>
struct GrowRegion {
  neighbors::GridView<T> grid;
  const std::uint32_t* list;
  T radius;
  std::uint32_t* region;
  std::uint32_t* stale;
  RIME_HD void operator()(Index k) const {
    grid.ForEachNeighbor(grid.points[list[k]], radius, [&](std::uint32_t n, const Vec3<T>&, T) {
      if (!region[n]) region[n] = 1u, stale[n] = 1u;  // benign races: same values
    });
  }
};

/// Whether each listed particle (new ice and its surroundings) is wet or next to a wet one: its
/// region membership after the boundary changed near it.
template <class T>
struct JoinRegion {
  neighbors::GridView<T> grid;
  const std::uint32_t* list;
  const std::uint32_t* wet;
  T radius;
  std::uint32_t* region;
  std::uint32_t* stale;
  RIME_HD void operator()(Index k) const {
    const std::uint32_t b = list[k];
    if (region[b]) return;
    bool near_wet = false;
    grid.ForEachNeighbor(grid.points[b], radius, [&](std::uint32_t n, const Vec3<T>&, T) { near_wet = near_wet || wet[n] != 0; });
    if (near_wet) region[b] = 1u, stale[b] = 1u;
  }
};

/// evaluate[n] = 1 for every region particle n within the radius of a listed (changed) particle:
/// the Laplacians that the change can alter.
template <class T>
struct MarkAffected {
  neighbors::GridView<T> grid;
  const std::uint32_t* list;
  const std::uint32_t* region;
  T radius;
  std::uint32_t* evaluate;
  RIME_HD void operator()(Index k) const {
    grid.ForEachNeighbor(grid.points[list[k]], radius, [&](std::uint32_t n, const Vec3<T>&, T) {
      if (region[n]) evaluate[n] = 1u;
    });
  }
};

/// Adds the stale region particles to the evaluation; stale stays set outside the region.
struct AddStale {
  const std::uint32_t* region;
  std::uint32_t* stale;
  std::uint32_t* evaluate;
  RIME_HD void operator()(Index b) const {
    evaluate[b] |= stale[b] & region[b];
    stale[b] &= 1u - region[b];
  }
};

/// flags[list[k]] = value for every listed particle.
struct SetListed {
  const std::uint32_t* list;
  std::uint32_t value;
  std::uint32_t* flags;
  RIME_HD void operator()(Index k) const { flags[list[k]] = value; }
};

/// out[k] = values[list[k]].
template <class T>
struct GatherListed {
  const std::uint32_t* list;
  const T* values;
  T* out;
  RIME_HD void operator()(Index k) const { out[k] = values[list[k]]; }
};

/// Neighbour rows kept per boundary particle while the boundary does not move: the particles
/// within the support of b, itself included, in the grid's query order, are
/// pool[begin[b] .. begin[b] + length[b]); length 0 means b has no row yet. Beside each pair, the
/// parts of the film Laplacian's weight that depend on the positions only (see FilmLaplacian).
template <class T>
struct NeighborRows {
  const std::uint32_t* begin;
  const std::uint32_t* length;
  const std::uint32_t* pool;
  const T* x_grad;       // −x_bk·∇W_bk
  const T* denominator;  // r² + εh²
};

/// flags[k] = 1 where the listed particle list[k] has no row yet.
struct MarkRowless {
  const std::uint32_t* list;
  const std::uint32_t* length;
  std::uint32_t* flags;
  RIME_HD void operator()(Index k) const { flags[k] = length[list[k]] == 0 ? 1u : 0u; }
};

/// Stores the CSR lists of the listed particles (row i for particle list[i]) as their rows, at
/// `base` in the pool, with each pair's position terms of the film Laplacian: the boundary does
/// not move while its rows are kept, so a diffusion pass reads them instead of a kernel gradient.
template <class T>
struct StoreRows {
  const std::uint32_t* list;
  const std::uint32_t* offsets;
  const std::uint32_t* indices;
  std::uint32_t base;
  const Vec3<T>* x;  // boundary positions
  CubicSpline<T> kernel;
  T epsilon;
  std::uint32_t* begin;
  std::uint32_t* length;
  std::uint32_t* pool;
  T* x_grad;
  T* denominator;
  RIME_HD void operator()(Index i) const {
    const std::uint32_t b = list[i], first = offsets[i], end = offsets[i + 1];
    begin[b] = base + first;
    length[b] = end - first;
    const Vec3<T> xb = x[b];
    const T eps_h2 = epsilon * kernel.h * kernel.h;
    for (std::uint32_t m = first; m < end; ++m) {
      const std::uint32_t n = indices[m];
      pool[base + m] = n;
      const Vec3<T> r = xb - x[n];
      const T r2 = Dot(r, r);
      // −x·∇W = −φ r² with φ = B'(q) σ/(h⁴ r) <= 0 (0 for b itself, which the Laplacian skips).
      x_grad[base + m] = n == b ? T(0) : -kernel.GradientFactor(std::sqrt(r2)) * r2;
      denominator[base + m] = r2 + eps_h2;
    }
  }
};

/// Copies particle b's kept row (length[b] entries from from_begin[b]) to to_begin[b] in a fresh
/// pool: compacting the pool keeps every row and its stored values, bit for bit.
template <class E>
struct MoveRows {
  const std::uint32_t* from_begin;
  const std::uint32_t* length;
  const std::uint32_t* to_begin;
  const E* from;
  E* to;
  RIME_HD void operator()(Index b) const {
    for (std::uint32_t m = 0; m < length[b]; ++m) to[to_begin[b] + m] = from[from_begin[b] + m];
  }
};

/// Conservative SPH Laplacian of the film over the boundary graph (spec §9.3):
/// L_b = 2 Σ_k V̄_bk (Γ_k − Γ_b)(−x_bk·∇W_bk)/(r²+εh²); also the stability bound λ_b. The
/// neighbours come from the rows, in the grid's order, so the sums are those of a grid query.
template <class T>
struct FilmLaplacian {
  const std::uint32_t* list;
  NeighborRows<T> rows;
  const T* volume;
  const T* film;
  T* laplacian;  // per boundary particle (of the listed ones)
  T* lambda;     // per boundary particle (of the listed ones)
  RIME_HD void operator()(Index k) const {
    const std::uint32_t b = list[k];
    const T fb = film[b], vb = volume[b];
    T l = T(0), lam = T(0);
    for (std::uint32_t m = rows.begin[b], e = m + rows.length[b]; m < e; ++m) {
      const std::uint32_t n = rows.pool[m];
      if (n == b) continue;
      const T weight = T(2) * T(0.5) * (vb + volume[n]) * rows.x_grad[m] / rows.denominator[m];
      l += weight * (film[n] - fb);
      lam += weight;
    }
    laplacian[b] = l;
    lambda[b] = lam;
  }
};

/// Γ_b += Δt_sub D_Γ L_b for the listed particles (after every L was computed: Jacobi).
template <class T>
struct ApplyFilmDiffusion {
  const std::uint32_t* list;
  const T* laplacian;  // per boundary particle
  T step;              // Δt_sub · D_Γ
  T* film;
  std::uint32_t* film_touched;
  RIME_HD void operator()(Index k) const {
    const std::uint32_t b = list[k];
    T f = film[b] + step * laplacian[b];
    f = f < T(0) ? T(0) : (f > T(1) ? T(1) : f);  // guards rounding only: the step is a convex combination
    if (f != film[b]) film_touched[b] = 1u;
    film[b] = f;
  }
};

/// Optional drying Γ ← Γ exp(−k_dry Δt) (no drying in the paper).
template <class T>
struct DryFilm {
  T factor;
  T* film;
  std::uint32_t* film_touched;
  RIME_HD void operator()(Index b) const {
    const T dried = film[b] * factor;
    if (dried != film[b]) film_touched[b] = 1u;
    film[b] = dried;
  }
};

/// Freezing fraction fr_bj (spec §9.5) for boundary b and fluid j.
/// On ice, `gravity_growth` w > 0 turns the direction into ĝv + w ĝ (ĝ along gravity, in the sense
/// that grows ice downwards), so water dripping below ice freezes onto it first: the paper's "ice
/// grows faster, mainly vertically, due to gravity" (icicles). Glaze on solids keeps Eq. 26 alone.
/// On ice, fr is raised to `tip_growth`: water beside an icicle freezes less than water below its tip.
template <class T>
RIME_HDI T FreezingFraction(const Vec3<T>& growth, bool valid, const Vec3<T>& x_isf, const FreezeParams<T>& p, bool on_ice = false) {
  const T len = Norm(x_isf);
  Vec3<T> direction = growth;
  bool has_direction = valid;
  if (on_ice && p.gravity_growth > T(0)) {
    const T flow = Norm(growth);
    direction = valid && flow > T(0) ? growth / flow : Vec3<T>{};
    direction += p.gravity_dir * (-p.gravity_growth * p.growth_sign);
    has_direction = true;  // gravity alone gives one where no flow was recorded
  }
  const T g = Norm(direction);
  if (!has_direction || len < T(1e-6) * p.h || !(g > T(0))) return T(0.5);
  const T dot = p.growth_sign * Dot(direction, x_isf) / (g * len);
  const T fr = p.fr_clamp ? (dot > T(0) ? dot : T(0)) : (dot + T(1)) * T(0.5);
  return on_ice && p.tip_growth != T(1) ? std::pow(fr, p.tip_growth) : fr;
}

/// Phase-shift decision (spec §9.6–9.7) for fluid j: the nucleation energy of every boundary
/// neighbor, aggregated separately over solids and ice; records the kind and the trigger.
template <class T>
struct PhaseDecision {
  const std::uint32_t* fb_offsets;
  const std::uint32_t* fb_index;
  const Vec3<T>* x;
  const Sym6<T>* d;
  const Vec3<T>* boundary_x;
  const std::uint8_t* boundary_phase;
  const T* film;
  const Vec3<T>* growth;
  const std::uint8_t* growth_valid;
  CubicSpline<T> kernel;
  FreezeParams<T> params;
  std::uint32_t* decision;  // IceKind
  std::uint32_t* trigger;   // boundary index whose energy decided (argmax)
  T* energy_solid;
  T* energy_ice;
  RIME_HD void operator()(Index j) const {
    decision[j] = kNotIce;
    const std::uint32_t begin = fb_offsets[j], end = fb_offsets[j + 1];
    if (begin == end) return;
    const Vec3<T> xj = x[j];
    const Mat3<T> G = anisotropy::FromComponents(d[j].c) * (T(1) / params.h);
    const T scale = params.ce_raw ? params.film_max : T(1) / kernel.W0();
    T ce_s = T(0), ce_i = T(0), best_s = T(-1), best_i = T(-1);
    std::uint32_t arg_s = 0, arg_i = 0;
    for (std::uint32_t k = begin; k < end; ++k) {
      const std::uint32_t b = fb_index[k];
      const T f = film[b];
      if (!(f > T(0))) continue;
      const Vec3<T> x_isf = boundary_x[b] - xj;
      const bool on_ice = boundary_phase[b] == kIcePhase;
      const T fr = FreezingFraction(growth[b], growth_valid[b] != 0, x_isf, params, on_ice);
      const T ce = f * fr * anisotropy::Kernel(x_isf, G) * scale;
      if (on_ice) {
        ce_i = params.ce_sum ? ce_i + ce : (ce > ce_i ? ce : ce_i);
        if (ce > best_i) best_i = ce, arg_i = b;
      } else {
        ce_s = params.ce_sum ? ce_s + ce : (ce > ce_s ? ce : ce_s);
        if (ce > best_s) best_s = ce, arg_s = b;
      }
    }
    energy_solid[j] = ce_s;
    energy_ice[j] = ce_i;
    if (ce_s > params.glaze_threshold) {  // glaze wins ties
      decision[j] = kGlaze;
      trigger[j] = arg_s;
    } else if (ce_i > params.icicle_threshold) {
      decision[j] = kIcicle;
      trigger[j] = arg_i;
    }
  }
};

/// Nucleation delay: a candidate keeps its decision only once its energy has stayed above a
/// threshold for `delay` seconds in a row; a step below the thresholds resets its clock.
template <class T>
struct NucleationDelay {
  T dt, delay;
  std::uint32_t* decision;  // IceKind, from PhaseDecision
  T* contact_time;          // s above a threshold, per fluid particle
  RIME_HD void operator()(Index j) const {
    if (decision[j] == kNotIce) {
      contact_time[j] = T(0);
      return;
    }
    contact_time[j] += dt;
    if (contact_time[j] < delay) decision[j] = kNotIce;
  }
};

/// keep[j] = 1 unless j freezes this step.
struct KeepUnfrozen {
  const std::uint32_t* decision;
  std::uint32_t* keep;
  std::uint32_t* frozen;
  RIME_HD void operator()(Index j) const {
    keep[j] = decision[j] == kNotIce ? 1u : 0u;
    frozen[j] = 1u - keep[j];
  }
};

}  // namespace kernels
}  // namespace rime::freeze

// One kernel per line: clang-format 14 keeps that layout but rewraps a line of several on every run.
#define RIME_FREEZE_KERNELS_T(X, T)               \
  X(rime::freeze::kernels::MarkContacts<T>)       \
  X(rime::freeze::kernels::FluidAnisotropy<T>)    \
  X(rime::freeze::kernels::FilmAndGrowth<T>)      \
  X(rime::freeze::kernels::MarkWet<T>)            \
  X(rime::freeze::kernels::DilateWet<T>)          \
  X(rime::freeze::kernels::FilmLaplacian<T>)      \
  X(rime::freeze::kernels::ApplyFilmDiffusion<T>) \
  X(rime::freeze::kernels::DryFilm<T>)            \
  X(rime::freeze::kernels::PhaseDecision<T>)      \
  X(rime::freeze::kernels::NucleationDelay<T>)    \
  X(rime::freeze::kernels::GrowRegion<T>)         \
  X(rime::freeze::kernels::JoinRegion<T>)         \
  X(rime::freeze::kernels::MarkAffected<T>)       \
  X(rime::freeze::kernels::GatherListed<T>)       \
  X(rime::freeze::kernels::StoreRows<T>)          \
  X(rime::freeze::kernels::MoveRows<T>)

#define RIME_FREEZE_KERNELS(X)                    \
  RIME_FREEZE_KERNELS_T(X, float)                 \
  RIME_FREEZE_KERNELS_T(X, double)                \
  X(rime::freeze::kernels::MarkFluidFromBoundary) \
  X(rime::freeze::kernels::KeepUnfrozen)          \
  X(rime::freeze::kernels::WetChanges)            \
  X(rime::freeze::kernels::AddStale)              \
  X(rime::freeze::kernels::SetListed)             \
  X(rime::freeze::kernels::MarkRowless)           \
  X(rime::freeze::kernels::MoveRows<std::uint32_t>)
