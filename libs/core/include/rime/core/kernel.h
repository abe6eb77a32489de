/// @file kernel.h
/// @brief The 3-D cubic spline kernel (spec §1, paper Eq. 2 with the 3-D normalisation).
///
/// W(r,h) = sigma3/h^3 B(q), q = r/h, support 2h, sigma3 = 1/(4 pi). The paper prints the 2-D
/// constant 5/(14 pi h^2); the simulation is 3-D.
#pragma once

#include "rime/core/hd.h"
#include "rime/core/math.h"

namespace rime {

template <class T>
struct CubicSpline {
  T h;  // smoothing length
  T inv_h;
  T w_norm;     // sigma3 / h^3
  T grad_norm;  // sigma3 / h^4

  RIME_HDI explicit CubicSpline(T smoothing_length = T(1))
      : h(smoothing_length),
        inv_h(T(1) / smoothing_length),
        w_norm(T(0.07957747154594767) / (smoothing_length * smoothing_length * smoothing_length)),
        grad_norm(w_norm / smoothing_length) {}

  RIME_HDI T SupportRadius() const { return T(2) * h; }
  /// W(0,h) = 1/(pi h^3), "W0" in the spec.
  RIME_HDI T W0() const { return T(4) * w_norm; }

  /// B(q) of spec §1 (4x the textbook M4 polynomial).
  RIME_HDI static T Shape(T q) {
    if (q >= T(2)) return T(0);
    const T a = T(2) - q;
    if (q >= T(1)) return a * a * a;
    const T b = T(1) - q;
    return a * a * a - T(4) * b * b * b;
  }
  /// B(q) without branches, for loops the compiler should vectorise (the same polynomial pieces:
  /// the clamped terms are exactly zero outside their range).
  RIME_HDI static T ShapeBranchFree(T q) {
    const T a = q < T(2) ? T(2) - q : T(0), b = q < T(1) ? T(1) - q : T(0);
    return a * a * a - T(4) * b * b * b;
  }
  /// B'(q).
  RIME_HDI static T ShapeDerivative(T q) {
    if (q >= T(2)) return T(0);
    const T a = T(2) - q;
    if (q >= T(1)) return T(-3) * a * a;
    const T b = T(1) - q;
    return T(-3) * a * a + T(12) * b * b;
  }

  RIME_HDI T W(T r) const { return w_norm * Shape(r * inv_h); }
  RIME_HDI T W(const Vec3<T>& r) const { return W(Norm(r)); }

  /// ∇W with respect to the first particle's position: sigma3/h^4 B'(q) r/|r|; 0 at r = 0.
  RIME_HDI Vec3<T> Gradient(const Vec3<T>& r) const {
    const T len = Norm(r);
    if (len < T(1e-9) * h) return {T(0), T(0), T(0)};
    return r * (grad_norm * ShapeDerivative(len * inv_h) / len);
  }
  /// The scalar phi with ∇W = phi * r (phi <= 0); used where x·∇W is needed cheaply.
  RIME_HDI T GradientFactor(T len) const {
    if (len < T(1e-9) * h) return T(0);
    return grad_norm * ShapeDerivative(len * inv_h) / len;
  }
};

}  // namespace rime
