// lwsccd — definitions for obb.hpp. Every multiply that feeds an add goes through detail/fp.hpp
// so that host and device produce the same bits.
#pragma once

#include "lwsccd/geometry/obb.hpp"

namespace lwsccd {

namespace detail {

// Orthonormal right-handed axes from the covariance of the points; identity when the points
// carry no direction (coincident points) or the solve degenerates.
template <class T, class U>
LWSCCD_HD void covariance_axes(const Vec3<U>* points, int n, Vec3<T> axis[3]) {
  using W = wider_t<T, U>;
  Vec3<W> mean{0, 0, 0};
  for (int i = 0; i < n; ++i) mean = vadd(mean, points[i].template cast<W>());
  mean = vscale(mean, W(1) / W(n));
  SymMat3<W> c{0, 0, 0, 0, 0, 0};
  for (int i = 0; i < n; ++i) {
    const Vec3<W> d = vsub(points[i].template cast<W>(), mean);
    c.xx = fadd(c.xx, fmul(d.x, d.x));
    c.yy = fadd(c.yy, fmul(d.y, d.y));
    c.zz = fadd(c.zz, fmul(d.z, d.z));
    c.xy = fadd(c.xy, fmul(d.x, d.y));
    c.xz = fadd(c.xz, fmul(d.x, d.z));
    c.yz = fadd(c.yz, fmul(d.y, d.z));
  }
  const SymEigen3<W> eig = symmetric_eigen3(c);
  // Re-orthonormalize (Gram-Schmidt) in W, then round to T.
  Vec3<W> u0 = eig.vectors[0];
  const W l0 = vnorm(u0);
  Vec3<W> u1 = eig.vectors[1];
  bool ok = l0 > W(0) && std::isfinite(l0);
  if (ok) {
    u0 = vscale(u0, W(1) / l0);
    u1 = vsub(u1, vscale(u0, vdot(u0, u1)));
    const W l1 = vnorm(u1);
    ok = l1 > W(0) && std::isfinite(l1);
    if (ok) u1 = vscale(u1, W(1) / l1);
  }
  if (!ok) {
    u0 = {1, 0, 0};
    u1 = {0, 1, 0};
  }
  const Vec3<W> u2 = vcross(u0, u1);
  axis[0] = u0.template cast<T>();
  axis[1] = u1.template cast<T>();
  axis[2] = u2.template cast<T>();
}

// Rigorous bound on the rounding error of fl(u . fl(p - c)) in W, relative to |u| . |p - c|:
// one subtraction and a three-term dot product, gamma_4 < 5u; taken as 8u.
template <class W>
LWSCCD_HD constexpr W projection_error_factor() {
  return W(8) * unit_roundoff<W>();
}

// |u . d| padded by the bound on its rounding error.
template <class W>
LWSCCD_HD W padded_projection(const Vec3<W>& u, const Vec3<W>& d) {
  return fadd(std::fabs(vdot(u, d)), fmul(projection_error_factor<W>(), vabs_dot(u, d)));
}

}  // namespace detail

template <class T>
template <class U>
LWSCCD_HD bool Obb<T>::contains(const Vec3<U>& p) const {
  using W = detail::wider_t<T, U>;
  const Vec3<W> d = detail::vsub(p.template cast<W>(), center.template cast<W>());
  LWSCCD_UNROLL for (int i = 0; i < 3; ++i) {
    const Vec3<W> u = axis[i].template cast<W>();
    const W proj = std::fabs(detail::vdot(u, d));
    const W err = detail::fmul(detail::projection_error_factor<W>(), detail::vabs_dot(u, d));
    if (detail::fsub(proj, err) > W(half[i])) return false;
  }
  return true;
}

template <class T>
template <class U>
LWSCCD_HD Obb<T> Obb<T>::fit(const Vec3<U>* points, int n) {
  using W = detail::wider_t<T, U>;
  Obb box;
  detail::covariance_axes<T>(points, n, box.axis);
  // Interval of the points along each stored axis.
  W lo[3], hi[3];
  LWSCCD_UNROLL for (int i = 0; i < 3; ++i) {
    lo[i] = std::numeric_limits<W>::max();
    hi[i] = std::numeric_limits<W>::lowest();
  }
  for (int k = 0; k < n; ++k) {
    const Vec3<W> p = points[k].template cast<W>();
    LWSCCD_UNROLL for (int i = 0; i < 3; ++i) {
      const W s = detail::vdot(box.axis[i].template cast<W>(), p);
      lo[i] = s < lo[i] ? s : lo[i];
      hi[i] = s > hi[i] ? s : hi[i];
    }
  }
  // The center only needs to be near the middle: the extents below are measured from the
  // stored (rounded) center, so its rounding costs nothing in correctness.
  Vec3<W> c{0, 0, 0};
  LWSCCD_UNROLL for (int i = 0; i < 3; ++i) c = detail::vadd_scaled(c, box.axis[i].template cast<W>(), detail::fmul(detail::fadd(lo[i], hi[i]), W(0.5)));
  box.center = c.template cast<T>();
  const Vec3<W> cw = box.center.template cast<W>();
  W ext[3] = {0, 0, 0};
  for (int k = 0; k < n; ++k) {
    const Vec3<W> d = detail::vsub(points[k].template cast<W>(), cw);
    LWSCCD_UNROLL for (int i = 0; i < 3; ++i) {
      const W e = detail::padded_projection(box.axis[i].template cast<W>(), d);
      ext[i] = e > ext[i] ? e : ext[i];
    }
  }
  LWSCCD_UNROLL for (int i = 0; i < 3; ++i) {
    // (1 + 4u) covers the rounding of the sum above; the tiny floor keeps a flat box closed.
    const W e = detail::fadd(detail::fmul(ext[i], W(1) + W(4) * detail::unit_roundoff<W>()), std::numeric_limits<W>::denorm_min());
    box.half[i] = detail::round_up<T>(e);
  }
  return box;
}

template <class T>
LWSCCD_HD Obb<T> Obb<T>::merge(const Obb& a, const Obb& b) {
  Vec3<T> pts[16];
  a.corners(pts);
  b.corners(pts + 8);
  Obb box;
  detail::covariance_axes<T>(pts, 16, box.axis);
  // Reach of a child along unit axis u from point m: |u.(c - m)| + sum_j safe_half_j |u . axis_j|
  // (the support function of the child's conservative extents).
  const Obb* child[2] = {&a, &b};
  T lo[3], hi[3];
  LWSCCD_UNROLL for (int i = 0; i < 3; ++i) {
    lo[i] = std::numeric_limits<T>::max();
    hi[i] = std::numeric_limits<T>::lowest();
    LWSCCD_UNROLL for (int k = 0; k < 2; ++k) {
      const Obb& ch = *child[k];
      const T mid = detail::vdot(box.axis[i], ch.center);
      T reach = T(0);
      LWSCCD_UNROLL for (int j = 0; j < 3; ++j)
        reach = detail::fadd(reach, detail::fmul(ch.safe_half(j), std::fabs(detail::vdot(box.axis[i], ch.axis[j]))));
      lo[i] = detail::fsub(mid, reach) < lo[i] ? detail::fsub(mid, reach) : lo[i];
      hi[i] = detail::fadd(mid, reach) > hi[i] ? detail::fadd(mid, reach) : hi[i];
    }
  }
  Vec3<T> c{0, 0, 0};
  LWSCCD_UNROLL for (int i = 0; i < 3; ++i) c = detail::vadd_scaled(c, box.axis[i], detail::fmul(detail::fadd(lo[i], hi[i]), T(0.5)));
  box.center = c;
  LWSCCD_UNROLL for (int i = 0; i < 3; ++i) {
    T ext = T(0), err = T(0);
    LWSCCD_UNROLL for (int k = 0; k < 2; ++k) {
      const Obb& ch = *child[k];
      const Vec3<T> d = detail::vsub(ch.center, box.center);
      T reach = std::fabs(detail::vdot(box.axis[i], d));
      T mag = detail::vabs_dot(box.axis[i], d);
      LWSCCD_UNROLL for (int j = 0; j < 3; ++j) {
        const T h = ch.safe_half(j);
        reach = detail::fadd(reach, detail::fmul(h, std::fabs(detail::vdot(box.axis[i], ch.axis[j]))));
        mag = detail::fadd(mag, detail::fmul(h, detail::vabs_dot(box.axis[i], ch.axis[j])));
      }
      ext = reach > ext ? reach : ext;
      err = mag > err ? mag : err;
    }
    // Rounding of the differences, dots, products and sums above: well under 16u of `err`.
    const T padded = detail::fadd(detail::fadd(ext, detail::fmul(T(16) * detail::unit_roundoff<T>(), err)),
                                  std::numeric_limits<T>::denorm_min());
    box.half[i] = std::nextafter(padded, std::numeric_limits<T>::infinity());
  }
  return box;
}

template <class T>
LWSCCD_HD bool Obb<T>::overlap(const Obb& a, const Obb& b) {
  const Vec3<T> t = detail::vsub(b.center, a.center);
  const T ha[3] = {a.safe_half(0), a.safe_half(1), a.safe_half(2)};
  const T hb[3] = {b.safe_half(0), b.safe_half(1), b.safe_half(2)};
  // Projects both boxes on l; separated only if the gap exceeds every rounding error made.
  auto separated_along = [&](const Vec3<T>& l) {
    T ra = T(0), rb = T(0), mag = detail::vabs_dot(t, l);
    LWSCCD_UNROLL for (int i = 0; i < 3; ++i) {
      ra = detail::fadd(ra, detail::fmul(ha[i], std::fabs(detail::vdot(a.axis[i], l))));
      rb = detail::fadd(rb, detail::fmul(hb[i], std::fabs(detail::vdot(b.axis[i], l))));
      mag = detail::fadd(mag, detail::fadd(detail::fmul(ha[i], detail::vabs_dot(a.axis[i], l)),
                                           detail::fmul(hb[i], detail::vabs_dot(b.axis[i], l))));
    }
    const T gap = detail::fsub(std::fabs(detail::vdot(t, l)), detail::fadd(ra, rb));
    // The denorm term covers underflow in the products when l is tiny.
    return gap > detail::fadd(detail::fmul(T(16) * detail::unit_roundoff<T>(), mag),
                              T(64) * std::numeric_limits<T>::denorm_min());
  };
  LWSCCD_UNROLL for (int i = 0; i < 3; ++i)
    if (separated_along(a.axis[i]) || separated_along(b.axis[i])) return false;
  // Edge-edge axes. A near-zero cross product (parallel edges) gives gap and bound both ~0 and
  // never separates, so no epsilon hack is needed for those.
  LWSCCD_UNROLL for (int i = 0; i < 3; ++i)
    LWSCCD_UNROLL for (int j = 0; j < 3; ++j)
      if (separated_along(detail::vcross(a.axis[i], b.axis[j]))) return false;
  return true;
}

}  // namespace lwsccd
