// lwsccd — the certified path in single precision (FP32 first): the pair's points relative to a
// local origin, rounded to float, and the screen on them with bounds that cover that rounding as
// well as the float arithmetic; the double screen runs only on what it leaves (the
// single-precision filter: CertifiedFilter::decides_single, certified_filter.hpp).
// Part of certified_ccd.hpp: include <lwsccd/narrow_phase/certified_ccd.hpp>, not this file.
#pragma once

#include <cstdint>
#include <cstring>
#include <limits>
#include <type_traits>

#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/core/detail/rounding.hpp"
#include "lwsccd/narrow_phase/detail/certified_screen.hpp"

namespace lwsccd::detail {

/// A query in single precision for the FP32-first passes: its points relative to its first point
/// at t = 0, and `m`, a per-axis bound such that every coordinate of the exact relative query
/// (and of any query within the certified path's perturbation of the input) lies within
/// single_input_perturbation() m_k of the float one.
template <class Q>
struct SingleQuery {
  Q q;
  Vec3<float> m;
};

/// Each coordinate is rounded to float first (no double arithmetic: on most GPUs double runs at
/// 1/64 of float), then the first point subtracted in float. With x, o a coordinate and the
/// origin's, x_f = x (1 + d_1), o_f = o (1 + d_2), f = (x_f - o_f)(1 + d_3), |d_i| <= u_f:
///   |f - (x - o)| <= u_f (|x| + |o| + |x_f - o_f|) <= u_f / (1 - u_f) (2 a + r)
/// with a = the largest |x_f| on the axis (the float input's magnitude) and r = the largest |f|
/// (the relative query's). The certified path's own perturbation, u_T times the input's
/// magnitude, adds at most u_f a / (1 - u_f). So m = r + 3 a covers both with the perturbation
/// below (docs/NARROW_PHASE.md, B9). Contact is invariant under translation, so the exact answers
/// of the relative query and of the input are the same; float inputs lose nothing in the cast.
template <class Q>
LWSCCD_HD LWSCCD_HOST_INLINE auto relative_single(const Q& q_in) {
  const auto a = q_in.template cast<float>();
  using QF = std::decay_t<decltype(a)>;
  const Vec3<float>* x = a.points();
  const Vec3<float> o = x[0];
  QF r = a;
  Vec3<float>* out = const_cast<Vec3<float>*>(r.points());
  for (int i = 0; i < 8; ++i) out[i] = vsub(x[i], o);
  const Vec3<float> input = coordinate_magnitude(a), relative = coordinate_magnitude(r);
  return SingleQuery<QF>{r, vadd(relative, vscale(input, 3.0f))};
}

/// The pair relative to its first point with the differences taken in double, then rounded to
/// float: the query of the search in single precision (B12), which only pairs that reach the
/// refinement take, so its 24 double subtractions are few, and its bound does not grow with the
/// pair's distance from the origin as relative_single's does. With d = x - o computed in double
/// (error u_d |x - o|) and rounded to float (u_f), every exact relative coordinate is within
/// (u_f + 2 u_d)(1 + 2 u_f) r <= u_f (1 + 2^-21) r of the float one (r: the largest |f| on the
/// axis), and the certified path's perturbation of x and o, u_T |x| each, adds at most
/// 2 u_T (1 + u_f) a (a: the largest |x_f|). So m = r (1 + 2^-20) + 4 (u_T / u_f) a covers both
/// with single_input_perturbation() (u_f (1 + 2^-18)), with room for m's own rounding.
template <class Q>
LWSCCD_HD LWSCCD_HOST_INLINE auto relative_single_in_double(const Q& q_in) {
  using TIn = typename std::decay_t<decltype(*q_in.points())>::scalar_type;
  const auto d = q_in.template cast<double>();
  const auto a = q_in.template cast<float>();
  using QF = std::decay_t<decltype(a)>;
  QF r = a;
  const Vec3<double>* x = d.points();
  Vec3<float>* out = const_cast<Vec3<float>*>(r.points());
  for (int i = 0; i < 8; ++i)
    out[i] = {static_cast<float>(fsub(x[i].x, x[0].x)), static_cast<float>(fsub(x[i].y, x[0].y)),
              static_cast<float>(fsub(x[i].z, x[0].z))};
  // 4 u_T / u_f: 2^-27 for double input, 4 for float input.
  const float input_share = sizeof(TIn) == 8 ? exact_pow2_neg<float>(27) : 4.0f;
  const Vec3<float> input = coordinate_magnitude(a), relative = coordinate_magnitude(r);
  return SingleQuery<QF>{r, vadd(vscale(relative, 1.0f + exact_pow2_neg<float>(20)), vscale(input, input_share))};
}

/// The relative perturbation that covers relative_single's rounding: every exact relative
/// coordinate lies within this times m_k of its float. u_f (1 + 2^-18) covers the 1 / (1 - u_f)
/// and the rounding of m's own sum and product (each a factor 1 + u_f) with room.
/// Policy::kSingleInputBound scales it (1 = as derived; the mutation tests show that less is
/// unsound).
template <class Policy>
LWSCCD_HD LWSCCD_HOST_INLINE float single_input_perturbation() {
  const float u = unit_roundoff<float>();
  return fmul(fadd(u, u * exact_pow2_neg<float>(18)), static_cast<float>(Policy::kSingleInputBound));
}

/// Whether point i of a query (points() order) belongs to its first feature: the vertex of a
/// vertex-face query (p0, p1), the first edge of an edge-edge one (a0, b0, a1, b1).
template <class Q>
LWSCCD_HD LWSCCD_HOST_INLINE constexpr bool first_feature_point(int i) {
  return std::is_same<Q, VertexFaceQuery<float>>::value ? (i & 3) == 0 : (i & 3) < 2;
}

/// True when the two features of the single-precision query are apart for the whole step, by a
/// separating direction of their swept hulls (bound B13, docs/NARROW_PHASE.md): a point of a
/// moving feature at time t is a convex combination of its vertices at t, each of them one of
/// (1 - t) x0 + t x1, so it lies in the convex hull of the feature's points at t = 0 and t = 1,
/// and a direction d with max d.x over one hull's points below min d.y over the other's keeps the
/// features apart at every t. The directions tried join the features' centroids (of both times,
/// at t = 0, at t = 1): on the screen's survivors of cloth-ball and armadillo-rollers they
/// separated a quarter to two fifths before the screen tested the differences (B14), 1-3%
/// since. Each dot product is within (gamma_3 + perturbation) S of the exact one for the exact
/// relative query (S = |d| . m), the sums with E within u (|x| + E), so
/// E = (perturbation + 6 u) S, plus the smallest normal float for underflow, covers both
/// (Policy::kSeparationBound scales E: 1 = as derived; the mutation tests show that less is
/// unsound).
template <class Policy, class QF>
LWSCCD_HD LWSCCD_HOST_INLINE bool swept_hulls_apart(const SingleQuery<QF>& s, float perturbation) {
  const Vec3<float>* x = s.q.points();
  Vec3<float> first[2] = {{0.0f, 0.0f, 0.0f}, {0.0f, 0.0f, 0.0f}}, second[2] = {{0.0f, 0.0f, 0.0f}, {0.0f, 0.0f, 0.0f}};
  int first_count = 0;
  for (int i = 0; i < 8; ++i) {
    if (first_feature_point<QF>(i)) first[i >> 2] = vadd(first[i >> 2], x[i]), ++first_count;
    else second[i >> 2] = vadd(second[i >> 2], x[i]);
  }
  // Centroids up to a common factor per feature (the direction's length does not matter).
  const float first_scale = first_count == 2 ? 4.0f : 2.0f, second_scale = first_count == 2 ? 4.0f / 3.0f : 2.0f;
  const Vec3<float> d0 = vsub(vscale(second[0], second_scale), vscale(first[0], first_scale));
  const Vec3<float> d1 = vsub(vscale(second[1], second_scale), vscale(first[1], first_scale));
  const Vec3<float> directions[3] = {vadd(d0, d1), d0, d1};
  const float factor = fmul(fadd(perturbation, 6.0f * unit_roundoff<float>()), static_cast<float>(Policy::kSeparationBound));
  for (int k = 0; k < 3; ++k) {
    const Vec3<float>& d = directions[k];
    float high = -std::numeric_limits<float>::infinity(), low = std::numeric_limits<float>::infinity();
    bool finite = true;
    for (int i = 0; i < 8; ++i) {
      const float p = vdot(d, x[i]);
      finite = finite && finite_value(p);
      if (first_feature_point<QF>(i)) high = p > high ? p : high;
      else low = p < low ? p : low;
    }
    const float margin = fadd(fmul(factor, vabs_dot(d, s.m)), Policy::kSeparationBound > 0 ? std::numeric_limits<float>::min() : 0.0f);
    if (finite && finite_value(margin) && fadd(high, margin) < fsub(low, margin)) return true;
  }
  return false;
}

/// The parameters the single-precision passes read, in float, so that they need no double
/// arithmetic: the time limit rounded up (pruning only pieces that start at or after it stays
/// sound) and the tolerance rounded to nearest (its only use, declining tolerances of at least a
/// power of two, is monotone under rounding).
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE CcdParams<float> single_params(const CcdParams<T>& params) {
  CcdParams<float> s;
  s.min_separation = params.min_separation > T(0) ? 1.0f : 0.0f;  // (only its sign is read)
  s.tolerance = static_cast<float>(params.tolerance);
  s.max_iterations = params.max_iterations;
  s.mode = params.mode;
  s.time_limit = round_up<float>(params.time_limit);
  s.time_from = 0.0f;  // (not read by the single passes)
  return s;
}

/// The single-precision screen: true when the pair certainly never touches in the step (or
/// before params.time_limit), decided in float alone, with the double path's guarantee (for the
/// input as given and within its perturbation). The swept boxes and the cubic's Bernstein signs,
/// as the double screen tests them, on the relative float query with a perturbation covering its
/// rounding: a sign beyond the bound holds for every query within that perturbation, the exact
/// relative query among them. What it leaves goes to the double screen.
/// `mixed`, when given, is set when the double screen cannot reject the pair either (screen_with):
/// the cubic's signs on the whole step are certainly mixed.
template <class Policy, class Q, class T>
LWSCCD_HD bool certified_screen_single(const Q& q_in, const CcdParams<T>& params, bool* mixed = nullptr) {
  if (mixed) *mixed = false;
  if (params.min_separation > T(0)) return false;  // the cubic only speaks of contact
  const auto s = relative_single(q_in);
  return screen_with<Policy>(s.q, params, single_input_perturbation<Policy>(), s.m, mixed);
}

/// certified_screen_single in its two parts (screen_in_space, screen_by_cubic), on the relative
/// float query: certified_screen_single is true exactly when one of them is.
template <class Policy, class QF, class T>
LWSCCD_HD bool single_screen_in_space(const SingleQuery<QF>& s, const CcdParams<T>& params) {
  return !(params.min_separation > T(0)) && screen_in_space<Policy>(s.q, params, single_input_perturbation<Policy>(), s.m);
}
template <class Policy, class QF, class T>
LWSCCD_HD bool single_screen_by_cubic(const SingleQuery<QF>& s, const CcdParams<T>& params) {
  return !(params.min_separation > T(0)) && screen_by_cubic<Policy>(s.q, params, single_input_perturbation<Policy>(), s.m);
}

/// How the screen ended for a pair: a miss decided in single precision, one decided in double,
/// or passed on to the refinement.
enum class ScreenVerdict : std::uint8_t { single_miss, double_miss, passed };

/// The certified path's cheap first step, whole: in single precision first (Policy::kSingleFirst),
/// then in the path's own precision for what that leaves, unless single precision found the
/// cubic's signs certainly mixed (the double screen's cubic test cannot reject such a pair; its
/// box test is left to the refinement, which decides the pair whatever the screen says).
template <class Policy, class Q, class T>
LWSCCD_HD ScreenVerdict certified_screen_verdict(const Q& q, const CcdParams<T>& params) {
  bool mixed = false;
  if (Policy::kSingleFirst && certified_screen_single<Policy>(q, params, &mixed)) return ScreenVerdict::single_miss;
  if (!mixed && certified_screen_double<Policy>(q, params)) return ScreenVerdict::double_miss;
  return ScreenVerdict::passed;
}

/// True when the query is certainly a miss (before params.time_limit) by the screen.
template <class Policy, class Q, class T>
LWSCCD_HD bool certified_screen(const Q& q, const CcdParams<T>& params) {
  return certified_screen_verdict<Policy>(q, params) != ScreenVerdict::passed;
}

/// The screen as a batch runs it first, on every pair: single precision alone when
/// Policy::kSingleFirst (the single-precision filter, then certified_screen_after_single, take
/// what it leaves: the filter decides nearly every pair the double screen would, in float), else
/// the double screen. Most pairs of a real step end here.
template <class Policy, class Q, class T>
LWSCCD_HD ScreenVerdict certified_first_screen(const Q& q, const CcdParams<T>& params) {
  if (Policy::kSingleFirst) return certified_screen_single<Policy>(q, params) ? ScreenVerdict::single_miss : ScreenVerdict::passed;
  return certified_screen_double<Policy>(q, params) ? ScreenVerdict::double_miss : ScreenVerdict::passed;
}

/// The double screen on what the single-precision passes left (false without
/// Policy::kSingleFirst: the first screen was the double one).
template <class Policy, class Q, class T>
LWSCCD_HD bool certified_screen_after_single(const Q& q, const CcdParams<T>& params) {
  return Policy::kSingleFirst && certified_screen_double<Policy>(q, params);
}

}  // namespace lwsccd::detail
