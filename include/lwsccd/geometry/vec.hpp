// lwsccd — a small 3-vector templated on the scalar (float or double), usable on host and device.
#pragma once

#include <cmath>
#include <type_traits>

#include "lwsccd/core/config.hpp"

namespace lwsccd {

template <class T>
struct Vec3 {
  static_assert(std::is_floating_point<T>::value, "lwsccd::Vec3<T>: T must be float or double");
  using scalar_type = T;

  T x, y, z;

  LWSCCD_HD constexpr T operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  LWSCCD_HD T& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }

  /// Converts between precisions (double -> float rounds to nearest).
  template <class U>
  LWSCCD_HD constexpr Vec3<U> cast() const {
    return {static_cast<U>(x), static_cast<U>(y), static_cast<U>(z)};
  }

  LWSCCD_HD Vec3& operator+=(const Vec3& o) { x += o.x; y += o.y; z += o.z; return *this; }
  LWSCCD_HD Vec3& operator-=(const Vec3& o) { x -= o.x; y -= o.y; z -= o.z; return *this; }
  LWSCCD_HD Vec3& operator*=(T s) { x *= s; y *= s; z *= s; return *this; }
};

using Vec3f = Vec3<float>;
using Vec3d = Vec3<double>;

template <class T> LWSCCD_HD constexpr Vec3<T> operator+(const Vec3<T>& a, const Vec3<T>& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
template <class T> LWSCCD_HD constexpr Vec3<T> operator-(const Vec3<T>& a, const Vec3<T>& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
template <class T> LWSCCD_HD constexpr Vec3<T> operator-(const Vec3<T>& a) { return {-a.x, -a.y, -a.z}; }
template <class T> LWSCCD_HD constexpr Vec3<T> operator*(const Vec3<T>& a, T s) { return {a.x * s, a.y * s, a.z * s}; }
template <class T> LWSCCD_HD constexpr Vec3<T> operator*(T s, const Vec3<T>& a) { return {a.x * s, a.y * s, a.z * s}; }
template <class T> LWSCCD_HD constexpr bool operator==(const Vec3<T>& a, const Vec3<T>& b) { return a.x == b.x && a.y == b.y && a.z == b.z; }
template <class T> LWSCCD_HD constexpr bool operator!=(const Vec3<T>& a, const Vec3<T>& b) { return !(a == b); }

template <class T> LWSCCD_HD constexpr T dot(const Vec3<T>& a, const Vec3<T>& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
template <class T> LWSCCD_HD constexpr Vec3<T> cross(const Vec3<T>& a, const Vec3<T>& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <class T> LWSCCD_HD constexpr T squared_norm(const Vec3<T>& a) { return dot(a, a); }
template <class T> LWSCCD_HD T norm(const Vec3<T>& a) { return std::sqrt(dot(a, a)); }
/// Componentwise |a| (std::fabs: a mask, no branch; the sign tests `x < 0 ? -x : x` compiled to
/// were branches that coordinates' random signs mispredicted, in the narrow phase's hottest loop).
template <class T> LWSCCD_HD Vec3<T> abs(const Vec3<T>& a) {
  return {std::fabs(a.x), std::fabs(a.y), std::fabs(a.z)};
}
template <class T> LWSCCD_HD constexpr Vec3<T> min(const Vec3<T>& a, const Vec3<T>& b) {
  return {a.x < b.x ? a.x : b.x, a.y < b.y ? a.y : b.y, a.z < b.z ? a.z : b.z};
}
template <class T> LWSCCD_HD constexpr Vec3<T> max(const Vec3<T>& a, const Vec3<T>& b) {
  return {a.x > b.x ? a.x : b.x, a.y > b.y ? a.y : b.y, a.z > b.z ? a.z : b.z};
}
template <class T> LWSCCD_HD constexpr T max_component(const Vec3<T>& a) {
  // Two selects (the nested form's branches mispredict); the same result for every input, NaN too.
  const T xy = a.x > a.y ? a.x : a.y;
  return xy > a.z ? xy : a.z;
}
/// True when no component is NaN or infinite.
template <class T> LWSCCD_HD bool is_finite(const Vec3<T>& a) {
  return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
}

/// Linear motion of a point over the step: position at time t in [0, 1].
template <class T> LWSCCD_HD constexpr Vec3<T> lerp(const Vec3<T>& p0, const Vec3<T>& p1, T t) {
  return p0 + (p1 - p0) * t;
}

}  // namespace lwsccd
