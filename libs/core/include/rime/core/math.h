/// @file math.h
/// @brief Small fixed-size vector and matrix math usable in kernels (host and device).
#pragma once

#include <cmath>

#include "rime/core/hd.h"

namespace rime {

template <class T>
struct Vec3 {
  T x{}, y{}, z{};

  constexpr Vec3() = default;
  RIME_HDI constexpr Vec3(T x_, T y_, T z_) : x(x_), y(y_), z(z_) {}
  RIME_HDI static constexpr Vec3 Splat(T v) { return {v, v, v}; }
  template <class U>
  RIME_HDI explicit constexpr Vec3(const Vec3<U>& o) : x(T(o.x)), y(T(o.y)), z(T(o.z)) {}

  RIME_HDI T& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
  RIME_HDI T operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }

  RIME_HDI Vec3& operator+=(const Vec3& o) {
    x += o.x;
    y += o.y;
    z += o.z;
    return *this;
  }
  RIME_HDI Vec3& operator-=(const Vec3& o) {
    x -= o.x;
    y -= o.y;
    z -= o.z;
    return *this;
  }
  RIME_HDI Vec3& operator*=(T s) {
    x *= s;
    y *= s;
    z *= s;
    return *this;
  }
  RIME_HDI Vec3& operator/=(T s) {
    x /= s;
    y /= s;
    z /= s;
    return *this;
  }
  RIME_HDI friend bool operator==(const Vec3& a, const Vec3& b) { return a.x == b.x && a.y == b.y && a.z == b.z; }
};

template <class T>
RIME_HDI Vec3<T> operator+(Vec3<T> a, const Vec3<T>& b) {
  return a += b;
}
template <class T>
RIME_HDI Vec3<T> operator-(Vec3<T> a, const Vec3<T>& b) {
  return a -= b;
}
template <class T>
RIME_HDI Vec3<T> operator-(const Vec3<T>& a) {
  return {-a.x, -a.y, -a.z};
}
template <class T>
RIME_HDI Vec3<T> operator*(Vec3<T> a, T s) {
  return a *= s;
}
template <class T>
RIME_HDI Vec3<T> operator*(T s, Vec3<T> a) {
  return a *= s;
}
template <class T>
RIME_HDI Vec3<T> operator/(Vec3<T> a, T s) {
  return a /= s;
}
template <class T>
RIME_HDI T Dot(const Vec3<T>& a, const Vec3<T>& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
template <class T>
RIME_HDI Vec3<T> Cross(const Vec3<T>& a, const Vec3<T>& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <class T>
RIME_HDI T SquaredNorm(const Vec3<T>& a) {
  return Dot(a, a);
}
template <class T>
RIME_HDI T Norm(const Vec3<T>& a) {
  return std::sqrt(Dot(a, a));
}
template <class T>
RIME_HDI Vec3<T> Min(const Vec3<T>& a, const Vec3<T>& b) {
  return {a.x < b.x ? a.x : b.x, a.y < b.y ? a.y : b.y, a.z < b.z ? a.z : b.z};
}
template <class T>
RIME_HDI Vec3<T> Max(const Vec3<T>& a, const Vec3<T>& b) {
  return {a.x > b.x ? a.x : b.x, a.y > b.y ? a.y : b.y, a.z > b.z ? a.z : b.z};
}
template <class T>
RIME_HDI bool IsFinite(const Vec3<T>& a) {
  return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
}

using Vec3f = Vec3<float>;
using Vec3d = Vec3<double>;

/// Dense 3x3 matrix, row-major.
template <class T>
struct Mat3 {
  T m[3][3]{};

  RIME_HDI static Mat3 Identity() {
    Mat3 r;
    r.m[0][0] = r.m[1][1] = r.m[2][2] = T(1);
    return r;
  }
  RIME_HDI static Mat3 OuterProduct(const Vec3<T>& a, const Vec3<T>& b) {
    Mat3 r;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) r.m[i][j] = a[i] * b[j];
    return r;
  }
  RIME_HDI static Mat3 FromColumns(const Vec3<T>& c0, const Vec3<T>& c1, const Vec3<T>& c2) {
    Mat3 r;
    for (int i = 0; i < 3; ++i) {
      r.m[i][0] = c0[i];
      r.m[i][1] = c1[i];
      r.m[i][2] = c2[i];
    }
    return r;
  }
  RIME_HDI Vec3<T> Column(int j) const { return {m[0][j], m[1][j], m[2][j]}; }
  RIME_HDI Mat3& operator+=(const Mat3& o) {
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) m[i][j] += o.m[i][j];
    return *this;
  }
  RIME_HDI Mat3& operator*=(T s) {
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) m[i][j] *= s;
    return *this;
  }
};

template <class T>
RIME_HDI Mat3<T> operator+(Mat3<T> a, const Mat3<T>& b) {
  return a += b;
}
template <class T>
RIME_HDI Mat3<T> operator*(Mat3<T> a, T s) {
  return a *= s;
}
template <class T>
RIME_HDI Vec3<T> operator*(const Mat3<T>& a, const Vec3<T>& v) {
  return {a.m[0][0] * v.x + a.m[0][1] * v.y + a.m[0][2] * v.z, a.m[1][0] * v.x + a.m[1][1] * v.y + a.m[1][2] * v.z,
          a.m[2][0] * v.x + a.m[2][1] * v.y + a.m[2][2] * v.z};
}
template <class T>
RIME_HDI Mat3<T> operator*(const Mat3<T>& a, const Mat3<T>& b) {
  Mat3<T> r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r.m[i][j] = a.m[i][0] * b.m[0][j] + a.m[i][1] * b.m[1][j] + a.m[i][2] * b.m[2][j];
  return r;
}
template <class T>
RIME_HDI Mat3<T> Transpose(const Mat3<T>& a) {
  Mat3<T> r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r.m[i][j] = a.m[j][i];
  return r;
}
template <class T>
RIME_HDI T Determinant(const Mat3<T>& a) {
  return a.m[0][0] * (a.m[1][1] * a.m[2][2] - a.m[1][2] * a.m[2][1]) - a.m[0][1] * (a.m[1][0] * a.m[2][2] - a.m[1][2] * a.m[2][0]) +
         a.m[0][2] * (a.m[1][0] * a.m[2][1] - a.m[1][1] * a.m[2][0]);
}

/// Rotation by `angle` radians about `axis` (any length > 0), by Rodrigues' formula.
template <class T>
RIME_HDI Mat3<T> AxisAngleRotation(const Vec3<T>& axis, T angle) {
  const Vec3<T> a = axis / Norm(axis);
  const T c = std::cos(angle), s = std::sin(angle), t = T(1) - c;
  Mat3<T> r;
  r.m[0][0] = c + a.x * a.x * t, r.m[0][1] = a.x * a.y * t - a.z * s, r.m[0][2] = a.x * a.z * t + a.y * s;
  r.m[1][0] = a.y * a.x * t + a.z * s, r.m[1][1] = c + a.y * a.y * t, r.m[1][2] = a.y * a.z * t - a.x * s;
  r.m[2][0] = a.z * a.x * t - a.y * s, r.m[2][1] = a.z * a.y * t + a.x * s, r.m[2][2] = c + a.z * a.z * t;
  return r;
}

/// Euler angles in degrees applied about X first, then Y, then Z (the scene file's `rotate`).
template <class T>
RIME_HDI Mat3<T> RotationXYZDegrees(const Vec3<T>& degrees) {
  const T k = T(3.14159265358979323846) / T(180);
  return AxisAngleRotation(Vec3<T>(0, 0, 1), degrees.z * k) * AxisAngleRotation(Vec3<T>(0, 1, 0), degrees.y * k) *
         AxisAngleRotation(Vec3<T>(1, 0, 0), degrees.x * k);
}

/// Solves A x = b for a symmetric positive definite 3x3 A by Cholesky (no pivoting needed).
template <class T>
RIME_HDI Vec3<T> SolveSpd(const Mat3<T>& a, const Vec3<T>& b) {
  const T l00 = std::sqrt(a.m[0][0]);
  const T l10 = a.m[1][0] / l00, l20 = a.m[2][0] / l00;
  const T l11 = std::sqrt(a.m[1][1] - l10 * l10);
  const T l21 = (a.m[2][1] - l20 * l10) / l11;
  const T l22 = std::sqrt(a.m[2][2] - l20 * l20 - l21 * l21);
  const T y0 = b.x / l00, y1 = (b.y - l10 * y0) / l11, y2 = (b.z - l20 * y0 - l21 * y1) / l22;
  const T x2 = y2 / l22, x1 = (y1 - l21 * x2) / l11, x0 = (y0 - l10 * x1 - l20 * x2) / l00;
  return {x0, x1, x2};
}

/// Symmetric 3x3 eigen decomposition by cyclic Jacobi rotations: robust for degenerate
/// (collinear, coplanar, repeated) inputs and usable in device code. On return
/// a = V diag(values) V^T with values sorted descending and V's columns the eigenvectors.
template <class T>
RIME_HDI void SymmetricEigen(Mat3<T> a, Vec3<T>& values, Mat3<T>& vectors) {
  Mat3<T> v = Mat3<T>::Identity();
  // Converged when the off-diagonal is at rounding level (ε², ε the precision's epsilon): float
  // never reaches a fixed 1e-30 and ran all 16 sweeps.
  const T tolerance = sizeof(T) == sizeof(float) ? T(1.5e-14) : T(1e-30);
  for (int sweep = 0; sweep < 16; ++sweep) {
    const T off = a.m[0][1] * a.m[0][1] + a.m[0][2] * a.m[0][2] + a.m[1][2] * a.m[1][2];
    const T diag = a.m[0][0] * a.m[0][0] + a.m[1][1] * a.m[1][1] + a.m[2][2] * a.m[2][2];
    if (off <= tolerance * diag || off == T(0)) break;
    for (int p = 0; p < 2; ++p) {
      for (int q = p + 1; q < 3; ++q) {
        const T apq = a.m[p][q];
        if (apq == T(0)) continue;
        const T theta = (a.m[q][q] - a.m[p][p]) / (T(2) * apq);
        const T t = (theta >= T(0) ? T(1) : T(-1)) / (std::fabs(theta) + std::sqrt(theta * theta + T(1)));
        const T c = T(1) / std::sqrt(t * t + T(1)), s = t * c;
        for (int k = 0; k < 3; ++k) {  // A <- A J
          const T akp = a.m[k][p], akq = a.m[k][q];
          a.m[k][p] = c * akp - s * akq;
          a.m[k][q] = s * akp + c * akq;
        }
        for (int k = 0; k < 3; ++k) {  // A <- J^T A
          const T apk = a.m[p][k], aqk = a.m[q][k];
          a.m[p][k] = c * apk - s * aqk;
          a.m[q][k] = s * apk + c * aqk;
        }
        for (int k = 0; k < 3; ++k) {  // V <- V J
          const T vkp = v.m[k][p], vkq = v.m[k][q];
          v.m[k][p] = c * vkp - s * vkq;
          v.m[k][q] = s * vkp + c * vkq;
        }
      }
    }
  }
  T d[3] = {a.m[0][0], a.m[1][1], a.m[2][2]};
  int order[3] = {0, 1, 2};
  for (int i = 0; i < 2; ++i)  // sort descending (3 elements)
    for (int j = 0; j < 2 - i; ++j)
      if (d[order[j]] < d[order[j + 1]]) {
        const int t = order[j];
        order[j] = order[j + 1];
        order[j + 1] = t;
      }
  values = {d[order[0]], d[order[1]], d[order[2]]};
  vectors = Mat3<T>::FromColumns(v.Column(order[0]), v.Column(order[1]), v.Column(order[2]));
}

}  // namespace rime
