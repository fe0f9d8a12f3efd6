// The certified fast path (certified_ccd.hpp) on generated hard cases with exactly known answers,
// and mutation checks: each of its error bounds, removed, lets a wrong answer through.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cstdio>
#include <map>
#include <random>
#include <string>

#include "lwsccd/narrow_phase/certified_ccd.hpp"

using namespace lwsccd;

namespace {

// A contact scenario in exact dyadic coordinates (multiples of 1/8, small): the eight points and
// the exact earliest contact time (as a ratio of small dyadics, exact in long double), or -1.
struct Case {
  std::string kind;
  bool vertex_face;
  Vec3<long double> p[8];
  long double toi;
};

long double eighth(std::mt19937& rng, int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng) / 8.0L; }

// Builds the generators' cases: every kind the certified path finds hard.
std::vector<Case> hard_cases(std::mt19937& rng, int per_kind) {
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

// Exact transforms of a case: axis permutation and signs, scaling by 2^k, translation by 2^20.
Case transformed(const Case& c, int permutation, int signs, int scale, bool translate) {
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
Q as_query(const Case& c) {
  return Q{c.p[0].cast<T>(), c.p[1].cast<T>(), c.p[2].cast<T>(), c.p[3].cast<T>(),
           c.p[4].cast<T>(), c.p[5].cast<T>(), c.p[6].cast<T>(), c.p[7].cast<T>()};
}

struct Outcome {
  std::size_t cases = 0, misses = 0, outside_interval = 0, undecided = 0, fallback_misses = 0;
};

// The policy's classification and the whole method on one case whose every coordinate is exact in T.
template <class Policy, class T>
void check_case(const Case& c, Outcome& o) {
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
Outcome run_generators(int per_kind, bool print) {
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

// The halving search alone, without the certain descent.
struct NoDescentPolicy : CertifiedPolicy {
  static constexpr bool kCertainDescent = false;
};

}  // namespace

TEST_CASE("certified path: hard generated cases never missed, intervals contain the exact TOI", "[narrow][certified]") {
  for (const Outcome& o : {run_generators<CertifiedPolicy, double>(12, true), run_generators<CertifiedPolicy, float>(12, true),
                           run_generators<NoDescentPolicy, double>(12, false), run_generators<NoDescentPolicy, float>(12, false)}) {
    CHECK(o.cases > 500);
    CHECK(o.misses == 0);
    CHECK(o.outside_interval == 0);
    CHECK(o.fallback_misses == 0);  // the whole method (fallback included): a hit no later than the TOI
  }
}

// The certified path without its tolerance contacts: what it leaves undecided on a boundary.
struct NoToleranceContactsPolicy : CertifiedPolicy {
  static constexpr bool kToleranceContacts = false;
};

TEST_CASE("certified path: contacts on a boundary settled within the tolerance, as the fallback settles them", "[narrow][certified]") {
  // Contacts exactly on a feature's boundary (a vertex through a triangle's edge or corner,
  // sliding in along the plane, collinear edges end to end) and the same moved beside the boundary
  // by a few multiples of the contact distance (tolerance x motion): a query the search leaves
  // undecided may become a tolerance hit at the same lower bound, and only where the fallback
  // searching from that bound finds a contact too, no later than the hit's interval.
  std::mt19937 rng(15);
  std::vector<Case> cases;
  using V = Vec3<long double>;
  const V a{0, 0, 0}, b{8, 0, 0}, c{0, 8, 0};
  for (int n = 0; n < 48; ++n) {
    const long double h0 = eighth(rng, 1, 64), h1 = eighth(rng, 1, 64), tc = h0 / (h0 + h1), x = eighth(rng, 1, 63);
    for (long double beside : {0.0L, 1e-6L, 4e-6L, 3e-5L}) {
      // Down through the edge y = 0, or beside it (outside the triangle by `beside` x the motion).
      const long double off = -beside * (h0 + h1);
      cases.push_back({"vf through an edge", true, {V{x, off, -h0}, a, b, c, V{x, off, h1}, a, b, c}, beside == 0 ? tc : -1});
      cases.push_back({"vf through a corner", true, {V{off, off, -h0}, a, b, c, V{off, off, h1}, a, b, c}, beside == 0 ? tc : -1});
      // Edge down onto the triangle's edge line end to end (collinear at tc).
      cases.push_back({"ee end on an edge", false,
                       {V{8 - off, 0, -h0}, V{12, 0, -h0}, b, c, V{8 - off, 0, h1}, V{12, 0, h1}, b, c}, beside == 0 ? tc : -1});
    }
  }
  std::size_t undecided_before = 0, settled = 0, changed_otherwise = 0, fallback_disagrees = 0, toi_outside = 0, exact_settled = 0;
  double float_early = 0;
  auto check = [&](const Case& k, auto tag) {
    using T = decltype(tag);
    const CcdParams<T> params;
    auto classify_both = [&](const auto& q) {
      const CertifiedAnswer<T> with = detail::certified_classify<CertifiedPolicy>(q, params);
      const CertifiedAnswer<T> without = detail::certified_classify<NoToleranceContactsPolicy>(q, params);
      if (without.certainty != Certainty::undecided) {
        changed_otherwise += with.certainty != without.certainty || with.lo != without.lo || with.hi != without.hi || with.tolerance;
        return;
      }
      ++undecided_before;
      if (with.certainty == Certainty::undecided) {
        changed_otherwise += with.lo != without.lo;
        return;
      }
      ++settled;
      // The window's end rounded in T: in float lo + tolerance may round up by an ulp of lo.
      const T width = sizeof(T) == 8 ? params.tolerance : 2 * params.tolerance;
      changed_otherwise += with.certainty != Certainty::hit || !with.tolerance || with.lo != without.lo || with.hi - with.lo > width;
      CcdParams<T> rest = params;
      rest.time_from = without.lo;
      CcdResult<T> fallback;
      if constexpr (std::is_same_v<std::decay_t<decltype(q)>, VertexFaceQuery<T>>) fallback = Filtered<InclusionCcd>::vertex_face(q, rest);
      else fallback = Filtered<InclusionCcd>::edge_edge(q, rest);
      fallback_disagrees += !fallback.hit || fallback.toi > with.hi;
      if (k.toi >= 0) {
        ++exact_settled;
        // The exact contact just after lo; in float only lo is exact (a contact within float's
        // rounding, as the fallback's answer), and how early it is gets reported.
        toi_outside += with.lo > k.toi || (sizeof(T) == 8 && k.toi - with.lo > 2 * params.tolerance);
        if (sizeof(T) == 4) float_early = std::max(float_early, double(k.toi - with.lo));
      }
    };
    for (int scale : {0, 40, -40}) {
      const Case t = transformed(k, int(rng() % 6), int(rng() % 8), scale, false);
      if (t.vertex_face) classify_both(as_query<T, VertexFaceQuery<T>>(t));
      else classify_both(as_query<T, EdgeEdgeQuery<T>>(t));
    }
  };
  for (const Case& k : cases) check(k, 0.0), check(k, 0.0f);
  std::printf("  tolerance contacts: %zu of %zu undecided queries settled (%zu exact contacts), %zu other changes, fallback "
              "disagreeing %zu, exact TOI outside %zu (float: lo up to %.3g before it)\n", settled, undecided_before, exact_settled,
              changed_otherwise, fallback_disagrees, toi_outside, float_early);
  CHECK(settled > 100);
  CHECK(exact_settled > 50);
  CHECK(changed_otherwise == 0);
  CHECK(fallback_disagrees == 0);
  CHECK(toi_outside == 0);
}

TEST_CASE("certified path: easy cases are decided without the fallback", "[narrow][certified]") {
  // A vertex through a triangle's middle with plenty of motion, and one passing well beside it.
  const VertexFaceQuery<double> through{{1, 1, -1}, {0, 0, 0}, {4, 0, 0}, {0, 4, 0}, {1, 1, 3}, {0, 0, 0}, {4, 0, 0}, {0, 4, 0}};
  const auto hit = CertifiedCcd::classify(through, CcdParams<double>{});
  REQUIRE(hit.certainty == Certainty::hit);
  CHECK(hit.lo <= 0.25);
  CHECK(hit.hi >= 0.25);
  CHECK(hit.hi - hit.lo <= 1e-6);
  VertexFaceQuery<double> beside = through;
  beside.p0 = {9, 1, -1}, beside.p1 = {9, 1, 3};
  CHECK(CertifiedCcd::classify(beside, CcdParams<double>{}).certainty == Certainty::miss);
  VertexFaceQuery<double> outside_plane_crossing = through;  // crosses the plane, beside the triangle
  outside_plane_crossing.p0 = {3, 3, -1}, outside_plane_crossing.p1 = {3, 3, 3};
  CHECK(CertifiedCcd::classify(outside_plane_crossing, CcdParams<double>{}).certainty == Certainty::miss);
  // A minimum separation is left to the fallback.
  CcdParams<double> separated;
  separated.min_separation = 1e-3;
  CHECK(CertifiedCcd::classify(through, separated).certainty == Certainty::undecided);
  // Time limit: a contact at 0.25 is ignored when only earlier ones are wanted.
  CcdParams<double> limited;
  limited.time_limit = 0.125;
  CHECK(CertifiedCcd::classify(through, limited).certainty != Certainty::hit);
}

TEST_CASE("certified path: removing any error bound lets wrong answers through (mutation check)", "[narrow][certified]") {
  // Coplanar motion in a tilted plane: the exact configuration (rotations by 3-4-5 and 5-12-13
  // triangles) touches, its rounding leaves the cubic as noise. Without the coefficient bound the
  // noise is taken for a sign: certified misses of true contacts.
  std::mt19937 rng(7);
  auto rotate = [](const Vec3<long double>& v) {
    const Vec3<long double> r{(3 * v.x - 4 * v.y) / 5, (4 * v.x + 3 * v.y) / 5, v.z};
    return Vec3<long double>{r.x, (5 * r.y - 12 * r.z) / 13, (12 * r.y + 5 * r.z) / 13};
  };
  std::size_t misses_sound = 0, misses_mutated = 0, tilted = 0;
  for (int n = 0; n < 400; ++n) {
    const long double y = eighth(rng, 1, 16), s0 = eighth(rng, 8, 64), s1 = eighth(rng, 1, 16);
    const Vec3<long double> pts[8] = {{-s0, y, 0}, {0, 0, 0}, {8, 0, 0}, {0, 8, 0}, {s1, y, 0}, {0, 0, 0}, {8, 0, 0}, {0, 8, 0}};
    VertexFaceQuery<double> q;
    Vec3<double>* out = &q.p0;
    for (int i = 0; i < 8; ++i) out[i] = rotate(pts[i]).cast<double>();
    ++tilted;
    misses_sound += detail::certified_classify<CertifiedPolicy>(q, CcdParams<double>{}).certainty == Certainty::miss;
    misses_mutated += detail::certified_classify<ShrunkPolicy<0, 100, 100>>(q, CcdParams<double>{}).certainty == Certainty::miss;
  }
  std::printf("  tilted coplanar contacts: %zu; certified misses %zu (sound), %zu (coefficient bound removed)\n", tilted,
              misses_sound, misses_mutated);
  CHECK(misses_sound == 0);
  CHECK(misses_mutated > 0);

  // Without the inside test's bound (rounding and motion within the interval), a vertex that
  // meets a triangle's edge while crossing the edge's line is judged outside at the interval's
  // middle: certified misses, or intervals without the TOI.
  const Outcome sound = run_generators<CertifiedPolicy, double>(8, false);
  const Outcome no_inside = run_generators<ShrunkPolicy<100, 100, 0>, double>(8, false);
  std::printf("  generated cases: %zu misses + %zu bad intervals (sound), %zu + %zu (inside bound removed)\n", sound.misses,
              sound.outside_interval, no_inside.misses, no_inside.outside_interval);
  CHECK(sound.misses + sound.outside_interval == 0);
  CHECK(no_inside.misses + no_inside.outside_interval > 0);

  // The halving bound, against long double: de Casteljau halves of random cubics, 24 levels
  // down a random path, stay within the accumulated bound of the exact coefficients; without
  // that bound they do not.
  std::uniform_real_distribution<double> coef(-1, 1);
  std::size_t violations_sound = 0, violations_mutated = 0;
  for (int n = 0; n < 200; ++n) {
    detail::BernsteinPiece<double> sound_piece{{coef(rng), coef(rng), coef(rng), coef(rng)}, 0, 0}, mutated_piece = sound_piece;
    long double ref[4] = {sound_piece.c[0], sound_piece.c[1], sound_piece.c[2], sound_piece.c[3]};
    for (int level = 0; level < 24; ++level) {
      const bool right = rng() & 1;
      detail::BernsteinPiece<double> l, r;
      detail::bernstein_halves<CertifiedPolicy>(sound_piece, l, r);
      sound_piece = right ? r : l;
      detail::bernstein_halves<ShrunkPolicy<100, 0, 100>>(mutated_piece, l, r);
      mutated_piece = right ? r : l;
      const long double m01 = (ref[0] + ref[1]) / 2, m12 = (ref[1] + ref[2]) / 2, m23 = (ref[2] + ref[3]) / 2;
      const long double m012 = (m01 + m12) / 2, m123 = (m12 + m23) / 2, mid = (m012 + m123) / 2;
      const long double next[2][4] = {{ref[0], m01, m012, mid}, {mid, m123, m23, ref[3]}};
      for (int i = 0; i < 4; ++i) ref[i] = next[right][i];
      for (int i = 0; i < 4; ++i) {
        violations_sound += std::fabs(static_cast<long double>(sound_piece.c[i]) - ref[i]) > sound_piece.bound;
        violations_mutated += std::fabs(static_cast<long double>(mutated_piece.c[i]) - ref[i]) > mutated_piece.bound;
      }
    }
  }
  std::printf("  halving: %zu coefficients outside the bound (sound), %zu (bound removed)\n", violations_sound,
              violations_mutated);
  CHECK(violations_sound == 0);
  CHECK(violations_mutated > 0);
}

TEST_CASE("certified path: the certain descent agrees with the halving search and contains the TOI", "[narrow][certified]") {
  // Vertices through a moving triangle and edges through moving edges at random (dyadic) times
  // and places, inside and just beside: the descent decides most contacts, and must give the
  // halving search's certainty and an interval that overlaps its interval and holds the TOI.
  std::mt19937 rng(20261123);
  std::uniform_int_distribution<int> grid(-64, 64);
  auto coordinate = [&] { return grid(rng) / 16.0; };
  std::size_t hits = 0, disagreements = 0, apart = 0, without_toi = 0;
  auto compare = [&](const auto& q, double toi) {
    using T = std::decay_t<decltype(q.points()[0].x)>;
    const CcdParams<T> params;
    const CertifiedAnswer<T> fast = detail::certified_classify<CertifiedPolicy>(q, params);
    const CertifiedAnswer<T> slow = detail::certified_classify<NoDescentPolicy>(q, params);
    hits += fast.certainty == Certainty::hit;
    // A miss on one side and a hit on the other is a contradiction; undecided may meet either.
    disagreements += (fast.certainty == Certainty::miss && slow.certainty == Certainty::hit) ||
                     (fast.certainty == Certainty::hit && slow.certainty == Certainty::miss);
    if (fast.certainty == Certainty::hit && slow.certainty == Certainty::hit) apart += fast.hi < slow.lo || slow.hi < fast.lo;
    // toi is a contact (maybe not the earliest: the tilting triangle's cubic may have more roots).
    if (fast.certainty == Certainty::hit && toi >= 0) {
      without_toi += fast.lo > T(toi);
      CHECK(fast.hi - fast.lo <= params.tolerance);
    }
  };
  for (int n = 0; n < 3000; ++n) {
    // The plane z = 0 at t = toi: every point's z is s (t - toi) for its own speed s.
    const double toi = std::uniform_int_distribution<int>(1, 1023)(rng) / 1024.0;
    auto point = [&](double x, double y, double z_speed, double dx, double dy, Vec3d& p0, Vec3d& p1) {
      p0 = {x, y, -z_speed * toi};
      p1 = {x + dx, y + dy, z_speed * (1 - toi)};
    };
    const double speed[4] = {1.0 + rng() % 8, 0.5 * (rng() % 3), 0.25 * (rng() % 3), 0.5 * (rng() % 2)};
    VertexFaceQuery<double> vf;
    const Vec3d a{coordinate(), coordinate(), 0}, b = a + Vec3d{4, 0, 0}, c = a + Vec3d{0, 4, 0};
    const bool beside = rng() % 4 == 0;  // outside the triangle at the plane time
    point(a.x + (beside ? 5.0 : 1.0), a.y + 1.0, speed[0], 0, 0, vf.p0, vf.p1);
    point(a.x, a.y, -speed[1], 0.25, 0, vf.a0, vf.a1);
    point(b.x, b.y, -speed[2], 0, 0.25, vf.b0, vf.b1);
    point(c.x, c.y, -speed[3], 0, 0, vf.c0, vf.c1);
    // Shift the moving corners so that at toi they sit at a, b, c: then the vertex is inside.
    for (Vec3d* p : {&vf.a0, &vf.a1}) *p = *p - Vec3d{0.25 * toi, 0, 0};
    for (Vec3d* p : {&vf.b0, &vf.b1}) *p = *p - Vec3d{0, 0.25 * toi, 0};
    compare(vf, beside ? -1.0 : toi);
    compare(vf.cast<float>(), -1.0);  // rounded to float: only agreement is checked
    EdgeEdgeQuery<double> ee;
    const double y = coordinate(), x = coordinate();
    point(-8, y, speed[0], 0, 0, ee.a0, ee.a1);
    point(8, y, speed[0], 0, 0, ee.b0, ee.b1);
    point(x, beside ? y + 9 : -8, -speed[1], 0, 0, ee.c0, ee.c1);
    point(x, y + 8, -speed[1], 0, 0, ee.d0, ee.d1);
    compare(ee, beside ? -1.0 : toi);
  }
  std::printf("  certain descent: %zu hits, %zu contradictions with the halving search, %zu disjoint intervals, %zu lower bounds past the TOI\n",
              hits, disagreements, apart, without_toi);
  CHECK(hits > 4000);
  CHECK(disagreements == 0);
  CHECK(apart == 0);
  CHECK(without_toi == 0);
}

TEST_CASE("certified filter: a query it decides gets the whole search's answer, in every mode", "[narrow][certified]") {
  // The GPU's first refinement step (CertifiedFilter) decides only what certified_refine answers
  // the same way (a miss, or undecided from the same time): the hard cases, with the vertex or an edge moved beside (near misses), under
  // the default parameters, mode set, a time limit and a coarse tolerance, double and float (whose
  // rounding makes pieces that only the query as given excludes).
  using Filter = detail::CertifiedFilter<CertifiedPolicy>;
  std::mt19937 rng(11);
  std::vector<Case> cases = hard_cases(rng, 8);
  const std::size_t base = cases.size();
  for (std::size_t k = 0; k < base; ++k)
    for (long double shift : {0.25L, 3.0L, 24.0L}) {
      Case beside = cases[k];
      for (int i : {0, 4}) beside.p[i] = beside.p[i] + Vec3<long double>{shift, shift / 2, 0};
      cases.push_back(beside);
    }
  std::vector<CcdParams<double>> settings(4);
  settings[1].mode = CcdMode::set;
  settings[2].time_limit = 0.3;
  settings[3].tolerance = 0.2;
  std::size_t excluded = 0, whole = 0, wrong = 0, refine_misses = 0, noted_lower = 0, second_round = 0;
  auto check = [&](const auto& q, const CcdParams<double>& double_params) {
    using T = std::decay_t<decltype(q.points()[0].x)>;
    CcdParams<T> params;
    params.mode = double_params.mode;
    params.time_limit = static_cast<T>(double_params.time_limit);
    params.tolerance = static_cast<T>(double_params.tolerance);
    detail::Noted<T> noted;
    const CertifiedAnswer<T> a = detail::certified_refine<CertifiedPolicy>(q, params);
    refine_misses += a.certainty == Certainty::miss;
    // The first round alone (the level-kInsideFrom intervals), then with the second (the
    // intervals left unknown split to the next inside-test level, as the GPU runs it).
    const bool first = Filter::decides(q, params, noted, false);
    if (!first && !Filter::decides(q, params, noted)) {
      ++whole;
      return;
    }
    second_round += !first;
    ++excluded;
    noted_lower += noted.any;
    if (noted.any) {
      // What the GPU's filter kernel settles such a query with: undecided from the noted time, or
      // a contact within the tolerance right after it.
      const CertifiedAnswer<T> settled = CertifiedCcd::undecided_from(q, params, noted.lower);
      wrong += a.certainty != settled.certainty || a.lo != settled.lo || a.hi != settled.hi;
      wrong += settled.lo != noted.lower;
    }
    else wrong += a.certainty != Certainty::miss || a.lo != T(0) || a.hi != T(1);
  };
  for (const CcdParams<double>& params : settings)
    for (const Case& c : cases)
      for (int scale : {0, 40}) {
        const Case t = transformed(c, int(rng() % 6), int(rng() % 8), scale, rng() % 2 == 0);
        if (t.vertex_face) check(as_query<double, VertexFaceQuery<double>>(t), params), check(as_query<float, VertexFaceQuery<float>>(t), params);
        else check(as_query<double, EdgeEdgeQuery<double>>(t), params), check(as_query<float, EdgeEdgeQuery<float>>(t), params);
      }
  std::printf("  certified filter: %zu queries decided (%zu by the second round, %zu undecided from a noted time; the whole "
              "search: %zu misses), %zu searched whole, %zu wrong\n", excluded, second_round, noted_lower, refine_misses, whole, wrong);
  CHECK(excluded > 100);  // the second round: see test_narrow.cpp's folded cloth (none of these reach it)
  CHECK(noted_lower > 0);
  CHECK(whole > 0);
  CHECK(wrong == 0);
}

TEST_CASE("certified path: a refinement stopped at a level, then run whole, gives the whole answer", "[narrow][certified]") {
  std::mt19937 rng(7);
  const std::vector<Case> cases = hard_cases(rng, 6);
  std::size_t deferred_at_3 = 0, finished_at_3 = 0;
  auto check = [&](const auto& q) {
    using T = std::decay_t<decltype(q.points()[0].x)>;
    const CcdParams<T> params;
    const CertifiedAnswer<T> whole = CertifiedCcd::refine(q, params);
    auto compare = [&](const CertifiedAnswer<T>& part, bool deferred) {
      if (deferred) {  // stopped: undecided, nothing claimed
        CHECK(part.certainty == Certainty::undecided);
        CHECK(part.lo == T(0));
      } else {
        CHECK(part.certainty == whole.certainty);
        CHECK(part.lo == whole.lo);
        CHECK(part.hi == whole.hi);
      }
    };
    bool d1 = false, d3 = false, d8 = false;
    const CertifiedAnswer<T> a1 = CertifiedCcd::refine_until<1>(q, params, &d1);
    const CertifiedAnswer<T> a3 = CertifiedCcd::refine_until<3>(q, params, &d3);
    const CertifiedAnswer<T> a8 = CertifiedCcd::refine_until<8>(q, params, &d8);
    compare(a1, d1);
    compare(a3, d3);
    compare(a8, d8);
    deferred_at_3 += d3;
    finished_at_3 += !d3;
    CHECK((!d8 || d3));  // deeper limits stop no more searches
  };
  std::vector<Case> with_misses = cases;
  for (const Case& c : cases)  // the vertex moved beside the triangle: it crosses the plane only
    if (c.vertex_face) {
      Case beside = c;
      beside.p[0] = beside.p[0] + Vec3<long double>{24, 0, 0};
      beside.p[4] = beside.p[4] + Vec3<long double>{24, 0, 0};
      with_misses.push_back(beside);
    }
  for (const Case& c : with_misses)
    for (int scale : {0, 60}) {
      const Case t = transformed(c, 0, 0, scale, false);
      if (t.vertex_face) check(as_query<double, VertexFaceQuery<double>>(t)), check(as_query<float, VertexFaceQuery<float>>(t));
      else check(as_query<double, EdgeEdgeQuery<double>>(t)), check(as_query<float, EdgeEdgeQuery<float>>(t));
    }
  CHECK(deferred_at_3 > 0);  // both outcomes were exercised
  CHECK(finished_at_3 > 0);
}

// The GPU warp's way of running the inside tests (WarpInsideSubtree), on the CPU: a test not at
// hand is evaluated with its subtree (the interval and 4 levels below it, 31 intervals, deeper than
// the search goes skipped) and the search reads the verdicts from there. `wrong_place` reads a
// neighbour's verdict instead (a mutation that the comparison must catch).
struct SubtreeInside {
  int max_level = 0, wrong_place = 0;
  int root_level = -1;
  std::uint32_t root_index = 0;
  detail::InsideVerdict verdicts[31] = {};
  int asked = 0, evaluated = 0;
  template <class Compute>
  detail::InsideVerdict operator()(int level, std::uint32_t index, const Compute& compute) {
    ++asked;
    const int depth = level - root_level;
    if (!(root_level >= 0 && depth >= 0 && depth < 5 && (index >> depth) == root_index)) {
      root_level = level, root_index = index;
      ++evaluated;
      for (int place = 0; place < 31; ++place) {
        int d = 0;
        while ((2 << d) <= place + 1) ++d;
        const std::uint32_t offset = static_cast<std::uint32_t>(place + 1 - (1 << d));
        verdicts[place] = level + d <= max_level ? compute(level + d, (index << d) | offset) : detail::InsideVerdict::unknown;
      }
    }
    const int d = level - root_level;
    const int place = (1 << d) - 1 + static_cast<int>(index - (root_index << d));
    return verdicts[(place + wrong_place) % 31];
  }
};

TEST_CASE("certified path: inside tests evaluated ahead by subtrees give the one-by-one answer", "[narrow][certified]") {
  std::mt19937 rng(17);
  const std::vector<Case> cases = hard_cases(rng, 6);
  int asked = 0, evaluated = 0, differ_when_wrong = 0, queries = 0;
  auto check = [&](const auto& q) {
    using T = std::decay_t<decltype(q.points()[0].x)>;
    for (CcdMode mode : {CcdMode::contacts, CcdMode::set}) {
      CcdParams<T> params;
      params.mode = mode;
      const CertifiedAnswer<T> whole = CertifiedCcd::refine<false>(q, params);
      SubtreeInside inside;
      inside.max_level = detail::certified_max_level(params.tolerance);
      const CertifiedAnswer<T> ahead = CertifiedCcd::refine_with<false>(q, params, inside);
      CHECK(ahead.certainty == whole.certainty);
      CHECK(ahead.lo == whole.lo);
      CHECK(ahead.hi == whole.hi);
      asked += inside.asked, evaluated += inside.evaluated, ++queries;
      SubtreeInside wrong;
      wrong.max_level = inside.max_level;
      wrong.wrong_place = 1;
      const CertifiedAnswer<T> misread = CertifiedCcd::refine_with<false>(q, params, wrong);
      differ_when_wrong += misread.certainty != whole.certainty || misread.lo != whole.lo || misread.hi != whole.hi;
    }
  };
  for (const Case& c : cases)
    for (int scale : {0, 60}) {
      const Case t = transformed(c, 0, 0, scale, false);
      if (t.vertex_face) check(as_query<double, VertexFaceQuery<double>>(t)), check(as_query<float, VertexFaceQuery<float>>(t));
      else check(as_query<double, EdgeEdgeQuery<double>>(t)), check(as_query<float, EdgeEdgeQuery<float>>(t));
    }
  INFO(queries << " searches: " << asked << " inside tests asked, " << evaluated << " subtrees evaluated");
  CHECK(queries > 100);
  CHECK(evaluated * 2 < asked);     // most tests were read from a subtree evaluated ahead
  CHECK(differ_when_wrong > 0);     // the comparison sees a misread verdict
}

TEST_CASE("inclusion search: time_from drops the time a caller proved free of contact", "[narrow][certified]") {
  // A vertex through a triangle's middle at t = 0.25.
  const VertexFaceQuery<double> through{{1, 1, -1}, {0, 0, 0}, {4, 0, 0}, {0, 4, 0}, {1, 1, 3}, {0, 0, 0}, {4, 0, 0}, {0, 4, 0}};
  CcdParams<double> params;
  const CcdResult<double> plain = InclusionCcd::vertex_face(through, params);
  REQUIRE(plain.hit);
  params.time_from = 0.2;  // still before the contact: the same contact, no earlier than 0.2 - tolerance
  const CcdResult<double> from = InclusionCcd::vertex_face(through, params);
  REQUIRE(from.hit);
  CHECK(from.toi <= 0.25);
  CHECK(from.toi >= 0.2 - params.tolerance);
  CHECK(from.toi >= plain.toi);
  params.time_from = 0.5;  // a (false) claim past the only contact: nothing left to find
  CHECK_FALSE(InclusionCcd::vertex_face(through, params).hit);
}

TEST_CASE("certified screen with a time limit: rejects only pairs whose cubic keeps its sign before it", "[narrow][certified]") {
  // A vertex falling through a static triangle, crossing its plane at tc: the windowed screen must
  // keep the pair for every window that reaches tc, and may drop it for windows ending before.
  using V = Vec3<double>;
  const V a{0, 0, 0}, b{1, 0, 0}, c{0, 1, 0};
  std::size_t dropped = 0;
  for (int k = 1; k <= 20; ++k) {
    const double tc = std::ldexp(1.0, -k) * 0.75;  // between 2^-(k+1) and 2^-k
    const VertexFaceQuery<double> q{V{0.2, 0.2, tc}, a, b, c, V{0.2, 0.2, tc - 1.0}, a, b, c};
    for (int w = 0; w <= 24; ++w) {
      CcdParams<double> params;
      params.time_limit = std::ldexp(1.0, -w);
      const bool rejected = CertifiedCcd::screen(q, params);
      INFO("contact at " << tc << ", window 2^-" << w);
      if (params.time_limit > tc) REQUIRE_FALSE(rejected);  // the contact lies in the window
      dropped += rejected;
      // Consistent with the refinement: a hit it certifies starts before the window's end.
      const auto answer = CertifiedCcd::refine(q, params);
      if (params.time_limit > tc) REQUIRE(answer.certainty == Certainty::hit);
      else REQUIRE(answer.certainty != Certainty::hit);
    }
  }
  CHECK(dropped > 100);  // windows that end well before the contact are screened out
}

TEST_CASE("certified screen with a time limit: the window's boxes never drop a contact inside it", "[narrow][certified]") {
  // Edge-edge and vertex-face contacts at tc, far from the origin and at several scales: every
  // window that reaches tc keeps the pair (the boxes over [0, w] must still overlap there, with
  // their rounding and the inputs' perturbation covered), and short windows drop it.
  using V = Vec3<double>;
  std::size_t dropped = 0, kept = 0;
  for (const double scale : {1.0, std::ldexp(1.0, 40), std::ldexp(1.0, -40)}) {
    for (const double offset : {0.0, 1e6}) {
      const V o{offset * scale, -offset * scale, offset * scale};
      auto at = [&](double x, double y, double z) { return V{o.x + x * scale, o.y + y * scale, o.z + z * scale}; };
      for (int k = 1; k <= 24; ++k) {
        const double tc = std::ldexp(1.0, -k) * 0.75;
        const EdgeEdgeQuery<double> ee{at(-1, 0, tc), at(1, 0, tc), at(0, -1, 0), at(0, 1, 0),
                                       at(-1, 0, tc - 1), at(1, 0, tc - 1), at(0, -1, 0), at(0, 1, 0)};
        const VertexFaceQuery<double> vf{at(0.2, 0.2, tc), at(0, 0, 0), at(1, 0, 0), at(0, 1, 0),
                                         at(0.2, 0.2, tc - 1), at(0, 0, 0), at(1, 0, 0), at(0, 1, 0)};
        for (int w = 1; w <= 26; ++w) {
          CcdParams<double> params;
          params.time_limit = std::ldexp(1.0, -w);
          INFO("scale " << scale << ", offset " << offset << ", contact at " << tc << ", window 2^-" << w);
          const bool ee_rejected = CertifiedCcd::screen(ee, params), vf_rejected = CertifiedCcd::screen(vf, params);
          if (params.time_limit > tc) {
            REQUIRE_FALSE(ee_rejected);
            REQUIRE_FALSE(vf_rejected);
            kept += 2;
          } else {
            dropped += ee_rejected + vf_rejected;
          }
        }
      }
    }
  }
  CHECK(kept > 500);
  CHECK(dropped > 1000);
}
