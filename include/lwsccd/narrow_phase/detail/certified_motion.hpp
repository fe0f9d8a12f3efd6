// lwsccd — the certified path's view of the motion: differences of moving points over an interval
// with their error bounds, the cross terms of the coplanarity cubic, sign tests, and the
// inside verdicts (is the contact point inside the triangle / on both edges over an interval).
// Part of certified_ccd.hpp: include <lwsccd/narrow_phase/certified_ccd.hpp>, not this file.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/core/detail/rounding.hpp"
#include "lwsccd/narrow_phase/detail/certified_bernstein.hpp"

namespace lwsccd::detail {

/// A difference of two moving points over a time interval: its value at the interval's middle
/// and, per axis, bounds on how far the exact difference can be from it anywhere in the interval:
/// `error` for the query as given (rounding, motion within half the interval), `perturbed` also
/// for its inputs' perturbation.
template <class T>
struct MovingDifference {
  Vec3<T> value, error, perturbed;
};

template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE Vec3<T> lerp_point(const Vec3<T>& x0, const Vec3<T>& x1, T t) {
  return vadd_scaled(x0, vsub(x1, x0), t);
}

// y - x at time `mid`, within `half` of which the difference is wanted; m: the query's per-axis
// coordinate magnitude. Rounding: each point at `mid` is off by at most 9 u m (a difference, a
// product, a sum, of magnitudes at most 2 m, m and 3 m), the difference by 2 * 9 u m + u 2 m =
// 20 u m, taken as 32 u m; a relative perturbation p of the inputs adds 2 p m. Motion:
// d/dt (y - x) = dy - dx exactly (dx = x1 - x0), computed as fl(fl(dy) - fl(dx)) with error at
// most u (|dx| + |dy|) (1 + u) + u |dy - dx|, taken as 4 u (|dx| + |dy|) over |fl(...)| (1 + 2u);
// features moving together (a sheet falling along its normal) thus keep tight bounds. Over at
// most `half`, with the products' rounding in the (1 + 8 u).
// `given`: a perturbation the as-given error covers too (0: rounding alone). A query that is only
// an approximation of the input (single precision's, bound B9) passes its whole perturbation, so
// that what it claims "as given" holds for the input.
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE MovingDifference<T> moving_difference(const Vec3<T>& x0, const Vec3<T>& x1, const Vec3<T>& y0, const Vec3<T>& y1,
                                                T mid, T half, const Vec3<T>& m, T perturbation, T given = T(0)) {
  const Vec3<T> x = lerp_point(x0, x1, mid), y = lerp_point(y0, y1, mid);
  const Vec3<T> dx = vsub(x1, x0), dy = vsub(y1, y0);
  const T u = unit_roundoff<T>();
  const Vec3<T> motion = vadd(vscale(abs(vsub(dy, dx)), T(1) + T(2) * u), vscale(vadd(abs(dx), abs(dy)), T(4) * u));
  const Vec3<T> error = vadd(vscale(m, T(32) * u), vscale(motion, fmul(half, T(1) + T(8) * u)));
  const Vec3<T> as_given = given > T(0) ? vadd(error, vscale(m, T(2) * given)) : error;
  return {vsub(y, x), as_given, vadd(error, vscale(m, T(2) * perturbation))};
}

/// outside: no contact in the interval, even perturbed; outside_as_given: none for the query as
/// given, but a perturbed one may touch; inside: a root in the interval is a contact of the query
/// as given; unknown: none of these.
enum class InsideVerdict : std::uint8_t { outside, outside_as_given, inside, unknown };

/// X x Y for two moving differences, with the majorants |X| x |Y| (abs_cross) at the computed
/// values and at the values widened by their perturbed errors; as_given() widens them by their
/// as-given errors, which only a test that does not exclude reads (most exclude). A sign test is
/// the dot product of two of these, so terms shared by several tests are computed once.
template <class T>
struct CrossTerm {
  const MovingDifference<T>& x;
  const MovingDifference<T>& y;
  Vec3<T> value, majorant, perturbed;
  LWSCCD_HD LWSCCD_HOST_INLINE CrossTerm(const MovingDifference<T>& X, const MovingDifference<T>& Y) : x(X), y(Y) {
    value = vcross(X.value, Y.value);
    const Vec3<T> ax = abs(X.value), ay = abs(Y.value);
    majorant = abs_cross(ax, ay);
    perturbed = abs_cross(vadd(ax, X.perturbed), vadd(ay, Y.perturbed));
  }
  LWSCCD_HD LWSCCD_HOST_INLINE Vec3<T> as_given() const {
    return abs_cross(vadd(abs(x.value), x.error), vadd(abs(y.value), y.error));
  }
};

/// sigma = (X x Y) . (A x B) and bounds on |exact - computed| when the exact vectors are within
/// the given per-axis errors: the majorant difference M(|X| + eX, ...) - M(|X|, ...) bounds the
/// errors' effect (a degree-4 polynomial whose monomials have coefficients +-1), and
/// 32 u M(|X| + eX, ...) the rounding of sigma and of both majorants (depth 5: 3 gamma_5 < 16 u),
/// with room. The normal A x B is expanded rather than rounded first, so its error is counted.
/// `bound` (perturbed) first: a test certainly negative under it decides alone, and the as-given
/// bound is then not needed.
template <class Policy, class T>
struct SignTest {
  T sigma, bound, exact = T(0);
  bool finite;
  LWSCCD_HD LWSCCD_HOST_INLINE SignTest(const CrossTerm<T>& xy, const CrossTerm<T>& ab, T slack) {
    sigma = vdot(xy.value, ab.value);
    const T m0 = vdot(xy.majorant, ab.majorant), mp = vdot(xy.perturbed, ab.perturbed);
    const T k = T(Policy::kInsideBound), r = T(32) * unit_roundoff<T>();
    bound = fadd(fmul(k, fadd(fsub(mp, m0), fmul(r, mp))), slack);
    finite = finite_value(sigma) && finite_value(bound);
    if (excludes()) return;
    const T me = vdot(xy.as_given(), ab.as_given());
    exact = fadd(fmul(k, fadd(fsub(me, m0), fmul(r, me))), slack);
  }
  /// Certainly negative, even for a perturbed query (the values are finite, so nothing overflowed).
  LWSCCD_HD LWSCCD_HOST_INLINE bool excludes() const { return finite && sigma < -bound; }
};

/// Combines the sign tests that must all be >= 0 at a contact: outside when one is certainly
/// negative even under perturbation, inside when all are certainly positive for the query as given.
/// Tests are added one at a time and the caller stops at the first that excludes.
template <class T>
struct InsideVote {
  bool all_positive = true, some_negative_as_given = false, finite = true;
  /// Adds a test that must be >= 0 at a contact; true when it alone excludes the contact.
  template <class Test>
  LWSCCD_HD LWSCCD_HOST_INLINE bool add(const Test& t) {
    if (t.excludes()) return true;
    finite = finite && t.finite;
    all_positive = all_positive && t.sigma > t.exact;
    some_negative_as_given = some_negative_as_given || t.sigma < -t.exact;
    return false;
  }
  /// Adds a test that must be <= 0 at a contact, given negated: only its certain sign counts.
  template <class Test>
  LWSCCD_HD LWSCCD_HOST_INLINE bool add_exclusion(const Test& t) {
    if (t.excludes()) return true;
    finite = finite && t.finite;
    some_negative_as_given = some_negative_as_given || t.sigma < -t.exact;
    return false;
  }
  LWSCCD_HD LWSCCD_HOST_INLINE InsideVerdict verdict() const {
    if (!finite) return InsideVerdict::unknown;
    if (some_negative_as_given) return InsideVerdict::outside_as_given;
    return all_positive ? InsideVerdict::inside : InsideVerdict::unknown;
  }
};

/// Vertex-face inside test over [mid - half, mid + half]: at a time when p is in the triangle's
/// plane, p = a + u (b - a) + v (c - a) and the signs of u, v, 1 - u - v are those of
/// (P x B) . n, (A x P) . n and ((b - p) x (c - p)) . n, with n = A x B.
template <class Policy, class T>
LWSCCD_HD InsideVerdict inside_over(const VertexFaceQuery<T>& q, T mid, T half, const Vec3<T>& m, T perturbation,
                                    T slack, T given = T(0)) {
  const MovingDifference<T> P = moving_difference(q.a0, q.a1, q.p0, q.p1, mid, half, m, perturbation, given);
  const MovingDifference<T> A = moving_difference(q.a0, q.a1, q.b0, q.b1, mid, half, m, perturbation, given);
  const MovingDifference<T> B = moving_difference(q.a0, q.a1, q.c0, q.c1, mid, half, m, perturbation, given);
  const CrossTerm<T> n(A, B);
  InsideVote<T> vote;
  if (vote.add(SignTest<Policy, T>(CrossTerm<T>(P, B), n, slack))) return InsideVerdict::outside;
  if (vote.add(SignTest<Policy, T>(CrossTerm<T>(A, P), n, slack))) return InsideVerdict::outside;
  const MovingDifference<T> PB = moving_difference(q.p0, q.p1, q.b0, q.b1, mid, half, m, perturbation, given);
  const MovingDifference<T> PC = moving_difference(q.p0, q.p1, q.c0, q.c1, mid, half, m, perturbation, given);
  if (vote.add(SignTest<Policy, T>(CrossTerm<T>(PB, PC), n, slack))) return InsideVerdict::outside;
  return vote.verdict();
}

/// Edge-edge inside test: with P = c - a, A = b - a, B = d - c and n = A x B, coplanar lines meet
/// at a + u A = c + v B where u n = P x B and v n = P x A; 0 <= u, v <= 1 are the signs of
/// (P x B) . n, ((b - c) x B) . n, (P x A) . n and (A x (d - a)) . n. These all vanish for
/// parallel edges, so two more tests exclude without n: c and d strictly on one side of the line
/// ab, (A x (c - a)) . (A x (d - a)) > 0, means segment cd never meets that line (the component
/// of x - a normal to A moves along a segment between two vectors at an acute angle, never
/// through zero); likewise a and b against the line cd, (B x (a - c)) . (B x (b - c)) > 0. Negated
/// they reuse the other tests' terms: (P x A) . (A x (d - a)) and (P x B) . ((b - c) x B) < 0.
template <class Policy, class T>
LWSCCD_HD InsideVerdict inside_over(const EdgeEdgeQuery<T>& q, T mid, T half, const Vec3<T>& m, T perturbation,
                                    T slack, T given = T(0)) {
  // Each term is computed where a test first needs it: most intervals are excluded by the first
  // tests, and the values are the same whatever the order.
  const MovingDifference<T> P = moving_difference(q.a0, q.a1, q.c0, q.c1, mid, half, m, perturbation, given);
  const MovingDifference<T> A = moving_difference(q.a0, q.a1, q.b0, q.b1, mid, half, m, perturbation, given);
  const MovingDifference<T> B = moving_difference(q.c0, q.c1, q.d0, q.d1, mid, half, m, perturbation, given);
  const CrossTerm<T> n(A, B), pb(P, B);
  InsideVote<T> vote;
  if (vote.add(SignTest<Policy, T>(pb, n, slack))) return InsideVerdict::outside;
  const MovingDifference<T> CB = moving_difference(q.c0, q.c1, q.b0, q.b1, mid, half, m, perturbation, given);
  const CrossTerm<T> cbb(CB, B);
  if (vote.add(SignTest<Policy, T>(cbb, n, slack))) return InsideVerdict::outside;
  const CrossTerm<T> pa(P, A);
  if (vote.add(SignTest<Policy, T>(pa, n, slack))) return InsideVerdict::outside;
  const MovingDifference<T> AD = moving_difference(q.a0, q.a1, q.d0, q.d1, mid, half, m, perturbation, given);
  const CrossTerm<T> aad(A, AD);
  if (vote.add(SignTest<Policy, T>(aad, n, slack))) return InsideVerdict::outside;
  if (vote.add_exclusion(SignTest<Policy, T>(pa, aad, slack))) return InsideVerdict::outside;
  if (vote.add_exclusion(SignTest<Policy, T>(pb, cbb, slack))) return InsideVerdict::outside;
  return vote.verdict();
}

}  // namespace lwsccd::detail
