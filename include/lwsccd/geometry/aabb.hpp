// lwsccd — axis-aligned bounding box.
#pragma once

#include <limits>

#include "lwsccd/core/config.hpp"
#include "lwsccd/core/detail/rounding.hpp"
#include "lwsccd/geometry/vec.hpp"

namespace lwsccd {

/// Axis-aligned box [lo, hi]. An empty box has lo > hi (the identity of merge).
template <class T>
struct Aabb {
  using scalar_type = T;
  Vec3<T> lo, hi;

  LWSCCD_HD static constexpr Aabb empty() {
    return {{std::numeric_limits<T>::max(), std::numeric_limits<T>::max(), std::numeric_limits<T>::max()},
            {std::numeric_limits<T>::lowest(), std::numeric_limits<T>::lowest(), std::numeric_limits<T>::lowest()}};
  }
  LWSCCD_HD constexpr bool is_empty() const { return lo.x > hi.x || lo.y > hi.y || lo.z > hi.z; }

  /// Grows the box to contain p; p may be wider than T (rounded outward, so still contained).
  template <class U>
  LWSCCD_HD void expand(const Vec3<U>& p) {
    lo = min(lo, Vec3<T>{detail::round_down<T>(p.x), detail::round_down<T>(p.y), detail::round_down<T>(p.z)});
    hi = max(hi, Vec3<T>{detail::round_up<T>(p.x), detail::round_up<T>(p.y), detail::round_up<T>(p.z)});
  }
  LWSCCD_HD void expand(const Aabb& b) {
    lo = min(lo, b.lo);
    hi = max(hi, b.hi);
  }

  LWSCCD_HD constexpr Vec3<T> center() const { return (lo + hi) * T(0.5); }
  LWSCCD_HD constexpr Vec3<T> extent() const { return hi - lo; }
  LWSCCD_HD constexpr bool contains(const Vec3<T>& p) const {
    return lo.x <= p.x && p.x <= hi.x && lo.y <= p.y && p.y <= hi.y && lo.z <= p.z && p.z <= hi.z;
  }
  /// Closed boxes: touching boxes overlap (a contact at the boundary must not be culled).
  LWSCCD_HD constexpr bool overlaps(const Aabb& b) const {
    return lo.x <= b.hi.x && b.lo.x <= hi.x && lo.y <= b.hi.y && b.lo.y <= hi.y && lo.z <= b.hi.z && b.lo.z <= hi.z;
  }
  LWSCCD_HD constexpr T volume() const {
    return is_empty() ? T(0) : (hi.x - lo.x) * (hi.y - lo.y) * (hi.z - lo.z);
  }
  LWSCCD_HD constexpr T surface_area() const {
    if (is_empty()) return T(0);
    const Vec3<T> d = hi - lo;
    return T(2) * (d.x * d.y + d.y * d.z + d.z * d.x);
  }
  /// The box grown by `margin` on every side, rounded outward.
  LWSCCD_HD Aabb inflated(T margin) const {
    constexpr T inf = std::numeric_limits<T>::infinity();
    Aabb r;
    for (int i = 0; i < 3; ++i) {
      r.lo[i] = std::nextafter(lo[i] - margin, -inf);
      r.hi[i] = std::nextafter(hi[i] + margin, inf);
    }
    return r;
  }
};

using Aabbf = Aabb<float>;
using Aabbd = Aabb<double>;

}  // namespace lwsccd
