// lwsccd — a conservative elemental test: inclusion-based root finding on (t, u, v) with a
// rigorous floating-point error bound (after Wang et al. 2021, "Tight Inclusion").
//
// Vertex-face: F(t, u, v) = p(t) - a(t) - u (b(t) - a(t)) - v (c(t) - a(t)), u, v >= 0, u + v <= 1.
// Edge-edge:   F(t, u, v) = a(t) + u (b(t) - a(t)) - c(t) - v (d(t) - c(t)), u, v in [0, 1].
// The features come within distance d (the minimum separation, infinity norm) at time t exactly
// when some (u, v) puts every component of F in [-d, d]. F is linear in each of t, u and v, so its
// range over a box of (t, u, v) is spanned by the values at the box's eight corners: the
// inclusion test is exact up to rounding, and the rounding is bounded by eps_k = 128 u m_k per
// axis k, where m_k is the largest |coordinate| of the query on that axis and u the unit
// roundoff of T (see docs/NARROW_PHASE.md for the derivation; it also covers a relative
// perturbation of u on every input, so a query rounded to float from exact data is covered).
//
// Boxes are examined in rounds of the earliest ones (InclusionSearch), split along the dimension
// that spreads F the most. A box that passes the test is reported as the contact when F over it
// lies within contact up to the distance the features move in `tolerance` of time, or when it
// cannot be split further (resolution `tolerance` in t, u and v), and no earlier box of its
// round was split. Its lower time bound is the reported time of impact: every box with an
// earlier time was excluded, so no contact happens before it.
//
// GUARANTEE. Never answers "no collision" when the features come within `min_separation`
// (infinity norm) at some time of the step, for the query as given or perturbed relatively by u;
// the reported toi is a lower bound of the earliest such time. Bounded work: after about
// `max_iterations` boxes (checked per round) it answers "hit" at the earliest time not yet
// excluded (gave_up = true): a false positive at worst, never a miss. Bounded memory: when more
// than Policy::kMaxBoxes boxes are live it drops the latest quarter and later searches again from
// the time the excluded part reaches, so a full store costs time, not a wrong answer.
#pragma once

#include <cassert>
#include <cmath>
#include <cstdint>
#include <limits>
#include <type_traits>

#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/core/detail/rounding.hpp"
#include "lwsccd/narrow_phase/ccd_filters.hpp"
#include "lwsccd/narrow_phase/ccd_query.hpp"

namespace lwsccd {

/// Tuning knobs of InclusionCcd.
struct InclusionPolicy {
  static constexpr int kMaxBoxes = 256;  ///< live boxes per query (sorted, double-buffered: 10 KiB on the GPU)
  static constexpr int kBatch = 32;      ///< boxes examined per round: a warp's lanes on the GPU, in turn elsewhere
};

namespace detail {

/// A dyadic box: dimension i spans [idx_i, idx_i + 1] * 2^-level_i.
struct DyadicBox {
  std::uint32_t idx[3];
  std::uint8_t level[3];
  std::uint8_t accepted;  ///< passed the contact test in a round that could not report it yet
};

// Earliest time of a box as an integer on the finest grid, for ordering.
LWSCCD_HD inline std::uint64_t box_time_key(const DyadicBox& b) {
  return static_cast<std::uint64_t>(b.idx[0]) << (40 - b.level[0]);
}
// The search's order: earlier first; at equal times the smaller (deeper) box first, so that
// ties dive; then any fixed order, so that the order is total (two distinct boxes are never
// tied) and "the k earliest boxes" is the same set however they are stored. As two words compared
// in turn: [time key (40 bits) | 127 - level sum | level t | level u] and [u index | v index |
// accepted mark] (levels are at most 31, InclusionSetup::max_level; equal time keys and t levels
// mean equal t indices, and the level sum then fixes the v level). The mark orders a box only
// against itself marked, which no store holds at once. The key is the whole box (box_of_key): the
// GPU's warp search keeps its live boxes as keys, ranked and merged by two word compares (by fields
// the ranking alone cost it ~22 K of a round's ~35 K cycles).
struct BoxOrderKey {
  std::uint64_t high, low;
};
constexpr int kMaxBoxLevel = 31;  ///< a box index has 31 bits (InclusionSetup::max_level's cap)
LWSCCD_HD inline BoxOrderKey box_order_key(const DyadicBox& b) {
  assert(b.level[0] <= kMaxBoxLevel && b.level[1] <= kMaxBoxLevel && b.level[2] <= kMaxBoxLevel);
  const std::uint64_t level_sum = static_cast<std::uint64_t>(b.level[0]) + b.level[1] + b.level[2];
  return {box_time_key(b) << 17 | (127u - level_sum) << 10 | static_cast<std::uint64_t>(b.level[0]) << 5 | b.level[1],
          static_cast<std::uint64_t>(b.idx[1]) << 33 | static_cast<std::uint64_t>(b.idx[2]) << 1 | (b.accepted ? 1u : 0u)};
}
LWSCCD_HD inline DyadicBox box_of_key(const BoxOrderKey& k) {
  const unsigned level_t = static_cast<unsigned>(k.high >> 5) & 31u, level_u = static_cast<unsigned>(k.high) & 31u;
  const unsigned level_sum = 127u - (static_cast<unsigned>(k.high >> 10) & 127u);
  DyadicBox b;
  b.idx[0] = static_cast<std::uint32_t>((k.high >> 17) >> (40u - level_t));
  b.idx[1] = static_cast<std::uint32_t>(k.low >> 33);
  b.idx[2] = static_cast<std::uint32_t>(k.low >> 1) & 0x7fffffffu;
  b.level[0] = static_cast<std::uint8_t>(level_t);
  b.level[1] = static_cast<std::uint8_t>(level_u);
  b.level[2] = static_cast<std::uint8_t>(level_sum - level_t - level_u);
  b.accepted = static_cast<std::uint8_t>(k.low & 1u);
  return b;
}
LWSCCD_HD inline bool key_before(const BoxOrderKey& a, const BoxOrderKey& b) {
  return a.high < b.high || (a.high == b.high && a.low < b.low);
}
// A stored box's time key and mark, as a box or as its key (InclusionSearch holds either).
LWSCCD_HD inline std::uint64_t box_time_key(const BoxOrderKey& k) { return k.high >> 17; }
LWSCCD_HD inline bool is_accepted(const DyadicBox& b) { return b.accepted != 0; }
LWSCCD_HD inline bool is_accepted(const BoxOrderKey& k) { return (k.low & 1u) != 0; }
LWSCCD_HD inline void whole_domain(DyadicBox& b) { b = DyadicBox{{0, 0, 0}, {0, 0, 0}, 0}; }
LWSCCD_HD inline void whole_domain(BoxOrderKey& k) { k = box_order_key(DyadicBox{{0, 0, 0}, {0, 0, 0}, 0}); }
LWSCCD_HD inline bool box_before(const DyadicBox& a, const DyadicBox& b) { return key_before(box_order_key(a), box_order_key(b)); }

template <class T>
LWSCCD_HD T dyadic(std::uint32_t idx, int level) {
  return std::ldexp(static_cast<T>(idx), -level);
}

// F at the 8 corners of a box: f[it][iu][iv]. Q selects the vertex-face or edge-edge form.
template <class T>
LWSCCD_HD void corner_values(const VertexFaceQuery<T>& q, const T t[2], const T u[2], const T v[2], Vec3<T> f[2][2][2]) {
  for (int it = 0; it < 2; ++it) {
    const Vec3<T> p = vadd_scaled(q.p0, vsub(q.p1, q.p0), t[it]);
    const Vec3<T> a = vadd_scaled(q.a0, vsub(q.a1, q.a0), t[it]);
    const Vec3<T> ab = vsub(vadd_scaled(q.b0, vsub(q.b1, q.b0), t[it]), a);
    const Vec3<T> ac = vsub(vadd_scaled(q.c0, vsub(q.c1, q.c0), t[it]), a);
    const Vec3<T> ap = vsub(p, a);
    LWSCCD_UNROLL for (int iu = 0; iu < 2; ++iu)
      LWSCCD_UNROLL for (int iv = 0; iv < 2; ++iv) f[it][iu][iv] = vsub(vsub(ap, vscale(ab, u[iu])), vscale(ac, v[iv]));
  }
}
template <class T>
LWSCCD_HD void corner_values(const EdgeEdgeQuery<T>& q, const T t[2], const T u[2], const T v[2], Vec3<T> f[2][2][2]) {
  for (int it = 0; it < 2; ++it) {
    const Vec3<T> a = vadd_scaled(q.a0, vsub(q.a1, q.a0), t[it]);
    const Vec3<T> ab = vsub(vadd_scaled(q.b0, vsub(q.b1, q.b0), t[it]), a);
    const Vec3<T> c = vadd_scaled(q.c0, vsub(q.c1, q.c0), t[it]);
    const Vec3<T> cd = vsub(vadd_scaled(q.d0, vsub(q.d1, q.d0), t[it]), c);
    const Vec3<T> ca = vsub(a, c);
    LWSCCD_UNROLL for (int iu = 0; iu < 2; ++iu)
      LWSCCD_UNROLL for (int iv = 0; iv < 2; ++iv) f[it][iu][iv] = vsub(vadd(ca, vscale(ab, u[iu])), vscale(cd, v[iv]));
  }
}

// Bernstein coefficients of the cubic on [lo, hi] from those on [0, 1]: de Casteljau at hi keeps
// the left part [0, hi] (the triangle's left edge), then at lo / hi keeps the right part (the
// right edge). Convex combinations: the coefficients' error grows only by the rounding here.
template <class T>
LWSCCD_HD void bernstein_restrict(const T b[4], T lo, T hi, T out[4]) {
  T y[4] = {b[0], b[1], b[2], b[3]};
  T left[4];
  left[0] = y[0];
  for (int r = 1; r < 4; ++r) {
    for (int i = 0; i < 4 - r; ++i) y[i] = fadd(y[i], fmul(hi, fsub(y[i + 1], y[i])));
    left[r] = y[0];
  }
  const T s = hi > T(0) ? lo / hi : T(0);
  out[3] = left[3];
  for (int r = 1; r < 4; ++r) {
    for (int i = 0; i < 4 - r; ++i) left[i] = fadd(left[i], fmul(s, fsub(left[i + 1], left[i])));
    out[3 - r] = left[3 - r];
  }
}

template <class T>
LWSCCD_HD bool is_vertex_face(const VertexFaceQuery<T>*) {
  return true;
}
template <class T>
LWSCCD_HD bool is_vertex_face(const EdgeEdgeQuery<T>*) {
  return false;
}

/// What a query needs for examining boxes, computed once.
template <class T>
struct InclusionSetup {
  Vec3<T> eps;        ///< rounding bound of F per axis
  T d = T(0);         ///< minimum separation
  T delta = T(0);     ///< distance that counts as contact (motion in `tolerance` of time)
  T eta = T(0);       ///< widening of a box's time range for the time filter
  T time_limit = T(1);  ///< boxes starting at or after this time are dropped (CcdParams::time_limit)
  T time_from = T(0);   ///< boxes ending at or before this time are dropped (CcdParams::time_from)
  T bern[4] = {0, 0, 0, 0}, bern_bound = T(0);
  int max_level = 1;  ///< finest level per dimension
  bool vf = false, time_filter = false;
  bool separated = false;  ///< the time filter excludes the whole step
};

template <class Q, class T>
LWSCCD_HD InclusionSetup<T> inclusion_setup(const Q& q, const CcdParams<T>& params) {
  InclusionSetup<T> s;
  const T unit = unit_roundoff<T>();
  s.d = params.min_separation;
  s.time_limit = params.time_limit;
  s.time_from = params.time_from;
  // Rounding bound per axis, and the length scale for the tolerance test.
  const Vec3<T>* pts = q.points();
  Vec3<T> m{0, 0, 0};
  T motion = T(0);  // the largest displacement of a point over the step
  for (int i = 0; i < 8; ++i) m = max(m, abs(pts[i]));
  for (int i = 0; i < 4; ++i) {
    const T moved = max_component(abs(vsub(pts[i + 4], pts[i])));
    motion = moved > motion ? moved : motion;
  }
  s.eps = vadd(vscale(m, T(128) * unit), Vec3<T>{1, 1, 1} * (T(64) * std::numeric_limits<T>::denorm_min()));
  // Distance that counts as contact: how far the features move in `tolerance` of time, so the
  // reported time stays within the tolerance of the real one (a resting pair must really touch).
  s.delta = fmul(params.tolerance, motion);
  // Finest level: time resolution `tolerance`, within T's mantissa and the key's 40 bits.
  int max_level = static_cast<int>(std::ceil(-std::log2(static_cast<double>(params.tolerance))));
  max_level = max_level < 1 ? 1 : max_level;
  const int mantissa = std::numeric_limits<T>::digits - 1;
  max_level = max_level > mantissa ? mantissa : max_level;
  s.max_level = max_level > 31 ? 31 : max_level;  // 32-bit box indices
  s.vf = is_vertex_face(&q);
  // Time filter (contact only): the coplanarity cubic must vanish at a contact, so a time range
  // on which its Bernstein coefficients share a sign is excluded for every (u, v).
  s.time_filter = s.d == T(0);
  if (s.time_filter) {
    s.bern_bound = coplanarity_bernstein(q, s.bern);
    T bern_max = T(0);
    for (int i = 0; i < 4; ++i) bern_max = std::fabs(s.bern[i]) > bern_max ? std::fabs(s.bern[i]) : bern_max;
    s.separated = same_sign_beyond(s.bern, s.bern_bound);
    // Restricting adds at most 6 rounded convex steps per coefficient, and the interval is
    // widened by eta so that rounding of its ends cannot uncover a root at a box boundary.
    s.bern_bound = fadd(s.bern_bound, fmul(T(16) * unit, bern_max));
  }
  s.eta = T(8) * unit;
  return s;
}

// Separating directions of a box, from the query at the box's middle (time t, parameters u, v):
// the face normal (vertex-face), or the edges' cross product and the part of F at the middle
// that is perpendicular to the first edge (edge-edge: the second one works where the edges are
// parallel, which the cross product cannot). Any direction is sound (along_direction); these are
// the ones along which F hardly varies over a box, so that F's distance shows.
template <class T>
LWSCCD_HD int separating_directions(const VertexFaceQuery<T>& q, T t, T, T, Vec3<T> n[2]) {
  const Vec3<T> a = vadd_scaled(q.a0, vsub(q.a1, q.a0), t);
  const Vec3<T> ab = vsub(vadd_scaled(q.b0, vsub(q.b1, q.b0), t), a);
  const Vec3<T> ac = vsub(vadd_scaled(q.c0, vsub(q.c1, q.c0), t), a);
  n[0] = vcross(ab, ac);
  return 1;
}
template <class T>
LWSCCD_HD int separating_directions(const EdgeEdgeQuery<T>& q, T t, T u, T v, Vec3<T> n[2]) {
  const Vec3<T> a = vadd_scaled(q.a0, vsub(q.a1, q.a0), t);
  const Vec3<T> ab = vsub(vadd_scaled(q.b0, vsub(q.b1, q.b0), t), a);
  const Vec3<T> c = vadd_scaled(q.c0, vsub(q.c1, q.c0), t);
  const Vec3<T> cd = vsub(vadd_scaled(q.d0, vsub(q.d1, q.d0), t), c);
  n[0] = vcross(ab, cd);
  const Vec3<T> middle = vsub(vadd(vsub(a, c), vscale(ab, u)), vscale(cd, v));
  const T ab2 = vdot(ab, ab);
  n[1] = ab2 > T(0) ? vsub(middle, vscale(ab, vdot(middle, ab) / ab2)) : middle;
  return 2;
}

// n . F over a box (n any direction, scaled to a largest component of exactly 1): whether it
// stays outside [-d |n|_1, d |n|_1], so that no point of the box has F within d (infinity norm)
// of 0; and, for a direction that steers the split, how wide it is and along which dimension it
// varies most. F over a box lies in the convex hull of its corner values (it is linear in each
// of t, u, v), so n . F lies between the corners' extremes, each known to within sum_k |n_k| (eps_k + 4 u |f_k|) (the
// corners' bound plus the dot product's rounding, bounded twice over; with |n_k| <= 1 = max,
// no product of the bound underflows below eps's denormal term). docs/NARROW_PHASE.md, section 1.
template <class T>
struct AlongDirection {
  bool excluded = false;
  T width = std::numeric_limits<T>::infinity();  ///< hi - lo of n . F over the box (as computed)
  int widest = 0;                                 ///< dimension (t, u, v) along which n . F varies most
  bool above_rounding = false;                    ///< the width is well above the rounding bound
};
template <class T>
LWSCCD_HD AlongDirection<T> along_direction(Vec3<T> n, const Vec3<T> f[2][2][2], const InclusionSetup<T>& s, bool steers) {
  AlongDirection<T> r;
  const T big = max_component(abs(n));
  if (!(big > T(0)) || !(big <= std::numeric_limits<T>::max())) return r;  // no direction, or NaN
  n = Vec3<T>{n.x / big, n.y / big, n.z / big};
  const Vec3<T> size = abs(n);
  T along[8];
  T lo = std::numeric_limits<T>::infinity(), hi = -lo;
  Vec3<T> magnitude{0, 0, 0};
  for (int c = 0; c < 8; ++c) {
    const Vec3<T>& x = f[c >> 2][(c >> 1) & 1][c & 1];
    along[c] = vdot(n, x);
    if (!(along[c] == along[c])) return r;  // NaN: nothing can be concluded
    lo = along[c] < lo ? along[c] : lo;
    hi = along[c] > hi ? along[c] : hi;
    magnitude = max(magnitude, abs(x));
  }
  const T unit = unit_roundoff<T>();
  const T error = fmul(T(2), vdot(size, vadd(s.eps, vscale(magnitude, T(4) * unit))));
  const T reach = fmul(fmul(fadd(fadd(size.x, size.y), size.z), s.d), fadd(T(1), T(8) * unit));
  r.excluded = fsub(lo, error) > reach || fadd(hi, error) < -reach;
  if (r.excluded || !steers) return r;
  r.width = fsub(hi, lo);
  // A range not much wider than the rounding (features that stay in one plane, along their
  // normal) says nothing about where to split.
  r.above_rounding = r.width > fmul(error, T(64));
  T best = T(-1);
  for (int k = 0; k < 3; ++k) {
    T spread = T(0);
    for (int c = 0; c < 8; ++c) {
      if ((c >> (2 - k)) & 1) continue;  // corners on the low side of dimension k
      const T w = std::fabs(fsub(along[c | (1 << (2 - k))], along[c]));
      spread = w > spread ? w : spread;
    }
    if (spread > best) {
      best = spread;
      r.widest = k;
    }
  }
  return r;
}

enum class BoxVerdict : std::uint8_t { excluded, accepted, split_t, split_u, split_v };

/// What the test of a box's ranges (t, u, v) found: excluded, accepted, or neither (then
/// `split_t` stands for "to be split", and the corner values and directions tell where).
template <class T>
struct RangeTest {
  BoxVerdict verdict = BoxVerdict::split_t;
  Vec3<T> f[2][2][2];
  AlongDirection<T> flattest;  ///< the flattest steering direction
  T axis_width = T(0);         ///< the widest range of F's components over the box
};

/// The inclusion test over the ranges t x u x v (any box inside the domain, dyadic or not):
/// excluded (no contact in it: past the time limits, the cubic of one sign over t when
/// `filter_time`, F apart from 0 along an axis or a separating direction), accepted (contact
/// within tolerance, or `finest`), or neither.
template <class Q, class T>
LWSCCD_HD void test_ranges(const Q& q, const InclusionSetup<T>& s, const T t[2], const T u[2], const T v[2], bool filter_time,
                           bool finest, RangeTest<T>& r) {
  r.verdict = BoxVerdict::excluded;
  // Later than the caller wants: every box after it in the search's order starts as late, so the
  // answer (the first accepted box with only excluded boxes before it) is unchanged before then.
  if (t[0] >= s.time_limit) return;
  if (t[1] <= s.time_from) return;  // before a time the caller proved free
  if (s.time_filter && filter_time) {
    T sub[4];
    const T t_lo = t[0] > s.eta ? fsub(t[0], s.eta) : T(0);
    const T t_hi = t[1] < fsub(T(1), s.eta) ? fadd(t[1], s.eta) : T(1);
    bernstein_restrict(s.bern, t_lo, t_hi, sub);
    if (same_sign_beyond(sub, s.bern_bound)) return;
  }
  corner_values(q, t, u, v, r.f);
  bool within_tolerance = true;
  for (int k = 0; k < 3; ++k) {
    T fmin = r.f[0][0][0][k], fmax = fmin;
    for (int c = 1; c < 8; ++c) {
      const T x = r.f[c >> 2][(c >> 1) & 1][c & 1][k];
      fmin = x < fmin ? x : fmin;
      fmax = x > fmax ? x : fmax;
    }
    r.axis_width = fsub(fmax, fmin) > r.axis_width ? fsub(fmax, fmin) : r.axis_width;
    const T low = fsub(fmin, s.eps[k]), high = fadd(fmax, s.eps[k]);
    if (low > s.d || high < -s.d) return;
    // Contact up to `delta`, and up to the rounding bound, which no subdivision can resolve.
    const T reach = fadd(fadd(s.d, s.delta), fmul(T(2), s.eps[k]));
    within_tolerance = within_tolerance && high <= reach && low >= -reach;
  }
  // Along directions other than the axes: parallel edges a few tolerances apart, or a vertex
  // hovering over a tilted face, are excluded by a few boxes instead of thousands.
  {
    Vec3<T> n[2];
    const T half = T(0.5);
    const int count = separating_directions(q, fmul(fadd(t[0], t[1]), half), fmul(fadd(u[0], u[1]), half),
                                            fmul(fadd(v[0], v[1]), half), n);
    for (int i = 0; i < count; ++i) {
      // Only the second edge-edge direction steers the split (parallel edges); the face normal
      // and the cross product steering it gave up on thousands of armadillo-rollers' pairs.
      const bool steers = i == 1;
      const AlongDirection<T> a = along_direction(n[i], r.f, s, steers);
      if (a.excluded) return;
      if (steers && a.above_rounding && a.width < r.flattest.width) r.flattest = a;
    }
  }
  r.verdict = within_tolerance || finest ? BoxVerdict::accepted : BoxVerdict::split_t;
}

/// One box's test: excluded (no contact in it), accepted (contact within tolerance, or finest),
/// or which dimension to split. Times before `t_floor` are already excluded (the box is cut).
template <class Q, class T>
LWSCCD_HD BoxVerdict examine_box(const Q& q, const InclusionSetup<T>& s, const DyadicBox& box, std::uint64_t floor_key,
                                 T t_floor) {
  if (box.accepted) return BoxVerdict::accepted;
  T t[2], u[2], v[2];
  T* dims[3] = {t, u, v};
  for (int k = 0; k < 3; ++k) {
    dims[k][0] = dyadic<T>(box.idx[k], box.level[k]);
    dims[k][1] = dyadic<T>(box.idx[k] + 1, box.level[k]);
  }
  if (box_time_key(box) < floor_key) t[0] = t_floor;
  const bool finest = box.level[0] >= s.max_level && box.level[1] >= s.max_level && box.level[2] >= s.max_level;
  RangeTest<T> r;
  test_ranges(q, s, t, u, v, box.level[0] > 0 || floor_key > 0, finest, r);
  if (r.verdict != BoxVerdict::split_t) return r.verdict;
  // A box across time_limit is split in time first: its later half is then dropped at once,
  // instead of after splits of u and v over time the caller does not want (mode earliest: most
  // fallback searches end in a few rounds). Not across time_from: there the box would be split
  // as often, and on cloth-funnel's boundary contacts the GPU's longest searches got slower.
  if (t[0] < s.time_limit && t[1] > s.time_limit && box.level[0] < s.max_level) return BoxVerdict::split_t;
  // Where F along a direction is far flatter than along the axes (its range is mostly the
  // distance between the features, as for parallel edges), split where that range varies most:
  // the splits that lead to its test excluding boxes (time, for parallel edges, while u and v
  // would be split thousands of times along them).
  if (r.flattest.width < fmul(r.axis_width, T(1) / T(16)) && box.level[r.flattest.widest] < s.max_level)
    return static_cast<BoxVerdict>(static_cast<int>(BoxVerdict::split_t) + r.flattest.widest);
  // Otherwise split the dimension along which F varies most (time first on ties).
  int split = -1;
  T best = T(-1);
  for (int k = 0; k < 3; ++k) {
    if (box.level[k] >= s.max_level) continue;
    T spread = T(0);
    for (int c = 0; c < 8; ++c) {
      if ((c >> (2 - k)) & 1) continue;  // corners on the low side of dimension k
      const int c_hi = c | (1 << (2 - k));
      const Vec3<T> diff = vsub(r.f[c_hi >> 2][(c_hi >> 1) & 1][c_hi & 1], r.f[c >> 2][(c >> 1) & 1][c & 1]);
      const T w = max_component(abs(diff));
      spread = w > spread ? w : spread;
    }
    if (spread > best) {
      best = spread;
      split = k;
    }
  }
  return static_cast<BoxVerdict>(static_cast<int>(BoxVerdict::split_t) + split);
}

/// The search over boxes, in rounds: take the (up to) kBatch earliest boxes, examine them all
/// (apart, so that a warp's lanes can do it together), then apply the verdicts in time order. A
/// box that passes is the contact when every earlier box of its round was excluded (then no
/// contact can come before it: everything earlier is excluded); otherwise it goes back, marked,
/// and the earlier boxes' halves are looked at first. The live boxes are kept sorted (by
/// box_before, a total order), the round's new boxes merged in: one thread does it in turn here,
/// a warp does it in parallel on the GPU (narrow_phase/detail/inclusion_kernels.cuh), with the same sets, rounds and
/// answers.
///
/// Bounded memory: when more than kMaxBoxes boxes are live after a round, only the earliest
/// three quarters are kept and the earliest dropped time is remembered. Once every box before that
/// time is excluded, the search restarts from the whole domain with the times before it cut off
/// (they are excluded already): a full store costs time, not the false "hit at the current time"
/// that giving up would answer (seen on a sliver triangle in cloth-ball, where that hit was at
/// t = 0).
///
/// kStore (at most kMaxBoxes) is the room this instance has: a search that would keep more live
/// boxes than that stops with `overflow` set, so that a small first attempt (a GPU thread with
/// little memory) can hand the query over to a full one, which then gives the same answer.
/// Item: how a live box is stored, as a DyadicBox or as its BoxOrderKey (the GPU's warp search,
/// which ranks and merges them itself; apply() is for DyadicBox).
template <class Policy, class T, int kStore = Policy::kMaxBoxes, class Item = DyadicBox>
struct InclusionSearch {
  static_assert(Policy::kMaxBoxes >= 2, "lwsccd: InclusionCcd policy: kMaxBoxes must be at least 2");
  static_assert(Policy::kBatch >= 1 && Policy::kBatch <= 32, "lwsccd: InclusionCcd policy: kBatch must be in [1, 32]");
  static_assert(kStore >= 1 && kStore <= Policy::kMaxBoxes, "lwsccd: InclusionSearch: kStore must be in [1, kMaxBoxes]");
  static constexpr int kBatch = Policy::kBatch;
  static constexpr int kCapacity = Policy::kMaxBoxes;
  static constexpr int kKeep = kCapacity - kCapacity / 4;  ///< kept when more than kCapacity are live
  static constexpr int kFresh = 2 * kBatch;                ///< new boxes of a round, at most
  static constexpr int kRoom = kStore + kFresh;
  bool overflow = false;  ///< more live boxes than kStore: this instance cannot go on
  static constexpr std::uint64_t kNone = ~std::uint64_t(0);
  enum class Round : std::uint8_t { examine, no_contact, gave_up };

  Item items[2][kRoom];  ///< live boxes, sorted: items[current][head, head + size)
  int current = 0, head = 0, size = 0, batch_size = 0, examined = 0;
  std::uint64_t floor_key = 0, evicted_key = kNone;
  T t_floor = T(0);

  LWSCCD_HD const Item* batch() const { return items[current] + head - batch_size; }
  LWSCCD_HD const Item* live() const { return items[current] + head; }

  LWSCCD_HD void restart_whole() {
    current = head = 0;
    size = 1;
    whole_domain(items[0][0]);
  }
  LWSCCD_HD void start() {
    restart_whole();
    batch_size = examined = 0;
    floor_key = 0;
    evicted_key = kNone;
    t_floor = T(0);
  }
  /// A box's earliest time not cut off (a time key is exact in T: T's rounding of idx0 is scaled
  /// by a power of two either way).
  template <class Box>
  LWSCCD_HD T time_of(const Box& b) const {
    const std::uint64_t key = box_time_key(b);
    return key < floor_key ? t_floor : std::ldexp(static_cast<T>(key), -40);
  }
  /// Takes the next round's boxes (restarting past dropped boxes when needed). On gave_up,
  /// `result` holds the conservative answer.
  LWSCCD_HD Round next_round(int max_iterations, CcdResult<T>& result) {
    if (!settle_front(result)) return result.hit ? Round::gave_up : Round::no_contact;
    int k = 0, unexamined = 0;
    while (in_batch(k)) unexamined += is_accepted(items[current][head + k]) ? 0 : 1, ++k;
    return take_batch(k, unexamined, max_iterations, result);
  }
  /// next_round in three steps, for a warp that finds the batch with one ballot: settle_front
  /// restarts past dropped boxes where needed (false: no round; `result` holds a hit when the
  /// search gave up, else none); in_batch(i): whether live box i joins the batch (the batch is a
  /// prefix of the live boxes); take_batch: takes the first k, `unexamined` of them not yet accepted.
  LWSCCD_HD bool settle_front(CcdResult<T>& result) {
    result = {};
    while (size == 0 || (evicted_key != kNone && box_time_key(items[current][head]) >= evicted_key)) {
      if (evicted_key == kNone) return false;  // everything excluded
      // No time excluded since the last restart: the store is too small for this query.
      if (evicted_key == floor_key) {
        result = {true, t_floor, true};
        return false;
      }
      floor_key = evicted_key;
      t_floor = std::ldexp(static_cast<T>(floor_key), -40);  // a box's time: exact in T
      evicted_key = kNone;
      restart_whole();
    }
    return true;
  }
  LWSCCD_HD bool in_batch(int i) const {
    return i < kBatch && i < size && (evicted_key == kNone || box_time_key(items[current][head + i]) < evicted_key);
  }
  LWSCCD_HD Round take_batch(int k, int unexamined, int max_iterations, CcdResult<T>& result) {
    const Item* first = items[current] + head;
    batch_size = k;
    head += k;
    size -= k;
    if (examined >= max_iterations) {
      result = {true, time_of(first[0]), true};  // the earliest time not excluded
      return Round::gave_up;
    }
    examined += unexamined;
    return Round::examine;
  }
  /// Whether the verdicts answer the query: the first accepted box of the round, if no box
  /// before it was split. Returns its index, or -1.
  LWSCCD_HD static int answer_index(const BoxVerdict* verdicts, int n) {
    for (int i = 0; i < n; ++i) {
      if (verdicts[i] == BoxVerdict::accepted) return i;
      if (verdicts[i] != BoxVerdict::excluded) return -1;
    }
    return -1;
  }
  /// The new boxes a verdict gives (0 to 2): the two halves of a split box, or an accepted box
  /// marked; without those that cannot matter (beyond u + v = 1 for vertex-face, before the cut,
  /// or at or after a dropped time: searched again after the restart).
  LWSCCD_HD int fresh_boxes(const DyadicBox& box, BoxVerdict verdict, bool vf, DyadicBox out[2]) const {
    int n = 0;
    auto keep = [&](const DyadicBox& b) {
      if ((static_cast<std::uint64_t>(b.idx[0]) + 1) << (40 - b.level[0]) <= floor_key) return;  // before the cut
      if (evicted_key != kNone && box_time_key(b) >= evicted_key) return;
      out[n++] = b;
    };
    if (verdict == BoxVerdict::excluded) return 0;
    if (verdict == BoxVerdict::accepted) {
      DyadicBox marked = box;
      marked.accepted = 1;
      keep(marked);
      return n;
    }
    const int split = static_cast<int>(verdict) - static_cast<int>(BoxVerdict::split_t);
    for (int half = 0; half < 2; ++half) {
      DyadicBox child = box;
      child.idx[split] = box.idx[split] * 2 + static_cast<std::uint32_t>(half);
      child.level[split] = static_cast<std::uint8_t>(box.level[split] + 1);
      if (vf) {  // vertex-face: drop boxes entirely beyond u + v = 1 (exact integer test)
        const std::uint64_t ulo = static_cast<std::uint64_t>(child.idx[1]) << (40 - child.level[1]);
        const std::uint64_t vlo = static_cast<std::uint64_t>(child.idx[2]) << (40 - child.level[2]);
        if (ulo + vlo > (std::uint64_t(1) << 40)) continue;
      }
      keep(child);
    }
    return n;
  }
  /// One thread's round end: the answer, or the new boxes merged into the live ones (kept to the
  /// earliest kKeep when more than kCapacity). True when `result` is the answer.
  LWSCCD_HD bool apply(const BoxVerdict* verdicts, bool vf, CcdResult<T>& result) {
    const DyadicBox* round = batch();
    const int answer = answer_index(verdicts, batch_size);
    if (answer >= 0) {
      result = {true, time_of(round[answer]), false};
      return true;
    }
    DyadicBox fresh[kFresh];
    int nf = 0;
    for (int i = 0; i < batch_size; ++i) nf += fresh_boxes(round[i], verdicts[i], vf, fresh + nf);
    for (int i = 1; i < nf; ++i)  // insertion sort: at most 2 kBatch boxes
      for (int j = i; j > 0 && box_before(fresh[j], fresh[j - 1]); --j) {
        const DyadicBox x = fresh[j];
        fresh[j] = fresh[j - 1];
        fresh[j - 1] = x;
      }
    const DyadicBox* a = live();
    DyadicBox* out = items[1 - current];
    const int total = size + nf, limit = total > kCapacity ? kKeep : total;
    int i = 0, j = 0;
    for (int o = 0; o <= limit && o < total; ++o) {
      const bool take_a = j == nf || (i < size && box_before(a[i], fresh[j]));
      const DyadicBox& next = take_a ? a[i++] : fresh[j++];
      if (o < limit) {
        out[o] = next;
      } else {  // the earliest dropped box
        const std::uint64_t dropped = box_time_key(next);
        evicted_key = dropped < evicted_key ? dropped : evicted_key;
      }
    }
    current = 1 - current;
    head = 0;
    size = limit;
    overflow = limit > kStore;
    return false;
  }
};

/// The search in one thread, for at most `max_rounds` rounds and kStore live boxes: false when
/// it stopped before the answer (then a full search must answer: the GPU's warp search).
template <class Policy, int kStore, class Q, class T>
LWSCCD_HD bool inclusion_try(const Q& q, const CcdParams<T>& params, int max_rounds, CcdResult<T>& result) {
  result = {};
  const InclusionSetup<T> setup = inclusion_setup(q, params);
  if (setup.separated) return true;
  InclusionSearch<Policy, T, kStore> search;
  search.start();
  BoxVerdict verdicts[Policy::kBatch];
  for (int round = 0; round < max_rounds; ++round) {
    const auto next = search.next_round(params.max_iterations, result);
    if (next == InclusionSearch<Policy, T, kStore>::Round::no_contact) {
      result = {};
      return true;
    }
    if (next == InclusionSearch<Policy, T, kStore>::Round::gave_up) return true;
    for (int i = 0; i < search.batch_size; ++i)
      verdicts[i] = examine_box(q, setup, search.batch()[i], search.floor_key, search.t_floor);
    if (search.apply(verdicts, setup.vf, result)) return true;
    if (search.overflow) return false;
  }
  return false;
}

/// The whole search in one thread (the CPU).
template <class Policy, class Q, class T>
LWSCCD_HD CcdResult<T> inclusion_solve(const Q& q, const CcdParams<T>& params) {
  CcdResult<T> result;
  inclusion_try<Policy, Policy::kMaxBoxes>(q, params, std::numeric_limits<int>::max(), result);
  return result;
}

}  // namespace detail

/// The conservative method as a policy (see the file comment for its guarantee).
template <class Policy = InclusionPolicy>
struct InclusionCcdT {
  static constexpr const char* name = "inclusion";
  static constexpr bool conservative = true;
  /// True when the method's first step (the time filter on [0, 1] and the test of the whole
  /// (t, u, v) domain) already answers "no collision": exactly the pairs for which
  /// vertex_face / edge_edge return no hit after one box. Batches use it as a cheap first pass.
  template <class Q, class T>
  LWSCCD_HD static bool quick_reject(const Q& q, const CcdParams<T>& params) {
    CcdParams<T> first = params;
    first.max_iterations = 1;
    return !detail::inclusion_solve<Policy>(q, first).hit;
  }
  template <class T>
  LWSCCD_HD static CcdResult<T> vertex_face(const VertexFaceQuery<T>& q, const CcdParams<T>& params) {
    return detail::inclusion_solve<Policy>(q, params);
  }
  template <class T>
  LWSCCD_HD static CcdResult<T> edge_edge(const EdgeEdgeQuery<T>& q, const CcdParams<T>& params) {
    return detail::inclusion_solve<Policy>(q, params);
  }
};
using InclusionCcd = InclusionCcdT<>;

namespace detail {
/// Methods whose full test is InclusionCcd's search (alone, or behind the non-penetration
/// filter): the GPU batch runs that search with a warp per query.
template <class Method>
struct inclusion_search_of : std::false_type {};
template <class Policy>
struct inclusion_search_of<InclusionCcdT<Policy>> : std::true_type {
  using policy = Policy;
  static constexpr bool filtered = false;
};
template <class Policy>
struct inclusion_search_of<Filtered<InclusionCcdT<Policy>>> : std::true_type {
  using policy = Policy;
  static constexpr bool filtered = true;
};
}  // namespace detail

template <class Policy>
struct filtered_name<InclusionCcdT<Policy>> {
  static constexpr const char* value = "filtered-inclusion";
};

}  // namespace lwsccd
