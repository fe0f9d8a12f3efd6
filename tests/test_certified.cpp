// The certified fast path (certified_ccd.hpp) on generated hard cases with exactly known answers,
// and mutation checks: each of its error bounds, removed, lets a wrong answer through (its
// filter, refinement in levels and screen with a time limit: test_certified_refine.cpp).
#include <catch2/catch.hpp>

#include <algorithm>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "certified_test_support.hpp"
#include "lwsccd/narrow_phase/certified_ccd.hpp"

using namespace lwsccd;
using namespace lwsccd::certified_test;

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
