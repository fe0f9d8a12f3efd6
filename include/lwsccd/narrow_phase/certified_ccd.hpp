// lwsccd — a certified floating-point fast path for the elemental CCD tests, and the method
// that puts it in front of a conservative fallback (CertifiedCcd).
//
// Exact predicates with a floating-point filter (in the spirit of Shewchuk): every decision is a
// sign of a computed value beyond a rigorous bound on that value's error, so the answer holds for
// the query as given and for every relative perturbation of u (unit roundoff) of its coordinates.
// Three outcomes:
//   miss       the features certainly never touch in [0, 1];
//   hit        they certainly touch, and their earliest contact time lies in [lo, hi] with
//              hi - lo <= tolerance (so lo is a lower bound of the time of impact);
//   undecided  anything the bounds cannot settle (motion that stays coplanar, parallel edges,
//              degenerate triangles, a root at a grid point, a minimum separation > 0, overflow):
//              the caller runs the conservative search instead.
//
// How. A contact happens only at a root of the coplanarity cubic f(t) = P(t) . (A(t) x B(t))
// (ccd_filters.hpp). Its Bernstein coefficients on [0, 1] come with a bound E on their error, so
// the exact f lies within E of the polynomial they define. The step is cut, earliest part first,
// into dyadic intervals (de Casteljau halves, whose rounding adds to the bound): an interval whose
// coefficients share a sign beyond the bound holds no root; the others are halved down to the time
// tolerance. On such a root interval the inside test (barycentric signs for vertex-face, segment
// parameters for edge-edge, all as sign tests of degree-4 polynomials) is bounded over the whole
// interval: certainly outside means no contact there, so the search goes on; certainly inside
// with a certain sign change of f across the interval is the contact. docs/NARROW_PHASE.md derives
// the bounds.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/core/detail/rounding.hpp"
#include "lwsccd/narrow_phase/ccd_filters.hpp"
#include "lwsccd/narrow_phase/ccd_query.hpp"
#include "lwsccd/narrow_phase/inclusion_ccd.hpp"

namespace lwsccd {

/// Tuning knobs of the certified fast path.
struct CertifiedPolicy {
  static constexpr int kMaxSplits = 96;  ///< interval halvings before a query is left undecided
  static constexpr int kMaxLeaves = 6;   ///< root intervals (at the time tolerance) examined, at most
  /// The inside test also runs on wider intervals that may hold a root, every this many levels
  /// from [0, 1]: features apart in space are excluded there instead of after a descent to the
  /// tolerance (0: at root intervals only).
  static constexpr int kInsideEvery = 4;
  static constexpr int kInsideFrom = 3;  ///< the first level of those tests
  /// Multipliers of the three error bounds (1 = as derived). Only the mutation tests change them:
  /// any value below 1 is unsound, and those tests show it.
  static constexpr double kCoefficientBound = 1.0;  ///< the cubic's Bernstein coefficients on [0, 1]
  static constexpr double kSplitBound = 1.0;        ///< rounding added by each de Casteljau halving
  static constexpr double kInsideBound = 1.0;       ///< the inside test's sign tests over an interval
  /// Mode earliest: the certified pass (and its fallback) first look only at the window
  /// [0, 2^-kEarliestFirst), then at windows kEarliestStep binary orders wider, up to the whole
  /// step, and stop at the first window that holds a contact. A step's earliest contact is
  /// usually early, and a search limited to a short window drops nearly all of each pair's time at
  /// once. The windows are fixed, so the answer does not depend on the order of work.
  static constexpr int kEarliestFirst = 16;
  static constexpr int kEarliestStep = 8;
  /// Certain descent: an interval that is certainly inside and over which every perturbed cubic
  /// has exactly one root is narrowed to the tolerance by halvings that keep only the half holding
  /// the root, decided by the sign of f at the middle alone (no stack, no more inside tests).
  static constexpr bool kCertainDescent = true;
  /// Whether a refinement stopped at a defer level (a GPU batch's first pass) may still run the
  /// certain descent, which goes below that level but costs only the halvings.
  static constexpr bool kDescentBeforeDefer = true;
  /// Look-ahead: at the inside-test levels an interval whose halves both keep one sign beyond
  /// their perturbed bounds is dropped without the inside test (no perturbed root lies in it).
  static constexpr bool kLookAhead = false;
  /// A query the search cannot decide, with every time before its lower bound excluded, is a hit
  /// at that bound when the inclusion test accepts a small box within the tolerance after it
  /// (detail::tolerance_contact): the contacts on a feature's boundary that no sign decides.
  static constexpr bool kToleranceContacts = true;
};

/// What the certified fast path decided about one query.
enum class Certainty : std::uint8_t { miss, hit, undecided };

template <class T>
struct CertifiedAnswer {
  Certainty certainty = Certainty::undecided;
  T lo = T(0), hi = T(1);  ///< hit: the earliest contact time lies in [lo, hi]
  /// hit: contact within the tolerance after lo (a box of [lo, hi] that the inclusion test
  /// accepts; Policy::kToleranceContacts), not a certain one - the fallback's kind of answer.
  bool tolerance = false;
};

namespace detail {

/// 2^-k for 0 <= k <= 120, built from its bits: exact, and no call (std::ldexp was a libm call on
/// the host, in the refinement's inner loop). x * exact_pow2_neg<T>(k) equals std::ldexp(x, -k)
/// wherever that does not underflow, which the refinement's dyadic times never do.
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE T exact_pow2_neg(int k) {
  static_assert(sizeof(T) == 8 || sizeof(T) == 4, "lwsccd: exact_pow2_neg is for float and double");
  T r;
  if constexpr (sizeof(T) == 8) {
    const std::uint64_t bits = static_cast<std::uint64_t>(1023 - k) << 52;
    std::memcpy(&r, &bits, sizeof r);
  } else {
    const std::uint32_t bits = static_cast<std::uint32_t>(127 - k) << 23;
    std::memcpy(&r, &bits, sizeof r);
  }
  return r;
}

/// Bound on what underflow can add to a degree-`d` product expression of values up to `mag`:
/// each operation loses at most a denormal, later multiplied by at most d - 1 factors.
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE T underflow_slack(T mag, int degree) {
  T s = T(64) * std::numeric_limits<T>::denorm_min();
  const T f = fadd(T(1), mag);
  for (int i = 1; i < degree; ++i) s = fmul(s, f);
  return s;
}

template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE bool finite_value(T x) {
  return x - x == T(0);  // false for NaN and infinities
}

/// The four Bernstein coefficients of the cubic on a dyadic interval and two bounds on their
/// error: `bound` covers rounding and the inputs' perturbation (what may be excluded), `exact`
/// rounding alone (what the query as given certainly does).
template <class T>
struct BernsteinPiece {
  T c[4];
  T bound, exact;
};

/// Halves a piece by de Casteljau at 1/2. Each average rounds once (|error| <= u max|c|, halving
/// is exact but for underflow); the innermost value goes through three: 3 u max|c| per halving.
template <class Policy, class T>
LWSCCD_HD LWSCCD_HOST_INLINE void bernstein_halves(const BernsteinPiece<T>& p, BernsteinPiece<T>& left, BernsteinPiece<T>& right) {
  const T h = T(0.5);
  const T m01 = fmul(fadd(p.c[0], p.c[1]), h), m12 = fmul(fadd(p.c[1], p.c[2]), h), m23 = fmul(fadd(p.c[2], p.c[3]), h);
  const T m012 = fmul(fadd(m01, m12), h), m123 = fmul(fadd(m12, m23), h);
  const T mid = fmul(fadd(m012, m123), h);
  T big = T(0);
  for (int i = 0; i < 4; ++i) big = std::fabs(p.c[i]) > big ? std::fabs(p.c[i]) : big;
  const T added = fmul(T(Policy::kSplitBound),
                       fadd(fmul(T(4) * unit_roundoff<T>(), big), T(4) * std::numeric_limits<T>::denorm_min()));
  const T bound = fadd(p.bound, added), exact = fadd(p.exact, added);
  left = {{p.c[0], m01, m012, mid}, bound, exact};
  right = {{mid, m123, m23, p.c[3]}, bound, exact};
}

/// -1, 0 or 1: the sign of x when |x| > bound, else 0.
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE int sign_beyond(T x, T bound) {
  return x > bound ? 1 : (x < -bound ? -1 : 0);
}

/// True when every cubic whose Bernstein coefficients lie within `bound` of c has exactly one root
/// in the interval: the end values have certain, opposite signs, and the coefficients change sign
/// once whatever the uncertain middle ones are (c1 certainly of c0's sign, or c2 of c3's), so by
/// Descartes' rule for the Bernstein basis there is at most one root, and an odd number.
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE bool single_crossing(const T c[4], T bound) {
  const int first = sign_beyond(c[0], bound), last = sign_beyond(c[3], bound);
  if (first == 0 || last != -first) return false;
  return sign_beyond(c[1], bound) == first || sign_beyond(c[2], bound) == last;
}

/// True when both halves of the piece keep one sign beyond their perturbed bound: no perturbed
/// cubic has a root in it, so no inside test is needed there.
template <class Policy, class T>
LWSCCD_HD LWSCCD_HOST_INLINE bool halves_keep_sign(const BernsteinPiece<T>& p) {
  BernsteinPiece<T> left, right;
  bernstein_halves<Policy>(p, left, right);
  return same_sign_beyond(left.c, left.bound) && same_sign_beyond(right.c, right.bound);
}

template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE bool all_within(const T c[4], T bound) {
  return std::fabs(c[0]) <= bound && std::fabs(c[1]) <= bound && std::fabs(c[2]) <= bound && std::fabs(c[3]) <= bound;
}

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
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE MovingDifference<T> moving_difference(const Vec3<T>& x0, const Vec3<T>& x1, const Vec3<T>& y0, const Vec3<T>& y1,
                                                T mid, T half, const Vec3<T>& m, T perturbation) {
  const Vec3<T> x = lerp_point(x0, x1, mid), y = lerp_point(y0, y1, mid);
  const Vec3<T> dx = vsub(x1, x0), dy = vsub(y1, y0);
  const T u = unit_roundoff<T>();
  const Vec3<T> motion = vadd(vscale(abs(vsub(dy, dx)), T(1) + T(2) * u), vscale(vadd(abs(dx), abs(dy)), T(4) * u));
  const Vec3<T> error = vadd(vscale(m, T(32) * u), vscale(motion, fmul(half, T(1) + T(8) * u)));
  return {vsub(y, x), error, vadd(error, vscale(m, T(2) * perturbation))};
}

/// outside: no contact in the interval, even perturbed; outside_as_given: none for the query as
/// given, but a perturbed one may touch; inside: a root in the interval is a contact of the query
/// as given; unknown: none of these.
enum class InsideVerdict : std::uint8_t { outside, outside_as_given, inside, unknown };

/// X x Y for two moving differences, with the majorants |X| x |Y| (abs_cross) at the computed
/// values, at the values widened by their as-given errors, and by their perturbed errors. A sign
/// test is the dot product of two of these, so terms shared by several tests are computed once.
template <class T>
struct CrossTerm {
  Vec3<T> value, majorant, as_given, perturbed;
  LWSCCD_HD LWSCCD_HOST_INLINE CrossTerm(const MovingDifference<T>& X, const MovingDifference<T>& Y) {
    value = vcross(X.value, Y.value);
    const Vec3<T> ax = abs(X.value), ay = abs(Y.value);
    majorant = abs_cross(ax, ay);
    as_given = abs_cross(vadd(ax, X.error), vadd(ay, Y.error));
    perturbed = abs_cross(vadd(ax, X.perturbed), vadd(ay, Y.perturbed));
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
    const T me = vdot(xy.as_given, ab.as_given);
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
                                    T slack) {
  const MovingDifference<T> P = moving_difference(q.a0, q.a1, q.p0, q.p1, mid, half, m, perturbation);
  const MovingDifference<T> A = moving_difference(q.a0, q.a1, q.b0, q.b1, mid, half, m, perturbation);
  const MovingDifference<T> B = moving_difference(q.a0, q.a1, q.c0, q.c1, mid, half, m, perturbation);
  const CrossTerm<T> n(A, B);
  InsideVote<T> vote;
  if (vote.add(SignTest<Policy, T>(CrossTerm<T>(P, B), n, slack))) return InsideVerdict::outside;
  if (vote.add(SignTest<Policy, T>(CrossTerm<T>(A, P), n, slack))) return InsideVerdict::outside;
  const MovingDifference<T> PB = moving_difference(q.p0, q.p1, q.b0, q.b1, mid, half, m, perturbation);
  const MovingDifference<T> PC = moving_difference(q.p0, q.p1, q.c0, q.c1, mid, half, m, perturbation);
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
                                    T slack) {
  const MovingDifference<T> P = moving_difference(q.a0, q.a1, q.c0, q.c1, mid, half, m, perturbation);
  const MovingDifference<T> A = moving_difference(q.a0, q.a1, q.b0, q.b1, mid, half, m, perturbation);
  const MovingDifference<T> B = moving_difference(q.c0, q.c1, q.d0, q.d1, mid, half, m, perturbation);
  const MovingDifference<T> CB = moving_difference(q.c0, q.c1, q.b0, q.b1, mid, half, m, perturbation);
  const MovingDifference<T> AD = moving_difference(q.a0, q.a1, q.d0, q.d1, mid, half, m, perturbation);
  const CrossTerm<T> n(A, B), pb(P, B), cbb(CB, B), pa(P, A), aad(A, AD);
  InsideVote<T> vote;
  if (vote.add(SignTest<Policy, T>(pb, n, slack))) return InsideVerdict::outside;
  if (vote.add(SignTest<Policy, T>(cbb, n, slack))) return InsideVerdict::outside;
  if (vote.add(SignTest<Policy, T>(pa, n, slack))) return InsideVerdict::outside;
  if (vote.add(SignTest<Policy, T>(aad, n, slack))) return InsideVerdict::outside;
  if (vote.add_exclusion(SignTest<Policy, T>(pa, aad, slack))) return InsideVerdict::outside;
  if (vote.add_exclusion(SignTest<Policy, T>(pb, cbb, slack))) return InsideVerdict::outside;
  return vote.verdict();
}

/// The cubic's Bernstein coefficients on [0, 1] (in b) and a cheap, looser bound on their error:
/// the majorant of every coefficient has at most 18 monomials |p_i| |a_j| |b_k| (k_1 and k_2 are
/// three times the middle coefficients), each at most M_P M_A M_B with M the largest |coordinate|
/// of the difference vectors at t = 0 and t = 1. So coplanarity_bernstein's bound, (majorant
/// change under the perturbation e) (1 + 8 u) + 16 u (perturbed majorant), is at most 18 times
/// that expression for the product M_P M_A M_B (a polynomial with positive coefficients grows most
/// at the largest arguments); (1 + 16 u) covers rounding this bound. Most pairs that reach the
/// cubic are rejected by it, for a third of the operations of the full bound.
template <class Q, class W>
LWSCCD_HD LWSCCD_HOST_INLINE W screening_bernstein(const Q& q, W b[4], const Vec3<W>& m, W perturbation) {
  const Coplanarity<W> c = coplanarity_of(q);
  W k[4];
  bernstein_controls(c, k);
  b[0] = k[0];
  b[1] = k[1] / W(3);
  b[2] = k[2] / W(3);
  b[3] = k[3];
  const W mp = max_component(max(abs(c.p0), abs(c.p1))), ma = max_component(max(abs(c.a0), abs(c.a1)));
  const W mb = max_component(max(abs(c.b0), abs(c.b1))), e = fmul(max_component(m), W(2) * perturbation);
  const W u = unit_roundoff<W>();
  const W pe = fadd(mp, e), ae = fadd(ma, e), be = fadd(mb, e);
  const W grown = fmul(fmul(pe, ae), be);  // (M_P + e)(M_A + e)(M_B + e)
  // (M_P + e)(M_A + e)(M_B + e) - M_P M_A M_B as a sum of positive terms (no cancellation).
  const W change = fadd(fadd(fmul(e, fmul(ae, be)), fmul(mp, fmul(e, be))), fmul(mp, fmul(ma, e)));
  const W bound = fadd(fmul(change, W(1) + W(8) * u), fmul(W(16) * u, grown));
  return fadd(fmul(fmul(W(18), bound), W(1) + W(16) * u), std::numeric_limits<W>::denorm_min());
}

/// The finest level of the time intervals: width 2^-level <= tolerance / 2, so that a root
/// interval may span two of them.
template <class T>
LWSCCD_HD int certified_max_level(T tolerance) {
  int level = static_cast<int>(std::ceil(-std::log2(static_cast<double>(tolerance)))) + 1;
  level = level < 1 ? 1 : level;
  const int mantissa = std::numeric_limits<T>::digits - 2;
  level = level > mantissa ? mantissa : level;
  return level > 30 ? 30 : level;
}

/// True when the features' swept boxes (each point at t = 0 and t = 1; a point's path and a
/// feature at any time lie in the hull of those) are apart by more than `pad` per axis: then they
/// never touch, even with every coordinate perturbed by pad / 4 (the pad is 4 p m; 2 p m is needed).
template <class W>
LWSCCD_HD LWSCCD_HOST_INLINE bool boxes_apart(const Vec3<W>* a, int na, const Vec3<W>* b, int nb, const Vec3<W>& pad) {
  Vec3<W> alo = a[0], ahi = a[0], blo = b[0], bhi = b[0];
  for (int i = 1; i < na; ++i) alo = min(alo, a[i]), ahi = max(ahi, a[i]);
  for (int i = 1; i < nb; ++i) blo = min(blo, b[i]), bhi = max(bhi, b[i]);
  for (int k = 0; k < 3; ++k)
    if (fadd(ahi[k], pad[k]) < blo[k] || fadd(bhi[k], pad[k]) < alo[k]) return true;
  return false;
}
template <class W>
LWSCCD_HD LWSCCD_HOST_INLINE bool swept_boxes_apart(const VertexFaceQuery<W>& q, const Vec3<W>& pad) {
  const Vec3<W> vertex[2] = {q.p0, q.p1}, face[6] = {q.a0, q.b0, q.c0, q.a1, q.b1, q.c1};
  return boxes_apart(vertex, 2, face, 6, pad);
}
template <class W>
LWSCCD_HD LWSCCD_HOST_INLINE bool swept_boxes_apart(const EdgeEdgeQuery<W>& q, const Vec3<W>& pad) {
  const Vec3<W> first[4] = {q.a0, q.b0, q.a1, q.b1}, second[4] = {q.c0, q.d0, q.c1, q.d1};
  return boxes_apart(first, 4, second, 4, pad);
}

/// True when, over the window [0, w] (w a power of two <= 1/2), the features' boxes are apart by
/// more than `pad` per axis: each point's path up to w lies between its position at 0 and at w.
/// The positions at w are computed (x0 + w (x1 - x0): w's product is exact, the two roundings
/// move a point by at most 3 u m for w <= 1/2); a perturbation of the inputs by e moves them by at
/// most e m. So pad = 20 e m (+ underflow's share) covers both sides' errors twice over (e >= u).
template <class W>
LWSCCD_HD LWSCCD_HOST_INLINE Vec3<W> position_at(const Vec3<W>& x0, const Vec3<W>& x1, W w) {
  return {fadd(x0.x, fmul(w, fsub(x1.x, x0.x))), fadd(x0.y, fmul(w, fsub(x1.y, x0.y))), fadd(x0.z, fmul(w, fsub(x1.z, x0.z)))};
}
template <class W>
LWSCCD_HD LWSCCD_HOST_INLINE bool window_boxes_apart(const VertexFaceQuery<W>& q, W w, const Vec3<W>& pad) {
  const Vec3<W> vertex[2] = {q.p0, position_at(q.p0, q.p1, w)};
  const Vec3<W> face[6] = {q.a0, q.b0, q.c0, position_at(q.a0, q.a1, w), position_at(q.b0, q.b1, w), position_at(q.c0, q.c1, w)};
  return boxes_apart(vertex, 2, face, 6, pad);
}
template <class W>
LWSCCD_HD LWSCCD_HOST_INLINE bool window_boxes_apart(const EdgeEdgeQuery<W>& q, W w, const Vec3<W>& pad) {
  const Vec3<W> first[4] = {q.a0, q.b0, position_at(q.a0, q.a1, w), position_at(q.b0, q.b1, w)};
  const Vec3<W> second[4] = {q.c0, q.d0, position_at(q.c0, q.c1, w), position_at(q.d0, q.d1, w)};
  return boxes_apart(first, 4, second, 4, pad);
}

/// Where the certified path computes: float queries in double (the cubic's coefficients carry
/// about 16 u of error, which in float is the size of a 1e-6 step's change), others as given.
template <class T>
struct certified_compute {
  using type = T;
};
template <>
struct certified_compute<float> {
  using type = double;
};

/// The certified path's cheap first step: true when the query is certainly a miss by its swept
/// boxes or by the cubic's coefficients under the screening bound (with params.time_limit < 1:
/// no contact before it, the cubic restricted to [0, time_limit)). Most pairs of a real step end
/// here; a batch runs it on every pair and certified_refine on the others.
template <class Policy, class Q, class T>
LWSCCD_HD bool certified_screen(const Q& q_in, const CcdParams<T>& params) {
  using W = typename certified_compute<T>::type;
  if (params.min_separation > T(0)) return false;  // the cubic only speaks of contact
  const auto q = q_in.template cast<W>();
  const W perturbation = unit_roundoff<T>();
  const Vec3<W> m = coordinate_magnitude(q);
  // Swept boxes apart: no arithmetic but the pad, so it goes first.
  if (swept_boxes_apart(q, vscale(m, W(4) * perturbation))) return true;
  // Only [0, time_limit) asked for (mode earliest's windows): the boxes over the smallest dyadic
  // [0, w] that covers it, which are far smaller than the whole step's when w is short.
  if (params.time_limit <= T(0.5)) {
    W w = W(0.5);
    for (int level = 1; level < 30 && w / 2 >= W(params.time_limit); ++level) w /= 2;
    const W tiny = W(4) * std::numeric_limits<W>::denorm_min();
    const Vec3<W> pad = vscale(m, W(20) * perturbation);
    if (window_boxes_apart(q, w, Vec3<W>{fadd(pad.x, tiny), fadd(pad.y, tiny), fadd(pad.z, tiny)})) return true;
  }
  W b[4];
  const W k = W(Policy::kCoefficientBound), slack = underflow_slack(fmul(W(4), max_component(m)), 3);
  const W screen = fadd(fmul(k, screening_bernstein(q, b, m, perturbation)), slack);
  const bool finite = finite_value(screen) && finite_value(b[0]) && finite_value(b[1]) && finite_value(b[2]) && finite_value(b[3]);
  if (!finite) return false;
  if (same_sign_beyond(b, screen)) return true;
  if (!(params.time_limit < T(1))) return false;
  // Only [0, time_limit) is asked for (mode earliest's windows): the cubic on the smallest dyadic
  // [0, 2^-k] that covers it, by k left halvings, each adding its rounding to the bound as in the
  // refinement (a halving is a convex combination, so the bound on [0, 1] still bounds the error).
  BernsteinPiece<W> piece{{b[0], b[1], b[2], b[3]}, screen, screen};
  // A wider piece that keeps its sign already covers the window: stop there (most pairs do early).
  for (int level = 0; level < 30 && exact_pow2_neg<W>(level + 1) >= W(params.time_limit); ++level) {
    if (level > 0 && same_sign_beyond(piece.c, piece.bound)) return true;
    BernsteinPiece<W> left, right;
    bernstein_halves<Policy>(piece, left, right);
    piece = left;
  }
  return same_sign_beyond(piece.c, piece.bound);
}

/// The cubic's Bernstein piece on [0, 1] with its perturbed and as-given bounds (the coefficient
/// bound of ccd_filters.hpp, plus underflow's share for differences up to `mag`); false when a
/// value is not finite (overflow: the caller leaves the query undecided).
template <class Policy, class Q, class W>
LWSCCD_HD LWSCCD_HOST_INLINE bool cubic_on_step(const Q& q, W mag, W perturbation, BernsteinPiece<W>& root) {
  const W k = W(Policy::kCoefficientBound), slack = underflow_slack(mag, 3);
  W rounding_bound = W(0);
  const W coefficient_bound = coplanarity_bernstein(q, root.c, perturbation, &rounding_bound);
  root.bound = fadd(fmul(k, coefficient_bound), slack);
  root.exact = fadd(fmul(k, rounding_bound), slack);
  bool finite = finite_value(root.bound);
  for (int i = 0; i < 4; ++i) finite = finite && finite_value(root.c[i]);
  return finite;
}

/// Points (u, v) of the domain near which a query's F(t, u, v) is smallest at time t: the plane's
/// least-squares point brought into the domain and the closest points on the domain's edges.
/// Only where to look: any point of the domain is sound (tolerance_contact tests a box around it).
template <class W>
LWSCCD_HD int contact_candidates(const VertexFaceQuery<W>& q, W t, W u[4], W v[4]) {
  const Vec3<W> a = vadd_scaled(q.a0, vsub(q.a1, q.a0), t);
  const Vec3<W> ab = vsub(vadd_scaled(q.b0, vsub(q.b1, q.b0), t), a), ac = vsub(vadd_scaled(q.c0, vsub(q.c1, q.c0), t), a);
  const Vec3<W> ap = vsub(vadd_scaled(q.p0, vsub(q.p1, q.p0), t), a), bc = vsub(ac, ab);
  const W aa = vdot(ab, ab), ab_ac = vdot(ab, ac), cc = vdot(ac, ac), pa = vdot(ap, ab), pc = vdot(ap, ac), bb = vdot(bc, bc);
  const W det = fsub(fmul(aa, cc), fmul(ab_ac, ab_ac));
  int n = 0;
  if (det > W(0)) {
    W x = fsub(fmul(cc, pa), fmul(ab_ac, pc)) / det, y = fsub(fmul(aa, pc), fmul(ab_ac, pa)) / det;
    x = x > W(0) ? x : W(0);
    y = y > W(0) ? y : W(0);
    const W sum = fadd(x, y);
    if (sum > W(1)) x = x / sum, y = y / sum;
    u[n] = x, v[n++] = y;
  }
  if (aa > W(0)) u[n] = unit_clamp(pa / aa), v[n++] = W(0);
  if (cc > W(0)) u[n] = W(0), v[n++] = unit_clamp(pc / cc);
  if (bb > W(0)) {
    const W s = unit_clamp(vdot(vsub(ap, ab), bc) / bb);
    u[n] = fsub(W(1), s), v[n++] = s;
  }
  return n;
}
template <class W>
LWSCCD_HD int contact_candidates(const EdgeEdgeQuery<W>& q, W t, W u[5], W v[5]) {
  const Vec3<W> a = vadd_scaled(q.a0, vsub(q.a1, q.a0), t), c = vadd_scaled(q.c0, vsub(q.c1, q.c0), t);
  const Vec3<W> ab = vsub(vadd_scaled(q.b0, vsub(q.b1, q.b0), t), a), cd = vsub(vadd_scaled(q.d0, vsub(q.d1, q.d0), t), c);
  const Vec3<W> ca = vsub(a, c);
  const W aa = vdot(ab, ab), ab_cd = vdot(ab, cd), cc = vdot(cd, cd), ra = -vdot(ab, ca), rc = vdot(cd, ca);
  const W det = fsub(fmul(aa, cc), fmul(ab_cd, ab_cd));
  int n = 0;
  if (det > W(0)) u[n] = unit_clamp(fadd(fmul(cc, ra), fmul(ab_cd, rc)) / det), v[n++] = unit_clamp(fadd(fmul(ab_cd, ra), fmul(aa, rc)) / det);
  if (cc > W(0)) {
    u[n] = W(0), v[n++] = unit_clamp(rc / cc);
    u[n] = W(1), v[n++] = unit_clamp(vdot(cd, vadd(ca, ab)) / cc);
  }
  if (aa > W(0)) {
    u[n] = unit_clamp(ra / aa), v[n++] = W(0);
    u[n] = unit_clamp(vdot(ab, vsub(cd, ca)) / aa), v[n++] = W(1);
  }
  return n;
}

/// Contact within the tolerance over [from, to]: a small box of (t, u, v) there
/// that the inclusion test accepts (not excluded by the time filter, an axis or a separating
/// direction, and F within the distance the features move in `tolerance` of time) - the answer
/// the fallback would give when it finds such a box with everything before it excluded. The boxes
/// tried: each half of the window in time, around the candidates of its middle (u and v +- an
/// eighth of that distance over the query's extent). Used where the certified search has
/// excluded every time before `from` but cannot prove a contact: features that touch on a
/// boundary (a vertex sliding along an edge), where no sign is certain.
template <class Q, class W>
LWSCCD_HD bool tolerance_contact(const Q& q, const CcdParams<W>& params, W from, W to) {
  const InclusionSetup<W> s = inclusion_setup(q, params);
  if (s.separated) return false;
  const Vec3<W>* pts = q.points();
  W extent = W(0);
  for (int i = 1; i < 8; ++i) extent = fmax_of(extent, max_component(abs(vsub(pts[i], pts[0]))));
  const W radius = extent > W(0) ? fmul(s.delta, W(0.125)) / extent : W(0);
  const W half = fmul(fsub(to, from), W(0.5));
  constexpr int kCandidates = 5;
  for (int h = 0; h < 2; ++h) {
    const W t[2] = {h == 0 ? from : fadd(from, half), h == 0 ? fadd(from, half) : to};
    W cu[kCandidates], cv[kCandidates];
    const int n = contact_candidates(q, fmul(fadd(t[0], t[1]), W(0.5)), cu, cv);
    for (int k = 0; k < n; ++k) {
      const W u[2] = {fmax_of(W(0), fsub(cu[k], radius)), fmin_of(W(1), fadd(cu[k], radius))};
      const W v[2] = {fmax_of(W(0), fsub(cv[k], radius)), fmin_of(W(1), fadd(cv[k], radius))};
      RangeTest<W> r;
      test_ranges(q, s, t, u, v, true, false, r);
      if (r.verdict == BoxVerdict::accepted) return true;
    }
  }
  return false;
}

/// The certified answer for a query whose search excluded every time before `lower` and proved no
/// contact after it: undecided from `lower` (the fallback's), or, with Policy::kToleranceContacts,
/// a hit at `lower` when tolerance_contact finds contact within the tolerance right after it.
/// The test runs in T with the inclusion test's rounding bound for T, as the fallback would (a float
/// query's contact within float's rounding is one for the fallback too).
template <class Policy, class Q, class T>
LWSCCD_HD CertifiedAnswer<T> certified_undecided(const Q& q_in, const CcdParams<T>& params, T lower) {
  const CertifiedAnswer<T> undecided{Certainty::undecided, lower, T(1)};
  if (!Policy::kToleranceContacts || params.min_separation > T(0) || !(lower < T(1)) || !(lower < params.time_limit))
    return undecided;
  // Two of the search's leaves (dyadic: lower is a multiple of them, so the end is exact), or one
  // where the level's cap makes two wider than the tolerance.
  const int level = certified_max_level(params.tolerance);
  const T width = exact_pow2_neg<T>(level - 1) <= params.tolerance ? exact_pow2_neg<T>(level - 1) : exact_pow2_neg<T>(level);
  const T to = fadd(lower, width) < T(1) ? fadd(lower, width) : T(1);
  if (!tolerance_contact(q_in.template cast<T>(), params, lower, to)) return undecided;
  return {Certainty::hit, lower, to, true};
}

/// The refinement's inside tests as they are asked for, one at a time (certified_refine's
/// `inside_at`: called with an interval's level and index, and a function that computes the
/// verdict there). The GPU's warp per search evaluates a whole subtree of them at once instead.
struct InsideOneByOne {
  template <class Compute>
  LWSCCD_HD InsideVerdict operator()(int level, std::uint32_t index, const Compute& compute) const {
    return compute(level, index);
  }
};

/// The certified classification of a query that certified_screen did not reject (see the file
/// comment); computed in W with the inputs' perturbation of T's unit roundoff. Also correct on a
/// query the screen would reject (it then finds the miss itself, at more cost).
/// `defer_level`: when an interval that deep would have to be halved, the search stops, answers
/// undecided and sets *deferred; a second call without the limit then gives the whole answer (the
/// same as one call without it). A GPU batch uses this to keep the long searches (contacts,
/// resolved at the tolerance) out of the warps that decide misses in a few levels.
/// `kStack`: pending intervals held at most (one per level; defer_level + 2 suffice): a GPU
/// thread keeps them in local memory, so a short search holds a short stack.
/// `kSettle` false: an undecided answer is returned as it is, for a batch that settles its
/// undecided queries apart (certified_undecided): the GPU keeps that test's code out of its
/// refinement kernels, whose registers it would cost on every pair.
/// `inside_at`: where the inside tests are asked for (InsideOneByOne's contract); any evaluator
/// that returns each test's own verdict gives the same answer.
template <class Policy, int kStack = 34, bool kSettle = true, class Q, class T, class InsideAt = InsideOneByOne>
LWSCCD_HD CertifiedAnswer<T> certified_refine(const Q& q_in, const CcdParams<T>& params, int defer_level = 1 << 30,
                                              bool* deferred = nullptr, InsideAt&& inside_at = InsideOneByOne{}) {
  using W = typename certified_compute<T>::type;
  const auto q = q_in.template cast<W>();
  const W perturbation = unit_roundoff<T>();
  CertifiedAnswer<T> undecided;
  if (params.min_separation > T(0)) return undecided;  // the cubic only speaks of contact
  const Vec3<W> m = coordinate_magnitude(q);
  // The cubic and its coefficient bound (ccd_filters.hpp), plus underflow's share.
  const W mag = fmul(W(4), max_component(m));  // bounds every difference and its motion
  BernsteinPiece<W> root;
  if (!cubic_on_step<Policy>(q, mag, perturbation, root)) return undecided;
  if (same_sign_beyond(root.c, root.bound)) return {Certainty::miss, T(0), T(1)};
  const W inside_slack = underflow_slack(mag, 4);
  if (!finite_value(inside_slack)) return undecided;
  const int max_level = certified_max_level(params.tolerance);
  const bool set_mode = params.mode == CcdMode::set;

  // Depth-first over dyadic intervals, earliest first: the stack holds right halves still to see.
  // Two bounds on everything: what a perturbed query may do (only that excludes time) and what
  // the query as given does (only that proves a contact). Between them lies rounding's share of
  // the inputs: in double about u of the geometry; in float it can move a contact by more than
  // the tolerance, and the reported lower bound is then that much earlier.
  struct Entry {
    BernsteinPiece<W> piece;
    std::uint32_t index;
    int level;
  };
  static_assert(kStack >= 3 && kStack <= 34, "lwsccd: certified_refine holds 3 to 34 pending intervals");
  Entry stack[kStack];  // one pending right half per level, levels <= 30
  int top = 0, splits = 0, leaves = 0;
  T lower = T(0), open_from = T(0);  // earliest time not excluded for a perturbed query / as given
  bool has_lower = false, has_open = false, open_inside = true;
  bool descent = Policy::kCertainDescent && !set_mode && (Policy::kDescentBeforeDefer || defer_level >= max_level);
  int open_sign = 0;  // sign of f (as given) at open_from, 0 when uncertain
  auto note_lower = [&](T t) {
    if (!has_lower) lower = t, has_lower = true;  // intervals come in time order
  };
  // Undecided from `from` (every earlier time excluded), unless contact within the tolerance
  // right after it settles the query.
  auto settle = [&](T from) {
    if constexpr (kSettle) return certified_undecided<Policy>(q, params, from);
    else return CertifiedAnswer<T>{Certainty::undecided, from, T(1)};
  };
  stack[top++] = {root, 0u, 0};
  while (top > 0) {
    const Entry e = stack[--top];
    // Dyadic with at most certified_max_level(T) bits: exact in T and W.
    const T scale = exact_pow2_neg<T>(e.level);
    const T lo = static_cast<T>(e.index) * scale, hi = static_cast<T>(e.index + 1u) * scale;
    if (lo >= params.time_limit) continue;  // later than what the caller still wants
    const W* c = e.piece.c;
    const W bound = e.piece.bound, exact = e.piece.exact;
    if (same_sign_beyond(c, bound)) continue;  // no root here, even perturbed
    if (same_sign_beyond(c, exact)) {          // none as given; a perturbed query's may be here
      note_lower(lo);
      continue;
    }
    // f(lo) = c[0], f(hi) = c[3]: a certain sign change proves a root of the query as given.
    const bool crossing = (c[0] < -exact && c[3] > exact) || (c[0] > exact && c[3] < -exact);
    const bool leaf = e.level >= max_level;
    // Set mode needs no tight time: a crossing interval is tried every fourth level on the way.
    const bool try_hit = leaf || (set_mode && crossing && (e.level & 3) == 0);
    const bool coarse = Policy::kInsideEvery > 0 && e.level >= Policy::kInsideFrom &&
                        (e.level - Policy::kInsideFrom) % (Policy::kInsideEvery > 0 ? Policy::kInsideEvery : 1) == 0;
    const bool coplanar = all_within(c, exact);
    // Both halves of one sign (a root of the control polygon, not of the cubic): no root here even
    // perturbed, so the costly inside test is skipped (before it, the interval was only split).
    if (Policy::kLookAhead && coarse && !leaf && !coplanar && halves_keep_sign<Policy>(e.piece)) continue;
    InsideVerdict inside = InsideVerdict::unknown;
    if (try_hit || coarse || coplanar) {
      // The test over interval `index` of `level` (this one, or another that inside_at evaluates
      // ahead): the same operations on the same values, so the same verdict.
      inside = inside_at(e.level, e.index, [&](int level, std::uint32_t index) {
        const W half_width = exact_pow2_neg<W>(level + 1);
        const T from = static_cast<T>(index) * exact_pow2_neg<T>(level);
        return inside_over<Policy>(q, fadd(W(from), half_width), half_width, m, perturbation, inside_slack);
      });
      if (inside == InsideVerdict::outside || inside == InsideVerdict::outside_as_given) {  // roots here are no contacts
        if (inside == InsideVerdict::outside_as_given) note_lower(lo);
        if (leaf && ++leaves > Policy::kMaxLeaves) return settle(has_lower ? lower : lo);
        continue;
      }
    }
    // Certain descent: over this interval every perturbed cubic has one root and a root is a
    // contact of the query as given. Halving keeps the half that holds the query's root, by the
    // sign of f at the middle (the left half's last coefficient): of c[0]'s sign beyond the
    // perturbed bound, no perturbed root lies in the left half; beyond only the as-given bound, the
    // query's root is right of it but a perturbed one may not be (the lower bound stops there); of
    // c[3]'s sign, the query's root is in the left half, and what lies right is later. A middle
    // value within its as-given error (a root on the grid) ends the descent: everything it noted
    // is undone and this interval is searched as usual.
    if (descent && inside == InsideVerdict::inside && !leaf && !has_open && single_crossing(c, bound)) {
      const int first = c[0] > W(0) ? 1 : -1;
      const T saved_lower = lower;
      const bool saved_has_lower = has_lower;
      const int saved_splits = splits;
      BernsteinPiece<W> piece = e.piece;
      std::uint32_t index = e.index;
      int level = e.level;
      for (;;) {
        const T step = exact_pow2_neg<T>(level);
        const T from = static_cast<T>(index) * step, to = static_cast<T>(index + 1u) * step;
        // Within the tolerance; an interval past the caller's time limit is narrowed to the leaves,
        // where the limit cuts as it does in the search (a root past it is no answer).
        if ((to - from <= params.tolerance && to <= params.time_limit) || level >= max_level) {
          note_lower(from);
          return {Certainty::hit, lower, to};
        }
        if (++splits > Policy::kMaxSplits) return settle(has_lower ? lower : from);
        BernsteinPiece<W> left, right;
        bernstein_halves<Policy>(piece, left, right);
        const W middle = left.c[3];
        const int sign = sign_beyond(middle, left.exact);
        if (sign == 0) break;  // the only way out of the loop but a return
        ++level;
        if (sign == first) {
          if (sign_beyond(middle, left.bound) == 0) note_lower(from);
          piece = right;
          index = 2u * index + 1u;
          // The query's root is past the caller's time limit; so is everything still stacked.
          if (static_cast<T>(index) * exact_pow2_neg<T>(level) >= params.time_limit)
            return has_lower ? settle(lower) : CertifiedAnswer<T>{Certainty::miss, T(0), T(1)};
        } else {
          piece = left;
          index = 2u * index;
        }
      }
      lower = saved_lower, has_lower = saved_has_lower, splits = saved_splits;
      descent = false;
      stack[top++] = e;
      continue;
    }
    if (try_hit) {
      // A root is certain across this leaf, or from the start of the unresolved leaves before it
      // (a root on the grid point between two leaves makes neither a crossing alone); those
      // leaves join the interval, which must stay within the tolerance.
      const int sign_lo = c[0] < -exact ? -1 : (c[0] > exact ? 1 : 0), sign_hi = c[3] < -exact ? -1 : (c[3] > exact ? 1 : 0);
      const bool is_inside = inside == InsideVerdict::inside;
      const bool joined = has_open && open_inside && is_inside && open_sign != 0 && sign_hi == -open_sign;
      const T from = has_open ? open_from : lo;
      if (((is_inside && crossing) || joined) && (set_mode || hi - from <= params.tolerance)) {
        note_lower(lo);
        return {Certainty::hit, lower, hi};
      }
      if (leaf) {
        note_lower(lo);  // not excluded (a wider interval tried in set mode is split instead)
        if (!has_open) open_from = lo, has_open = true, open_sign = sign_lo, open_inside = true;
        open_inside = open_inside && is_inside;
        if (++leaves > Policy::kMaxLeaves || (!set_mode && hi + (hi - lo) - open_from > params.tolerance))
          return settle(lower);
        continue;  // touching, tangent or on a boundary: look further
      }
    }
    const T open = has_lower ? lower : lo;
    // f is zero within its error here (motion that stays coplanar): only the inside test can
    // still exclude time, when the features are apart within the plane; it was not certain over
    // this interval, so halves (with less motion each) are tried, unless they are certainly in
    // contact in the plane (no sign of f left to resolve).
    if (coplanar && inside == InsideVerdict::inside) return settle(open);
    if (++splits > Policy::kMaxSplits || top + 2 > kStack) return settle(open);
    if (e.level >= defer_level) {
      if (deferred) *deferred = true;
      return undecided;
    }
    BernsteinPiece<W> left, right;
    bernstein_halves<Policy>(e.piece, left, right);
    stack[top++] = {right, 2u * e.index + 1u, e.level + 1};
    stack[top++] = {left, 2u * e.index, e.level + 1};
  }
  // Nothing as given; a perturbed query may still touch where only the as-given bounds excluded.
  if (has_lower) return settle(lower);
  return {Certainty::miss, T(0), T(1)};
}

/// The refinement's first levels as a filter without a stack, for batches that run the inside
/// tests apart (a GPU thread per test keeps its warp's lanes busy; the search proper diverges).
/// The cubic's pieces down to level Policy::kInsideFrom are pruned exactly as certified_refine
/// prunes them (past the time limit, or of one sign beyond the perturbed bound); a piece it would
/// treat otherwise before that level (set mode's early hit test) makes the whole search necessary;
/// a piece excluded only as given lowers `lower` as it would there. What is left are the intervals that certified_refine tests for inside
/// next: those of that level, less the ones whose halves both keep a sign (it skips their test),
/// and pieces of coplanar motion above it. A query whose every such interval is `outside` is a
/// miss there too (undecided from `lower` when `noted`: the fallback's case), by the same tests on
/// the same values; any other query is searched whole. Returns -1 (search whole) or the number of those intervals, as the bits of `mask`: bit
/// 2^level + k for interval [k, k + 1] 2^-level (a binary heap's numbering).
/// A lower bound noted by CertifiedFilter: the earliest piece excluded only for the query as given.
template <class T>
struct Noted {
  bool any = false;
  T lower = T(0);
};

template <class Policy>
struct CertifiedFilter {
  static constexpr int kLevel = Policy::kInsideFrom;
  static constexpr int kMaxIntervals = 1 << kLevel;
  static_assert(kLevel >= 1 && kLevel <= 4, "lwsccd: the certified filter runs to levels 1 to 4 (kInsideFrom)");
  static_assert(Policy::kInsideEvery > 0, "lwsccd: the certified filter needs the inside tests at kInsideFrom");

  template <int kAt, class W, class T>
  LWSCCD_HD static bool visit(const BernsteinPiece<W>& p, std::uint32_t index, const CcdParams<T>& params, std::uint32_t& mask,
                              Noted<T>& noted) {
    const T lo = static_cast<T>(index) * exact_pow2_neg<T>(kAt);
    if (lo >= params.time_limit) return true;
    if (same_sign_beyond(p.c, p.bound)) return true;
    if (same_sign_beyond(p.c, p.exact)) {  // the search notes a lower bound here and goes on
      if (!noted.any || lo < noted.lower) noted = {true, lo};
      return true;
    }
    const bool coplanar = all_within(p.c, p.exact);  // tested for inside at any level
    if constexpr (kAt == kLevel) {
      if (Policy::kLookAhead && !coplanar && halves_keep_sign<Policy>(p)) return true;
      mask |= 1u << ((1u << kAt) + index);
      return true;
    } else {
      if (coplanar) {
        mask |= 1u << ((1u << kAt) + index);
        return true;
      }
      const bool crossing = (p.c[0] < -p.exact && p.c[3] > p.exact) || (p.c[0] > p.exact && p.c[3] < -p.exact);
      if ((kAt & 3) == 0 && params.mode == CcdMode::set && crossing) return false;  // set mode's hit test
      BernsteinPiece<W> left, right;
      bernstein_halves<Policy>(p, left, right);
      return visit<kAt + 1>(left, 2u * index, params, mask, noted) && visit<kAt + 1>(right, 2u * index + 1u, params, mask, noted);
    }
  }

  template <class Q, class T>
  LWSCCD_HD static int intervals(const Q& q_in, const CcdParams<T>& params, std::uint32_t& mask, Noted<T>& noted) {
    using W = typename certified_compute<T>::type;
    mask = 0;
    noted = {};
    if (params.min_separation > T(0)) return -1;
    if (certified_max_level(params.tolerance) <= kLevel) return -1;  // leaves within the filter's levels
    const auto q = q_in.template cast<W>();
    const W perturbation = unit_roundoff<T>();
    const Vec3<W> m = coordinate_magnitude(q);
    const W mag = fmul(W(4), max_component(m));
    BernsteinPiece<W> root;
    if (!cubic_on_step<Policy>(q, mag, perturbation, root)) return -1;
    if (same_sign_beyond(root.c, root.bound)) return 0;
    if (!finite_value(underflow_slack(mag, 4))) return -1;
    if (!visit<0>(root, 0u, params, mask, noted)) return -1;
    int n = 0;
    for (std::uint32_t b = mask; b; b &= b - 1u) ++n;
    return n;
  }

  /// The inside test certified_refine runs over the interval numbered `node`, on the same values.
  template <class Q, class T>
  LWSCCD_HD static InsideVerdict inside_verdict(const Q& q_in, const CcdParams<T>& /*params: their T*/, unsigned node) {
    int level = 0;
    while ((node >> (level + 1)) != 0u) ++level;
    const unsigned index = node - (1u << level);
    using W = typename certified_compute<T>::type;
    const auto q = q_in.template cast<W>();
    const W perturbation = unit_roundoff<T>();
    const Vec3<W> m = coordinate_magnitude(q);
    const W inside_slack = underflow_slack(fmul(W(4), max_component(m)), 4);
    const T lo = static_cast<T>(index) * exact_pow2_neg<T>(level);
    const W half = exact_pow2_neg<W>(level + 1);
    return inside_over<Policy>(q, fadd(W(lo), half), half, m, perturbation, inside_slack);
  }
  /// True when the query is certainly outside over the interval numbered `node`.
  template <class Q, class T>
  LWSCCD_HD static bool excluded(const Q& q, const CcdParams<T>& params, unsigned node) {
    return inside_verdict(q, params, node) == InsideVerdict::outside;
  }

  /// The second round, below one interval of level kLevel whose inside test was `unknown` (not
  /// inside, not outside as given): certified_refine halves it there and runs the next inside
  /// tests kInsideEvery levels down. Its pieces to that level (kDeepLevel) are pruned as the search
  /// prunes them; returns -1 (search whole: a lower bound would be noted) or the number of
  /// intervals left, the bits of `mask` numbered within the subtree (bit 2^d + k: level
  /// kLevel + d, the k-th below `node`; deep_node() gives the global number). With every such
  /// interval `outside`, the search excludes the interval `node` after these very splits.
  static constexpr int kDeepLevel = kLevel + Policy::kInsideEvery;
  static_assert(kDeepLevel <= 7, "lwsccd: the certified filter's second round numbers intervals to level 7 (one byte)");
  /// Whether the search can split every interval of this round without passing kMaxSplits: the
  /// levels above kLevel (2^kLevel - 1 splits) and, for each of `count` intervals, its subtree to
  /// the level above kDeepLevel. A query with more intervals is searched whole.
  LWSCCD_HD static constexpr bool expandable(int count) {
    return (1 << kLevel) - 1 + count * ((1 << Policy::kInsideEvery) - 1) <= Policy::kMaxSplits;
  }
  LWSCCD_HD static constexpr unsigned deep_node(unsigned node, unsigned local) {
    unsigned depth = 0;
    while ((local >> (depth + 1)) != 0u) ++depth;
    return (node << depth) + (local - (1u << depth));
  }

  template <int kAt, class W, class T>
  LWSCCD_HD static bool visit_deep(const BernsteinPiece<W>& p, std::uint32_t index, std::uint32_t local, const CcdParams<T>& params,
                                   std::uint32_t& mask) {
    const T lo = static_cast<T>(index) * exact_pow2_neg<T>(kAt);
    if (lo >= params.time_limit) return true;
    if (same_sign_beyond(p.c, p.bound)) return true;
    if (same_sign_beyond(p.c, p.exact)) return false;  // the search notes a lower bound here: whole
    if constexpr (kAt == kDeepLevel) {
      if (Policy::kLookAhead && !all_within(p.c, p.exact) && halves_keep_sign<Policy>(p)) return true;
      mask |= 1u << local;
      return true;
    } else {
      if (all_within(p.c, p.exact)) {  // coplanar: tested for inside at any level
        mask |= 1u << local;
        return true;
      }
      BernsteinPiece<W> left, right;
      bernstein_halves<Policy>(p, left, right);
      return visit_deep<kAt + 1>(left, 2u * index, 2u * local, params, mask) &&
             visit_deep<kAt + 1>(right, 2u * index + 1u, 2u * local + 1u, params, mask);
    }
  }

  template <class Q, class T>
  LWSCCD_HD static int expand(const Q& q_in, const CcdParams<T>& params, unsigned node, std::uint32_t& mask) {
    using W = typename certified_compute<T>::type;
    mask = 0;
    if (params.mode == CcdMode::set || node < (1u << kLevel) || node >= (2u << kLevel)) return -1;
    if (certified_max_level(params.tolerance) <= kDeepLevel) return -1;  // leaves within these levels
    const auto q = q_in.template cast<W>();
    const W perturbation = unit_roundoff<T>();
    const Vec3<W> m = coordinate_magnitude(q);
    const W mag = fmul(W(4), max_component(m));
    BernsteinPiece<W> piece;
    if (!cubic_on_step<Policy>(q, mag, perturbation, piece)) return -1;
    // The interval's piece, by the halvings the search made on the way (the same values).
    for (int d = kLevel - 1; d >= 0; --d) {
      BernsteinPiece<W> left, right;
      bernstein_halves<Policy>(piece, left, right);
      piece = ((node >> d) & 1u) ? right : left;
    }
    BernsteinPiece<W> left, right;
    bernstein_halves<Policy>(piece, left, right);
    const std::uint32_t index = node - (1u << kLevel);
    if (!visit_deep<kLevel + 1>(left, 2u * index, 2u, params, mask) || !visit_deep<kLevel + 1>(right, 2u * index + 1u, 3u, params, mask))
      return -1;
    int n = 0;
    for (std::uint32_t b = mask; b; b &= b - 1u) ++n;
    return n;
  }

  /// Both rounds on one thread, as a GPU batch runs them apart (the tests' reference): true when
  /// the filter decides the query (then certified_refine answers a miss, or undecided from
  /// noted.lower when noted.any); false when the whole search must run.
  template <class Q, class T>
  static bool decides(const Q& q, const CcdParams<T>& params, Noted<T>& noted, bool second_round = true) {
    std::uint32_t mask = 0;
    const int count = intervals(q, params, mask, noted);
    if (count < 0 || (count > 0 && noted.any)) return false;
    for (unsigned node = 0; node < 32; ++node) {
      if (!((mask >> node) & 1u)) continue;
      const InsideVerdict v = inside_verdict(q, params, node);
      if (v == InsideVerdict::outside) continue;
      std::uint32_t deep = 0;
      if (!second_round || v != InsideVerdict::unknown || !expandable(count) || expand(q, params, node, deep) < 0) return false;
      for (unsigned local = 0; local < 32; ++local)
        if (((deep >> local) & 1u) && !excluded(q, params, deep_node(node, local))) return false;
    }
    return true;
  }
};

/// The whole certified classification of one query: the screen, then the refinement.
template <class Policy, class Q, class T>
LWSCCD_HD CertifiedAnswer<T> certified_classify(const Q& q, const CcdParams<T>& params) {
  if (certified_screen<Policy>(q, params)) return {Certainty::miss, T(0), T(1)};
  return certified_refine<Policy>(q, params);
}

}  // namespace detail

/// The certified fast path in front of a conservative method: queries it decides cost a few
/// hundred operations; the others run `Fallback` unchanged. Conservative when Fallback is.
template <class Fallback = Filtered<InclusionCcd>, class Policy = CertifiedPolicy>
struct CertifiedCcdT {
  static_assert(require_ccd_method<Fallback>::value, "");
  static constexpr const char* name = "certified";
  static constexpr bool conservative = Fallback::conservative;
  using fallback_type = Fallback;
  using policy_type = Policy;

  template <class Q, class T>
  LWSCCD_HD static CertifiedAnswer<T> classify(const Q& q, const CcdParams<T>& params) {
    return detail::certified_classify<Policy>(q, params);
  }
  /// classify in two steps, for batches that run the cheap one on every pair first: screen is
  /// true for a certain miss; refine classifies the others (classify = screen, then refine).
  template <class Q, class T>
  LWSCCD_HD static bool screen(const Q& q, const CcdParams<T>& params) {
    return detail::certified_screen<Policy>(q, params);
  }
  /// kSettle false: undecided answers are left for undecided_from (a batch's separate pass).
  template <bool kSettle = true, class Q, class T>
  LWSCCD_HD static CertifiedAnswer<T> refine(const Q& q, const CcdParams<T>& params) {
    return detail::certified_refine<Policy, 34, kSettle>(q, params);
  }
  /// refine with its inside tests asked of `inside_at` (detail::InsideOneByOne's contract): the
  /// same answer, whatever order the tests are evaluated in.
  template <bool kSettle, class Q, class T, class InsideAt>
  LWSCCD_HD static CertifiedAnswer<T> refine_with(const Q& q, const CcdParams<T>& params, InsideAt&& inside_at) {
    return detail::certified_refine<Policy, 34, kSettle>(q, params, 1 << 30, nullptr, inside_at);
  }
  /// What refine answers for a query whose search excluded every time before `lower` and found
  /// nothing certain after it (CertifiedFilter's queries with only a noted time): undecided from
  /// `lower`, or a hit there when contact within the tolerance follows (kToleranceContacts).
  template <class Q, class T>
  LWSCCD_HD static CertifiedAnswer<T> undecided_from(const Q& q, const CcdParams<T>& params, T lower) {
    return detail::certified_undecided<Policy>(q, params, lower);
  }
  /// Mode earliest: the time limit of window `round` (0, 1, ...) for a caller's `time_limit`; the
  /// last window is the one that returns `time_limit` itself.
  template <class T>
  LWSCCD_HD static T earliest_window(int round, T time_limit) {
    const int exponent = Policy::kEarliestFirst - Policy::kEarliestStep * round;
    if (exponent <= 0) return time_limit;
    const T window = std::ldexp(T(1), -exponent);
    return window < time_limit ? window : time_limit;
  }
  /// refine, stopped (*deferred set) where it would halve an interval at `kDeferLevel` or deeper
  /// (with a stack only that deep).
  template <int kDeferLevel, bool kSettle = true, class Q, class T>
  LWSCCD_HD static CertifiedAnswer<T> refine_until(const Q& q, const CcdParams<T>& params, bool* deferred) {
    static_assert(kDeferLevel >= 1 && kDeferLevel <= 30, "lwsccd: the defer level must be in [1, 30]");
    return detail::certified_refine<Policy, kDeferLevel + 2, kSettle>(q, params, kDeferLevel, deferred);
  }
  template <class T>
  LWSCCD_HD static CcdResult<T> vertex_face(const VertexFaceQuery<T>& q, const CcdParams<T>& params) {
    return solve(q, params, [&](const CcdParams<T>& p) { return Fallback::vertex_face(q, p); });
  }
  template <class T>
  LWSCCD_HD static CcdResult<T> edge_edge(const EdgeEdgeQuery<T>& q, const CcdParams<T>& params) {
    return solve(q, params, [&](const CcdParams<T>& p) { return Fallback::edge_edge(q, p); });
  }

 private:
  template <class Q, class T, class F>
  LWSCCD_HD static CcdResult<T> solve(const Q& q, const CcdParams<T>& params, F&& fallback) {
    const CertifiedAnswer<T> a = classify(q, params);
    if (a.certainty == Certainty::miss) return {};
    if (a.certainty == Certainty::hit) return {true, a.lo, false};
    // The fallback need not search before the time the certified pass excluded contact.
    CcdParams<T> rest = params;
    rest.time_from = a.lo > rest.time_from ? a.lo : rest.time_from;
    return fallback(rest);
  }
};
using CertifiedCcd = CertifiedCcdT<>;

namespace detail {
/// Methods with a certified first pass: batches classify every pair first and run the fallback
/// only on the undecided ones.
template <class Method>
struct certified_of : std::false_type {};
template <class Fallback, class Policy>
struct certified_of<CertifiedCcdT<Fallback, Policy>> : std::true_type {
  using fallback = Fallback;
};
/// The method a batch runs on the pairs its first pass leaves: the fallback of a certified
/// method, any other method itself.
template <class Method>
struct full_test_of {
  using type = Method;
};
template <class Fallback, class Policy>
struct full_test_of<CertifiedCcdT<Fallback, Policy>> {
  using type = Fallback;
};
}  // namespace detail

}  // namespace lwsccd
