// lwsccd — the deforming non-penetration filters of Tang et al. 2010 (dissertation eq. 2.5).
//
// Both elemental tests reduce to a coplanarity function f(t) = P(t) . (A(t) x B(t)), cubic in t:
// vertex-face P = p - a, A = b - a, B = c - a; edge-edge P = c - a, A = b - a, B = d - c. Written
// in the cubic Bernstein basis its four control values bound f on [0, 1] (convex hull), so when
// all four share a sign the features are never coplanar during the step and cannot touch.
//
// Conservative under rounding: a value counts only if its magnitude exceeds a rigorous bound on
// its rounding error plus the effect of a relative perturbation of u_T on every input coordinate
// (a query rounded from more precise data). The filter only concerns contact: with a minimum
// separation > 0 it never culls. All arithmetic goes through detail/fp.hpp, so the host and the
// device cull exactly the same pairs.
#pragma once

#include <cmath>
#include <limits>
#include <type_traits>
#include <utility>

#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/core/detail/rounding.hpp"
#include "lwsccd/narrow_phase/ccd_query.hpp"

namespace lwsccd {

namespace detail {

/// The coplanarity function's ingredients: P, A, B at t = 0 and t = 1.
template <class T>
struct Coplanarity {
  Vec3<T> p0, p1, a0, a1, b0, b1;
};

template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE Coplanarity<T> coplanarity_of(const VertexFaceQuery<T>& q) {
  return {vsub(q.p0, q.a0), vsub(q.p1, q.a1), vsub(q.b0, q.a0), vsub(q.b1, q.a1), vsub(q.c0, q.a0), vsub(q.c1, q.a1)};
}
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE Coplanarity<T> coplanarity_of(const EdgeEdgeQuery<T>& q) {
  return {vsub(q.c0, q.a0), vsub(q.c1, q.a1), vsub(q.b0, q.a0), vsub(q.b1, q.a1), vsub(q.d0, q.c0), vsub(q.d1, q.c1)};
}

/// |a| x |b| componentwise: the majorant of a cross product.
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE Vec3<T> abs_cross(const Vec3<T>& a, const Vec3<T>& b) {
  return {fadd(fmul(a.y, b.z), fmul(a.z, b.y)), fadd(fmul(a.z, b.x), fmul(a.x, b.z)), fadd(fmul(a.x, b.y), fmul(a.y, b.x))};
}

/// Bernstein control values (scaled by positive factors) of f, and their majorants.
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE void bernstein_controls(const Coplanarity<T>& c, T k[4]) {
  const Vec3<T> n0 = vcross(c.a0, c.b0), n1 = vcross(c.a1, c.b1);
  const Vec3<T> nm = vadd(vcross(c.a0, c.b1), vcross(c.a1, c.b0));  // twice the middle control normal
  k[0] = vdot(c.p0, n0);
  k[1] = fadd(vdot(c.p0, nm), vdot(c.p1, n0));
  k[2] = fadd(vdot(c.p1, nm), vdot(c.p0, n1));
  k[3] = vdot(c.p1, n1);
}

template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE void bernstein_majorants(const Coplanarity<T>& c, T k[4]) {
  const Vec3<T> n0 = abs_cross(c.a0, c.b0), n1 = abs_cross(c.a1, c.b1);
  const Vec3<T> nm = vadd(abs_cross(c.a0, c.b1), abs_cross(c.a1, c.b0));
  k[0] = vdot(c.p0, n0);
  k[1] = fadd(vdot(c.p0, nm), vdot(c.p1, n0));
  k[2] = fadd(vdot(c.p1, nm), vdot(c.p0, n1));
  k[3] = vdot(c.p1, n1);
}

template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE Coplanarity<T> abs_plus(const Coplanarity<T>& c, const Vec3<T>& e) {
  return {vadd(abs(c.p0), e), vadd(abs(c.p1), e), vadd(abs(c.a0), e), vadd(abs(c.a1), e), vadd(abs(c.b0), e), vadd(abs(c.b1), e)};
}

/// Largest coordinate magnitude per axis over the query's eight points.
template <class Q>
LWSCCD_HD LWSCCD_HOST_INLINE auto coordinate_magnitude(const Q& q) {
  const auto* pts = q.points();
  using T = typename std::decay_t<decltype(*pts)>::scalar_type;
  Vec3<T> m{0, 0, 0};
  for (int i = 0; i < 8; ++i) m = max(m, abs(pts[i]));
  return m;
}

}  // namespace detail

namespace detail {

/// The Bernstein coefficients b[0..3] of the coplanarity cubic on [0, 1] and a rigorous bound on
/// their error: rounding in T, and a relative perturbation `perturbation` (default u_T) of every
/// input coordinate (the certified path computes a float query in double with u_float here).
/// `rounding_only`, when given, receives the bound without the perturbation (the error of the
/// coefficients for the query exactly as given). `magnitude`, when given, replaces the query's
/// coordinate magnitude in the perturbation (any per-axis bound at least as large).
template <class Q, class T>
LWSCCD_HD T coplanarity_bernstein(const Q& q, T b[4], T perturbation = unit_roundoff<T>(), T* rounding_only = nullptr,
                                  const Vec3<T>* magnitude = nullptr) {
  const Coplanarity<T> c = coplanarity_of(q);
  T k[4], mag[4], mag_perturbed[4];
  bernstein_controls(c, k);
  bernstein_majorants(abs_plus(c, Vec3<T>{0, 0, 0}), mag);
  // A difference of two coordinates moves by at most 2 u m under the input perturbation.
  const T u = unit_roundoff<T>();
  const Vec3<T> e = vscale(magnitude ? *magnitude : coordinate_magnitude(q), T(2) * perturbation);
  bernstein_majorants(abs_plus(c, e), mag_perturbed);
  T bound = T(0), rounding = T(0);
  for (int i = 0; i < 4; ++i) {
    // Perturbation effect (majorant difference) plus rounding (depth ~8 -> 16u of the majorant).
    const T bi = fadd(fmul(fsub(mag_perturbed[i], mag[i]), T(1) + T(8) * u), fmul(T(16) * u, mag_perturbed[i]));
    bound = bi > bound ? bi : bound;
    const T ri = fmul(T(16) * u, mag[i]);
    rounding = ri > rounding ? ri : rounding;
  }
  if (rounding_only) *rounding_only = fadd(rounding, std::numeric_limits<T>::denorm_min());
  // k[1], k[2] are three times the middle Bernstein coefficients; dividing keeps the bound valid.
  b[0] = k[0];
  b[1] = k[1] / T(3);
  b[2] = k[2] / T(3);
  b[3] = k[3];
  return fadd(bound, std::numeric_limits<T>::denorm_min());
}

/// True when the four values share a strict sign beyond `bound`.
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE bool same_sign_beyond(const T b[4], T bound) {
  const bool positive = b[0] > bound && b[1] > bound && b[2] > bound && b[3] > bound;
  const bool negative = b[0] < -bound && b[1] < -bound && b[2] < -bound && b[3] < -bound;
  return positive || negative;
}

}  // namespace detail

/// True when the pair may touch during the step; false only when the non-penetration filter
/// proves it cannot (rigorously, see the file comment).
template <class Q, class T>
LWSCCD_HD bool non_penetration_filter(const Q& q, const CcdParams<T>& params) {
  if (params.min_separation > T(0)) return true;
  T b[4];
  const T bound = detail::coplanarity_bernstein(q, b);
  return !detail::same_sign_beyond(b, bound);
}

/// The name a filtered method reports (methods specialize it, e.g. "filtered-inclusion").
template <class Method>
struct filtered_name {
  static constexpr const char* value = "filtered";
};

/// Any method behind the non-penetration filter: pairs the filter proves separate are answered
/// "no collision" without running the method.
namespace detail {
template <class M, class = void>
struct has_quick_reject : std::false_type {};
template <class M>
struct has_quick_reject<M, std::void_t<decltype(M::quick_reject(std::declval<const VertexFaceQuery<float>&>(),
                                                                 std::declval<const CcdParams<float>&>()))>>
    : std::true_type {};
}  // namespace detail

template <class Method>
struct Filtered {
  static constexpr const char* name = filtered_name<Method>::value;
  static constexpr bool conservative = Method::conservative;
  /// The filter, then the method's own first step when it has one (see InclusionCcd).
  template <class Q, class T>
  LWSCCD_HD static bool quick_reject(const Q& q, const CcdParams<T>& params) {
    if (!non_penetration_filter(q, params)) return true;
    if constexpr (detail::has_quick_reject<Method>::value) return Method::quick_reject(q, params);
    return false;
  }
  template <class T>
  LWSCCD_HD static CcdResult<T> vertex_face(const VertexFaceQuery<T>& q, const CcdParams<T>& params) {
    return non_penetration_filter(q, params) ? Method::vertex_face(q, params) : CcdResult<T>{};
  }
  template <class T>
  LWSCCD_HD static CcdResult<T> edge_edge(const EdgeEdgeQuery<T>& q, const CcdParams<T>& params) {
    return non_penetration_filter(q, params) ? Method::edge_edge(q, params) : CcdResult<T>{};
  }
};

}  // namespace lwsccd
