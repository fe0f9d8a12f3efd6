// lwsccd — what the inclusion search tests on a box: the function's values at its corners, the
// query's setup (bounds, tolerance), separating directions and the ranges along them, and
// examine_box's verdict (apart, inside the tolerance, or split).
// Part of inclusion_ccd.hpp: include <lwsccd/narrow_phase/inclusion_ccd.hpp>, not this file.
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
#include "lwsccd/narrow_phase/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase/detail/inclusion_boxes.hpp"

namespace lwsccd::detail {

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
// no product of the bound underflows below eps's denormal term). docs/NARROW_PHASE.md, section 2.3.
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

}  // namespace lwsccd::detail
