// lwsccd — squared distances point-triangle and segment-segment (closest-feature algorithms of
// Ericson, Real-Time Collision Detection, 5.1.5 and 5.1.9), with host/device-identical rounding.
#pragma once

#include "lwsccd/core/config.hpp"
#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/geometry/vec.hpp"

namespace lwsccd::detail {

template <class T>
LWSCCD_HD T clamp01(T x) {
  return x < T(0) ? T(0) : (x > T(1) ? T(1) : x);
}

/// Squared distance from p to triangle (a, b, c); degenerate triangles are handled through
/// their edges.
template <class T>
LWSCCD_HD T point_triangle_distance2(const Vec3<T>& p, const Vec3<T>& a, const Vec3<T>& b, const Vec3<T>& c) {
  const Vec3<T> ab = vsub(b, a), ac = vsub(c, a), ap = vsub(p, a);
  const T d1 = vdot(ab, ap), d2 = vdot(ac, ap);
  auto dist2 = [&](const Vec3<T>& q) {
    const Vec3<T> d = vsub(p, q);
    return vdot(d, d);
  };
  if (d1 <= T(0) && d2 <= T(0)) return dist2(a);
  const Vec3<T> bp = vsub(p, b);
  const T d3 = vdot(ab, bp), d4 = vdot(ac, bp);
  if (d3 >= T(0) && d4 <= d3) return dist2(b);
  const T vc = fsub(fmul(d1, d4), fmul(d3, d2));
  if (vc <= T(0) && d1 >= T(0) && d3 <= T(0)) {
    const T den = fsub(d1, d3);
    return dist2(vadd_scaled(a, ab, den > T(0) ? d1 / den : T(0)));
  }
  const Vec3<T> cp = vsub(p, c);
  const T d5 = vdot(ab, cp), d6 = vdot(ac, cp);
  if (d6 >= T(0) && d5 <= d6) return dist2(c);
  const T vb = fsub(fmul(d5, d2), fmul(d1, d6));
  if (vb <= T(0) && d2 >= T(0) && d6 <= T(0)) {
    const T den = fsub(d2, d6);
    return dist2(vadd_scaled(a, ac, den > T(0) ? d2 / den : T(0)));
  }
  const T va = fsub(fmul(d3, d6), fmul(d5, d4));
  if (va <= T(0) && fsub(d4, d3) >= T(0) && fsub(d5, d6) >= T(0)) {
    const T den = fadd(fsub(d4, d3), fsub(d5, d6));
    return dist2(vadd_scaled(b, vsub(c, b), den > T(0) ? fsub(d4, d3) / den : T(0)));
  }
  const T sum = fadd(fadd(va, vb), vc);
  if (!(sum > T(0))) {  // degenerate triangle: the nearest of its three edges
    auto seg = [&](const Vec3<T>& s0, const Vec3<T>& s1) {
      const Vec3<T> d = vsub(s1, s0);
      const T len2 = vdot(d, d);
      const T t = len2 > T(0) ? clamp01(vdot(vsub(p, s0), d) / len2) : T(0);
      return dist2(vadd_scaled(s0, d, t));
    };
    const T e0 = seg(a, b), e1 = seg(b, c), e2 = seg(c, a);
    return e0 < e1 ? (e0 < e2 ? e0 : e2) : (e1 < e2 ? e1 : e2);
  }
  const T v = vb / sum, w = vc / sum;
  return dist2(vadd(vadd_scaled(a, ab, v), vscale(ac, w)));
}

/// Squared distance between segments [p1, q1] and [p2, q2], parallel and degenerate included.
template <class T>
LWSCCD_HD T segment_segment_distance2(const Vec3<T>& p1, const Vec3<T>& q1, const Vec3<T>& p2, const Vec3<T>& q2) {
  const Vec3<T> d1 = vsub(q1, p1), d2 = vsub(q2, p2), r = vsub(p1, p2);
  const T a = vdot(d1, d1), e = vdot(d2, d2), f = vdot(d2, r);
  T s, t;
  if (a <= T(0) && e <= T(0)) {
    s = t = T(0);
  } else if (a <= T(0)) {
    s = T(0);
    t = clamp01(f / e);
  } else {
    const T c = vdot(d1, r);
    if (e <= T(0)) {
      t = T(0);
      s = clamp01(-c / a);
    } else {
      const T b = vdot(d1, d2);
      const T denom = fsub(fmul(a, e), fmul(b, b));
      s = denom > T(0) ? clamp01(fsub(fmul(b, f), fmul(c, e)) / denom) : T(0);
      t = fadd(fmul(b, s), f) / e;
      if (t < T(0)) {
        t = T(0);
        s = clamp01(-c / a);
      } else if (t > T(1)) {
        t = T(1);
        s = clamp01(fsub(b, c) / a);
      }
    }
  }
  const Vec3<T> diff = vsub(vadd_scaled(p1, d1, s), vadd_scaled(p2, d2, t));
  return vdot(diff, diff);
}

}  // namespace lwsccd::detail
