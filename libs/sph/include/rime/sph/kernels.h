/// @file kernels.h
/// @brief Every per-particle kernel of one IISPH step (spec §3–§7, §11), written once as RIME_HD
/// functors over raw arrays and run by both backends (kernel list at the end of the file).
///
/// Conventions: fluid particle i, fluid neighbor j, boundary neighbor b. Neighborhoods are CSR
/// lists with precomputed kernel values w and gradients grad = ∇_i W(x_i − x_j) (valid for a whole
/// step: positions change only in the final integration). Densities are absolute (kg/m³); the
/// density *error* ρ − ρ0 is carried separately so float keeps its precision (spec §15).
#pragma once

#include <cmath>
#include <cstdint>

#include "rime/core/hd.h"
#include "rime/core/kernel.h"
#include "rime/core/math.h"
#include "rime/exec/kernel_list.h"
#include "rime/exec/kernels.h"
#include "rime/freeze/kernels.h"
#include "rime/neighbors/grid_kernels.h"

namespace rime::sph {

/// A CSR neighborhood with per-pair kernel values.
template <class T>
struct Pairs {
  const std::uint32_t* offsets = nullptr;
  const std::uint32_t* index = nullptr;
  const T* w = nullptr;
  const Vec3<T>* grad = nullptr;
};

/// Rigid motion of a boundary object at one instant: x = R x_local + t; v = v_lin + ω × (x − c).
template <class T>
struct RigidMotion {
  Mat3<T> rotation = Mat3<T>::Identity();
  Vec3<T> translation{};
  Vec3<T> linear_velocity{};
  Vec3<T> angular_velocity{};
  Vec3<T> center{};
};

namespace kernels {

/// ρ_i = m W0 + Σ_j m W_ij + Σ_b Ψ_b W_ib  (spec §4); also the density error ρ_i − ρ0.
template <class T>
struct Density {
  Pairs<T> ff, fb;
  const T* boundary_psi;
  T mass, w0, rest_density;
  T* density;
  T* density_error;
  RIME_HD void operator()(Index i) const {
    T fluid = T(0), wall = T(0);
    for (std::uint32_t k = ff.offsets[i], e = ff.offsets[i + 1]; k < e; ++k) fluid += ff.w[k];
    for (std::uint32_t k = fb.offsets[i], e = fb.offsets[i + 1]; k < e; ++k) wall += boundary_psi[fb.index[k]] * fb.w[k];
    const T rho = mass * (w0 + fluid) + wall;
    density[i] = rho;
    density_error[i] = rho - rest_density;
  }
};

/// max(0, ρ_i − ρ0): the compression the particle actually has (for the measured density error).
template <class T>
struct Compression {
  const T* density_error;
  T* compression;
  RIME_HD void operator()(Index i) const { compression[i] = density_error[i] > T(0) ? density_error[i] : T(0); }
};

/// accel_i = g (the start of every step's non-pressure accelerations; gravity module off → 0).
template <class T>
struct InitAcceleration {
  Vec3<T> gravity;
  Vec3<T>* accel;
  RIME_HD void operator()(Index i) const { accel[i] = gravity; }
};

/// Fluid–fluid viscosity: Morris (spec §5.1) + Monaghan "sticky" term F^vf (spec §5.2).
template <class T>
struct ViscosityAcceleration {
  Pairs<T> ff;
  const Vec3<T>* x;
  const Vec3<T>* v;
  const T* density;
  T mass, mu, beta0_beta1, h, epsilon;
  bool limiter;
  Vec3<T>* accel;
  RIME_HD void operator()(Index i) const {
    const Vec3<T> xi = x[i], vi = v[i];
    const T rhoi = density[i], eps_h2 = epsilon * h * h;
    Vec3<T> a{};
    for (std::uint32_t k = ff.offsets[i], e = ff.offsets[i + 1]; k < e; ++k) {
      const std::uint32_t j = ff.index[k];
      const Vec3<T> xij = xi - x[j], vij = vi - v[j];
      const T rho_bar = T(0.5) * (rhoi + density[j]);
      const T denom = Dot(xij, xij) + eps_h2;
      const Vec3<T> g = ff.grad[k];
      // Morris: m (μi+μj)/ρ̄² (x·∇W)/(r²+εh²) v_ij
      a += vij * (mass * T(2) * mu / (rho_bar * rho_bar) * Dot(xij, g) / denom);
      // Monaghan: m β0 β1 u_ij / ρ̄ ∇W, u_ij = h (v·x)/(r²+εh²)
      const T vx = Dot(vij, xij);
      if (!limiter || vx < T(0)) a += g * (mass * beta0_beta1 * h * vx / (denom * rho_bar));
    }
    accel[i] += a;
  }
};

/// He 2014 colour field c_i = V_i W0 + Σ_j V_j W_ij + Σ_b V_b W_ib (spec §5.3, Eq. 33).
template <class T>
struct SurfaceColor {
  Pairs<T> ff, fb;
  const T* density;
  const T* boundary_volume;
  T mass, w0;
  T* color;
  RIME_HD void operator()(Index i) const {
    T c = mass / density[i] * w0;
    for (std::uint32_t k = ff.offsets[i], e = ff.offsets[i + 1]; k < e; ++k) c += mass / density[ff.index[k]] * ff.w[k];
    for (std::uint32_t k = fb.offsets[i], e = fb.offsets[i + 1]; k < e; ++k) c += boundary_volume[fb.index[k]] * fb.w[k];
    color[i] = c;
  }
};

/// E_i = ‖∇c_i‖², ∇c_i = Σ_j V_j c_j ∇W_ij / c_i (Eq. 34).
template <class T>
struct SurfaceEnergy {
  Pairs<T> ff;
  const T* density;
  const T* color;
  T mass;
  T* energy;
  RIME_HD void operator()(Index i) const {
    Vec3<T> g{};
    for (std::uint32_t k = ff.offsets[i], e = ff.offsets[i + 1]; k < e; ++k) {
      const std::uint32_t j = ff.index[k];
      g += ff.grad[k] * (mass / density[j] * color[j]);
    }
    g /= color[i];
    energy[i] = Dot(g, g);
  }
};

/// a_i^st = κ/(4ρ_i) Σ_j V_j (E_i+E_j) ∇W_ij + κ_b/(4ρ_i) Σ_b V_b E_i ∇W_ib (Eq. 35 / m_i).
template <class T>
struct SurfaceTensionAcceleration {
  Pairs<T> ff, fb;
  const T* density;
  const T* energy;
  const T* boundary_volume;
  T mass, kappa, kappa_boundary;
  Vec3<T>* accel;
  RIME_HD void operator()(Index i) const {
    const T ei = energy[i];
    Vec3<T> fluid{}, wall{};
    for (std::uint32_t k = ff.offsets[i], e = ff.offsets[i + 1]; k < e; ++k) {
      const std::uint32_t j = ff.index[k];
      fluid += ff.grad[k] * (mass / density[j] * (ei + energy[j]));
    }
    for (std::uint32_t k = fb.offsets[i], e = fb.offsets[i + 1]; k < e; ++k) wall += fb.grad[k] * boundary_volume[fb.index[k]];
    accel[i] += (fluid * kappa + wall * (kappa_boundary * ei)) / (T(4) * density[i]);
  }
};

/// Akinci et al. 2013 cohesion spline C(r) for the support radius H (their h), normalised as
/// published: 32/(π H⁹) {(H−r)³r³ for H/2 < r ≤ H; 2(H−r)³r³ − H⁶/64 for 0 < r ≤ H/2}.
template <class T>
RIME_HDI T AkinciCohesion(T r, T H) {
  if (r <= T(0) || r > H) return T(0);
  const T a = (H - r) * (H - r) * (H - r) * r * r * r, H3 = H * H * H;
  const T c = T(32) / (T(3.14159265358979323846) * H3 * H3 * H3);
  return T(2) * r > H ? c * a : c * (T(2) * a - H3 * H3 / T(64));
}

/// Akinci et al. 2013 adhesion spline A(r) = 0.007/H^3.25 (−4r²/H + 6r − 2H)^¼ for H/2 < r ≤ H.
template <class T>
RIME_HDI T AkinciAdhesion(T r, T H) {
  if (T(2) * r <= H || r > H) return T(0);
  using std::pow;
  // The bracket vanishes at both ends of the range; rounding there must not make it negative (NaN).
  const T bracket = -T(4) * r * r / H + T(6) * r - T(2) * H;
  return bracket > T(0) ? T(0.007) / pow(H, T(3.25)) * pow(bracket, T(0.25)) : T(0);
}

/// Σ_j V_j ∇W_ij over i's water neighbours, V_j = m/ρ_j.
template <class T>
RIME_HDI Vec3<T> WaterGradientSum(const Pairs<T>& ff, Index i, const T* density, T mass) {
  Vec3<T> s{};
  for (std::uint32_t k = ff.offsets[i], e = ff.offsets[i + 1]; k < e; ++k) s += ff.grad[k] * (mass / density[ff.index[k]]);
  return s;
}

/// Akinci 2013 surface normal n_i = H Σ_j (m/ρ_j) ∇W_ij (the Im et al. 2013 baseline's surface tension).
template <class T>
struct AkinciNormal {
  Pairs<T> ff;
  const T* density;
  T mass, support;
  Vec3<T>* normal;
  RIME_HD void operator()(Index i) const { normal[i] = WaterGradientSum(ff, i, density, mass) * support; }
};

/// Akinci 2013 surface tension and adhesion per unit mass:
/// a_i = Σ_j K_ij (−γ m C(r) x̂_ij − γ (n_i − n_j)) − β Σ_b Ψ_b A(r) x̂_ib, K_ij = 2ρ0/(ρ_i + ρ_j).
/// Antisymmetric in i, j, so it conserves momentum among the water.
template <class T>
struct AkinciSurfaceTensionAcceleration {
  Pairs<T> ff, fb;
  const Vec3<T>* x;
  const Vec3<T>* boundary_x;
  const T* density;
  const Vec3<T>* normal;
  const T* boundary_psi;
  T mass, gamma, beta, rest_density, support;
  Vec3<T>* accel;
  RIME_HD void operator()(Index i) const {
    const Vec3<T> xi = x[i], ni = normal[i];
    const T rhoi = density[i];
    Vec3<T> a{};
    for (std::uint32_t k = ff.offsets[i], e = ff.offsets[i + 1]; k < e; ++k) {
      const std::uint32_t j = ff.index[k];
      const Vec3<T> xij = xi - x[j];
      const T r = Norm(xij);
      Vec3<T> f = (ni - normal[j]) * (-gamma);
      if (r > T(1e-6) * support) f += xij * (-gamma * mass * AkinciCohesion(r, support) / r);  // coincident pairs: no direction
      a += f * (T(2) * rest_density / (rhoi + density[j]));
    }
    if (beta != T(0))
      for (std::uint32_t k = fb.offsets[i], e = fb.offsets[i + 1]; k < e; ++k) {
        const std::uint32_t b = fb.index[k];
        const Vec3<T> xib = xi - boundary_x[b];
        const T r = Norm(xib);
        if (r > T(1e-6) * support) a += xib * (-beta * boundary_psi[b] * AkinciAdhesion(r, support) / r);
      }
    accel[i] += a;
  }
};

/// a_i^air = (p_atm/ρ_i)(Σ_j V_j ∇W_ij + Σ_b V_b ∇W_ib) (spec §5.5, Eq. 36 / m_i).
template <class T>
struct AirPressureAcceleration {
  Pairs<T> ff, fb;
  const T* density;
  const T* boundary_volume;
  T mass, p_atm;
  Vec3<T>* accel;
  RIME_HD void operator()(Index i) const {
    Vec3<T> s = WaterGradientSum(ff, i, density, mass);
    for (std::uint32_t k = fb.offsets[i], e = fb.offsets[i + 1]; k < e; ++k) s += fb.grad[k] * boundary_volume[fb.index[k]];
    accel[i] += s * (p_atm / density[i]);
  }
};

/// a_i^p of Eq. 12 for the pressures p: symmetric between water particles, Akinci pressure
/// mirroring at boundary particles.
template <class T>
RIME_HDI Vec3<T> PressureAcceleration(Index i, const Pairs<T>& ff, const Pairs<T>& fb, const T* p, const T* density, const T* boundary_psi,
                                      T mass) {
  const T rhoi = density[i], pi_term = p[i] / (rhoi * rhoi);
  Vec3<T> a{};
  for (std::uint32_t k = ff.offsets[i], e = ff.offsets[i + 1]; k < e; ++k) {
    const std::uint32_t j = ff.index[k];
    const T rhoj = density[j];
    a -= ff.grad[k] * (mass * (pi_term + p[j] / (rhoj * rhoj)));
  }
  for (std::uint32_t k = fb.offsets[i], e = fb.offsets[i + 1]; k < e; ++k) a -= fb.grad[k] * (boundary_psi[fb.index[k]] * pi_term);
  return a;
}

/// v* = v + Δt a^np, then the fluid–boundary viscosity of spec §5.4 applied implicitly per particle,
/// K_ib = −Ψ_b β0b β1 h φ_ib /(ρ̄_ib (r²+εh²)) x_ib x_ibᵀ, M_i = Σ_b K_ib, evaluated at the velocity
/// the particle will have at the end of the step:
///   v^pred = v* + Δt â^p,   v^adv = (I + Δt M_i)^{-1} (v^pred + Δt Σ_b K_ib v_b) − Δt â^p,
/// where â^p is the pressure acceleration (Eq. 12) of the previous step's pressures at the current
/// positions (a predictor, as in incremental pressure-correction schemes). The wall term is a force
/// on the relative velocity; applied to v* alone it saw, in water at rest, the Δt g that the pressure
/// solve removes next, and held wall-adjacent water up by Δt-dependent friction: the interior sank,
/// the wall layer rose, and that circulation drew energy from the walls without end (a block at rest
/// kept 5–20 mm/s for 20 s). With â^p = 0 (first step, new particles) this is spec §5.4 as written.
template <class T>
struct AdvectVelocity {
  const Vec3<T>* v;
  const Vec3<T>* accel;
  T dt;
  // Wall viscosity (wall_coefficient = β0b β1 = 0 disables it).
  Pairs<T> fb;
  const Vec3<T>* x;
  const Vec3<T>* boundary_x;
  const Vec3<T>* boundary_v;
  const T* boundary_psi;
  const T* density;
  T wall_coefficient, h, epsilon, rest_density;
  bool limiter;
  CubicSpline<T> kernel;
  // The pressure predictor: water neighbourhoods and the previous step's pressures.
  Pairs<T> ff;
  const T* pressure_previous;
  T mass;
  Vec3<T>* v_adv;
  RIME_HD void operator()(Index i) const {
    const Vec3<T> v_star = v[i] + accel[i] * dt;
    if (wall_coefficient == T(0) || fb.offsets[i] == fb.offsets[i + 1]) {
      v_adv[i] = v_star;
      return;
    }
    const T rhoi = density[i];
    const Vec3<T> v_pred = v_star + PressureAcceleration(i, ff, fb, pressure_previous, density, boundary_psi, mass) * dt;
    Mat3<T> system = Mat3<T>::Identity();
    Vec3<T> rhs = v_pred;
    const Vec3<T> xi = x[i];
    const T rho_bar_base = T(0.5) * (rhoi + rest_density);
    for (std::uint32_t k = fb.offsets[i], e = fb.offsets[i + 1]; k < e; ++k) {
      const std::uint32_t b = fb.index[k];
      const Vec3<T> xib = xi - boundary_x[b];
      const T r2 = Dot(xib, xib);
      if (limiter && Dot(v_pred - boundary_v[b], xib) >= T(0)) continue;
      const T phi = kernel.GradientFactor(std::sqrt(r2));  // <= 0
      const T coefficient = -boundary_psi[b] * wall_coefficient * h * phi / (rho_bar_base * (r2 + epsilon * h * h));
      const Mat3<T> kib = Mat3<T>::OuterProduct(xib, xib) * coefficient;
      system += kib * dt;
      rhs += (kib * boundary_v[b]) * dt;
    }
    // v* + (the wall-viscosity change of v^pred): the pressure predictor itself is not applied.
    v_adv[i] = v_star + (SolveSpd(system, rhs) - v_pred);
  }
};

/// IISPH predict advection (spec §6): d_ii, ρ^adv − ρ0, a_ii, warm-started pressure.
template <class T>
struct PredictAdvection {
  Pairs<T> ff, fb;
  const Vec3<T>* v_adv;
  const Vec3<T>* boundary_v;
  const T* boundary_psi;
  const T* density;
  const T* density_error;
  const T* pressure_previous;
  T mass, dt, chi, warm_start;
  Vec3<T>* d_ii;
  T* advected_error;  // ρ_i^adv − ρ0
  T* a_ii;
  T* pressure;
  RIME_HD void operator()(Index i) const {
    const T rho = density[i], inv_rho2 = T(1) / (rho * rho), dt2 = dt * dt;
    const Vec3<T> vi = v_adv[i];
    Vec3<T> sum_fluid{}, sum_wall{};
    T divergence = T(0);
    for (std::uint32_t k = ff.offsets[i], e = ff.offsets[i + 1]; k < e; ++k) {
      sum_fluid += ff.grad[k];
      divergence += mass * Dot(vi - v_adv[ff.index[k]], ff.grad[k]);
    }
    for (std::uint32_t k = fb.offsets[i], e = fb.offsets[i + 1]; k < e; ++k) {
      const std::uint32_t b = fb.index[k];
      sum_wall += fb.grad[k] * boundary_psi[b];
      divergence += boundary_psi[b] * Dot(vi - boundary_v[b], fb.grad[k]);
    }
    const Vec3<T> dii = (sum_fluid * mass + sum_wall) * (-dt2 * inv_rho2);
    T aii = T(0);
    for (std::uint32_t k = ff.offsets[i], e = ff.offsets[i + 1]; k < e; ++k) {
      const Vec3<T> dji = ff.grad[k] * (dt2 * mass * inv_rho2);
      aii += mass * Dot(dii - dji, ff.grad[k]);
    }
    for (std::uint32_t k = fb.offsets[i], e = fb.offsets[i + 1]; k < e; ++k) {
      const Vec3<T> dbi = fb.grad[k] * (dt2 * mass * inv_rho2);
      aii += boundary_psi[fb.index[k]] * Dot(dii - dbi * chi, fb.grad[k]);
    }
    d_ii[i] = dii;
    advected_error[i] = density_error[i] + dt * divergence;
    a_ii[i] = aii;
    pressure[i] = warm_start * pressure_previous[i];
  }
};

/// Jacobi pass 1: s_i = Σ_j d_ij p_j = −Δt² Σ_j m p_j/ρ_j² ∇W_ij.
template <class T>
struct DisplacementSum {
  Pairs<T> ff;
  const T* pressure;
  const T* density;
  T mass, dt;
  Vec3<T>* s;
  RIME_HD void operator()(Index i) const {
    Vec3<T> sum{};
    for (std::uint32_t k = ff.offsets[i], e = ff.offsets[i + 1]; k < e; ++k) {
      const std::uint32_t j = ff.index[k];
      const T rhoj = density[j];
      sum += ff.grad[k] * (pressure[j] / (rhoj * rhoj));
    }
    s[i] = sum * (-dt * dt * mass);
  }
};

/// Jacobi pass 2: σ_i, relaxed update p_i ← max(0, (1−ω)p_i + ω(ρ0 − ρ^adv − σ_i)/a_ii), and the
/// particle's contribution to the average compression (spec §6, steps 2–3).
template <class T>
struct PressureUpdate {
  Pairs<T> ff, fb;
  const Vec3<T>* s;
  const Vec3<T>* d_ii;
  const T* a_ii;
  const T* pressure;
  const T* density;
  const T* advected_error;
  const T* boundary_psi;
  T mass, dt, omega, min_aii;
  T* pressure_next;
  T* compression;  // ρ_pred − ρ0 where p > 0, else 0
  RIME_HD void operator()(Index i) const {
    const Vec3<T> si = s[i];
    const T pi = pressure[i], rhoi = density[i], dt2 = dt * dt;
    T sigma = T(0);
    for (std::uint32_t k = ff.offsets[i], e = ff.offsets[i + 1]; k < e; ++k) {
      const std::uint32_t j = ff.index[k];
      const Vec3<T> dji_pi = ff.grad[k] * (dt2 * mass * pi / (rhoi * rhoi));
      sigma += mass * Dot(si - d_ii[j] * pressure[j] - (s[j] - dji_pi), ff.grad[k]);
    }
    for (std::uint32_t k = fb.offsets[i], e = fb.offsets[i + 1]; k < e; ++k) sigma += boundary_psi[fb.index[k]] * Dot(si, fb.grad[k]);
    const T aii = a_ii[i];
    T p = T(0);
    if (aii < -min_aii || aii > min_aii) {
      p = (T(1) - omega) * pi + omega * (-advected_error[i] - sigma) / aii;
      if (p < T(0)) p = T(0);
    }
    pressure_next[i] = p;
    compression[i] = p > T(0) ? advected_error[i] + aii * p + sigma : T(0);
  }
};

/// a_i^p (Eq. 12), v = v^adv + Δt a^p, x += Δt v (symplectic Euler); keeps p for the warm start.
template <class T>
struct IntegratePressure {
  Pairs<T> ff, fb;
  const T* pressure;
  const T* density;
  const T* boundary_psi;
  const Vec3<T>* v_adv;
  T mass, dt;
  Vec3<T>* v;
  Vec3<T>* x;
  T* pressure_previous;
  RIME_HD void operator()(Index i) const {
    const Vec3<T> a = PressureAcceleration(i, ff, fb, pressure, density, boundary_psi, mass);
    const Vec3<T> vi = v_adv[i] + a * dt;
    v[i] = vi;
    x[i] += vi * dt;
    pressure_previous[i] = pressure[i];
  }
};

/// out[i] = factor * in[i] (Ψ_b = ρ0 V_b).
template <class T>
struct Scale {
  const T* in;
  T factor;
  T* out;
  RIME_HD void operator()(Index i) const { out[i] = factor * in[i]; }
};

/// Caps an ice particle's Akinci volume at the volume of the water it froze from (m/ρ0). Akinci's
/// V_b = 1/Σ_k W_bk assumes a densely sampled surface: ice frozen away from walls and other ice has
/// few boundary neighbours and got up to π h³ ≈ 3 d_p³, so its water neighbours' density jumped by
/// up to 26 % at the conversion and the pressure solve blasted them away (up to 450 m/s at tight η).
template <class T>
struct CapIceVolume {
  const std::uint8_t* phase;
  T cap;
  T* volume;
  RIME_HD void operator()(Index b) const {
    if (phase[b] == freeze::kIcePhase && volume[b] > cap) volume[b] = cap;
  }
};

/// out[i] = x_i·u and out[n + i] = −x_i·u: the fluid's extent along u from two maxima.
template <class T>
struct Heights {
  const Vec3<T>* x;
  Vec3<T> up;
  Index n;
  T* out;
  RIME_HD void operator()(Index i) const {
    const T z = Dot(x[i], up);
    out[i] = z;
    out[n + i] = -z;
  }
};

/// out[i] = ‖v_i‖² (for the CFL condition and the divergence check).
template <class T>
struct SquaredSpeed {
  const Vec3<T>* v;
  T* out;
  RIME_HD void operator()(Index i) const { out[i] = Dot(v[i], v[i]); }
};

/// Moves boundary particles with their object: x = R x_local + t, v = v_lin + ω × (x − c).
template <class T>
struct MoveBoundary {
  const Vec3<T>* local;
  const std::uint32_t* object;
  const RigidMotion<T>* motions;
  Vec3<T>* x;
  Vec3<T>* v;
  RIME_HD void operator()(Index b) const {
    const RigidMotion<T> m = motions[object[b]];
    const Vec3<T> p = m.rotation * local[b] + m.translation;
    x[b] = p;
    v[b] = m.linear_velocity + Cross(m.angular_velocity, p - m.center);
  }
};

/// keep[i] = 1 when x_i is finite and inside the domain box.
template <class T>
struct InsideDomain {
  const Vec3<T>* x;
  Vec3<T> lo, hi;
  std::uint32_t* keep;
  RIME_HD void operator()(Index i) const {
    const Vec3<T> p = x[i];
    const bool inside = p.x >= lo.x && p.y >= lo.y && p.z >= lo.z && p.x <= hi.x && p.y <= hi.y && p.z <= hi.z;
    keep[i] = inside ? 1u : 0u;
  }
};

/// flags[index[k]] = 1 for every entry of the CSR lists of the given rows (benign races: same value).
struct MarkListed {
  const std::uint32_t* offsets;
  const std::uint32_t* index;
  std::uint32_t* flags;
  RIME_HD void operator()(Index i) const {
    for (std::uint32_t k = offsets[i], e = offsets[i + 1]; k < e; ++k) flags[index[k]] = 1u;
  }
};

}  // namespace kernels
}  // namespace rime::sph

// Kernels of both precisions; Gather of the anisotropy (exec lists the other attribute types).
// One kernel per line: clang-format 14 keeps that layout but rewraps a line of several on every run.
#define RIME_SPH_KERNELS_T(X, T)                             \
  X(rime::sph::kernels::Density<T>)                          \
  X(rime::sph::kernels::Compression<T>)                      \
  X(rime::sph::kernels::InitAcceleration<T>)                 \
  X(rime::sph::kernels::ViscosityAcceleration<T>)            \
  X(rime::sph::kernels::SurfaceColor<T>)                     \
  X(rime::sph::kernels::SurfaceEnergy<T>)                    \
  X(rime::sph::kernels::SurfaceTensionAcceleration<T>)       \
  X(rime::sph::kernels::AkinciNormal<T>)                     \
  X(rime::sph::kernels::AkinciSurfaceTensionAcceleration<T>) \
  X(rime::sph::kernels::AirPressureAcceleration<T>)          \
  X(rime::sph::kernels::AdvectVelocity<T>)                   \
  X(rime::sph::kernels::PredictAdvection<T>)                 \
  X(rime::sph::kernels::DisplacementSum<T>)                  \
  X(rime::sph::kernels::PressureUpdate<T>)                   \
  X(rime::sph::kernels::IntegratePressure<T>)                \
  X(rime::sph::kernels::SquaredSpeed<T>)                     \
  X(rime::sph::kernels::Heights<T>)                          \
  X(rime::sph::kernels::CapIceVolume<T>)                     \
  X(rime::sph::kernels::Scale<T>)                            \
  X(rime::sph::kernels::MoveBoundary<T>)                     \
  X(rime::sph::kernels::InsideDomain<T>)                     \
  X(rime::exec::Gather<rime::freeze::Sym6<T>>)

#define RIME_SPH_KERNELS(X)     \
  RIME_SPH_KERNELS_T(X, float)  \
  RIME_SPH_KERNELS_T(X, double) \
  X(rime::sph::kernels::MarkListed)
