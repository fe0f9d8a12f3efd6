// lwsccd — the seed's elemental test (Provot 1997; dissertation 2.3.2): roots of the coplanarity
// cubic on [0, 1] by Newton-Raphson safeguarded with bisection (Press et al., rtsafe), then an
// inside test (distance at the root within the tolerance) at each root in time order.
//
// Not conservative: roots can be lost to rounding, and motions that stay coplanar (f == 0 over
// an interval) have no isolated root, so such contacts are missed. InclusionCcd is the method
// that never misses; this one is fast and is kept as the baseline the dissertation used.
#pragma once

#include <cmath>

#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/narrow_phase/ccd_filters.hpp"
#include "lwsccd/narrow_phase/ccd_query.hpp"
#include "lwsccd/narrow_phase/detail/distance.hpp"

namespace lwsccd {

namespace detail {

/// Coefficients c0 + c1 t + c2 t^2 + c3 t^3 of f(t) = P(t) . (A(t) x B(t)).
template <class T>
LWSCCD_HD void coplanarity_cubic(const Coplanarity<T>& c, T coef[4]) {
  const Vec3<T> vp = vsub(c.p1, c.p0), va = vsub(c.a1, c.a0), vb = vsub(c.b1, c.b0);
  const Vec3<T> n0 = vcross(c.a0, c.b0), n1 = vadd(vcross(c.a0, vb), vcross(va, c.b0)), n2 = vcross(va, vb);
  coef[0] = vdot(c.p0, n0);
  coef[1] = fadd(vdot(c.p0, n1), vdot(vp, n0));
  coef[2] = fadd(vdot(c.p0, n2), vdot(vp, n1));
  coef[3] = vdot(vp, n2);
}

template <class T>
LWSCCD_HD T cubic_value(const T c[4], T t) {
  return fadd(fmul(fadd(fmul(fadd(fmul(c[3], t), c[2]), t), c[1]), t), c[0]);
}
template <class T>
LWSCCD_HD T cubic_slope(const T c[4], T t) {
  return fadd(fmul(fadd(fmul(fmul(T(3), c[3]), t), fmul(T(2), c[2])), t), c[1]);
}

/// Root of the cubic in [lo, hi] where f(lo), f(hi) differ in sign (Press et al., rtsafe).
template <class T>
LWSCCD_HD T safeguarded_newton(const T c[4], T lo, T hi, T f_lo, T tolerance) {
  if (f_lo > T(0)) {  // orient so that f(lo) < 0
    const T tmp = lo;
    lo = hi;
    hi = tmp;
  }
  T x = fmul(fadd(lo, hi), T(0.5));
  T dx_old = std::fabs(fsub(hi, lo)), dx = dx_old;
  T f = cubic_value(c, x), df = cubic_slope(c, x);
  for (int it = 0; it < 100; ++it) {
    const bool newton_leaves = fsub(fmul(fsub(x, hi), df), f) * fsub(fmul(fsub(x, lo), df), f) > T(0);
    if (newton_leaves || std::fabs(fmul(T(2), f)) > std::fabs(fmul(dx_old, df))) {
      dx_old = dx;
      dx = fmul(fsub(hi, lo), T(0.5));
      x = fadd(lo, dx);
    } else {
      dx_old = dx;
      dx = f / df;
      x = fsub(x, dx);
    }
    if (std::fabs(dx) < fmul(tolerance, T(0.5))) break;
    f = cubic_value(c, x);
    df = cubic_slope(c, x);
    if (f == T(0)) break;
    if (f < T(0)) lo = x;
    else hi = x;
  }
  return x;
}

/// Roots of the cubic in [0, 1], ascending; returns their count (at most 3).
template <class T>
LWSCCD_HD int cubic_roots_01(const T c[4], T tolerance, T roots[3]) {
  // Split [0, 1] at the critical points (roots of 3 c3 t^2 + 2 c2 t + c1) into monotone pieces.
  T cuts[4] = {T(0), T(1), T(1), T(1)};
  int ncuts = 1;
  const T qa = fmul(T(3), c[3]), qb = fmul(T(2), c[2]), qc = c[1];
  T crit[2];
  int ncrit = 0;
  if (qa != T(0)) {
    const T disc = fsub(fmul(qb, qb), fmul(fmul(T(4), qa), qc));
    if (disc >= T(0)) {
      const T sq = std::sqrt(disc);
      const T q = fmul(T(-0.5), fadd(qb, qb >= T(0) ? sq : -sq));  // stable quadratic formula
      if (q != T(0)) crit[ncrit++] = qc / q;
      crit[ncrit++] = q / qa;
    }
  } else if (qb != T(0)) {
    crit[ncrit++] = -qc / qb;
  }
  if (ncrit == 2 && crit[0] > crit[1]) {
    const T tmp = crit[0];
    crit[0] = crit[1];
    crit[1] = tmp;
  }
  for (int i = 0; i < ncrit; ++i)
    if (crit[i] > T(0) && crit[i] < T(1)) cuts[ncuts++] = crit[i];
  cuts[ncuts++] = T(1);
  int n = 0;
  T f_lo = cubic_value(c, T(0));
  for (int i = 0; i + 1 < ncuts && n < 3; ++i) {
    const T lo = cuts[i], hi = cuts[i + 1];
    const T f_hi = cubic_value(c, hi);
    if (f_lo == T(0)) {
      if (n == 0 || roots[n - 1] != lo) roots[n++] = lo;
    } else if ((f_lo < T(0)) != (f_hi < T(0)) && f_hi != T(0)) {
      roots[n++] = safeguarded_newton(c, lo, hi, f_lo, tolerance);
    }
    f_lo = f_hi;
  }
  if (n < 3 && f_lo == T(0) && (n == 0 || roots[n - 1] != T(1))) roots[n++] = T(1);
  return n;
}

template <class T>
LWSCCD_HD Vec3<T> at_time(const Vec3<T>& x0, const Vec3<T>& x1, T t) {
  return vadd_scaled(x0, vsub(x1, x0), t);
}

}  // namespace detail

/// The seed's method as a policy (see the file comment).
struct CubicCcd {
  static constexpr const char* name = "cubic";
  static constexpr bool conservative = false;

  template <class T>
  LWSCCD_HD static CcdResult<T> vertex_face(const VertexFaceQuery<T>& q, const CcdParams<T>& params) {
    T coef[4], roots[3];
    detail::coplanarity_cubic(detail::coplanarity_of(q), coef);
    const int n = detail::cubic_roots_01(coef, params.tolerance, roots);
    for (int i = 0; i < n; ++i) {
      const T t = roots[i];
      const Vec3<T> p = detail::at_time(q.p0, q.p1, t), a = detail::at_time(q.a0, q.a1, t),
                    b = detail::at_time(q.b0, q.b1, t), c = detail::at_time(q.c0, q.c1, t);
      const T eta = inside_tolerance(a, b, c, params);
      if (detail::point_triangle_distance2(p, a, b, c) <= detail::fmul(eta, eta)) return {true, t, false};
    }
    return {};
  }

  template <class T>
  LWSCCD_HD static CcdResult<T> edge_edge(const EdgeEdgeQuery<T>& q, const CcdParams<T>& params) {
    T coef[4], roots[3];
    detail::coplanarity_cubic(detail::coplanarity_of(q), coef);
    const int n = detail::cubic_roots_01(coef, params.tolerance, roots);
    for (int i = 0; i < n; ++i) {
      const T t = roots[i];
      const Vec3<T> a = detail::at_time(q.a0, q.a1, t), b = detail::at_time(q.b0, q.b1, t),
                    c = detail::at_time(q.c0, q.c1, t), d = detail::at_time(q.d0, q.d1, t);
      const T eta = inside_tolerance(a, b, c, params, &d);
      if (detail::segment_segment_distance2(a, b, c, d) <= detail::fmul(eta, eta)) return {true, t, false};
    }
    return {};
  }

 private:
  // Distance accepted as contact at a root: the tolerance relative to the features' size, or the
  // minimum separation if larger.
  template <class T>
  LWSCCD_HD static T inside_tolerance(const Vec3<T>& a, const Vec3<T>& b, const Vec3<T>& c, const CcdParams<T>& params,
                                      const Vec3<T>* d = nullptr) {
    const Vec3<T> e0 = detail::vsub(b, a), e1 = detail::vsub(c, a);
    T size = max_component(abs(e0));
    size = size > max_component(abs(e1)) ? size : max_component(abs(e1));
    if (d) {
      const T e2 = max_component(abs(detail::vsub(*d, c)));
      size = size > e2 ? size : e2;
    }
    const T eta = detail::fmul(params.tolerance, size);
    return eta > params.min_separation ? eta : params.min_separation;
  }
};

template <>
struct filtered_name<CubicCcd> {
  static constexpr const char* value = "filtered-cubic";
};

}  // namespace lwsccd
