/// @file anisotropy.h
/// @brief Yu & Turk (2013) anisotropy from a weighted neighbour covariance (spec §8, paper
/// Eqs. 27–30) and the anisotropic kernel W_A. The one implementation shared by the freezing
/// module (inside kernels, host and device) and the surface stage.
///
/// @code
/// rime::anisotropy::CovarianceAccumulator<float> acc;
/// acc.AddSelf(kernel.W0());
/// grid.ForEachNeighbor(x_i, 2 * h, [&](auto j, auto r, auto r2) { if (j != i) acc.Add(-r, kernel.W(r)); });
/// const auto a = rime::anisotropy::Compute(acc.Covariance(), acc.neighbors, h, params);
/// const rime::Mat3<float> G = a.G(h);   // W_A(r, G) = Kernel(r, G)
/// @endcode
///
/// Plain values only (no containers, no exceptions) and C++17, because nvcc compiles this header.
#pragma once

#include "rime/core/hd.h"
#include "rime/core/kernel.h"
#include "rime/core/math.h"

namespace rime::anisotropy {

/// σ_iso / h²: every eigenvalue of the W-weighted covariance (support 2h) of an ideal cubic
/// lattice at h = d_p (spec §8). k_s = 1/σ_iso makes a full neighbourhood isotropic, G = I/h.
inline constexpr double kSigmaIsoLattice = 0.2994;

template <class T>
struct Params {
  T k_s = T(0);                     // 1/m²; 0 = automatic 1/σ_iso = 1/(0.2994 h²)
  T k_r = T(4);                     // largest allowed ratio s_1 / s_k
  T k_n = T(0.5);                   // isotropic stretch of particles with fewer than n_eps neighbours
  int n_eps = 6;                    // N_ε: minimum neighbour count for the PCA to be trusted
  T s_min = T(0.125);               // det(hG) <= 512: bounded kernel peak
  T s_max = T(1);                   // support never exceeds the 2h search radius
  bool center_on_particle = false;  // literal paper Eq. 28 (centred on x_i) instead of the weighted mean
};

/// Weighted mean and covariance of neighbour offsets (spec §8, Eq. 28). Offsets r = x_k − x_i are
/// accumulated relative to the particle, which keeps float precision where absolute positions
/// are large.
template <class T>
struct CovarianceAccumulator {
  T weight_sum = T(0);
  Vec3<T> first{};    // Σ w r
  T second[6] = {};   // Σ w r rᵀ: xx, yy, zz, xy, xz, yz
  int neighbors = 0;  // n_j = |N(j)|, the particle itself excluded

  /// The particle's own contribution (offset 0, weight W(0)); not counted as a neighbour.
  RIME_HDI void AddSelf(T w) { weight_sum += w; }
  /// Neighbour at offset r = x_k − x_i with weight w = W(r, h).
  RIME_HDI void Add(const Vec3<T>& r, T w) {
    weight_sum += w;
    first += r * w;
    second[0] += w * r.x * r.x;
    second[1] += w * r.y * r.y;
    second[2] += w * r.z * r.z;
    second[3] += w * r.x * r.y;
    second[4] += w * r.x * r.z;
    second[5] += w * r.y * r.z;
    ++neighbors;
  }
  /// Weighted mean offset Σ w r / Σ w (add x_i for the weighted mean position x̄^w).
  RIME_HDI Vec3<T> MeanOffset() const { return weight_sum > T(0) ? first / weight_sum : Vec3<T>{}; }
  /// C = Σ w (x_k − c)(x_k − c)ᵀ / Σ w with c the weighted mean (default) or the particle.
  RIME_HDI Mat3<T> Covariance(bool center_on_particle = false) const {
    Mat3<T> c;
    if (!(weight_sum > T(0))) return c;
    const T inv = T(1) / weight_sum;
    const Vec3<T> m = center_on_particle ? Vec3<T>{} : first * inv;
    c.m[0][0] = second[0] * inv - m.x * m.x;
    c.m[1][1] = second[1] * inv - m.y * m.y;
    c.m[2][2] = second[2] * inv - m.z * m.z;
    c.m[0][1] = c.m[1][0] = second[3] * inv - m.x * m.y;
    c.m[0][2] = c.m[2][0] = second[4] * inv - m.x * m.z;
    c.m[1][2] = c.m[2][1] = second[5] * inv - m.y * m.z;
    return c;
  }
};

/// Principal frame and stretches of one particle: G = (1/h) R diag(1/s) Rᵀ (Eq. 29).
template <class T>
struct Anisotropy {
  Mat3<T> rotation = Mat3<T>::Identity();  // columns: principal directions, s_1 >= s_2 >= s_3 order
  Vec3<T> stretch{T(1), T(1), T(1)};       // s_1, s_2, s_3 (dimensionless)

  /// D = R diag(1/s) Rᵀ: dimensionless, stored per ice particle at freezing time (spec §10).
  RIME_HDI Mat3<T> D() const {
    Mat3<T> d;
    const T inv[3] = {T(1) / stretch.x, T(1) / stretch.y, T(1) / stretch.z};
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        d.m[a][b] = rotation.m[a][0] * inv[0] * rotation.m[b][0] + rotation.m[a][1] * inv[1] * rotation.m[b][1] +
                    rotation.m[a][2] * inv[2] * rotation.m[b][2];
    return d;
  }
  /// G = D / h (1/m), the argument of W_A.
  RIME_HDI Mat3<T> G(T h) const { return D() * (T(1) / h); }
};

/// Stretches from a covariance (spec §8): s_1 = k_s σ1, s_{2,3} = k_s max(σ_{2,3}, σ1/k_r) when
/// n >= N_ε, else k_n for all three; then clamped to [s_min, s_max]. A degenerate covariance
/// (σ1 < 1e−12 h², e.g. duplicated positions) is treated as isolated (spec §15).
template <class T>
RIME_HDI Anisotropy<T> Compute(const Mat3<T>& covariance, int neighbor_count, T h, const Params<T>& p) {
  Anisotropy<T> a;
  Vec3<T> sigma;
  SymmetricEigen(covariance, sigma, a.rotation);
  const T k_s = p.k_s > T(0) ? p.k_s : T(1) / (T(kSigmaIsoLattice) * h * h);
  const bool trusted = neighbor_count >= p.n_eps && sigma.x >= T(1e-12) * h * h;
  if (trusted) {
    const T floor = sigma.x / p.k_r;
    a.stretch = {k_s * sigma.x, k_s * (sigma.y > floor ? sigma.y : floor), k_s * (sigma.z > floor ? sigma.z : floor)};
  } else {
    a.stretch = Vec3<T>::Splat(p.k_n);
  }
  for (int k = 0; k < 3; ++k) {
    T& s = a.stretch[k];
    s = s < p.s_min ? p.s_min : (s > p.s_max ? p.s_max : s);
  }
  return a;
}

/// W_A(r, G) = σ3 det(G) B(‖G r‖) (spec §8, the corrected Eq. 27); ∫ W_A dV = 1 for any
/// invertible G and W_A(r, I/h) = W(r, h).
template <class T>
RIME_HDI T Kernel(const Vec3<T>& r, const Mat3<T>& G) {
  return T(0.07957747154594767) * Determinant(G) * CubicSpline<T>::Shape(Norm(G * r));
}

/// Symmetric matrix <-> the six stored components (order xx, yy, zz, xy, xz, yz: the particle
/// attributes `anisotropy_0..5`).
template <class T>
RIME_HDI Mat3<T> FromComponents(const T c[6]) {
  Mat3<T> m;
  m.m[0][0] = c[0];
  m.m[1][1] = c[1];
  m.m[2][2] = c[2];
  m.m[0][1] = m.m[1][0] = c[3];
  m.m[0][2] = m.m[2][0] = c[4];
  m.m[1][2] = m.m[2][1] = c[5];
  return m;
}
template <class T>
RIME_HDI void ToComponents(const Mat3<T>& m, T c[6]) {
  c[0] = m.m[0][0];
  c[1] = m.m[1][1];
  c[2] = m.m[2][2];
  c[3] = m.m[0][1];
  c[4] = m.m[0][2];
  c[5] = m.m[1][2];
}

}  // namespace rime::anisotropy
