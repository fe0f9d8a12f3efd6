// lwsccd — the single-precision screen on several pairs at once, for the CPU batch: the same
// operations as certified_screen_single in the same order, on a vector of lanes (GCC/Clang vector
// extensions: SSE, AVX or NEON as the compiler targets), so every lane's verdict is the one-pair
// screen's bit for bit. Why: the screen is the same arithmetic for every pair and most pairs of a
// step end there; one pair at a time it was a fifth of a CPU step (cloth-ball).
// Part of narrow_phase.hpp: include <lwsccd/narrow_phase/narrow_phase.hpp>, not this file.
#pragma once

#include <cstdint>
#include <cstring>
#include <limits>

#include "lwsccd/narrow_phase/certified_ccd.hpp"

#if (defined(__GNUC__) || defined(__clang__)) && !defined(__CUDACC__)
#define LWSCCD_SCREEN_IN_LANES 1
#endif

namespace lwsccd::detail {

/// How many pairs the CPU batch screens at once: a vector register's floats (wider vectors than
/// the target has are split, and their selects done a lane at a time).
#if defined(__AVX__)
inline constexpr int kScreenLanes = 8;
#else
inline constexpr int kScreenLanes = 4;
#endif

/// True when screen_single_in_lanes may stand for certified_screen_single: contact (no minimum
/// separation), over the whole step or a window [0, time_limit) of mode earliest.
template <class T>
inline bool screen_in_lanes_applies(const CcdParams<T>& params) {
#if defined(LWSCCD_SCREEN_IN_LANES)
  return !(params.min_separation > T(0));
#else
  (void)params;
  return false;
#endif
}

#if defined(LWSCCD_SCREEN_IN_LANES)
typedef float ScreenLane __attribute__((vector_size(4 * kScreenLanes)));
typedef std::int32_t ScreenLaneMask __attribute__((vector_size(4 * kScreenLanes)));

/// Which points the screen pairs up, as certified_screen.hpp and ccd_filters.hpp do (indices into
/// points(): the two swept boxes' points, and the coplanarity's differences p, a, b at t = 0 and
/// t = 1 as minuend, subtrahend).
template <class Q>
struct ScreenPoints;
template <class T>
struct ScreenPoints<VertexFaceQuery<T>> {
  static constexpr int kFirstCount = 2, kSecondCount = 6;
  static constexpr int kFirst[2] = {0, 4}, kSecond[6] = {1, 2, 3, 5, 6, 7};  // {p0, p1}, {a0, b0, c0, a1, b1, c1}
  // p0 - a0, p1 - a1, b0 - a0, b1 - a1, c0 - a0, c1 - a1
  static constexpr int kDifference[6][2] = {{0, 1}, {4, 5}, {2, 1}, {6, 5}, {3, 1}, {7, 5}};
  // differences_apart's differences: p0 - a0, p0 - b0, p0 - c0, p1 - a1, p1 - b1, p1 - c1
  static constexpr int kCornerCount = 6;
  static constexpr int kCorner[6][2] = {{0, 1}, {0, 2}, {0, 3}, {4, 5}, {4, 6}, {4, 7}};
  // window_boxes_apart's points: {i, i} is point i, {i, j} its position at w on the way to point j.
  static constexpr int kWindowFirst[2][2] = {{0, 0}, {0, 4}};                                      // p0, p(w)
  static constexpr int kWindowSecond[6][2] = {{1, 1}, {2, 2}, {3, 3}, {1, 5}, {2, 6}, {3, 7}};  // a0, b0, c0, a(w), b(w), c(w)
};
template <class T>
struct ScreenPoints<EdgeEdgeQuery<T>> {
  static constexpr int kFirstCount = 4, kSecondCount = 4;
  static constexpr int kFirst[4] = {0, 1, 4, 5}, kSecond[4] = {2, 3, 6, 7};  // {a0, b0, a1, b1}, {c0, d0, c1, d1}
  // c0 - a0, c1 - a1, b0 - a0, b1 - a1, d0 - c0, d1 - c1
  static constexpr int kDifference[6][2] = {{2, 0}, {6, 4}, {1, 0}, {5, 4}, {3, 2}, {7, 6}};
  // differences_apart's differences: a0 - c0, a0 - d0, b0 - c0, b0 - d0, then the same at t = 1
  static constexpr int kCornerCount = 8;
  static constexpr int kCorner[8][2] = {{0, 2}, {0, 3}, {1, 2}, {1, 3}, {4, 6}, {4, 7}, {5, 6}, {5, 7}};
  // window_boxes_apart's points: {i, i} is point i, {i, j} its position at w on the way to point j.
  static constexpr int kWindowFirst[4][2] = {{0, 0}, {1, 1}, {0, 4}, {1, 5}};  // a0, b0, a(w), b(w)
  static constexpr int kWindowSecond[4][2] = {{2, 2}, {3, 3}, {2, 6}, {3, 7}};  // c0, d0, c(w), d(w)
};

namespace lanes {
inline ScreenLane abs(ScreenLane a) {
  return reinterpret_cast<ScreenLane>(reinterpret_cast<ScreenLaneMask>(a) & 0x7fffffff);
}
// The selects of vec.hpp's min, max and max_component, lane by lane (NaN alike).
inline ScreenLane min(ScreenLane a, ScreenLane b) { return a < b ? a : b; }
inline ScreenLane max(ScreenLane a, ScreenLane b) { return a > b ? a : b; }
inline ScreenLane max_component(const ScreenLane v[3]) {
  const ScreenLane xy = v[0] > v[1] ? v[0] : v[1];
  return xy > v[2] ? xy : v[2];
}
inline void cross(const ScreenLane a[3], const ScreenLane b[3], ScreenLane out[3]) {
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}
inline ScreenLane dot(const ScreenLane a[3], const ScreenLane b[3]) { return (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]; }
}  // namespace lanes

/// certified_screen_single<Policy>(queries[i], params) for i < n <= kScreenLanes, into miss[i],
/// where screen_in_lanes_applies(params). Each step below is the one-pair screen's (named), on
/// every lane. (The host never contracts a * b + c: the library's target compiles with
/// -ffp-contract=off, as the one-pair screen needs too.) With params.time_limit < 1 (mode
/// earliest's windows) the window's boxes are tested in lanes too, and the few pairs that neither
/// test rejects take the one-pair screen, whose halvings of the cubic differ from lane to lane.
template <class Policy, class Q, class T>
void screen_single_in_lanes(const Q* queries, int n, const CcdParams<T>& params, bool* miss) {
  using Points = ScreenPoints<Q>;
  using L = ScreenLane;
  // The queries, rounded to float as relative_single reads them, a lane each (spare lanes repeat
  // the first query).
  L x[8][3];
  for (int lane = 0; lane < kScreenLanes; ++lane) {
    const auto q = queries[lane < n ? lane : 0].template cast<float>();
    const Vec3<float>* p = q.points();
    for (int i = 0; i < 8; ++i) {
      x[i][0][lane] = p[i].x;
      x[i][1][lane] = p[i].y;
      x[i][2][lane] = p[i].z;
    }
  }
  // relative_single: the points relative to the first, and m = relative magnitude + 3 input's.
  L r[8][3], input[3] = {}, relative[3] = {}, m[3];
  for (int i = 0; i < 8; ++i)
    for (int k = 0; k < 3; ++k) {
      r[i][k] = x[i][k] - x[0][k];
      input[k] = lanes::max(input[k], lanes::abs(x[i][k]));
    }
  for (int i = 0; i < 8; ++i)
    for (int k = 0; k < 3; ++k) relative[k] = lanes::max(relative[k], lanes::abs(r[i][k]));
  for (int k = 0; k < 3; ++k) m[k] = relative[k] + input[k] * 3.0f;
  const float perturbation = single_input_perturbation<Policy>();
  // swept_boxes_apart, with the pad vscale(m, 4 perturbation).
  const float pad_scale = 4.0f * perturbation;
  ScreenLaneMask apart = {};
  for (int k = 0; k < 3; ++k) {
    const L pad = m[k] * pad_scale;
    L alo = r[Points::kFirst[0]][k], ahi = alo, blo = r[Points::kSecond[0]][k], bhi = blo;
    for (int i = 1; i < Points::kFirstCount; ++i) alo = lanes::min(alo, r[Points::kFirst[i]][k]), ahi = lanes::max(ahi, r[Points::kFirst[i]][k]);
    for (int i = 1; i < Points::kSecondCount; ++i) blo = lanes::min(blo, r[Points::kSecond[i]][k]), bhi = lanes::max(bhi, r[Points::kSecond[i]][k]);
    apart |= (ahi + pad < blo) | (bhi + pad < alo);
  }
  // Every lane apart already (neighbouring pairs of a real step mostly are): the tests left can
  // only agree. (Mode earliest's window boxes go first: over a short window they reject nearly
  // every pair, so the differences would cost for nothing there; the verdicts do not depend on
  // the order.)
  auto all_apart = [&] {
    for (int lane = 0; lane < n; ++lane)
      if (apart[lane] == 0) return false;
    for (int lane = 0; lane < n; ++lane) miss[lane] = true;
    return true;
  };
  // screen_with's window boxes: the boxes over [0, w], w the smallest power of two that covers
  // [0, time_limit), with the pad vscale(m, 20 perturbation) + tiny.
  if (params.time_limit <= T(0.5)) {
    float w = 0.5f;
    for (int level = 1; level < 30 && T(w / 2) >= params.time_limit; ++level) w /= 2;
    const float tiny = 4.0f * std::numeric_limits<float>::denorm_min();
    const float window_pad_scale = 20.0f * perturbation;
    auto window_point = [&](const int (&index)[2], int k) {
      const L& start = r[index[0]][k];
      return index[0] == index[1] ? start : start + w * (r[index[1]][k] - start);  // position_at
    };
    for (int k = 0; k < 3; ++k) {
      const L pad = m[k] * window_pad_scale + tiny;
      L alo = window_point(Points::kWindowFirst[0], k), ahi = alo;
      L blo = window_point(Points::kWindowSecond[0], k), bhi = blo;
      for (int i = 1; i < Points::kFirstCount; ++i) {
        const L x_i = window_point(Points::kWindowFirst[i], k);
        alo = lanes::min(alo, x_i), ahi = lanes::max(ahi, x_i);
      }
      for (int i = 1; i < Points::kSecondCount; ++i) {
        const L x_i = window_point(Points::kWindowSecond[i], k);
        blo = lanes::min(blo, x_i), bhi = lanes::max(bhi, x_i);
      }
      apart |= (ahi + pad < blo) | (bhi + pad < alo);
    }
  }
  if (all_apart()) return;
  // differences_apart: along each axis, then along the differences' sum, with its margins.
  if (Policy::kCornerDifferences) {
    const DifferenceMargins<float> f = difference_margins<Policy>(perturbation);
    const L zero = {};
    L d[Points::kCornerCount][3];
    for (int i = 0; i < Points::kCornerCount; ++i)
      for (int k = 0; k < 3; ++k) d[i][k] = r[Points::kCorner[i][0]][k] - r[Points::kCorner[i][1]][k];
    for (int k = 0; k < 3; ++k) {
      const L margin = m[k] * f.axis + f.smallest;
      ScreenLaneMask above = margin - margin == zero, below = above;
      for (int i = 0; i < Points::kCornerCount; ++i) {
        above &= d[i][k] > margin;
        below &= d[i][k] < -margin;
      }
      apart |= above | below;
    }
    L c[3] = {d[0][0], d[0][1], d[0][2]};
    for (int i = 1; i < Points::kCornerCount; ++i)
      for (int k = 0; k < 3; ++k) c[k] = c[k] + d[i][k];
    const L abs_c[3] = {lanes::abs(c[0]), lanes::abs(c[1]), lanes::abs(c[2])};
    const L margin = lanes::dot(abs_c, m) * f.direction + f.smallest;
    ScreenLaneMask along_apart = margin - margin == zero;
    for (int i = 0; i < Points::kCornerCount; ++i) {
      const L along = lanes::dot(c, d[i]);
      along_apart &= (along - along == zero) & (along > margin);
    }
    apart |= along_apart;
  }
  if (all_apart()) return;
  // screening_bernstein: coplanarity_of, bernstein_controls and the bound.
  L c[6][3];  // p0, p1, a0, a1, b0, b1
  for (int d = 0; d < 6; ++d)
    for (int k = 0; k < 3; ++k) c[d][k] = r[Points::kDifference[d][0]][k] - r[Points::kDifference[d][1]][k];
  L n0[3], n1[3], cross_01[3], cross_10[3], nm[3];
  lanes::cross(c[2], c[4], n0);
  lanes::cross(c[3], c[5], n1);
  lanes::cross(c[2], c[5], cross_01);
  lanes::cross(c[3], c[4], cross_10);
  for (int k = 0; k < 3; ++k) nm[k] = cross_01[k] + cross_10[k];
  const L b0 = lanes::dot(c[0], n0);
  const L b1 = (lanes::dot(c[0], nm) + lanes::dot(c[1], n0)) / 3.0f;
  const L b2 = (lanes::dot(c[1], nm) + lanes::dot(c[0], n1)) / 3.0f;
  const L b3 = lanes::dot(c[1], n1);
  L abs_p[3], abs_a[3], abs_b[3];
  for (int k = 0; k < 3; ++k) {
    abs_p[k] = lanes::max(lanes::abs(c[0][k]), lanes::abs(c[1][k]));
    abs_a[k] = lanes::max(lanes::abs(c[2][k]), lanes::abs(c[3][k]));
    abs_b[k] = lanes::max(lanes::abs(c[4][k]), lanes::abs(c[5][k]));
  }
  const L mp = lanes::max_component(abs_p), ma = lanes::max_component(abs_a), mb = lanes::max_component(abs_b);
  const L mm = lanes::max_component(m);
  const L e = mm * (2.0f * perturbation);
  const float u = unit_roundoff<float>();
  const L pe = mp + e, ae = ma + e, be = mb + e;
  const L grown = (pe * ae) * be;
  const L change = (e * (ae * be) + mp * (e * be)) + mp * (ma * e);
  const L bound = change * (1.0f + 8.0f * u) + (16.0f * u) * grown;
  const L screening = (18.0f * bound) * (1.0f + 16.0f * u) + std::numeric_limits<float>::denorm_min();
  // screen_with: k bound + underflow slack (a lane at a time: see underflow_slack), then the signs.
  L slack;
  const L slack_magnitude = 4.0f * mm;
  for (int lane = 0; lane < kScreenLanes; ++lane) slack[lane] = underflow_slack(slack_magnitude[lane], 3);
  const L screen = static_cast<float>(Policy::kCoefficientBound) * screening + slack;
  const L zero = {};
  const ScreenLaneMask finite = (screen - screen == zero) & (b0 - b0 == zero) & (b1 - b1 == zero) & (b2 - b2 == zero) & (b3 - b3 == zero);
  const ScreenLaneMask positive = (b0 > screen) & (b1 > screen) & (b2 > screen) & (b3 > screen);
  const ScreenLane low = -screen;
  const ScreenLaneMask negative = (b0 < low) & (b1 < low) & (b2 < low) & (b3 < low);
  const ScreenLaneMask rejected = apart | (finite & (positive | negative));
  // A window's pair that neither the boxes nor the whole step's signs reject: the one-pair screen
  // (the cubic halved down to the window).
  const bool window = params.time_limit < T(1);
  for (int lane = 0; lane < n; ++lane)
    miss[lane] = rejected[lane] != 0 || (window && finite[lane] != 0 && certified_screen_single<Policy>(queries[lane], params));
}
#else
template <class Policy, class Q, class T>
void screen_single_in_lanes(const Q* queries, int n, const CcdParams<T>& params, bool* miss) {
  for (int lane = 0; lane < n; ++lane) miss[lane] = certified_screen_single<Policy>(queries[lane], params);
}
#endif

}  // namespace lwsccd::detail
