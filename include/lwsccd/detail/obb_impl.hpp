// lwsccd — definitions for obb.hpp.
#pragma once

#include "lwsccd/obb.hpp"

namespace lwsccd {

namespace detail {

template <class W>
LWSCCD_HD constexpr W abs_dot(const Vec3<W>& a, const Vec3<W>& b) {
  return std::fabs(a.x) * std::fabs(b.x) + std::fabs(a.y) * std::fabs(b.y) + std::fabs(a.z) * std::fabs(b.z);
}

// Orthonormal right-handed axes from the covariance of the points; identity when the points
// carry no direction (coincident points) or the solve degenerates.
template <class T, class U>
LWSCCD_HD void covariance_axes(const Vec3<U>* points, int n, Vec3<T> axis[3]) {
  using W = wider_t<T, U>;
  Vec3<W> mean{0, 0, 0};
  for (int i = 0; i < n; ++i) mean += points[i].template cast<W>();
  mean *= W(1) / W(n);
  SymMat3<W> c{0, 0, 0, 0, 0, 0};
  for (int i = 0; i < n; ++i) {
    const Vec3<W> d = points[i].template cast<W>() - mean;
    c.xx += d.x * d.x; c.yy += d.y * d.y; c.zz += d.z * d.z;
    c.xy += d.x * d.y; c.xz += d.x * d.z; c.yz += d.y * d.z;
  }
  const SymEigen3<W> eig = symmetric_eigen3(c);
  // Re-orthonormalize (Gram-Schmidt) in W, then round to T.
  Vec3<W> u0 = eig.vectors[0];
  W l0 = norm(u0);
  Vec3<W> u1 = eig.vectors[1];
  bool ok = l0 > W(0) && std::isfinite(l0);
  if (ok) {
    u0 *= W(1) / l0;
    u1 -= u0 * dot(u0, u1);
    const W l1 = norm(u1);
    ok = l1 > W(0) && std::isfinite(l1);
    if (ok) u1 *= W(1) / l1;
  }
  if (!ok) {
    u0 = {1, 0, 0};
    u1 = {0, 1, 0};
  }
  const Vec3<W> u2 = cross(u0, u1);
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

}  // namespace detail

template <class T>
template <class U>
LWSCCD_HD bool Obb<T>::contains(const Vec3<U>& p) const {
  using W = detail::wider_t<T, U>;
  const Vec3<W> d = p.template cast<W>() - center.template cast<W>();
  for (int i = 0; i < 3; ++i) {
    const Vec3<W> u = axis[i].template cast<W>();
    const W proj = std::fabs(dot(u, d));
    const W err = detail::projection_error_factor<W>() * detail::abs_dot(u, d);
    if (proj - err > W(half[i])) return false;
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
  for (int i = 0; i < 3; ++i) {
    lo[i] = std::numeric_limits<W>::max();
    hi[i] = std::numeric_limits<W>::lowest();
  }
  for (int k = 0; k < n; ++k) {
    const Vec3<W> p = points[k].template cast<W>();
    for (int i = 0; i < 3; ++i) {
      const W s = dot(box.axis[i].template cast<W>(), p);
      lo[i] = s < lo[i] ? s : lo[i];
      hi[i] = s > hi[i] ? s : hi[i];
    }
  }
  // The center only needs to be near the middle: the extents below are measured from the
  // stored (rounded) center, so its rounding costs nothing in correctness.
  Vec3<W> c{0, 0, 0};
  for (int i = 0; i < 3; ++i) c += box.axis[i].template cast<W>() * ((lo[i] + hi[i]) * W(0.5));
  box.center = c.template cast<T>();
  const Vec3<W> cw = box.center.template cast<W>();
  W ext[3] = {0, 0, 0};
  for (int k = 0; k < n; ++k) {
    const Vec3<W> d = points[k].template cast<W>() - cw;
    for (int i = 0; i < 3; ++i) {
      const Vec3<W> u = box.axis[i].template cast<W>();
      const W e = std::fabs(dot(u, d)) + detail::projection_error_factor<W>() * detail::abs_dot(u, d);
      ext[i] = e > ext[i] ? e : ext[i];
    }
  }
  for (int i = 0; i < 3; ++i) {
    // (1 + 4u) covers the rounding of the sum above; the tiny floor keeps a flat box closed.
    const W e = ext[i] * (W(1) + W(4) * detail::unit_roundoff<W>()) + std::numeric_limits<W>::denorm_min();
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
  // Support of a child along unit axis u: u.c +- sum_j safe_half_j |u . axis_j|.
  T lo[3], hi[3];
  const Obb* child[2] = {&a, &b};
  for (int i = 0; i < 3; ++i) {
    lo[i] = std::numeric_limits<T>::max();
    hi[i] = std::numeric_limits<T>::lowest();
    for (int k = 0; k < 2; ++k) {
      const Obb& ch = *child[k];
      const T mid = dot(box.axis[i], ch.center);
      T reach = T(0);
      for (int j = 0; j < 3; ++j) reach += ch.safe_half(j) * std::fabs(dot(box.axis[i], ch.axis[j]));
      lo[i] = mid - reach < lo[i] ? mid - reach : lo[i];
      hi[i] = mid + reach > hi[i] ? mid + reach : hi[i];
    }
  }
  Vec3<T> c{0, 0, 0};
  for (int i = 0; i < 3; ++i) c += box.axis[i] * ((lo[i] + hi[i]) * T(0.5));
  box.center = c;
  for (int i = 0; i < 3; ++i) {
    T ext = T(0), err = T(0);
    for (int k = 0; k < 2; ++k) {
      const Obb& ch = *child[k];
      const Vec3<T> d = ch.center - box.center;
      T reach = std::fabs(dot(box.axis[i], d));
      T mag = detail::abs_dot(box.axis[i], d);
      for (int j = 0; j < 3; ++j) {
        const T h = ch.safe_half(j);
        reach += h * std::fabs(dot(box.axis[i], ch.axis[j]));
        mag += h * detail::abs_dot(box.axis[i], ch.axis[j]);
      }
      ext = reach > ext ? reach : ext;
      err = mag > err ? mag : err;
    }
    // Rounding of the differences, dots, products and sums above: well under 16u of `err`.
    box.half[i] = std::nextafter(ext + T(16) * detail::unit_roundoff<T>() * err + std::numeric_limits<T>::denorm_min(),
                                 std::numeric_limits<T>::infinity());
  }
  return box;
}

template <class T>
LWSCCD_HD bool Obb<T>::overlap(const Obb& a, const Obb& b) {
  const Vec3<T> t = b.center - a.center;
  const T ha[3] = {a.safe_half(0), a.safe_half(1), a.safe_half(2)};
  const T hb[3] = {b.safe_half(0), b.safe_half(1), b.safe_half(2)};
  // Projects both boxes on l; separated only if the gap exceeds every rounding error made.
  auto separated_along = [&](const Vec3<T>& l) {
    T ra = T(0), rb = T(0), mag = detail::abs_dot(t, l);
    for (int i = 0; i < 3; ++i) {
      ra += ha[i] * std::fabs(dot(a.axis[i], l));
      rb += hb[i] * std::fabs(dot(b.axis[i], l));
      mag += ha[i] * detail::abs_dot(a.axis[i], l) + hb[i] * detail::abs_dot(b.axis[i], l);
    }
    const T gap = std::fabs(dot(t, l)) - (ra + rb);
    // The denorm term covers underflow in the products when l is tiny.
    return gap > T(16) * detail::unit_roundoff<T>() * mag + T(64) * std::numeric_limits<T>::denorm_min();
  };
  for (int i = 0; i < 3; ++i)
    if (separated_along(a.axis[i]) || separated_along(b.axis[i])) return false;
  // Edge-edge axes. A near-zero cross product (parallel edges) gives gap and bound both ~0 and
  // never separates, so no epsilon hack is needed for those.
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (separated_along(cross(a.axis[i], b.axis[j]))) return false;
  return true;
}

}  // namespace lwsccd
