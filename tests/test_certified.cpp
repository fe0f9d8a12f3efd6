// The certified fast path (certified_ccd.hpp) on generated hard cases with exactly known answers,
// and mutation checks: each of its error bounds, removed, lets a wrong answer through (its
// filter, refinement in levels and screen with a time limit: test_certified_refine.cpp).
#include <catch2/catch.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "certified_test_support.hpp"
#include "lwsccd/features/representative.hpp"
#include "lwsccd/narrow_phase/certified_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.hpp"

using namespace lwsccd;
using namespace lwsccd::certified_test;

namespace {
// A vertex-face and an edge-edge pair near contact: small motions of jittered features of size
// 2^-10 .. 2^9, up to 2^(origin_bits - 1) from the origin.
std::pair<VertexFaceQuery<double>, EdgeEdgeQuery<double>> near_contact_pairs(std::mt19937_64& rng, int origin_bits) {
  std::uniform_real_distribution<double> jitter(-1, 1);
  const double s = std::ldexp(1.0, int(rng() % 20) - 10), o = std::ldexp(1.0, int(rng() % origin_bits));
  auto point = [&](double x, double y, double z) {
    return Vec3<double>{o + s * (x + 0.1 * jitter(rng)), -o + s * (y + 0.1 * jitter(rng)), s * (z + 0.1 * jitter(rng))};
  };
  const VertexFaceQuery<double> vf{point(0.3, 0.3, 0.2), point(0, 0, 0), point(1, 0, 0), point(0, 1, 0),
                                   point(0.3 + jitter(rng), 0.3 + jitter(rng), -0.2 * jitter(rng)), point(0, 0, 0),
                                   point(1, 0, 0), point(0, 1, 0)};
  const EdgeEdgeQuery<double> ee{point(-1, 0, 0.2), point(1, 0, 0.2), point(0, -1, 0), point(0, 1, 0),
                                 point(-1, jitter(rng), -0.2 * jitter(rng)), point(1, jitter(rng), -0.2 * jitter(rng)),
                                 point(0, -1, 0), point(0, 1, 0)};
  return {vf, ee};
}

// A vertex through a triangle's interior and an edge through an edge at t = toi, the plane z = 0
// at that time (off the dyadic grid, where the descent cannot halve; the coordinates' rounding
// moves the exact time by ~1e-16), and toi.
std::tuple<VertexFaceQuery<double>, EdgeEdgeQuery<double>, double> contacts_at_known_time(std::mt19937_64& rng) {
    const double toi = (std::uniform_int_distribution<int>(1, 1022)(rng) + 1.0 / 3.0) / 1024.0, speed = 1.0 + rng() % 8;
    const double x = std::uniform_int_distribution<int>(-64, 64)(rng) / 16.0;
    const VertexFaceQuery<double> vf{{x + 1, 1, -speed * toi}, {x, 0, 0}, {x + 4, 0, 0}, {x, 4, 0},
                                     {x + 1, 1, speed * (1 - toi)}, {x, 0, 0}, {x + 4, 0, 0}, {x, 4, 0}};
    const EdgeEdgeQuery<double> ee{{-8, x, -speed * toi}, {8, x, -speed * toi}, {x, -8, 0}, {x, 8, 0},
                                   {-8, x, speed * (1 - toi)}, {8, x, speed * (1 - toi)}, {x, -8, 0}, {x, 8, 0}};
  return {vf, ee, toi};
}

using LongVec = std::array<long double, 3>;
// The coplanarity function f at t of a query's eight points (in Q::points() order) in long double:
// coplanarity_of's differences (vertex-face: p - a, b - a, c - a; edge-edge: c - a, b - a, d - c).
long double f_long(const std::array<LongVec, 8>& x, bool vertex_face, long double t) {
  const int vf[3][2] = {{0, 1}, {2, 1}, {3, 1}}, ee[3][2] = {{2, 0}, {1, 0}, {3, 2}};
  const int(&first)[3][2] = vertex_face ? vf : ee;
  LongVec d[3];
  for (int v = 0; v < 3; ++v)
    for (int k = 0; k < 3; ++k) {
      const long double at0 = x[first[v][0]][k] - x[first[v][1]][k], at1 = x[4 + first[v][0]][k] - x[4 + first[v][1]][k];
      d[v][k] = at0 + t * (at1 - at0);
    }
  const LongVec c{d[1][1] * d[2][2] - d[1][2] * d[2][1], d[1][2] * d[2][0] - d[1][0] * d[2][2], d[1][0] * d[2][1] - d[1][1] * d[2][0]};
  return d[0][0] * c[0] + d[0][1] * c[1] + d[0][2] * c[2];
}

// Whether the single-precision screen and filter leave the pair to the refinement.
template <class Q, class T>
bool certified_first_passes_leave(const Q& q, const CcdParams<T>& params) {
  return detail::certified_first_screen<CertifiedPolicy>(q, params) == detail::ScreenVerdict::passed &&
         !detail::CertifiedFilter<CertifiedPolicy>::decides_single(q, params);
}
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

// The certified path without inside tests in pieces (CertifiedPolicy::kPieceLevels).
struct NoPiecesPolicy : CertifiedPolicy {
  static constexpr int kPieceLevels = 0;
};

TEST_CASE("certified path: coplanar contacts decided by inside tests in pieces, within the tolerance below the exact TOI",
          "[narrow][certified]") {
  // A vertex sliding onto an edge in coplanar motion (cloth-funnel's contacts of nearly shared
  // vertices): without pieces the search spends kMaxSplits on the bands of unknown intervals
  // before the contact and leaves most such pairs to the fallback; with them it settles more, each
  // a hit whose lower bound is at most the tolerance before the exact contact (exact in double).
  std::mt19937 rng(23);
  const std::vector<Case> cases = coplanar_sliding_cases(rng, 120);
  std::size_t queries = 0, hits_with = 0, hits_without = 0, undecided_with = 0, misses = 0, after_toi = 0, too_early = 0,
              fallback_misses = 0;
  for (const Case& base : cases)
    for (int permutation = 0; permutation < 6; ++permutation) {
      const Case c = transformed(base, permutation, int(rng() % 8), int(rng() % 21) - 10, false);
      const CcdParams<double> params;
      const auto q = as_query<double, EdgeEdgeQuery<double>>(c);
      const CertifiedAnswer<double> with = detail::certified_classify<CertifiedPolicy>(q, params);
      const CertifiedAnswer<double> without = detail::certified_classify<NoPiecesPolicy>(q, params);
      ++queries;
      misses += with.certainty == Certainty::miss || without.certainty == Certainty::miss;
      hits_without += without.certainty == Certainty::hit;
      undecided_with += with.certainty == Certainty::undecided;
      if (with.certainty == Certainty::hit) {
        ++hits_with;
        after_toi += with.lo > c.toi;
        too_early += c.toi - with.lo > params.tolerance;
      }
      const CcdResult<double> whole = CertifiedCcd::edge_edge(q, params);
      fallback_misses += !whole.hit || whole.toi > c.toi;
    }
  std::printf("  coplanar sliding contacts: %zu queries, hits %zu with pieces, %zu without; %zu left to the fallback\n", queries,
              hits_with, hits_without, undecided_with);
  CHECK(misses == 0);
  CHECK(after_toi == 0);
  CHECK(too_early == 0);
  CHECK(fallback_misses == 0);
  CHECK(hits_with >= hits_without + queries / 5);  // pieces settle what the bands left undecided
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
  std::size_t misses_sound = 0, misses_mutated = 0, tilted = 0;
  for (int n = 0; n < 400; ++n) {
    const VertexFaceQuery<double> q = tilted_coplanar_contact(rng);
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

  // The value at a point (bernstein_at, B11), against long double: random cubics at random dyadic
  // points of 1 to 30 bits stay within the bound; without the added bound they do not.
  std::size_t point_sound = 0, point_mutated = 0;
  for (int n = 0; n < 4000; ++n) {
    const detail::BernsteinPiece<double> piece{{coef(rng), coef(rng), coef(rng), coef(rng)}, 0, 0};
    const int bits = 1 + int(rng() % 30);
    const double s = std::ldexp(double(rng() % (1ull << bits)), -bits);
    long double c[4] = {piece.c[0], piece.c[1], piece.c[2], piece.c[3]};
    for (int level = 3; level > 0; --level)
      for (int i = 0; i < level; ++i) c[i] = c[i] + static_cast<long double>(s) * (c[i + 1] - c[i]);
    const auto sound_value = detail::bernstein_at<CertifiedPolicy>(piece, s);
    const auto mutated_value = detail::bernstein_at<ShrunkPolicy<100, 0, 100>>(piece, s);
    point_sound += std::fabs(static_cast<long double>(sound_value.value) - c[0]) > sound_value.exact;
    point_mutated += std::fabs(static_cast<long double>(mutated_value.value) - c[0]) > mutated_value.exact;
  }
  std::printf("  the cubic at a point: %zu values outside the bound (sound), %zu (bound removed)\n", point_sound, point_mutated);
  CHECK(point_sound == 0);
  CHECK(point_mutated > 0);

  // f at a point from the query's points (CubicAtPoints, B15), against long double: near-contact
  // pairs near and far from the origin, at random dyadic times of 1 to 30 bits, stay within `exact`
  // of f for the query as given and within `bound` of f for the query with every coordinate moved
  // by u m_k (either way at random); with the bounds removed they do not.
  std::size_t at_points_sound = 0, at_points_mutated = 0, moved_sound = 0, moved_mutated = 0;
  const double u = detail::unit_roundoff<double>();
  std::mt19937_64 rng64(17);
  for (int n = 0; n < 4000; ++n) {
    const auto [vf, ee] = near_contact_pairs(rng64, 24);
    const auto check = [&](const auto& q, bool vertex_face) {
      const Vec3<double> m = detail::coordinate_magnitude(q);
      const detail::CubicAtPoints<CertifiedPolicy, double> sound(q, m, u);
      const detail::CubicAtPoints<ShrunkPointPolicy<0>, double> mutated(q, m, u);
      const int bits = 1 + int(rng64() % 30);
      const double t = std::ldexp(double(rng64() % (1ull << bits)), -bits);
      std::array<LongVec, 8> given, moved;
      for (int i = 0; i < 8; ++i)
        for (int k = 0; k < 3; ++k) {
          given[i][k] = q.points()[i][k];
          moved[i][k] = given[i][k] + ((rng64() & 1) ? 1.0L : -1.0L) * static_cast<long double>(u) * m[k];
        }
      const long double exact_value = f_long(given, vertex_face, t), moved_value = f_long(moved, vertex_face, t);
      const auto s = sound.at(t), w = mutated.at(t);
      at_points_sound += std::fabs(static_cast<long double>(s.value) - exact_value) > s.exact;
      at_points_mutated += std::fabs(static_cast<long double>(w.value) - exact_value) > w.exact;
      moved_sound += std::fabs(static_cast<long double>(s.value) - moved_value) > s.bound;
      moved_mutated += std::fabs(static_cast<long double>(w.value) - moved_value) > w.bound;
    };
    check(vf, true);
    check(ee, false);
  }
  std::printf("  f from the points: %zu values outside the bound as given, %zu moved (sound); %zu, %zu (bounds removed)\n",
              at_points_sound, moved_sound, at_points_mutated, moved_mutated);
  CHECK(at_points_sound == 0);
  CHECK(moved_sound == 0);
  CHECK(at_points_mutated > 0);
  CHECK(moved_mutated > 0);
}

TEST_CASE("single precision: the input bound covers rounding to float; without it a contact is lost (mutation check)",
          "[narrow][certified][single]") {
  // relative_single against the exact relative query (long double holds x - o exactly for these
  // doubles): every coordinate within single_input_perturbation() m_k, with room for the double
  // path's own perturbation u_T |x|; the queries far from the origin and of every scale.
  std::mt19937_64 rng(43);
  std::uniform_real_distribution<double> unit(-1, 1);
  const long double p = detail::single_input_perturbation<CertifiedPolicy>();
  std::size_t outside = 0, samples = 0;
  for (int n = 0; n < 20000; ++n) {
    const double scale = std::ldexp(1.0, int(rng() % 40) - 20), offset = std::ldexp(unit(rng), int(rng() % 30) - 10);
    VertexFaceQuery<double> q;
    Vec3<double>* pts = &q.p0;
    for (int i = 0; i < 8; ++i) pts[i] = {offset + unit(rng) * scale, -offset + unit(rng) * scale, unit(rng) * scale};
    const auto s = detail::relative_single(q);
    const Vec3<float>* f = s.q.points();
    for (int i = 0; i < 8; ++i)
      for (int k = 0; k < 3; ++k) {
        const long double exact = static_cast<long double>(pts[i][k]) - static_cast<long double>(pts[0][k]);
        const long double error = std::fabs(static_cast<long double>(f[i][k]) - exact);
        outside += error + detail::unit_roundoff<double>() * std::fabs(static_cast<long double>(pts[i][k])) > p * s.m[k];
        ++samples;
      }
  }
  std::printf("  rounding to float: %zu of %zu coordinates outside the bound\n", outside, samples);
  CHECK(outside == 0);

  // A vertex rising onto a tilted triangle far from the origin, touching it exactly at t = 1.
  // Rounded to float, the triangle's raised corner rounds up and the vertex's end down, so the
  // float query ends below the plane: without the input bound (kSingleInputBound 0) the single
  // screen takes the float query's sign for the input's and answers a miss.
  std::size_t lost_sound = 0, lost_mutated = 0, cases = 0;
  for (int e = 8; e <= 14; ++e)
    for (int corner = 1; corner <= 4; ++corner) {
      const double o = std::ldexp(1.0, e), half_ulp = std::ldexp(1.0, e - 24);
      const double h = half_ulp + std::ldexp(half_ulp, -18);  // just over half an ulp of o in float: rounds up
      const double x = corner / 4.0;                           // the vertex's end: on the plane z = o + h x / 4
      const VertexFaceQuery<double> q{{o + x, o + 1, o - 1}, {o, o, o}, {o + 4, o, o + h}, {o, o + 4, o},
                                      {o + x, o + 1, o + h * x / 4}, {o, o, o}, {o + 4, o, o + h}, {o, o + 4, o}};
      ++cases;
      lost_sound += detail::certified_screen_single<CertifiedPolicy>(q, CcdParams<double>{}) ||
                    detail::CertifiedFilter<CertifiedPolicy>::decides_single(q, CcdParams<double>{});
      lost_mutated += detail::certified_screen_single<ShrunkInputPolicy<0>>(q, CcdParams<double>{}) ||
                      detail::CertifiedFilter<ShrunkInputPolicy<0>>::decides_single(q, CcdParams<double>{});
    }
  std::printf("  contacts at t = 1 that rounding to float separates: %zu; single-precision misses %zu (sound), %zu (input "
              "bound removed)\n", cases, lost_sound, lost_mutated);
  CHECK(lost_sound == 0);
  CHECK(lost_mutated > 0);
}

TEST_CASE("single-precision screen: never a miss of a true contact, misses for pairs far apart (mutation check)",
          "[narrow][certified][single]") {
  // The generated hard cases (exact TOIs; scaled by 2^-60..2^60, translated by 2^20, in double
  // and float): neither the single screen nor the single filter ever rejects a contact. Without
  // the inside test's bound the single filter takes contacts on an edge for misses.
  std::mt19937 rng(20261125);
  std::size_t contacts = 0, rejected = 0, filtered = 0, filtered_mutated = 0;
  auto check = [&](const auto& q, const auto& params) {
    rejected += detail::certified_screen_single<CertifiedPolicy>(q, params);
    filtered += detail::CertifiedFilter<CertifiedPolicy>::decides_single(q, params);
    filtered_mutated += detail::CertifiedFilter<ShrunkPolicy<100, 100, 0>>::decides_single(q, params);
  };
  for (const Case& base : hard_cases(rng, 12))
    for (int scale : {0, 60, -60})
      for (bool translate : {false, true}) {
        const Case c = transformed(base, int(rng() % 6), int(rng() % 8), scale, translate);
        ++contacts;
        if (c.vertex_face) {
          check(as_query<double, VertexFaceQuery<double>>(c), CcdParams<double>{});
          check(as_query<float, VertexFaceQuery<float>>(c), CcdParams<float>{});
        } else {
          check(as_query<double, EdgeEdgeQuery<double>>(c), CcdParams<double>{});
          check(as_query<float, EdgeEdgeQuery<float>>(c), CcdParams<float>{});
        }
      }
  std::printf("  hard cases: %zu contacts; single screen misses %zu, single filter misses %zu (sound), %zu (inside bound "
              "removed)\n", contacts, rejected, filtered, filtered_mutated);
  CHECK(contacts > 500);
  CHECK(rejected == 0);
  CHECK(filtered == 0);
  CHECK(filtered_mutated > 0);

  // Coplanar motion in a tilted plane (as the double screen's mutation check): a true contact
  // whose cubic is rounding noise. Sound: never rejected; without the coefficient bound the
  // single screen takes the noise for a sign.
  std::size_t tilted = 0, rejected_sound = 0, rejected_mutated = 0;
  for (int n = 0; n < 400; ++n) {
    const VertexFaceQuery<double> q = tilted_coplanar_contact(rng, {1000, -2000, 3000});
    ++tilted;
    rejected_sound += detail::certified_screen_single<CertifiedPolicy>(q, CcdParams<double>{});
    rejected_mutated += detail::certified_screen_single<ShrunkPolicy<0, 100, 100>>(q, CcdParams<double>{});
  }
  std::printf("  tilted coplanar contacts: %zu; single-precision misses %zu (sound), %zu (coefficient bound removed)\n",
              tilted, rejected_sound, rejected_mutated);
  CHECK(rejected_sound == 0);
  CHECK(rejected_mutated > 0);

  // Pairs apart (a vertex moving above a triangle's plane, over it or beside it, far from the
  // origin): the single screen decides them by the cubic's sign, as the double screen does.
  std::size_t apart = 0, single = 0, double_only = 0;
  for (int n = 0; n < 200; ++n) {
    const double far = std::ldexp(1.0, int(rng() % 40)), x = 0.5 + double(rng() % 64) / 8;
    const VertexFaceQuery<double> q{{far + x, far + x, 1}, {far, far, 0}, {far + 4, far, 0}, {far, far + 4, 0},
                                    {far + x, far + x, 3}, {far, far, 0}, {far + 4, far, 0}, {far, far + 4, 0}};
    ++apart;
    single += detail::certified_screen_single<CertifiedPolicy>(q, CcdParams<double>{});
    double_only += detail::certified_screen_double<CertifiedPolicy>(q, CcdParams<double>{});
  }
  CHECK(single == apart);
  CHECK(double_only == apart);
}

TEST_CASE("single precision: FP32 first never contradicts the double path", "[narrow][certified][single]") {
  // Random near-contact pairs (small motions of jittered features, near and far from the origin),
  // classified with the single screen in front and without it. A single-precision miss is a proof,
  // so the double path never finds such a pair a hit; every other answer is the same. (The single
  // screen, on coordinates relative to the pair, may decide a pair far from the origin that the
  // double screen leaves undecided: then undecided becomes a miss.)
  std::mt19937_64 rng(7);
  std::size_t pairs = 0, differ = 0, single = 0, contradicted = 0, decided_more = 0, second_round = 0;
  for (int n = 0; n < 20000; ++n) {
    const auto [vf, ee] = near_contact_pairs(rng, 30);
    const auto a = detail::certified_classify<CertifiedPolicy>(vf, CcdParams<double>{});
    const auto b = detail::certified_classify<DoubleScreenPolicy>(vf, CcdParams<double>{});
    const auto c = detail::certified_classify<CertifiedPolicy>(ee, CcdParams<double>{});
    const auto d = detail::certified_classify<DoubleScreenPolicy>(ee, CcdParams<double>{});
    // Decided a miss in single precision: the screen, the filter, or the search in float.
    auto search_miss = [](const auto& q) {
      bool done = false;
      return detail::certified_refine_single_first<CertifiedPolicy>(q, CcdParams<double>{}, done).certainty == Certainty::miss && done;
    };
    const bool vf_single = detail::certified_screen_single<CertifiedPolicy>(vf, CcdParams<double>{}) ||
                           detail::CertifiedFilter<CertifiedPolicy>::decides_single(vf, CcdParams<double>{}) || search_miss(vf);
    const bool ee_single = detail::certified_screen_single<CertifiedPolicy>(ee, CcdParams<double>{}) ||
                           detail::CertifiedFilter<CertifiedPolicy>::decides_single(ee, CcdParams<double>{}) || search_miss(ee);
    contradicted += (vf_single && b.certainty == Certainty::hit) + (ee_single && d.certainty == Certainty::hit);
    // The same answer, or a hit whose lower bound the double search noted earlier (section 3.4, B10).
    auto same_or_later_lower = [](const auto& x, const auto& y) {
      return (x.certainty == y.certainty && x.lo == y.lo && x.hi == y.hi) ||
             (x.certainty == Certainty::hit && y.certainty == Certainty::hit && x.hi == y.hi && y.lo < x.lo);
    };
    const bool vf_same = same_or_later_lower(a, b);
    const bool ee_same = same_or_later_lower(c, d);
    decided_more += (!vf_same && vf_single && b.certainty == Certainty::undecided) + (!ee_same && ee_single && d.certainty == Certainty::undecided);
    differ += (!vf_same && !(vf_single && b.certainty == Certainty::undecided)) + (!ee_same && !(ee_single && d.certainty == Certainty::undecided));
    single += vf_single + ee_single;
    // Decided only with the filter's second round (split below an interval whose test is unknown).
    second_round += (detail::CertifiedFilter<CertifiedPolicy>::decides_single(vf, CcdParams<double>{}) &&
                     !detail::CertifiedFilter<SingleFirstRoundPolicy>::decides_single(vf, CcdParams<double>{})) +
                    (detail::CertifiedFilter<CertifiedPolicy>::decides_single(ee, CcdParams<double>{}) &&
                     !detail::CertifiedFilter<SingleFirstRoundPolicy>::decides_single(ee, CcdParams<double>{}));
    pairs += 2;
  }
  std::printf("  near-contact pairs: %zu, %zu decided in single precision (%zu by the filter's second round; %zu the double "
              "path left undecided)\n", pairs, single, second_round, decided_more);
  CHECK(single > pairs / 10);
  CHECK(second_round > 0);
  CHECK(contradicted == 0);
  CHECK(differ == 0);
}

// The listed form of the single-precision filter, as the GPU's kernels run it apart (a thread a
// pair lists the intervals, a thread an interval tests them, a thread an unknown one lists its
// pieces): true where every interval left is certainly outside in float; `inside` is set where an
// interval (of either round) is certainly inside.
template <class Policy, class Q>
bool listed_filter_decides(const Q& q, const CcdParams<float>& params, bool& inside) {
  using Filter = detail::CertifiedFilter<Policy>;
  inside = false;
  std::uint32_t mask = 0;
  const int count = Filter::intervals_single(q, params, mask);
  if (count < 0) return false;
  bool decided = true;
  for (unsigned node = 0; node < 32; ++node) {
    if (!((mask >> node) & 1u)) continue;
    const detail::InsideVerdict v = Filter::inside_single(q, node);
    inside = inside || v == detail::InsideVerdict::inside;
    if (v == detail::InsideVerdict::outside) continue;
    std::uint32_t deep = 0;
    if (v != detail::InsideVerdict::unknown || !Filter::expandable(count) || (node >> Filter::kLevel) != 1u ||
        Filter::expand_single(q, params, node, deep) < 0) {
      decided = false;
      continue;
    }
    for (unsigned local = 0; local < 32; ++local) {
      if (!((deep >> local) & 1u)) continue;
      const detail::InsideVerdict d = Filter::inside_single(q, Filter::deep_node(node, local));
      inside = inside || d == detail::InsideVerdict::inside;
      decided = decided && d == detail::InsideVerdict::outside;
    }
  }
  return decided;
}

TEST_CASE("single precision: the filter on one thread (route_single) decides what its listed form decides",
          "[narrow][certified][single]") {
  // The GPU runs the float filter either way: on one thread a pair (route_single, which
  // decides_single also is) or listed (intervals_single, inside_single, expand_single, a thread
  // each). A miss exactly where the listed form finds every interval outside; the whole search
  // only for a pair with an interval inside in float, and only where asked.
  std::mt19937_64 rng(11);
  std::size_t pairs = 0, differ = 0, misses = 0, whole = 0, whole_unasked = 0, whole_not_inside = 0, first_only_differ = 0;
  const CcdParams<float> params = detail::single_params(CcdParams<double>{});
  auto check = [&](const auto& q) {
    using Filter = detail::CertifiedFilter<CertifiedPolicy>;
    bool inside = false;
    const bool decided = listed_filter_decides<CertifiedPolicy>(q, params, inside);
    const detail::SingleRoute route = Filter::route_single(q, params, false, true);
    differ += decided != (route == detail::SingleRoute::miss);
    differ += decided != Filter::decides_single(q, CcdParams<double>{});
    misses += decided;
    whole += route == detail::SingleRoute::whole_search;
    whole_not_inside += route == detail::SingleRoute::whole_search && !inside;
    whole_unasked += Filter::route_single(q, params, false, false) == detail::SingleRoute::whole_search;
    // The first round alone (no second round), likewise.
    using FirstOnly = detail::CertifiedFilter<SingleFirstRoundPolicy>;
    first_only_differ += listed_filter_decides<SingleFirstRoundPolicy>(q, params, inside) !=
                         (FirstOnly::route_single(q, params, false, true) == detail::SingleRoute::miss);
    ++pairs;
  };
  for (int n = 0; n < 20000; ++n) {
    const auto [vf, ee] = near_contact_pairs(rng, 30);
    check(vf);
    check(ee);
  }
  std::printf("  near-contact pairs: %zu, the float filter's misses %zu, sent to the whole search %zu\n", pairs, misses, whole);
  CHECK(misses > pairs / 20);
  CHECK(whole > 0);
  CHECK(whole_unasked == 0);
  CHECK(whole_not_inside == 0);
  CHECK(differ == 0);
  CHECK(first_only_differ == 0);
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

TEST_CASE("single precision: contacts searched in float with a double tail agree with the double search",
          "[narrow][certified][single]") {
  // Near-contact pairs near and far from the origin (as above) and contacts at known dyadic times,
  // classified with the search in single precision (CertifiedPolicy::kSingleDescent) and without.
  // The float search's misses and hand-offs are proofs for the input, so the answers agree: the
  // same certainty and interval, except a miss where the double search left the pair undecided,
  // or a hit whose lower bound the double search noted earlier (an interval excluded only as
  // given); no hit is ever lost or gained, and a known contact time is never before the lower bound.
  std::mt19937_64 rng(11);
  std::size_t pairs = 0, descents = 0, hits = 0, differ = 0, decided_more = 0, earlier_noted = 0, past_toi = 0;
  std::size_t known_hits = 0, known_descents = 0;  // of the contacts at known times
  std::size_t tail_differ = 0;                      // the leaf proved against the halvings
  std::size_t points_differ = 0;                    // the leaf proved from the points against the cubic's
  std::size_t handoff_differ = 0, handoff_same = 0;  // handed over at the descent against after float's halvings
  auto compare = [&](const auto& q, double toi) {
    using T = std::decay_t<decltype(q.points()[0].x)>;
    const CcdParams<T> params;
    const CertifiedAnswer<T> mixed = detail::certified_classify<CertifiedPolicy>(q, params);
    const CertifiedAnswer<T> whole = detail::certified_classify<NoSingleDescentPolicy>(q, params);
    bool done = false;
    if (certified_first_passes_leave(q, params)) {
      const CertifiedAnswer<T> single = detail::certified_refine_single_first<CertifiedPolicy>(q, params, done);
      descents += done && single.certainty == Certainty::hit;
      known_descents += done && single.certainty == Certainty::hit && toi >= 0;
    }
    hits += mixed.certainty == Certainty::hit;
    known_hits += mixed.certainty == Certainty::hit && toi >= 0;
    const bool same = mixed.certainty == whole.certainty && mixed.lo == whole.lo && mixed.hi == whole.hi;
    const bool more = mixed.certainty == Certainty::miss && whole.certainty == Certainty::undecided;
    const bool noted = mixed.certainty == Certainty::hit && whole.certainty == Certainty::hit && mixed.hi == whole.hi &&
                       whole.lo < mixed.lo;
    decided_more += more;
    earlier_noted += noted;
    differ += !same && !more && !noted;
    if (mixed.certainty == Certainty::hit && toi >= 0) past_toi += mixed.lo > T(toi + 1e-12);
    // The double tail's leaf, proved by its ends' signs, against the halvings down to it: the same
    // answer, or a later lower bound where the halvings noted one only as given on the way.
    const CertifiedAnswer<T> halved = detail::certified_classify<NoDescentJumpPolicy>(q, params);
    const bool tail_same = mixed.certainty == halved.certainty && mixed.lo == halved.lo && mixed.hi == halved.hi;
    tail_differ += !tail_same && !(mixed.certainty == Certainty::hit && halved.certainty == Certainty::hit &&
                                   mixed.hi == halved.hi && halved.lo < mixed.lo);
    // The leaf proved from the points (B15) against the one proved from the cubic built in double:
    // the same answer, or the same leaf with an earlier lower bound the cubic's path noted.
    const CertifiedAnswer<T> cubic = detail::certified_classify<NoJumpAtPointsPolicy>(q, params);
    const bool points_same = mixed.certainty == cubic.certainty && mixed.lo == cubic.lo && mixed.hi == cubic.hi;
    points_differ += !points_same && !(mixed.certainty == Certainty::hit && cubic.certainty == Certainty::hit &&
                                       mixed.hi == cubic.hi && cubic.lo < mixed.lo);
    // Handed to double where float's certain descent starts against after float's halvings: the
    // same leaf, or the same leaf with an earlier lower bound the tail's halvings in double noted.
    const CertifiedAnswer<T> halved_in_float = detail::certified_classify<NoHandOffAtDescentPolicy>(q, params);
    const bool handoff_equal = mixed.certainty == halved_in_float.certainty && mixed.lo == halved_in_float.lo &&
                               mixed.hi == halved_in_float.hi;
    handoff_same += handoff_equal && mixed.certainty == Certainty::hit;
    handoff_differ += !handoff_equal && !(mixed.certainty == Certainty::hit && halved_in_float.certainty == Certainty::hit &&
                                          mixed.hi == halved_in_float.hi);
    ++pairs;
  };
  for (int n = 0; n < 20000; ++n) {
    const auto [vf, ee] = near_contact_pairs(rng, 24);
    compare(vf, -1.0);
    compare(ee, -1.0);
    compare(vf.cast<float>(), -1.0);
  }
  // Contacts at known times off the dyadic grid.
  for (int n = 0; n < 2000; ++n) {
    const auto [vf, ee, toi] = contacts_at_known_time(rng);
    compare(vf, toi);
    compare(ee, toi);
  }
  std::printf("  single-precision search: %zu pairs, %zu hits, %zu of them with a double tail (contacts at known times: %zu of "
              "%zu); %zu misses the double search left undecided, %zu lower bounds the double search noted earlier, %zu other "
              "differences, %zu lower bounds past the TOI\n",
              pairs, hits, descents, known_descents, known_hits, decided_more, earlier_noted, differ, past_toi);
  CHECK(known_hits == 4000);
  CHECK(known_descents * 10 > known_hits * 9);
  CHECK(descents * 4 > hits);
  std::printf("  the double tail's leaf proved by its ends' signs against the halvings: %zu differences\n", tail_differ);
  CHECK(tail_differ == 0);
  std::printf("  the leaf proved from the points against the cubic's: %zu differences\n", points_differ);
  CHECK(points_differ == 0);
  std::printf("  handed to double at the descent against after float's halvings: %zu hits the same, %zu other differences\n",
              handoff_same, handoff_differ);
  CHECK(handoff_differ == 0);
  CHECK(handoff_same * 10 > hits * 9);
  CHECK(differ == 0);
  CHECK(past_toi == 0);
}

TEST_CASE("pairs of floats: operations within their unit, the split within 2^-47 of a double, no FP64 (mutation check)",
          "[narrow][certified][single]") {
  using detail::FloatPair;
  const auto value = [](const FloatPair& x) { return static_cast<long double>(x.hi) + static_cast<long double>(x.lo); };
  const auto normalized = [](const FloatPair& x) {
    return x.hi == 0.0f ? x.lo == 0.0f : std::fabs(x.lo) <= std::ldexp(1.0f, std::ilogb(x.hi) - 24);
  };
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> unit(-1, 1);
  std::size_t split_outside = 0, not_normalized = 0, op_outside = 0, ops = 0;
  long double worst_split = 0, worst_op = 0;
  for (int n = 0; n < 200000; ++n) {
    // (significands in [1, 2), exponents in [-50, 49])
    const auto number = [&] { return std::ldexp(std::copysign(1.0 + std::fabs(unit(rng)), unit(rng)), int(rng() % 100) - 50); };
    const double x = number(), y = number();
    FloatPair a, b;
    REQUIRE(detail::split_to_pair(x, a));
    REQUIRE(detail::split_to_pair(y, b));
    for (const auto& [pair, exact] : {std::pair<FloatPair, double>{a, x}, std::pair<FloatPair, double>{b, y}}) {
      const long double error = std::fabs(value(pair) - exact) / std::fabs(static_cast<long double>(exact));
      worst_split = std::max(worst_split, error);
      split_outside += error > std::ldexp(1.0L, -47);
      not_normalized += !normalized(pair);
    }
    const float s = static_cast<float>(unit(rng));
    const long double sum = value(a) + value(b), product = value(a) * value(b), scaled = value(a) * s;
    for (const auto& [computed, exact] : {std::pair<FloatPair, long double>{detail::pair_add(a, b), sum},
                                          std::pair<FloatPair, long double>{detail::pair_sub(a, b), value(a) - value(b)},
                                          std::pair<FloatPair, long double>{detail::pair_mul(a, b), product},
                                          std::pair<FloatPair, long double>{detail::pair_scale(a, s), scaled}}) {
      ++ops;
      if (exact == 0) continue;
      const long double error = std::fabs(value(computed) - exact) / std::fabs(exact);
      worst_op = std::max(worst_op, error / detail::kFloatPairUnit);
      op_outside += error > detail::kFloatPairUnit;
      not_normalized += !normalized(computed);
    }
  }
  std::printf("  pairs of floats: split error at most %.3Lg of 2^-47, %zu operations at most %.3Lg of 6u^2; %zu outside, %zu "
              "not normalized\n", worst_split * std::ldexp(1.0L, 47), ops, worst_op, split_outside + op_outside, not_normalized);
  CHECK(split_outside == 0);
  CHECK(op_outside == 0);
  CHECK(not_normalized == 0);
  // Doubles the split refuses: subnormal, from 2^60 on, not finite; 0 and the range's ends it takes.
  FloatPair out;
  CHECK_FALSE(detail::split_to_pair(std::numeric_limits<double>::denorm_min(), out));
  CHECK_FALSE(detail::split_to_pair(std::ldexp(1.0, -61), out));
  CHECK_FALSE(detail::split_to_pair(std::ldexp(1.0, 60), out));
  CHECK_FALSE(detail::split_to_pair(std::numeric_limits<double>::infinity(), out));
  CHECK_FALSE(detail::split_to_pair(std::numeric_limits<double>::quiet_NaN(), out));
  CHECK(detail::split_to_pair(-0.0, out));
  CHECK((out.hi == 0.0f && out.lo == 0.0f));
  CHECK(detail::split_to_pair(std::nextafter(std::ldexp(1.0, 60), 0.0), out));
  CHECK(value(out) == static_cast<long double>(static_cast<float>(std::ldexp(1.0, 60))));  // rounds up to 2^60 exactly
  CHECK(detail::split_to_pair(-std::ldexp(1.0, -60) * (1 + std::ldexp(1.0, -40)), out));
  CHECK(std::fabs(value(out) + std::ldexp(1.0L, -60) * (1 + std::ldexp(1.0L, -40))) <= std::ldexp(1.0L, -107));

  // B17's value of f at a point against long double, on near-contact pairs (their coordinates up to
  // 2^20) at dyadic times of 1 to 24 bits: within `own` of f for the query as given; with a tenth
  // of that bound, values fall outside (the bound is within a few times the errors seen).
  std::size_t usable = 0, checked = 0, sound_outside = 0, mutated_outside = 0;
  long double worst = 0;
  for (int n = 0; n < 4000; ++n) {
    const auto [vf, ee] = near_contact_pairs(rng, 20);
    const auto check = [&](const auto& q, bool vertex_face) {
      ++checked;
      const detail::CubicAtPointsInFloatPairs<CertifiedPolicy> sound(q);
      const detail::CubicAtPointsInFloatPairs<ShrunkFloatPairPolicy<10>> mutated(q);
      if (!sound.usable) return;
      ++usable;
      const int bits = 1 + int(rng() % 24);
      const float t = std::ldexp(float(rng() % (1ull << bits)), -bits);
      std::array<LongVec, 8> given;
      for (int i = 0; i < 8; ++i)
        for (int k = 0; k < 3; ++k) given[i][k] = q.points()[i][k];
      const long double exact_value = f_long(given, vertex_face, t);
      const long double sound_error = std::fabs(value(sound.pair_at(t)) - exact_value);
      worst = std::max(worst, sound_error / sound.own);
      sound_outside += sound_error > sound.own;
      mutated_outside += std::fabs(value(mutated.pair_at(t)) - exact_value) > mutated.own;
      // The threshold holds the pairs' own bound and twice B15's bounds for the same query.
      const auto cast = q.template cast<double>();
      const detail::CubicAtPoints<CertifiedPolicy, double> b15(cast, detail::coordinate_magnitude(cast),
                                                                double(detail::unit_roundoff<std::decay_t<decltype(q.points()[0].x)>>()));
      CHECK(static_cast<double>(sound.threshold) >= static_cast<double>(sound.own) + 2 * std::max(b15.exact, b15.bound));
    };
    check(vf, true);
    check(ee, false);
    check(vf.cast<float>(), true);
  }
  std::printf("  f in pairs of floats: %zu of %zu queries usable; error at most %.3Lg of the bound; %zu values outside "
              "(sound), %zu (a tenth of the bound)\n", usable, checked, worst, sound_outside, mutated_outside);
  CHECK(usable * 10 > checked * 9);
  CHECK(sound_outside == 0);
  CHECK(mutated_outside > 0);
  // Out of range: a coordinate past 2^20, or a subnormal one: not usable (double proves those).
  auto far = near_contact_pairs(rng, 20).second;
  far.a0.x = std::ldexp(1.0, 21);
  CHECK_FALSE(detail::CubicAtPointsInFloatPairs<CertifiedPolicy>(far).usable);
  far.a0.x = std::numeric_limits<double>::denorm_min();
  CHECK_FALSE(detail::CubicAtPointsInFloatPairs<CertifiedPolicy>(far).usable);
}

TEST_CASE("single precision: contacts' leaves proved in pairs of floats give the double tail's answers bit for bit",
          "[narrow][certified][single]") {
  // CcdParams::leaves_in_float_pairs: where B17's values prove a leaf, B15's prove the same one, so
  // every answer is the same as without it. Most contacts' leaves are proved that way; not all
  // here, where features as small as 2^-10 lie up to 2^7 from the origin: the split's rounding
  // (u^2 of a coordinate) then outweighs |f| at some leaf ends, which double still proves.
  std::mt19937_64 rng(29);
  std::size_t pairs = 0, descents = 0, in_pairs = 0, differ = 0, counted_differ = 0;
  auto compare = [&](const auto& q) {
    using T = std::decay_t<decltype(q.points()[0].x)>;
    CcdParams<T> plain, with_pairs;
    with_pairs.leaves_in_float_pairs = true;
    const CertifiedAnswer<T> a = detail::certified_classify<CertifiedPolicy>(q, plain);
    const CertifiedAnswer<T> b = detail::certified_classify<CertifiedPolicy>(q, with_pairs);
    differ += !(a.certainty == b.certainty && a.lo == b.lo && a.hi == b.hi);
    if (certified_first_passes_leave(q, plain)) {
      bool done_plain = false, done_pairs = false, plain_flag = true, pairs_flag = false;
      const CertifiedAnswer<T> s = detail::certified_refine_single_first<CertifiedPolicy>(q, plain, done_plain, &plain_flag);
      const CertifiedAnswer<T> p = detail::certified_refine_single_first<CertifiedPolicy>(q, with_pairs, done_pairs, &pairs_flag);
      counted_differ += plain_flag || done_plain != done_pairs || s.certainty != p.certainty || s.lo != p.lo || s.hi != p.hi;
      descents += done_pairs && p.certainty == Certainty::hit;
      in_pairs += pairs_flag;
      if (pairs_flag) CHECK((done_pairs && p.certainty == Certainty::hit));
    }
    ++pairs;
  };
  for (int n = 0; n < 20000; ++n) {
    const auto [vf, ee] = near_contact_pairs(rng, 8);
    compare(vf);
    compare(ee);
    compare(vf.cast<float>());
  }
  for (int n = 0; n < 2000; ++n) {
    const auto [vf, ee, toi] = contacts_at_known_time(rng);
    compare(vf);
    compare(ee);
  }
  std::printf("  leaves in pairs of floats: %zu pairs, %zu contacts with a tail, %zu of them proved in pairs; %zu answers "
              "differ, %zu tails differ\n", pairs, descents, in_pairs, differ, counted_differ);
  CHECK(differ == 0);
  CHECK(counted_differ == 0);
  CHECK(descents > 1000);
  CHECK(in_pairs * 4 > descents * 3);
}

TEST_CASE("single precision: a contact claimed in float holds for the input; without the inside test's bound a miss is "
          "a hit (mutation check)", "[narrow][certified][single]") {
  // A vertex crossing a triangle's plane slowly (0.01 a step), beside an edge by d = 5e-8: a
  // certain miss in double (d is far beyond double's rounding of the coordinates, and beyond what
  // the vertex moves in the tolerance's time), but below float's rounding of the pair's relative
  // coordinates (up to ~4: 2.4e-7), so the float query may put the vertex inside. The search in
  // single precision claims the contact only where its inside test is certain for every query
  // within the input's rounding to float (B12, counted as given: moving_difference's `given`);
  // without the inside test's bound it hands such misses to double as contacts. (The double path
  // alone, with the bound removed, still sees the vertex outside: its rounding is far below d.)
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> unit(-1, 1), along(0.2, 0.8);
  std::size_t cases = 0, hits_sound = 0, hits_mutated = 0, hits_double_mutated = 0, misses_double = 0;
  for (int n = 0; n < 4000; ++n) {
    const double o = std::ldexp(1.0, 4 + int(rng() % 4));
    const Vec3d a{o + unit(rng), o + unit(rng), o + unit(rng)};
    const Vec3d b = a + Vec3d{3 + unit(rng), unit(rng), 0.3 * unit(rng)}, c = a + Vec3d{unit(rng), 3 + unit(rng), 0.3 * unit(rng)};
    const auto unit_vector = [](const Vec3d& v) { return v * (1.0 / norm(v)); };
    const Vec3d normal = unit_vector(cross(b - a, c - a));
    Vec3d out = unit_vector(cross(b - a, normal));  // in the plane, normal to ab
    if (dot(out, c - a) > 0) out = out * -1.0;    // away from c: outside the triangle
    const Vec3d beside = a + (b - a) * along(rng) + out * 5e-8;
    const VertexFaceQuery<double> q{beside + normal * 0.003, a, b, c, beside - normal * 0.007, a, b, c};  // (at t = 0.3: off the grid)
    ++cases;
    misses_double += detail::certified_classify<DoubleScreenPolicy>(q, CcdParams<double>{}).certainty == Certainty::miss;
    hits_sound += detail::certified_classify<CertifiedPolicy>(q, CcdParams<double>{}).certainty == Certainty::hit;
    hits_mutated += detail::certified_classify<ShrunkPolicy<100, 100, 0>>(q, CcdParams<double>{}).certainty == Certainty::hit;
    hits_double_mutated +=
        detail::certified_classify<ShrunkDoublePolicy<100, 100, 0>>(q, CcdParams<double>{}).certainty == Certainty::hit;
  }
  std::printf("  slow vertices beside an edge by 5e-8: %zu; certain misses in double %zu; hits %zu "
              "(sound), %zu (inside bound removed), %zu (inside bound removed, double alone)\n", cases, misses_double, hits_sound,
              hits_mutated, hits_double_mutated);
  CHECK(misses_double * 10 > cases * 9);
  CHECK(hits_sound == 0);
  CHECK(hits_mutated > 0);
  CHECK(hits_double_mutated == 0);
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

namespace {
// underflow_slack against its definition by multiplication, bit for bit, on magnitudes of every
// size (random bit patterns, integers over small integers, powers of two near 1) and degrees 1-6;
// returns how many differ.
template <class T, class Bits>
std::size_t slack_differences(std::mt19937_64& rng, std::size_t n) {
  std::size_t differ = 0;
  for (std::size_t i = 0; i < n; ++i) {
    T mag;
    const Bits bits = static_cast<Bits>(rng());
    std::memcpy(&mag, &bits, sizeof mag);
    mag = std::fabs(mag);
    if (i % 4 == 1) mag = T(rng() % 100000) / T(1 + rng() % 1000);
    if (i % 4 == 2) mag = std::ldexp(T(1 + rng() % 7), int(rng() % 40) - 20);
    const int degree = 1 + int(i % 6);
    const T fast = detail::underflow_slack(mag, degree);
    const T defined = detail::underflow_slack_by_multiplication(detail::fadd(T(1), mag), degree);
    Bits a, b;
    std::memcpy(&a, &fast, sizeof a);
    std::memcpy(&b, &defined, sizeof b);
    differ += a != b && !(std::isnan(fast) && std::isnan(defined));
  }
  return differ;
}
}  // namespace

TEST_CASE("underflow slack: the host's value without denormal multiplications equals the multiplied one",
          "[narrow][certified]") {
  // The host computes it in double (float) or in integers (double), where x86 would take a
  // microcode assist per denormal product; the device multiplies. Both must give the same bits.
  std::mt19937_64 rng(29);
  CHECK(slack_differences<float, std::uint32_t>(rng, 200000) == 0);
  CHECK(slack_differences<double, std::uint64_t>(rng, 200000) == 0);
  // Around the edges: the normal range reached, a carry into the next binade, overflow.
  for (const double mag : {0.0, 1.0, 2047.0, 131071.0, 1e10, 1e30, 3.4e38, 1e300, 1.7e308}) {
    for (int degree = 1; degree <= 6; ++degree) {
      const float f = detail::underflow_slack(static_cast<float>(mag), degree);
      const float g = detail::underflow_slack_by_multiplication(detail::fadd(1.0f, static_cast<float>(mag)), degree);
      CHECK(std::memcmp(&f, &g, sizeof f) == 0);
      const double d = detail::underflow_slack(mag, degree);
      const double e = detail::underflow_slack_by_multiplication(detail::fadd(1.0, mag), degree);
      CHECK(std::memcmp(&d, &e, sizeof d) == 0);
    }
  }
}

namespace {
// Screens `queries` in lanes and one pair at a time; returns how many verdicts differ, and counts
// the misses (so that a test sees both verdicts exercised).
template <class Q>
std::size_t lane_differences(const std::vector<Q>& queries, std::size_t& misses, const CcdParams<double>& params = {}) {
  std::size_t differ = 0;
  for (std::size_t begin = 0; begin < queries.size(); begin += detail::kScreenLanes) {
    const int n = static_cast<int>(std::min<std::size_t>(detail::kScreenLanes, queries.size() - begin));
    bool lanes[detail::kScreenLanes];
    detail::screen_single_in_lanes<CertifiedPolicy>(queries.data() + begin, n, params, lanes);
    for (int lane = 0; lane < n; ++lane) {
      const bool one = detail::certified_screen_single<CertifiedPolicy>(queries[begin + lane], params);
      differ += lanes[lane] != one;
      misses += one;
    }
  }
  return differ;
}

// The screen in its two parts, as the GPU's screen kernel runs them (the tests in space on every
// pair, the cubic's on the pairs they leave, gathered into full warps), against the one-pair
// screen: how many verdicts differ; `in_space` and `by_cubic` count the misses of each part.
template <class Q>
std::size_t part_differences(const std::vector<Q>& queries, std::size_t& in_space, std::size_t& by_cubic,
                             const CcdParams<double>& params = {}) {
  std::size_t differ = 0;
  for (const Q& q : queries) {
    const auto s = detail::relative_single(q);
    const bool space = detail::single_screen_in_space<CertifiedPolicy>(s, params);
    const bool cubic = !space && detail::single_screen_by_cubic<CertifiedPolicy>(s, params);
    differ += (space || cubic) != detail::certified_screen_single<CertifiedPolicy>(q, params);
    in_space += space;
    by_cubic += cubic;
  }
  return differ;
}
}  // namespace

TEST_CASE("single-precision screen: pairs screened in lanes get the one-pair screen's verdicts", "[narrow][certified][single]") {
  // Near contacts at every scale and distance from the origin, pairs far apart, coordinates whose
  // products overflow (NaN and infinities inside the screen), denormal and zero motion.
  std::mt19937_64 rng(31);
  std::vector<VertexFaceQuery<float>> vf;
  std::vector<EdgeEdgeQuery<float>> ee;
  std::uniform_real_distribution<float> unit(-1, 1);
  for (int i = 0; i < 20000; ++i) {
    const auto [v, e] = near_contact_pairs(rng, 1 + i % 24);
    vf.push_back(v.cast<float>());
    ee.push_back(e.cast<float>());
    VertexFaceQuery<float> far = vf.back();
    EdgeEdgeQuery<float> apart = ee.back();
    const float scale = std::ldexp(1.0f, int(rng() % 260) - 140);  // 2^-140 .. 2^119
    for (Vec3<float>* p : {&far.p0, &far.a0, &far.b0, &far.c0, &far.p1, &far.a1, &far.b1, &far.c1})
      *p = {unit(rng) * scale, unit(rng) * scale, unit(rng) * scale};
    for (Vec3<float>* p : {&apart.a0, &apart.b0, &apart.c0, &apart.d0, &apart.a1, &apart.b1, &apart.c1, &apart.d1})
      *p = {unit(rng) * scale, unit(rng) * scale, unit(rng) * scale};
    if (i % 7 == 0) far.p1 = far.p0, apart.a1 = apart.a0;  // a point at rest
    vf.push_back(far);
    ee.push_back(apart);
    // The near contact's first feature moved along an axis by 2^-k of the pair's extent (k of 0 ..
    // 29), or by 1/4 .. 40 float roundings of its coordinates (B14's margins are about 18 of them):
    // apart by the differences, at their margins, or not.
    VertexFaceQuery<float> shifted_vf = vf[vf.size() - 2];
    EdgeEdgeQuery<float> shifted_ee = ee[ee.size() - 2];
    const int axis = static_cast<int>(rng() % 3), k = static_cast<int>(rng() % 30);
    const bool at_margin = rng() % 2 == 0;
    const float roundings = static_cast<float>(1 + rng() % 160) / 4;
    auto shift = [&](auto& q, std::initializer_list<Vec3<float>*> first) {
      float extent = 0, magnitude = 0;
      for (int p = 0; p < 8; ++p) {
        extent = std::max(extent, std::fabs(q.points()[p][axis] - q.points()[0][axis]));
        magnitude = std::max(magnitude, std::fabs(q.points()[p][axis]));
      }
      const float size = at_margin ? std::ldexp(magnitude, -24) * roundings : std::ldexp(extent, -k);
      const float by = size * (rng() % 2 ? 1.0f : -1.0f);
      for (Vec3<float>* p : first) (*p)[axis] += by;
    };
    shift(shifted_vf, {&shifted_vf.p0, &shifted_vf.p1});
    shift(shifted_ee, {&shifted_ee.a0, &shifted_ee.b0, &shifted_ee.a1, &shifted_ee.b1});
    vf.push_back(shifted_vf);
    ee.push_back(shifted_ee);
  }
  std::size_t vf_misses = 0, ee_misses = 0;
  CHECK(lane_differences(vf, vf_misses) == 0);
  CHECK(lane_differences(ee, ee_misses) == 0);
  // The GPU's two parts, over the whole step and a short window; each part decides some pairs.
  for (const double limit : {1.0, std::ldexp(1.0, -8)}) {
    CcdParams<double> window;
    window.time_limit = limit;
    std::size_t in_space = 0, by_cubic = 0;
    CHECK(part_differences(vf, in_space, by_cubic, window) == 0);
    CHECK(part_differences(ee, in_space, by_cubic, window) == 0);
    std::printf("screen in two parts, window [0, %g): %zu misses by the tests in space, %zu by the cubic\n", limit, in_space,
                by_cubic);
    CHECK(in_space > 0);
    CHECK(by_cubic > 0);
  }
  std::printf("screen in lanes (%d): %zu vertex-face and %zu edge-edge pairs, %zu and %zu misses, the rest passed\n",
              detail::kScreenLanes, vf.size(), ee.size(), vf_misses, ee_misses);
  CHECK(vf_misses > vf.size() / 10);
  CHECK(vf_misses < vf.size() * 9 / 10);
  CHECK(ee_misses > ee.size() / 10);
  CHECK(ee_misses < ee.size() * 9 / 10);
  // Mode earliest's windows [0, time_limit): the window's boxes in lanes, the cubic's halvings
  // one pair at a time. Each window must reject pairs the whole step passes (else the window's
  // tests were not exercised).
  for (const double limit : {std::ldexp(1.0, -16), std::ldexp(1.0, -8), 0.3, 0.5, 0.75}) {
    CcdParams<double> window;
    window.time_limit = limit;
    std::size_t vf_window_misses = 0, ee_window_misses = 0;
    CHECK(lane_differences(vf, vf_window_misses, window) == 0);
    CHECK(lane_differences(ee, ee_window_misses, window) == 0);
    std::printf("screen in lanes, window [0, %g): %zu and %zu misses\n", limit, vf_window_misses, ee_window_misses);
    CHECK(vf_window_misses >= vf_misses);
    CHECK(ee_window_misses >= ee_misses);
    if (limit <= 0.5) {
      CHECK(vf_window_misses > vf_misses);
      CHECK(ee_window_misses > ee_misses);
    }
  }
  // The batch takes them in lanes for contact (any window), not for a minimum separation.
  CcdParams<double> params;
#if defined(LWSCCD_SCREEN_IN_LANES)
  CHECK(detail::screen_in_lanes_applies(params));
  params.time_limit = 0.5;
  CHECK(detail::screen_in_lanes_applies(params));
#else
  CHECK_FALSE(detail::screen_in_lanes_applies(params));  // (a compiler without vector extensions)
#endif
  params.time_limit = 1;
  params.min_separation = 1e-3;
  CHECK_FALSE(detail::screen_in_lanes_applies(params));
}

namespace {
template <int kPercent>
struct ShrunkSeparationPolicy : CertifiedPolicy {
  static constexpr double kSeparationBound = kPercent / 100.0;
};

// Exact double coordinates of a point far from the origin (2^20 .. 2^21 in 64ths: float rounds
// them), axes permuted and signs flipped as `axes` and `signs` say.
Vec3<double> far_point(const Vec3<long double>& p, const Vec3<long double>& offset, const int axes[3], int signs) {
  const Vec3<long double> q = p + offset;
  Vec3<long double> r;
  for (int k = 0; k < 3; ++k) r[k] = q[axes[k]] * (((signs >> k) & 1) ? -1 : 1);
  return r.cast<double>();
}

// A random point far from the origin: each coordinate 2^20 .. 2^21 in 64ths (float rounds them).
Vec3<long double> far_origin(std::mt19937& rng) {
  auto one = [&] { return std::ldexp(1.0L, 20) + std::ldexp(static_cast<long double>(rng() % (1u << 26)), -6); };
  return {one(), one(), one()};
}

// The axis orders a far_point may take.
constexpr int kAxisOrders[6][3] = {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 2, 1}, {2, 1, 0}, {1, 0, 2}};

// The verdicts of a margin's mutation check on cases below the margin whose moved copies touch:
// none claimed apart with the margin, every one without it, every moved copy touching.
void check_below_margin(const char* what, std::size_t cases, std::size_t claimed, std::size_t claimed_mutated,
                        std::size_t touching_moved) {
  std::printf("  %s below the margin: %zu; apart %zu (sound), %zu (margins removed); the moved copies that touch: %zu\n",
              what, cases, claimed, claimed_mutated, touching_moved);
  CHECK(claimed == 0);
  CHECK(claimed_mutated == cases);
  CHECK(touching_moved == cases);
}
}  // namespace

TEST_CASE("single-precision filter: separating directions only for features apart, within their bound (mutation check)",
          "[narrow][certified][single]") {
  // Touching pairs whose hulls meet with a gap of exactly 0 along the direction between the
  // features' centroids (a vertex sliding in a face's plane onto an edge across that direction; an
  // edge sliding onto another edge so), far from the origin so that the float query is rounded:
  // never declared apart; with the bound removed, rounding separates some. Pairs apart (a vertex
  // passing over a face's plane beside it, an edge passing above another), nearer the origin:
  // declared apart.
  std::mt19937 rng(20261127);
  const auto& axes = kAxisOrders;
  const float perturbation = detail::single_input_perturbation<CertifiedPolicy>();
  std::size_t touching = 0, claimed = 0, claimed_mutated = 0, apart = 0, separated = 0;
  auto offset = [&] { return far_origin(rng); };
  for (int n = 0; n < 4000; ++n) {
    const int* axis = axes[rng() % 6];
    const int signs = static_cast<int>(rng() % 8);
    const Vec3<long double> o = offset();
    const long double a = eighth(rng, 8, 128), s = eighth(rng, -7, 7) * a / 8, y = eighth(rng, 1, 128), z = eighth(rng, 0, 64),
                      c = eighth(rng, 8, 128);
    // (u, v, z) -> (u + v, u - v, z): the edges the pairs touch lie along (1, 1, 0), so that the
    // float rounding of x and y breaks the exact tie of the projections either way.
    auto at_from = [&](const Vec3<long double>& origin) {
      return [&, origin](long double pu, long double pv, long double pz) { return far_point({pu + pv, pu - pv, pz}, origin, axis, signs); };
    };
    const auto at = at_from(o);
    const auto near = at_from(o * std::ldexp(1.0L, -12));  // 2^8 .. 2^9 from the origin
    // Vertex from (-s, y, z) to (s, 0, 0), on the edge from (-a, 0, 0) to (a, 0, 0) at t = 1.
    const VertexFaceQuery<double> vf{at(-s, y, z), at(-a, 0, 0), at(a, 0, 0), at(0, -c, 0),
                                     at(s, 0, 0),  at(-a, 0, 0), at(a, 0, 0), at(0, -c, 0)};
    // Edge from (u, y, z)-(-(s + t + u), y + y', z) to (s, 0, 0)-(t, y', 0): its first point on
    // the edge (-a, 0, 0)-(a, 0, 0) at t = 1; the x of its four points sum to 0.
    const long double t = eighth(rng, -64, 64), u = eighth(rng, -64, 64), y2 = eighth(rng, 1, 64);
    const EdgeEdgeQuery<double> ee{at(u, y, z), at(-(s + t + u), y + y2, z), at(-a, 0, 0), at(a, 0, 0),
                                   at(s, 0, 0), at(t, y2, 0),                at(-a, 0, 0), at(a, 0, 0)};
    touching += 2;
    for (bool sound : {true, false}) {
      const std::size_t vf_claim = sound ? detail::swept_hulls_apart<CertifiedPolicy>(detail::relative_single(vf), perturbation)
                                         : detail::swept_hulls_apart<ShrunkSeparationPolicy<0>>(detail::relative_single(vf), perturbation);
      const std::size_t ee_claim = sound ? detail::swept_hulls_apart<CertifiedPolicy>(detail::relative_single(ee), perturbation)
                                         : detail::swept_hulls_apart<ShrunkSeparationPolicy<0>>(detail::relative_single(ee), perturbation);
      (sound ? claimed : claimed_mutated) += vf_claim + ee_claim;
    }
    // Apart: the vertex moving over the face's plane beside the face; the edge passing above the other.
    const VertexFaceQuery<double> over{near(-s, y, z + 1), near(-a, 0, 0), near(a, 0, 0), near(0, -c, 0),
                                       near(s, y / 2, z + 1), near(-a, 0, 0), near(a, 0, 0), near(0, -c, 0)};
    const EdgeEdgeQuery<double> above{near(u, y, z), near(-(s + t + u), y + y2, z), near(-a, 0, 0), near(a, 0, 0),
                                      near(s, y / 2, 0), near(t, y2 + y / 2, 0), near(-a, 0, 0), near(a, 0, 0)};
    apart += 2;
    separated += detail::swept_hulls_apart<CertifiedPolicy>(detail::relative_single(over), perturbation);
    separated += detail::swept_hulls_apart<CertifiedPolicy>(detail::relative_single(above), perturbation);
    // A point of a hull that is not finite: never apart.
    VertexFaceQuery<double> huge = over;
    huge.p1 = {3e38, 0, 0};
    CHECK_FALSE(detail::swept_hulls_apart<CertifiedPolicy>(detail::relative_single(huge), perturbation));
  }
  std::printf("  separating directions: %zu touching pairs declared apart %zu times (sound), %zu (bound removed); %zu of %zu "
              "pairs apart separated\n", touching, claimed, claimed_mutated, separated, apart);
  CHECK(claimed == 0);
  CHECK(claimed_mutated > 0);
  CHECK(separated == apart);
}

namespace {
template <int kPercent>
struct ShrunkDifferencePolicy : CertifiedPolicy {
  static constexpr double kDifferenceBound = kPercent / 100.0;
};
struct WithoutDifferencesPolicy : CertifiedPolicy {
  static constexpr bool kCornerDifferences = false;
};
template <class Policy, class Q>
bool differences_apart_single(const Q& q) {
  const auto s = detail::relative_single(q);
  return detail::differences_apart<Policy>(s.q, s.m, detail::single_input_perturbation<Policy>());
}
}  // namespace

TEST_CASE("screen: features moving together are apart by their relative motion, within its bound (mutation check)",
          "[narrow][certified][single]") {
  std::mt19937 rng(20261128);
  // Collinear edges of a grid line carried as a whole (a cloth's line moved by far more than an
  // edge's length, as the built-in scene's interpolated cloth moves): their cubic is zero and their
  // inside tests degenerate, so without the differences the certified path leaves them to the
  // fallback; with them the screen rejects them in single precision.
  std::size_t collinear = 0, screened = 0, missed = 0, undecided_without = 0;
  for (int n = 0; n < 600; ++n) {
    const Vec3<long double> along{eighth(rng, -64, 64), eighth(rng, -64, 64), eighth(rng, 1, 64)};
    const Vec3<long double> origin{eighth(rng, -8192, 8192), eighth(rng, -8192, 8192), eighth(rng, -8192, 8192)};
    const Vec3<long double> motion{eighth(rng, -4096, 4096), eighth(rng, -4096, 4096), eighth(rng, -4096, 4096)};
    const long double gap = 1 + rng() % 3;  // the second edge starts 1-3 edge lengths past the first's end
    auto at = [&](long double k, bool later) { return (origin + along * k + (later ? motion : Vec3<long double>{0, 0, 0})).cast<double>(); };
    const EdgeEdgeQuery<double> q{at(0, false), at(1, false), at(1 + gap, false), at(2 + gap, false),
                                  at(0, true),  at(1, true),  at(1 + gap, true),  at(2 + gap, true)};
    ++collinear;
    screened += CertifiedCcd::screen_verdict(q, CcdParams<double>{}) == detail::ScreenVerdict::single_miss;
    missed += CertifiedCcd::classify(q, CcdParams<double>{}).certainty == Certainty::miss;
    undecided_without += CertifiedCcdT<Filtered<InclusionCcd>, WithoutDifferencesPolicy>::classify(q, CcdParams<double>{}).certainty ==
                         Certainty::undecided;
  }
  std::printf("  collinear edges moving together: %zu; rejected by the single screen %zu, misses %zu; undecided without the "
              "differences %zu\n", collinear, screened, missed, undecided_without);
  CHECK(screened == collinear);
  CHECK(missed == collinear);
  CHECK(undecided_without > collinear / 2);

  // A vertex passing a face's corner at a gap g along x, below the margin: the query moved by g
  // touches, and it is within the perturbation the screen's misses cover, so the differences must
  // not call it apart; without the margins they do. (The query itself is apart: its misses by the
  // double path stay misses.)
  const auto& axes = kAxisOrders;
  std::size_t passing = 0, claimed = 0, claimed_mutated = 0, touching_moved = 0;
  for (int n = 0; n < 400; ++n) {
    const int* axis = axes[rng() % 6];
    const int signs = static_cast<int>(rng() % 8);
    const long double g = std::ldexp(1.0L, -28 - int(rng() % 8)), a = eighth(rng, 4, 32), b = eighth(rng, 4, 32), z = eighth(rng, 4, 32);
    auto at = [&](long double gap, long double x, long double y, long double w) {
      return far_point({x + gap, y, w}, {0, 0, 0}, axis, signs);
    };
    for (const long double gap : {g, 0.0L}) {
      const VertexFaceQuery<double> q{at(gap, 0, 0, -z), at(0, 0, 0, 0), at(0, -a, b, 0), at(0, -a, -b, 0),
                                      at(gap, 0, 0, z),  at(0, 0, 0, 0), at(0, -a, b, 0), at(0, -a, -b, 0)};
      if (gap == 0) {
        touching_moved += CertifiedCcd::classify(q, CcdParams<double>{}).certainty != Certainty::miss;
        continue;
      }
      ++passing;
      claimed += differences_apart_single<CertifiedPolicy>(q);
      claimed_mutated += differences_apart_single<ShrunkDifferencePolicy<0>>(q);
    }
  }
  check_below_margin("a vertex passing a corner (the features' differences)", passing, claimed, claimed_mutated, touching_moved);

  // A vertex moving straight onto an edge's midpoint, far from the origin with the axes turned by
  // 45 degrees: along the differences' sum two of them are exactly 0, and float's rounding of the
  // relative query breaks the tie: never apart with the margin, sometimes without it.
  std::size_t ties = 0, tie_claims = 0, tie_claims_mutated = 0;
  for (int n = 0; n < 4000; ++n) {
    const int* axis = axes[rng() % 6];
    const int signs = static_cast<int>(rng() % 8);
    const Vec3<long double> o = far_origin(rng);
    const long double a = eighth(rng, 8, 128), c = eighth(rng, 8, 128), y = eighth(rng, 1, 128), z = eighth(rng, 0, 64);
    auto at = [&](long double pu, long double pv, long double pz) { return far_point({pu + pv, pu - pv, pz}, o, axis, signs); };
    const VertexFaceQuery<double> q{at(0, y, z), at(-a, 0, 0), at(a, 0, 0), at(0, -c, 0),
                                    at(0, 0, 0), at(-a, 0, 0), at(a, 0, 0), at(0, -c, 0)};
    ++ties;
    tie_claims += differences_apart_single<CertifiedPolicy>(q);
    tie_claims_mutated += differences_apart_single<ShrunkDifferencePolicy<0>>(q);
    // Beyond float's range (not finite once rounded): never apart.
    VertexFaceQuery<double> huge = q;
    huge.p1 = {1e39, -1e39, 1e39};
    CHECK_FALSE(differences_apart_single<CertifiedPolicy>(huge));
  }
  std::printf("  a vertex onto an edge's midpoint: %zu; apart by the differences %zu (sound), %zu (margins removed)\n", ties,
              tie_claims, tie_claims_mutated);
  CHECK(tie_claims == 0);
  CHECK(tie_claims_mutated > 0);
}

TEST_CASE("emission: faces apart by their relative motion, within its bound (mutation check)", "[representative][certified]") {
  std::mt19937 rng(20261128);
  const auto& axes = kAxisOrders;
  auto corners_of = [](const std::array<Vec3<double>, 3>& at0, const std::array<Vec3<double>, 3>& at1) {
    FaceCorners c;
    for (int k = 0; k < 3; ++k) c.at[k] = at0[k].cast<float>(), c.at[3 + k] = at1[k].cast<float>();
    return c;
  };
  // A face's corner passing another face's corner at a gap g along x, below the test's margin,
  // the rest of its face beyond: the faces moved by g touch, and that is within the perturbation
  // faces_apart covers, so it must not call them apart; without the margins it does.
  std::size_t passing = 0, claimed = 0, claimed_mutated = 0, touching_moved = 0;
  for (int n = 0; n < 400; ++n) {
    const int* axis = axes[rng() % 6];
    const int signs = static_cast<int>(rng() % 8);
    const long double g = std::ldexp(1.0L, -28 - int(rng() % 8)), a = eighth(rng, 4, 32), b = eighth(rng, 4, 32),
                      z = eighth(rng, 4, 32), w = eighth(rng, 1, 32), h = eighth(rng, 1, 32);
    auto at = [&](long double x, long double y, long double v) { return far_point({x, y, v}, {0, 0, 0}, axis, signs); };
    const std::array<Vec3<double>, 3> still{at(0, 0, 0), at(0, -a, b), at(0, -a, -b)};
    const FaceCorners first = corners_of(still, still);
    for (const long double gap : {g, 0.0L}) {
      const FaceCorners second = corners_of({at(gap, 0, -z), at(gap + w, h, -z), at(gap + w, -h, -z)},
                                            {at(gap, 0, z), at(gap + w, h, z), at(gap + w, -h, z)});
      if (gap == 0) {
        const VertexFaceQuery<double> q{at(0, 0, -z), still[0], still[1], still[2], at(0, 0, z), still[0], still[1], still[2]};
        touching_moved += CertifiedCcd::classify(q, CcdParams<double>{}).certainty != Certainty::miss;
        continue;
      }
      ++passing;
      claimed += faces_apart(first, second) || faces_apart(second, first);
      claimed_mutated += faces_apart<ShrunkDifferencePolicy<0>>(first, second);
    }
  }
  check_below_margin("a face's corner passing another's (the faces' differences)", passing, claimed, claimed_mutated,
                     touching_moved);

  // A face's corner moving straight onto another face's edge midpoint, far from the origin with
  // the axes turned by 45 degrees, the moving face beyond that edge: the faces touch at t = 1, and
  // float's rounding of their corners may break the tie along the differences' sum: never apart
  // with the margins, sometimes without them.
  std::size_t ties = 0, tie_claims = 0, tie_claims_mutated = 0;
  for (int n = 0; n < 4000; ++n) {
    const int* axis = axes[rng() % 6];
    const int signs = static_cast<int>(rng() % 8);
    const Vec3<long double> o = far_origin(rng);
    const long double a = eighth(rng, 8, 128), c = eighth(rng, 8, 128), y = eighth(rng, 1, 128), z = eighth(rng, 0, 64),
                      s = eighth(rng, 1, 64), r = eighth(rng, 1, 64);
    auto at = [&](long double pu, long double pv, long double pz) { return far_point({pu + pv, pu - pv, pz}, o, axis, signs); };
    const std::array<Vec3<double>, 3> edge_face{at(-a, 0, 0), at(a, 0, 0), at(0, -c, 0)};
    const FaceCorners first = corners_of(edge_face, edge_face);
    const FaceCorners second = corners_of({at(0, y, z), at(-s, y + r, z), at(s, y + r, z)}, {at(0, 0, 0), at(-s, r, 0), at(s, r, 0)});
    ++ties;
    tie_claims += faces_apart(first, second) || faces_apart(second, first);
    tie_claims_mutated += faces_apart<ShrunkDifferencePolicy<0>>(first, second) || faces_apart<ShrunkDifferencePolicy<0>>(second, first);
    // Beyond float's range (not finite once rounded): never apart.
    FaceCorners huge = second;
    huge.at[5] = Vec3<double>{1e39, -1e39, 1e39}.cast<float>();
    CHECK_FALSE(faces_apart(first, huge));
  }
  std::printf("  a face's corner onto another's edge midpoint: %zu; apart by the faces' differences %zu (sound), %zu (margins "
              "removed)\n", ties, tie_claims, tie_claims_mutated);
  CHECK(tie_claims == 0);
  CHECK(tie_claims_mutated > 0);
}
