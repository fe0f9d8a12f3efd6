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
  /// FP32 first: the screen and the refinement's first levels run in single precision on the pair
  /// relative to a local origin (detail::certified_screen_single, CertifiedFilter::decides_single), and in
  /// double only on what they leave undecided. Their misses are certain for the input as given
  /// (double or float); false: the double path alone.
  static constexpr bool kSingleFirst = true;
  /// The single-precision filter's second round: an interval whose inside test in float is
  /// unknown is split kInsideEvery levels further and its pieces tested in float before the pair
  /// goes to double (CertifiedFilter::expand_single).
  static constexpr bool kSingleSecondRound = true;
  /// The single-precision filter first tries directions that separate the pair's swept features
  /// (their hulls over the step, detail::swept_hulls_apart; on the GPU in the screen's tail). Off:
  /// since the screen tests the differences (kCornerDifferences) they end only 1-3% of the pairs
  /// it passes on cloth-ball and armadillo-rollers, which the filter's intervals decide in float
  /// anyway, and trying them on every such pair cost more than it saved (NVIDIA H200: cloth-ball's
  /// narrow phase 0.86 -> 0.83 ms; one CPU thread 524-528 -> 493-503 ms; docs/NARROW_PHASE.md,
  /// B13). True for degenerate motion whose hulls are apart but whose intervals stay undecided.
  static constexpr bool kSeparatingDirections = false;
  /// Multiplier of the single-precision screen's input bound, which covers rounding the relative
  /// coordinates to float (1 = as derived; only the mutation tests change it).
  static constexpr double kSingleInputBound = 1.0;
  /// The screen tests the differences of the features' points at the same time before the cubic
  /// (detail::differences_apart): features that move together are apart there, however their
  /// swept boxes overlap, and those whose motion is coplanar or collinear are decided at once
  /// instead of by a search that cannot end (the inclusion fallback's work, before).
  static constexpr bool kCornerDifferences = true;
  /// Multiplier of that test's margins (1 = as derived; only the mutation tests change it).
  static constexpr double kDifferenceBound = 1.0;
  /// Multiplier of the separating directions' bound (1 = as derived; only the mutation tests
  /// change it).
  static constexpr double kSeparationBound = 1.0;
  /// FP32 first for contacts: a pair the single-precision screen and filter leave is searched in
  /// single precision first (its as-given bounds made its perturbed ones, so that its claims hold
  /// for the input), and a contact's certain descent goes on in double only from the interval
  /// float can no longer halve (refine_single_first); false: the pairs the
  /// single passes leave are searched in double from [0, 1].
  static constexpr bool kSingleDescent = true;
  /// The search in single precision leaves to double a pair that needs more halvings than this
  /// before a certain descent (its levels to kInsideFrom and one interval's to the next inside
  /// test take 22), or whose motion is coplanar: such searches are long, and float rarely
  /// decides them.
  static constexpr int kSingleSearchSplits = 24;
  /// Where the search in single precision reaches a certain descent, it hands the interval to
  /// double as it is, with the root guessed on it (detail::estimated_root); false: it first
  /// halves the interval in float as far as float can decide the middle signs. The double tail
  /// proves the same leaf either way (docs/NARROW_PHASE.md, B10).
  static constexpr bool kHandOffAtDescent = true;
  /// The double tail of such a contact proves the leaf that holds the root from f's signs at its
  /// two ends, the leaf guessed in float, instead of halving down to it (about a third of the
  /// tail's FP64 instructions); false, or where those signs are not certain: the halvings.
  static constexpr bool kDescentJump = true;
  /// The leaf is first proved from f computed at its ends from the query's points, with the root
  /// guessed by the search in single precision (detail::CubicAtPoints, B15), and the cubic built in
  /// double only where that cannot prove it: about a third of the double tail's FP64 instructions.
  static constexpr bool kJumpAtPoints = true;
  /// Multiplier of B15's bounds (1 = as derived; only the mutation tests change it).
  static constexpr double kPointBound = 1.0;
  /// Multiplier of B17's own error bound (the pairs of floats against the query as given; 1 = as
  /// derived; only the mutation tests change it).
  static constexpr double kFloatPairBound = 1.0;
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
  /// An interval whose inside test is unknown, a leaf or a piece of coplanar motion at level
  /// kCoplanarPiecesFrom or deeper, is tested again in 2^kPieceLevels pieces (fewer where the time
  /// grid has no room) and excluded when every piece is: a piece's bound covers an eighth of the
  /// motion, so features that approach slowly (a vertex sliding onto an edge in coplanar motion,
  /// where only the inside test excludes time) are excluded up to about a leaf before they touch,
  /// instead of a band of intervals on every level that ran out of kMaxSplits (0: no pieces).
  static constexpr int kPieceLevels = 3;
  /// Below the certified filter's levels (CertifiedFilter: 3 and 7), whose verdicts must stay the
  /// search's own there.
  static constexpr int kCoplanarPiecesFrom = 8;
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

}  // namespace lwsccd

// The definitions, in the order they were written in (each part includes the one before it).
#include "lwsccd/narrow_phase/detail/certified_bernstein.hpp"
#include "lwsccd/narrow_phase/detail/certified_motion.hpp"
#include "lwsccd/narrow_phase/detail/certified_screen.hpp"
#include "lwsccd/narrow_phase/detail/certified_single.hpp"
#include "lwsccd/narrow_phase/detail/certified_refine.hpp"
#include "lwsccd/narrow_phase/detail/certified_filter.hpp"

namespace lwsccd {

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
  /// A batch's steps, in this order (classify runs them on one query): screen_verdict on every
  /// pair (single precision alone when Policy::kSingleFirst, saying in which precision a miss was
  /// decided); filter_single on what it passes (detail::CertifiedFilter::decides_single: true for
  /// a certain miss proved in float by the refinement's first levels); refine_single_first on
  /// what that leaves (the search in float: its misses and contacts); screen_after_single, the
  /// double screen, on what that leaves; then refine. The batches give the first two the pair's
  /// vertices rounded to float (gather_single_vertex_face: no double arithmetic before a pair is
  /// decided in float), the others the double query.
  template <class Q, class T>
  LWSCCD_HD static detail::ScreenVerdict screen_verdict(const Q& q, const CcdParams<T>& params) {
    return detail::certified_first_screen<Policy>(q, params);
  }
  template <class Q, class T>
  LWSCCD_HD static bool filter_single(const Q& q, const CcdParams<T>& params) {
    return detail::CertifiedFilter<Policy>::decides_single(q, params);
  }
  template <class Q, class T>
  LWSCCD_HD static bool screen_after_single(const Q& q, const CcdParams<T>& params) {
    return detail::certified_screen_after_single<Policy>(q, params);
  }
  /// What a batch runs first on a pair the single-precision screen and filter left, where
  /// Policy::kSingleDescent: the search in single precision, whose certain misses and contacts
  /// (the certain descent's last levels in double) decide the pair (`done` set); on what it
  /// leaves, screen_after_single then refine (detail::certified_refine_after_single: the order
  /// classify runs them in).
  /// `in_float_pairs`, where given, tells whether a contact's leaf was proved in pairs of floats
  /// (CcdParams::leaves_in_float_pairs: no FP64 in its tail). kLanesAlike: every lane of a GPU
  /// warp runs it on the same values (a warp per pair).
  template <bool kSettle = true, bool kLanesAlike = false, class Q, class T>
  LWSCCD_HD static CertifiedAnswer<T> refine_single_first(const Q& q, const CcdParams<T>& params, bool& done,
                                                          bool* in_float_pairs = nullptr) {
    return detail::certified_refine_single_first<Policy, kSettle, kLanesAlike>(q, params, done, in_float_pairs);
  }
  /// kSettle false: undecided answers are left for undecided_from (a batch's separate pass).
  template <bool kSettle = true, class Q, class T>
  LWSCCD_HD static CertifiedAnswer<T> refine(const Q& q, const CcdParams<T>& params) {
    return detail::certified_refine<Policy, detail::kRefineStackMax, kSettle>(q, params);
  }
  /// refine with its inside tests asked of `inside_at` (detail::InsideOneByOne's contract): the
  /// same answer, whatever order the tests are evaluated in.
  template <bool kSettle, class Q, class T, class InsideAt>
  LWSCCD_HD static CertifiedAnswer<T> refine_with(const Q& q, const CcdParams<T>& params, InsideAt&& inside_at) {
    return detail::certified_refine<Policy, detail::kRefineStackMax, kSettle>(q, params, detail::kNeverDefer, nullptr, inside_at);
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
/// Whether a method decides in single precision first (a certified method whose policy says so).
template <class Method, bool = certified_of<Method>::value>
struct single_first_of : std::false_type {};
template <class Method>
struct single_first_of<Method, true> : std::bool_constant<Method::policy_type::kSingleFirst> {};
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
