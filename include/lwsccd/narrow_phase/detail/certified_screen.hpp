// lwsccd — the certified screen: the cheap Bernstein bound of the coplanarity cubic, swept and
// window boxes, and the screen in the path's own precision (a pair it rejects cannot touch in the
// step); certified_single.hpp puts the single-precision screen in front of it.
// Part of certified_ccd.hpp: include <lwsccd/narrow_phase/certified_ccd.hpp>, not this file.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/core/detail/rounding.hpp"
#include "lwsccd/narrow_phase/detail/certified_motion.hpp"

namespace lwsccd::detail {

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

/// The first level whose intervals are within `tolerance`: the least level >= 0 with
/// 2^-level <= tolerance, from the tolerance's binary exponent (exact, where a logarithm rounded to
/// an integer may not be, and cheap: the searches ask for it per pair). No level for a tolerance
/// that is not positive (NaN included): 2^20, past every level the searches reach.
template <class T>
LWSCCD_HD int tolerance_level(T tolerance) {
  if (!(tolerance > T(0))) return 1 << 20;
  if (tolerance >= T(1)) return 0;
  int exponent = 0;  // tolerance = f 2^exponent, f in [1/2, 1): 2^-level <= tolerance from level 1 - exponent
  (void)std::frexp(static_cast<double>(tolerance), &exponent);
  return 1 - exponent;
}

/// The finest level of the time intervals: width 2^-level <= tolerance / 2, so that a root
/// interval may span two of them (one level past tolerance_level), within T's time grid.
template <class T>
LWSCCD_HD int certified_max_level(T tolerance) {
  int level = tolerance_level(tolerance) + 1;
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

/// True when the features' relative motion keeps them apart for the whole step, by the
/// differences of their points at the same time (bound B14, docs/NARROW_PHASE.md): a contact at
/// time t is a point of one feature equal to a point of the other, and their difference is a
/// convex combination of the differences x_i(t) - y_j(t) of the features' vertices, each of them
/// (1 - t) (x_i0 - y_j0) + t (x_i1 - y_j1), so 0 lies in the convex hull of the `n` differences
/// `d` at t = 0 and t = 1. A direction along which every difference is beyond its error rules
/// contact out: the coordinate axes first (a comparison each), then the differences' sum. Unlike
/// the features' own boxes or hulls this ignores the motion they share: features moving together,
/// e.g. collinear edges of a cloth carried as a whole, or a vertex riding beside a face, are
/// apart here though their swept boxes overlap, and their cubic may stay within its bound
/// (coplanar or collinear motion) however long it is searched.
/// Each coordinate of the exact differences, of every query within `perturbation` m_k of `q`, is
/// within (2 p + 2 u) m_k of the computed one (both points move by p m_k; the subtraction rounds
/// by u |d| <= 2 u m_k); a dot product with c adds gamma_3 |c|.|d| <= 2 gamma_3 (1 + u) |c|.m.
/// The margins (2 p + 4 u) m_k and (2 p + 10 u) |c|.m, computed in W, cover those with their
/// own rounding, and the smallest normal added covers underflow. A value that is not finite
/// decides nothing. Policy::kDifferenceBound scales the margins (1 = as derived; only the mutation
/// tests change it).
template <class W>
struct DifferenceMargins {
  W axis, direction, smallest;  ///< margins: axis m_k + smallest, direction |c|.m + smallest
};
template <class Policy, class W>
LWSCCD_HD LWSCCD_HOST_INLINE DifferenceMargins<W> difference_margins(W perturbation) {
  const W u = unit_roundoff<W>(), scale = W(Policy::kDifferenceBound);
  return {fmul(fadd(W(2) * perturbation, W(4) * u), scale), fmul(fadd(W(2) * perturbation, W(10) * u), scale),
          scale > W(0) ? std::numeric_limits<W>::min() : W(0)};
}
template <class Policy, class W>
LWSCCD_HD LWSCCD_HOST_INLINE bool differences_apart(const Vec3<W>* d, int n, const Vec3<W>& m, W perturbation) {
  const DifferenceMargins<W> f = difference_margins<Policy>(perturbation);
  for (int k = 0; k < 3; ++k) {
    const W margin = fadd(fmul(f.axis, m[k]), f.smallest);
    bool above = finite_value(margin), below = above;
    for (int i = 0; i < n; ++i) {
      above = above && d[i][k] > margin;
      below = below && d[i][k] < -margin;
    }
    if (above || below) return true;
  }
  Vec3<W> c = d[0];
  for (int i = 1; i < n; ++i) c = vadd(c, d[i]);
  const W margin = fadd(fmul(f.direction, vabs_dot(c, m)), f.smallest);
  bool apart = finite_value(margin);
  for (int i = 0; i < n; ++i) {
    const W along = vdot(c, d[i]);
    apart = apart && finite_value(along) && along > margin;
  }
  return apart;
}
template <class Policy, class W>
LWSCCD_HD LWSCCD_HOST_INLINE bool differences_apart(const VertexFaceQuery<W>& q, const Vec3<W>& m, W perturbation) {
  const Vec3<W> d[6] = {vsub(q.p0, q.a0), vsub(q.p0, q.b0), vsub(q.p0, q.c0), vsub(q.p1, q.a1), vsub(q.p1, q.b1), vsub(q.p1, q.c1)};
  return differences_apart<Policy>(d, 6, m, perturbation);
}
template <class Policy, class W>
LWSCCD_HD LWSCCD_HOST_INLINE bool differences_apart(const EdgeEdgeQuery<W>& q, const Vec3<W>& m, W perturbation) {
  const Vec3<W> d[8] = {vsub(q.a0, q.c0), vsub(q.a0, q.d0), vsub(q.b0, q.c0), vsub(q.b0, q.d0),
                        vsub(q.a1, q.c1), vsub(q.a1, q.d1), vsub(q.b1, q.c1), vsub(q.b1, q.d1)};
  return differences_apart<Policy>(d, 8, m, perturbation);
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

/// The screen's tests on a query already in its working precision W, with m a per-axis bound on
/// its coordinates: true when no query whose coordinates are within `perturbation` m_k of its own
/// touches (before params.time_limit). `mixed`, when given, is set when the whole step is asked
/// for and the cubic's Bernstein coefficients on [0, 1] certainly have both signs: then no
/// screen in any precision rejects the pair by the cubic (the exact coefficients have both signs,
/// and a computed one is within its rounding bound of the exact one).
template <class Policy, class W, class Q, class T>
LWSCCD_HD bool screen_in_space(const Q& q, const CcdParams<T>& params, W perturbation, const Vec3<W>& m);
template <class Policy, class W, class Q, class T>
LWSCCD_HD bool screen_by_cubic(const Q& q, const CcdParams<T>& params, W perturbation, const Vec3<W>& m, bool* mixed = nullptr);
template <class Policy, class W, class Q, class T>
LWSCCD_HD bool screen_with(const Q& q, const CcdParams<T>& params, W perturbation, const Vec3<W>& m, bool* mixed = nullptr) {
  if (mixed) *mixed = false;
  return screen_in_space<Policy>(q, params, perturbation, m) || screen_by_cubic<Policy>(q, params, perturbation, m, mixed);
}

/// screen_with's first part: the features apart in space over the step (swept boxes; a window's
/// boxes; the differences of their points at the same time), before any cubic. A batch may run
/// the two parts apart (the GPU's screen gathers the pairs this part leaves into full warps).
template <class Policy, class W, class Q, class T>
LWSCCD_HD bool screen_in_space(const Q& q, const CcdParams<T>& params, W perturbation, const Vec3<W>& m) {
  // Swept boxes apart: no arithmetic but the pad, so it goes first.
  if (swept_boxes_apart(q, vscale(m, W(4) * perturbation))) return true;
  // Only [0, time_limit) asked for (mode earliest's windows): the boxes over the smallest dyadic
  // [0, w] that covers it, which are far smaller than the whole step's when w is short. (w is a
  // power of two, so its comparisons with the time limit are exact in T.)
  if (params.time_limit <= T(0.5)) {
    W w = W(0.5);
    for (int level = 1; level < 30 && T(w / 2) >= params.time_limit; ++level) w /= 2;
    const W tiny = W(4) * std::numeric_limits<W>::denorm_min();
    const Vec3<W> pad = vscale(m, W(20) * perturbation);
    if (window_boxes_apart(q, w, Vec3<W>{fadd(pad.x, tiny), fadd(pad.y, tiny), fadd(pad.z, tiny)})) return true;
  }
  // The features' relative motion: cheaper than the cubic, and it decides most pairs of a real
  // step, whose features move much as their neighbours do. (After a window's boxes, which over a
  // short window reject nearly every pair alone; the verdict does not depend on the order.)
  return Policy::kCornerDifferences && differences_apart<Policy>(q, m, perturbation);
}

/// screen_with's second part: the cubic's Bernstein signs on the step (or on the smallest dyadic
/// window that covers [0, time_limit)).
template <class Policy, class W, class Q, class T>
LWSCCD_HD bool screen_by_cubic(const Q& q, const CcdParams<T>& params, W perturbation, const Vec3<W>& m, bool* mixed) {
  W b[4];
  const W k = W(Policy::kCoefficientBound), slack = underflow_slack(fmul(W(4), max_component(m)), 3);
  const W screen = fadd(fmul(k, screening_bernstein(q, b, m, perturbation)), slack);
  const bool finite = finite_value(screen) && finite_value(b[0]) && finite_value(b[1]) && finite_value(b[2]) && finite_value(b[3]);
  if (!finite) return false;
  if (same_sign_beyond(b, screen)) return true;
  if (!(params.time_limit < T(1))) {
    if (mixed) {
      const bool positive = b[0] > screen || b[1] > screen || b[2] > screen || b[3] > screen;
      const bool negative = b[0] < -screen || b[1] < -screen || b[2] < -screen || b[3] < -screen;
      *mixed = positive && negative;
    }
    return false;
  }
  // Only [0, time_limit) is asked for (mode earliest's windows): the cubic on the smallest dyadic
  // [0, 2^-k] that covers it, by k left halvings, each adding its rounding to the bound as in the
  // refinement (a halving is a convex combination, so the bound on [0, 1] still bounds the error).
  BernsteinPiece<W> piece{{b[0], b[1], b[2], b[3]}, screen, screen};
  // A wider piece that keeps its sign already covers the window: stop there (most pairs do early).
  for (int level = 0; level < 30 && T(exact_pow2_neg<W>(level + 1)) >= params.time_limit; ++level) {
    if (level > 0 && same_sign_beyond(piece.c, piece.bound)) return true;
    BernsteinPiece<W> left, right;
    bernstein_halves<Policy>(piece, left, right);
    piece = left;
  }
  return same_sign_beyond(piece.c, piece.bound);
}

/// The certified path's cheap first step in the precision the path computes in (double for
/// double and float inputs): true when the query is certainly a miss by its swept boxes or by the
/// cubic's coefficients under the screening bound (with params.time_limit < 1: no contact before
/// it, the cubic restricted to [0, time_limit)). certified_screen puts the single-precision
/// screen in front of it.
template <class Policy, class Q, class T>
LWSCCD_HD bool certified_screen_double(const Q& q_in, const CcdParams<T>& params) {
  using W = typename certified_compute<T>::type;
  if (params.min_separation > T(0)) return false;  // the cubic only speaks of contact
  const auto q = q_in.template cast<W>();
  return screen_with<Policy>(q, params, W(unit_roundoff<T>()), coordinate_magnitude(q));
}

/// The cubic's Bernstein piece on [0, 1] with its perturbed and as-given bounds (the coefficient
/// bound of ccd_filters.hpp, plus underflow's share for differences up to `mag`); false when a
/// value is not finite (overflow: the caller leaves the query undecided).
template <class Policy, class Q, class W>
LWSCCD_HD LWSCCD_HOST_INLINE bool cubic_on_step(const Q& q, W mag, W perturbation, BernsteinPiece<W>& root,
                                                const Vec3<W>* magnitude = nullptr) {
  const W k = W(Policy::kCoefficientBound), slack = underflow_slack(mag, 3);
  W rounding_bound = W(0);
  const W coefficient_bound = coplanarity_bernstein(q, root.c, perturbation, &rounding_bound, magnitude);
  root.bound = fadd(fmul(k, coefficient_bound), slack);
  root.exact = fadd(fmul(k, rounding_bound), slack);
  bool finite = finite_value(root.bound);
  for (int i = 0; i < 4; ++i) finite = finite && finite_value(root.c[i]);
  return finite;
}

}  // namespace lwsccd::detail
