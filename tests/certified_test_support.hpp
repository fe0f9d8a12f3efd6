// What the certified-path tests share (test_certified.cpp, test_certified_refine.cpp): contact
// scenarios in exact dyadic coordinates with exactly known answers, the generators of the hard
// kinds, a run over them that counts misses, and policies with an error bound shrunk or a search
// step removed (the mutation checks).
#pragma once

#include <catch2/catch.hpp>

#include <algorithm>
#include <cstdio>
#include <map>
#include <random>
#include <string>

#include "lwsccd/narrow_phase/certified_ccd.hpp"

namespace lwsccd::certified_test {

// A contact scenario in exact dyadic coordinates (multiples of 1/8, small): the eight points and
// the exact earliest contact time (as a ratio of small dyadics, exact in long double), or -1.
struct Case {
  std::string kind;
  bool vertex_face;
  Vec3<long double> p[8];
  long double toi;
};

inline long double eighth(std::mt19937& rng, int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng) / 8.0L; }

// Builds the generators' cases: every kind the certified path finds hard.
inline std::vector<Case> hard_cases(std::mt19937& rng, int per_kind) {
  std::vector<Case> out;
  using V = Vec3<long double>;
  for (int n = 0; n < per_kind; ++n) {
    const long double h0 = eighth(rng, 1, 64), h1 = eighth(rng, 1, 64), tc = h0 / (h0 + h1);
    const long double x = eighth(rng, 1, 24), y = eighth(rng, 1, 64 - 8 * 3 - 8) / 2;  // inside (0,0)-(8,0)-(0,8)
    const V a{0, 0, 0}, b{8, 0, 0}, c{0, 8, 0};
    // Vertex through the interior of a static triangle.
    out.push_back({"vf interior", true, {V{x, y, -h0}, a, b, c, V{x, y, h1}, a, b, c}, tc});
    // Through an edge (y = 0) while moving across the edge's line: on the edge exactly at tc.
    out.push_back({"vf on a moving edge crossing", true, {V{x, -h0 / 4, -h0}, a, b, c, V{x, h1 / 4, h1}, a, b, c}, tc});
    // Through a triangle vertex.
    out.push_back({"vf through a vertex", true, {V{0, 0, -h0}, a, b, c, V{0, 0, h1}, a, b, c}, tc});
    // Contact exactly at t = 0 and at t = 1.
    out.push_back({"vf at t = 0", true, {V{x, y, 0}, a, b, c, V{x, y, h1}, a, b, c}, 0});
    out.push_back({"vf at t = 1", true, {V{x, y, -h0}, a, b, c, V{x, y, 0}, a, b, c}, 1});
    // Coplanar motion: the vertex slides in the plane into the triangle (enters at x = 0).
    const long double s0 = eighth(rng, 8, 64), s1 = eighth(rng, 1, 16);
    out.push_back({"vf coplanar sliding in", true, {V{-s0, y, 0}, a, b, c, V{s1, y, 0}, a, b, c}, s0 / (s0 + s1)});
    // A sliver triangle, the vertex through its middle.
    const V sb{8, 0, 0}, sc{4, 1.0L / 64, 0};
    out.push_back({"vf sliver triangle", true, {V{4, 1.0L / 128, -h0}, a, sb, sc, V{4, 1.0L / 128, h1}, a, sb, sc}, tc});
    // A zero-area triangle (collinear corners); the vertex through the segment it is.
    const V zc{4, 0, 0};
    out.push_back({"vf zero-area triangle", true, {V{x, 0, -h0}, a, sb, zc, V{x, 0, h1}, a, sb, zc}, tc});
    // Edge-edge: crossing edges, the first coming down through the second.
    const V ea0{-8, y, 0}, ea1{8, y, 0}, eb0{x, -8, 0}, eb1{x, 8, 0};
    out.push_back({"ee crossing", false,
                   {ea0 + V{0, 0, -h0}, ea1 + V{0, 0, -h0}, eb0, eb1, ea0 + V{0, 0, h1}, ea1 + V{0, 0, h1}, eb0, eb1}, tc});
    // Parallel edges overlapping, one coming down onto the other.
    const V pb0{-4, y, 0}, pb1{4, y, 0};
    out.push_back({"ee parallel", false,
                   {ea0 + V{0, 0, -h0}, ea1 + V{0, 0, -h0}, pb0, pb1, ea0 + V{0, 0, h1}, ea1 + V{0, 0, h1}, pb0, pb1}, tc});
    // Collinear edges closing end to end.
    const V ca0{-16, 0, 0}, cb0{4, 0, 0}, cb1{12, 0, 0};
    out.push_back({"ee collinear end to end", false,
                   {ca0, V{4 - h0, 0, 0}, cb0, cb1, ca0, V{4 + h1, 0, 0}, cb0, cb1}, tc});
    // Touching at t = 0.
    out.push_back({"ee at t = 0", false, {ea0, ea1, eb0, eb1, ea0 + V{0, 0, h1}, ea1 + V{0, 0, h1}, eb0, eb1}, 0});
  }
  return out;
}

// Coplanar motion in the plane z = 0 moving to z = fall: a vertex c slides along the edge a-b (the
// diagonal y = x) and onto it, approaching `slide / approach` times slower than it slides, the
// other end d above the line; c is on the edge exactly at toi. Only the inside test can exclude
// time there (the cubic is 0), and over an interval its bound covers the sliding motion, so a
// band of intervals before the contact stays unknown on every level of the search.
inline std::vector<Case> coplanar_sliding_cases(std::mt19937& rng, int n) {
  using V = Vec3<long double>;
  std::vector<Case> out;
  for (int i = 0; i < n; ++i) {
    const long double h0 = eighth(rng, 1, 64), h1 = eighth(rng, 1, 64), toi = h0 / (h0 + h1);
    const long double approach = std::ldexp(1.0L, -std::uniform_int_distribution<int>(10, 16)(rng));
    const long double slide = eighth(rng, 1, 16) * std::ldexp(1.0L, -std::uniform_int_distribution<int>(4, 8)(rng));
    const long double along = eighth(rng, 1, 32), fall = eighth(rng, 1, 64);
    const V a{0, 0, 0}, b{8, 8, 0}, up{0, 0, fall}, cd{-2, 6, 0};
    const V c0{along, along + h0 * approach, 0}, c1{along + slide, along + slide - h1 * approach, fall};
    out.push_back({"ee coplanar sliding onto an edge", false, {a, b, c0, c0 + cd, a + up, b + up, c1, c1 + cd}, toi});
  }
  return out;
}

// A vertex sliding into a triangle in a tilted plane (rotations by 3-4-5 and 5-12-13 triangles),
// moved by `offset`: the exact configuration touches, its rounding leaves the cubic as noise.
inline VertexFaceQuery<double> tilted_coplanar_contact(std::mt19937& rng, const Vec3<long double>& offset = {0, 0, 0}) {
  auto rotate = [](const Vec3<long double>& v) {
    const Vec3<long double> r{(3 * v.x - 4 * v.y) / 5, (4 * v.x + 3 * v.y) / 5, v.z};
    return Vec3<long double>{r.x, (5 * r.y - 12 * r.z) / 13, (12 * r.y + 5 * r.z) / 13};
  };
  const long double y = eighth(rng, 1, 16), s0 = eighth(rng, 8, 64), s1 = eighth(rng, 1, 16);
  const Vec3<long double> pts[8] = {{-s0, y, 0}, {0, 0, 0}, {8, 0, 0}, {0, 8, 0}, {s1, y, 0}, {0, 0, 0}, {8, 0, 0}, {0, 8, 0}};
  VertexFaceQuery<double> q;
  Vec3<double>* out = &q.p0;
  for (int i = 0; i < 8; ++i) out[i] = (rotate(pts[i]) + offset).cast<double>();
  return q;
}

// Exact transforms of a case: axis permutation and signs, scaling by 2^k, translation by 2^20.
inline Case transformed(const Case& c, int permutation, int signs, int scale, bool translate) {
  Case t = c;
  const int axes[6][3] = {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 2, 1}, {2, 1, 0}, {1, 0, 2}};
  for (auto& q : t.p) {
    const Vec3<long double> o = q;
    for (int k = 0; k < 3; ++k) q[k] = o[axes[permutation][k]] * (((signs >> k) & 1) ? -1 : 1);
    q = q * std::ldexp(1.0L, scale);
    if (translate) q = q + Vec3<long double>{std::ldexp(1.0L, 20 + scale), -std::ldexp(1.0L, 20 + scale), 0};
  }
  return t;
}

template <class T, class Q>
inline Q as_query(const Case& c) {
  return Q{c.p[0].cast<T>(), c.p[1].cast<T>(), c.p[2].cast<T>(), c.p[3].cast<T>(),
           c.p[4].cast<T>(), c.p[5].cast<T>(), c.p[6].cast<T>(), c.p[7].cast<T>()};
}

struct Outcome {
  std::size_t cases = 0, misses = 0, outside_interval = 0, undecided = 0, fallback_misses = 0;
};

// The policy's classification and the whole method on one case whose every coordinate is exact in T.
template <class Policy, class T>
inline void check_case(const Case& c, Outcome& o) {
  const CcdParams<T> params;
  CertifiedAnswer<T> a;
  CcdResult<T> full;
  if (c.vertex_face) {
    const auto q = as_query<T, VertexFaceQuery<T>>(c);
    a = detail::certified_classify<Policy>(q, params);
    full = CertifiedCcdT<Filtered<InclusionCcd>, Policy>::vertex_face(q, params);
  } else {
    const auto q = as_query<T, EdgeEdgeQuery<T>>(c);
    a = detail::certified_classify<Policy>(q, params);
    full = CertifiedCcdT<Filtered<InclusionCcd>, Policy>::edge_edge(q, params);
  }
  // Rounding to T (float, translated) perturbs the case: then only the lower bound is exact.
  bool exact = true;
  for (const auto& x : c.p) exact = exact && x.cast<T>().template cast<long double>() == x;
  ++o.cases;
  o.misses += a.certainty == Certainty::miss;
  o.undecided += a.certainty == Certainty::undecided;
  // A float contact within the tolerance is one within float's rounding (as the fallback's): only
  // its lower bound is exact.
  const bool interval_exact = exact && !(a.tolerance && sizeof(T) == 4);
  if (a.certainty == Certainty::hit && (a.lo > c.toi || (interval_exact && a.hi < c.toi))) ++o.outside_interval;
  if (!full.hit || full.toi > c.toi) ++o.fallback_misses;
}

template <class Policy, class T>
inline Outcome run_generators(int per_kind, bool print) {
  std::mt19937 rng(20261122);
  std::map<std::string, Outcome> by_kind;
  Outcome all;
  for (const Case& base : hard_cases(rng, per_kind)) {
    for (int scale : {0, 60, -60})
      for (bool translate : {false, true}) {
        const Case c = transformed(base, int(rng() % 6), int(rng() % 8), scale, translate);
        check_case<Policy, T>(c, by_kind[base.kind]);
        check_case<Policy, T>(c, all);
      }
  }
  if (print)
    for (const auto& [kind, o] : by_kind)
      std::printf("  %-6s %-30s %4zu cases: %zu undecided, %zu certified misses, %zu intervals without the TOI\n",
                  sizeof(T) == 4 ? "float" : "double", kind.c_str(), o.cases, o.undecided, o.misses, o.outside_interval);
  return all;
}

// The sound policy with the bounds scaled by the given percentages.
template <int kCoefficient, int kSplit, int kInside>
struct ShrunkPolicy : CertifiedPolicy {
  static constexpr double kCoefficientBound = kCoefficient / 100.0;
  static constexpr double kSplitBound = kSplit / 100.0;
  static constexpr double kInsideBound = kInside / 100.0;
};

// ShrunkPolicy with the double path alone (no single-precision pass).
template <int kCoefficient, int kSplit, int kInside>
struct ShrunkDoublePolicy : ShrunkPolicy<kCoefficient, kSplit, kInside> {
  static constexpr bool kSingleFirst = false;
};

// The sound policy with the single-precision screen's input bound scaled by the given percentage.
template <int kInput>
struct ShrunkInputPolicy : CertifiedPolicy {
  static constexpr double kSingleInputBound = kInput / 100.0;
};

// The double screen alone (no single-precision screen in front of it).
struct DoubleScreenPolicy : CertifiedPolicy {
  static constexpr bool kSingleFirst = false;
};

// The single-precision filter's first round alone.
struct SingleFirstRoundPolicy : CertifiedPolicy {
  static constexpr bool kSingleSecondRound = false;
};

// Pairs the single passes leave searched in double from [0, 1] (no search in single precision).
struct NoSingleDescentPolicy : CertifiedPolicy {
  static constexpr bool kSingleDescent = false;
};

// The double tail halves down to the leaf instead of proving the leaf it guesses.
struct NoDescentJumpPolicy : CertifiedPolicy {
  static constexpr bool kDescentJump = false;
};

// The search in single precision halves its certain descent in float before it hands the
// interval to double (as far as float decides the middle signs).
struct NoHandOffAtDescentPolicy : CertifiedPolicy {
  static constexpr bool kHandOffAtDescent = false;
};

// The double tail proves its leaf from the cubic built in double only (no values at the points).
struct NoJumpAtPointsPolicy : CertifiedPolicy {
  static constexpr bool kJumpAtPoints = false;
};

// The sound policy with the bounds of f at a point from the query's points (B15) scaled.
template <int kPoint>
struct ShrunkPointPolicy : CertifiedPolicy {
  static constexpr double kPointBound = kPoint / 100.0;
};

// The sound policy with B17's own bound (the pairs of floats against the query as given) scaled.
template <int kPairs>
struct ShrunkFloatPairPolicy : CertifiedPolicy {
  static constexpr double kFloatPairBound = kPairs / 100.0;
};

// The halving search alone, without the certain descent.
struct NoDescentPolicy : CertifiedPolicy {
  static constexpr bool kCertainDescent = false;
};

}  // namespace lwsccd::certified_test
