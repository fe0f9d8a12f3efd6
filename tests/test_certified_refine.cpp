// The certified path's filter, its refinement stopped at a level and resumed, inside tests
// evaluated ahead by subtrees, and its screen with a time limit, each against the whole search
// on the generated hard cases (certified_test_support.hpp).
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "certified_test_support.hpp"
#include "lwsccd/narrow_phase/certified_ccd.hpp"

using namespace lwsccd;
using namespace lwsccd::certified_test;

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
// the search goes skipped) and the search reads the verdicts from there; an interval's pieces
// (CertifiedPolicy::kPieceLevels) are evaluated all at once, as the warp's lanes do, without
// touching the subtree held. `wrong_place` reads a neighbour's verdict instead, `any_piece`
// excludes an interval when one of its pieces is outside (mutations the comparison must catch).
struct SubtreeInside {
  int max_level = 0, wrong_place = 0;
  bool any_piece = false;
  int root_level = -1;
  std::uint32_t root_index = 0;
  detail::InsideVerdict verdicts[31] = {};
  int asked = 0, evaluated = 0, pieced = 0;
  static constexpr bool kEvaluatesPieces = true;
  template <class Compute>
  detail::InsideVerdict pieces(int level, std::uint32_t index, int depth, const Compute& compute) {
    ++pieced;
    detail::PieceVotes votes;
    bool some_outside = false;
    for (std::uint32_t k = 0; k < (1u << depth); ++k) {
      const detail::InsideVerdict v = compute(level + depth, (index << depth) | k);
      votes.add(v);
      some_outside = some_outside || v == detail::InsideVerdict::outside;
    }
    return any_piece && some_outside ? detail::InsideVerdict::outside : votes.verdict();
  }
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
  std::vector<Case> cases = hard_cases(rng, 6);
  for (const Case& c : coplanar_sliding_cases(rng, 12)) cases.push_back(c);
  int asked = 0, evaluated = 0, pieced = 0, differ_when_wrong = 0, differ_any_piece = 0, queries = 0;
  auto check = [&](const auto& q) {
    using T = std::decay_t<decltype(q.points()[0].x)>;
    for (CcdMode mode : {CcdMode::contacts, CcdMode::set}) {
      CcdParams<T> params;
      params.mode = mode;
      const CertifiedAnswer<T> whole = CertifiedCcd::refine<false>(q, params);
      SubtreeInside inside;
      inside.max_level = detail::certified_inside_levels<CertifiedPolicy, double>(params.tolerance);
      const CertifiedAnswer<T> ahead = CertifiedCcd::refine_with<false>(q, params, inside);
      CHECK(ahead.certainty == whole.certainty);
      CHECK(ahead.lo == whole.lo);
      CHECK(ahead.hi == whole.hi);
      asked += inside.asked, evaluated += inside.evaluated, pieced += inside.pieced, ++queries;
      SubtreeInside wrong;
      wrong.max_level = inside.max_level;
      wrong.wrong_place = 1;
      const CertifiedAnswer<T> misread = CertifiedCcd::refine_with<false>(q, params, wrong);
      differ_when_wrong += misread.certainty != whole.certainty || misread.lo != whole.lo || misread.hi != whole.hi;
      SubtreeInside loose;
      loose.max_level = inside.max_level;
      loose.any_piece = true;
      const CertifiedAnswer<T> pieces_misread = CertifiedCcd::refine_with<false>(q, params, loose);
      differ_any_piece += pieces_misread.certainty != whole.certainty || pieces_misread.lo != whole.lo || pieces_misread.hi != whole.hi;
    }
  };
  for (const Case& c : cases)
    for (int scale : {0, 60}) {
      const Case t = transformed(c, 0, 0, scale, false);
      if (t.vertex_face) check(as_query<double, VertexFaceQuery<double>>(t)), check(as_query<float, VertexFaceQuery<float>>(t));
      else check(as_query<double, EdgeEdgeQuery<double>>(t)), check(as_query<float, EdgeEdgeQuery<float>>(t));
    }
  INFO(queries << " searches: " << asked << " inside tests asked, " << evaluated << " subtrees evaluated, " << pieced
                << " intervals in pieces");
  CHECK(queries > 100);
  CHECK(evaluated * 2 < asked);     // most tests were read from a subtree evaluated ahead
  CHECK(pieced > 0);                // intervals were tested in pieces
  CHECK(differ_when_wrong > 0);     // the comparison sees a misread verdict
  CHECK(differ_any_piece > 0);      // and pieces combined wrongly
}

namespace {

// One lane of a simulated GPU warp: a search set up as certified_refine sets it up, run in parts.
template <class Q, class T>
struct SearchLane {
  using W = typename detail::certified_compute<T>::type;
  using QW = std::decay_t<decltype(std::declval<Q>().template cast<W>())>;
  using Search = detail::CertifiedSearch<CertifiedPolicy, detail::kRefineStackMax, false, false, QW, W, T>;
  QW q;
  Vec3<W> m;
  CcdParams<T> params;
  typename Search::Entry stack[detail::kRefineStackMax];
  std::optional<Search> search;
  CertifiedAnswer<T> settled;  // where no search runs (as certified_refine answers there)
  bool running = false;

  SearchLane(const Q& q_in, const CcdParams<T>& p) : q(q_in.template cast<W>()), m(detail::coordinate_magnitude(q)), params(p) {
    const W mag = detail::fmul(W(4), max_component(m));
    detail::BernsteinPiece<W> root;
    if (!detail::cubic_on_step<CertifiedPolicy>(q, mag, W(detail::unit_roundoff<T>()), root)) return;
    if (detail::same_sign_beyond(root.c, root.bound)) {
      settled = {Certainty::miss, T(0), T(1)};
      return;
    }
    const W slack = detail::underflow_slack(mag, 4);
    if (!detail::finite_value(slack)) return;
    search.emplace(stack, q, m, W(detail::unit_roundoff<T>()), root, slack, params, detail::kNeverDefer, nullptr, nullptr);
    running = true;
  }
  CertifiedAnswer<T> answer() const { return search ? search->answer() : settled; }
};

// Runs the lanes' searches in rounds, as certified_search's loop does on a GPU warp: every running
// lane advances to its next inside test, then the round's tests are answered, last lane first.
// `misroute`: each lane is given the verdict of the next asking lane's interval (a control).
// Returns the rounds; `shared` counts the rounds in which two or more lanes asked at once.
template <class Lanes>
int run_in_rounds(Lanes& lanes, bool misroute, int& shared) {
  int rounds = 0;
  detail::InsideOneByOne one_by_one;
  for (;;) {
    std::vector<std::size_t> asking;
    for (std::size_t k = 0; k < lanes.size(); ++k) {
      if (!lanes[k].running) continue;
      lanes[k].running = lanes[k].search->advance();
      if (lanes[k].running) asking.push_back(k);
    }
    if (asking.empty()) return rounds;
    ++rounds;
    shared += asking.size() >= 2;
    for (std::size_t j = asking.size(); j-- > 0;) {
      auto& lane = *lanes[asking[j]].search;
      const auto& from = *lanes[asking[misroute ? (j + 1) % asking.size() : j]].search;
      const auto compute = [&](int level, std::uint32_t index) { return lane.inside(level, index); };
      lane.resume(lane.inside(from.level(), from.index()), one_by_one, compute);
    }
  }
}

}  // namespace

TEST_CASE("certified path: searches run side by side, their tests answered in rounds, give each one's own answer",
          "[narrow][certified]") {
  // The GPU's lanes meet before each round of inside tests (certified_search): a search's two parts
  // must carry nothing from one lane's search to another's, whatever order the tests come in.
  std::mt19937 rng(23);
  std::vector<Case> cases = hard_cases(rng, 6);
  for (const Case& c : coplanar_sliding_cases(rng, 12)) cases.push_back(c);
  int rounds = 0, shared = 0, differ = 0, differ_misrouted = 0, searches = 0;
  auto run = [&](auto tag) {
    using T = decltype(tag);
    for (const bool vf : {true, false}) {
      CcdParams<T> params;
      auto check = [&](auto make) {
        using Q = std::decay_t<decltype(make(cases[0]))>;
        for (std::size_t first = 0; first < cases.size(); first += 32) {
          for (const bool misroute : {false, true}) {
            std::vector<SearchLane<Q, T>> lanes;
            lanes.reserve(32);
            for (std::size_t k = first; k < std::min(cases.size(), first + 32); ++k)
              if (cases[k].vertex_face == vf) lanes.emplace_back(make(cases[k]), params);
            int lane_shared = 0;
            const int lane_rounds = run_in_rounds(lanes, misroute, lane_shared);
            for (std::size_t k = 0, lane = 0; k < std::min(cases.size(), first + 32) - first; ++k) {
              if (cases[first + k].vertex_face != vf) continue;
              const CertifiedAnswer<T> whole = CertifiedCcd::refine<false>(make(cases[first + k]), params);
              const CertifiedAnswer<T> side = lanes[lane++].answer();
              const bool same = side.certainty == whole.certainty && side.lo == whole.lo && side.hi == whole.hi;
              if (misroute) differ_misrouted += !same;
              else differ += !same, ++searches;
            }
            if (!misroute) rounds += lane_rounds, shared += lane_shared;
          }
        }
      };
      if (vf) check([](const Case& c) { return as_query<T, VertexFaceQuery<T>>(c); });
      else check([](const Case& c) { return as_query<T, EdgeEdgeQuery<T>>(c); });
    }
  };
  run(double{});
  run(float{});
  INFO(searches << " searches in " << rounds << " rounds, " << shared << " with two or more tests");
  CHECK(searches > 100);
  CHECK(differ == 0);
  CHECK(shared > 0);            // lanes asked for tests in the same round
  CHECK(differ_misrouted > 0);  // the comparison sees a verdict given to the wrong search
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

// The search's levels from a tolerance's exponent: the least level whose width is within it, and
// one past it for the finest, checked against their definitions (widths compared exactly).
template <class T>
static void check_tolerance_levels(T tolerance) {
  int least = 0;  // by definition: 2^-least <= tolerance
  while (least < 2000 && !(std::ldexp(1.0L, -least) <= static_cast<long double>(tolerance))) ++least;
  INFO("tolerance " << static_cast<double>(tolerance));
  REQUIRE(detail::tolerance_level(tolerance) == least);
  const int grid = std::min(std::numeric_limits<T>::digits - 2, 30);
  REQUIRE(detail::certified_max_level(tolerance) == std::clamp(least + 1, 1, grid));
}
TEST_CASE("certified path: the levels of a tolerance are exact, at powers of two and an ulp either side", "[narrow][certified]") {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int k = 0; k <= 60; ++k) {
    const double p = std::ldexp(1.0, -k);
    for (const double t : {p, std::nextafter(p, 0.0), std::nextafter(p, 2.0), 0.75 * p}) {
      if (t > 0.0 && t < 1.0) check_tolerance_levels(t);
      const float f = static_cast<float>(t);
      if (f > 0.0f && f < 1.0f) check_tolerance_levels(f);
    }
    check_tolerance_levels(std::nextafter(static_cast<float>(p), 0.0f));
  }
  for (int i = 0; i < 2000; ++i) {
    const double t = std::ldexp(unit(rng), -static_cast<int>(unit(rng) * 40.0));
    if (t > 0.0) check_tolerance_levels(t), check_tolerance_levels(static_cast<float>(t));
  }
  check_tolerance_levels(std::numeric_limits<double>::denorm_min());
  check_tolerance_levels(1.0);
  check_tolerance_levels(3.0f);
  // Not a tolerance (rejected by the pipelines): no level within it, so the finest.
  for (const double bad : {0.0, -1e-6, std::numeric_limits<double>::quiet_NaN()}) {
    REQUIRE(detail::tolerance_level(bad) >= (1 << 20));
    REQUIRE(detail::certified_max_level(bad) == 30);
  }
}
