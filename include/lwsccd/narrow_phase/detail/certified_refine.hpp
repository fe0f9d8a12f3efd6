// lwsccd — the certified refinement: contact candidates and the tolerance test, the undecided
// answer, the search (time halved until every piece is decided, or the fallback's) in double
// (certified_refine) and in single precision with a double tail for contacts
// (certified_refine_single_first), and the order a batch runs them in.
// Part of certified_ccd.hpp: include <lwsccd/narrow_phase/certified_ccd.hpp>, not this file.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <type_traits>

#include "lwsccd/core/detail/float_pair.hpp"
#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/core/detail/rounding.hpp"
#include "lwsccd/narrow_phase/detail/certified_screen.hpp"
#include "lwsccd/narrow_phase/detail/certified_single.hpp"

namespace lwsccd::detail {

/// Points (u, v) of the domain near which a query's F(t, u, v) is smallest at time t: the plane's
/// least-squares point brought into the domain and the closest points on the domain's edges.
/// Only where to look: any point of the domain is sound (tolerance_contact tests a box around it).
template <class W>
LWSCCD_HD int contact_candidates(const VertexFaceQuery<W>& q, W t, W u[4], W v[4]) {
  const Vec3<W> a = vadd_scaled(q.a0, vsub(q.a1, q.a0), t);
  const Vec3<W> ab = vsub(vadd_scaled(q.b0, vsub(q.b1, q.b0), t), a), ac = vsub(vadd_scaled(q.c0, vsub(q.c1, q.c0), t), a);
  const Vec3<W> ap = vsub(vadd_scaled(q.p0, vsub(q.p1, q.p0), t), a), bc = vsub(ac, ab);
  const W aa = vdot(ab, ab), ab_ac = vdot(ab, ac), cc = vdot(ac, ac), pa = vdot(ap, ab), pc = vdot(ap, ac), bb = vdot(bc, bc);
  const W det = fsub(fmul(aa, cc), fmul(ab_ac, ab_ac));
  int n = 0;
  if (det > W(0)) {
    W x = fsub(fmul(cc, pa), fmul(ab_ac, pc)) / det, y = fsub(fmul(aa, pc), fmul(ab_ac, pa)) / det;
    x = x > W(0) ? x : W(0);
    y = y > W(0) ? y : W(0);
    const W sum = fadd(x, y);
    if (sum > W(1)) x = x / sum, y = y / sum;
    u[n] = x, v[n++] = y;
  }
  if (aa > W(0)) u[n] = unit_clamp(pa / aa), v[n++] = W(0);
  if (cc > W(0)) u[n] = W(0), v[n++] = unit_clamp(pc / cc);
  if (bb > W(0)) {
    const W s = unit_clamp(vdot(vsub(ap, ab), bc) / bb);
    u[n] = fsub(W(1), s), v[n++] = s;
  }
  return n;
}
template <class W>
LWSCCD_HD int contact_candidates(const EdgeEdgeQuery<W>& q, W t, W u[5], W v[5]) {
  const Vec3<W> a = vadd_scaled(q.a0, vsub(q.a1, q.a0), t), c = vadd_scaled(q.c0, vsub(q.c1, q.c0), t);
  const Vec3<W> ab = vsub(vadd_scaled(q.b0, vsub(q.b1, q.b0), t), a), cd = vsub(vadd_scaled(q.d0, vsub(q.d1, q.d0), t), c);
  const Vec3<W> ca = vsub(a, c);
  const W aa = vdot(ab, ab), ab_cd = vdot(ab, cd), cc = vdot(cd, cd), ra = -vdot(ab, ca), rc = vdot(cd, ca);
  const W det = fsub(fmul(aa, cc), fmul(ab_cd, ab_cd));
  int n = 0;
  if (det > W(0)) u[n] = unit_clamp(fadd(fmul(cc, ra), fmul(ab_cd, rc)) / det), v[n++] = unit_clamp(fadd(fmul(ab_cd, ra), fmul(aa, rc)) / det);
  if (cc > W(0)) {
    u[n] = W(0), v[n++] = unit_clamp(rc / cc);
    u[n] = W(1), v[n++] = unit_clamp(vdot(cd, vadd(ca, ab)) / cc);
  }
  if (aa > W(0)) {
    u[n] = unit_clamp(ra / aa), v[n++] = W(0);
    u[n] = unit_clamp(vdot(ab, vsub(cd, ca)) / aa), v[n++] = W(1);
  }
  return n;
}

/// Contact within the tolerance over [from, to]: a small box of (t, u, v) there
/// that the inclusion test accepts (not excluded by the time filter, an axis or a separating
/// direction, and F within the distance the features move in `tolerance` of time) - the answer
/// the fallback would give when it finds such a box with everything before it excluded. The boxes
/// tried: each half of the window in time, around the candidates of its middle (u and v +- an
/// eighth of that distance over the query's extent). Used where the certified search has
/// excluded every time before `from` but cannot prove a contact: features that touch on a
/// boundary (a vertex sliding along an edge), where no sign is certain.
template <class Q, class W>
LWSCCD_HD bool tolerance_contact(const Q& q, const CcdParams<W>& params, W from, W to) {
  const InclusionSetup<W> s = inclusion_setup(q, params);
  if (s.separated) return false;
  const Vec3<W>* pts = q.points();
  W extent = W(0);
  for (int i = 1; i < 8; ++i) extent = fmax_of(extent, max_component(abs(vsub(pts[i], pts[0]))));
  const W radius = extent > W(0) ? fmul(s.delta, W(0.125)) / extent : W(0);
  const W half = fmul(fsub(to, from), W(0.5));
  constexpr int kCandidates = 5;
  for (int h = 0; h < 2; ++h) {
    const W t[2] = {h == 0 ? from : fadd(from, half), h == 0 ? fadd(from, half) : to};
    W cu[kCandidates], cv[kCandidates];
    const int n = contact_candidates(q, fmul(fadd(t[0], t[1]), W(0.5)), cu, cv);
    for (int k = 0; k < n; ++k) {
      const W u[2] = {fmax_of(W(0), fsub(cu[k], radius)), fmin_of(W(1), fadd(cu[k], radius))};
      const W v[2] = {fmax_of(W(0), fsub(cv[k], radius)), fmin_of(W(1), fadd(cv[k], radius))};
      RangeTest<W> r;
      test_ranges(q, s, t, u, v, true, false, r);
      if (r.verdict == BoxVerdict::accepted) return true;
    }
  }
  return false;
}

/// The certified answer for a query whose search excluded every time before `lower` and proved no
/// contact after it: undecided from `lower` (the fallback's), or, with Policy::kToleranceContacts,
/// a hit at `lower` when tolerance_contact finds contact within the tolerance right after it.
/// The test runs in T with the inclusion test's rounding bound for T, as the fallback would (a float
/// query's contact within float's rounding is one for the fallback too).
template <class Policy, class Q, class T>
LWSCCD_HD CertifiedAnswer<T> certified_undecided(const Q& q_in, const CcdParams<T>& params, T lower) {
  const CertifiedAnswer<T> undecided{Certainty::undecided, lower, T(1)};
  if (!Policy::kToleranceContacts || params.min_separation > T(0) || !(lower < T(1)) || !(lower < params.time_limit))
    return undecided;
  // Two of the search's leaves (dyadic: lower is a multiple of them, so the end is exact), or one
  // where the level's cap makes two wider than the tolerance.
  const int level = certified_max_level(params.tolerance);
  const T width = exact_pow2_neg<T>(level - 1) <= params.tolerance ? exact_pow2_neg<T>(level - 1) : exact_pow2_neg<T>(level);
  const T to = fadd(lower, width) < T(1) ? fadd(lower, width) : T(1);
  if (!tolerance_contact(q_in.template cast<T>(), params, lower, to)) return undecided;
  return {Certainty::hit, lower, to, true};
}

/// The deepest levels the time grid has room for: dyadic indices in 32 bits whose times are exact
/// in T and in W (certified_max_level's cap for the narrower of the two).
template <class T, class W>
LWSCCD_HD constexpr int certified_grid_levels() {
  constexpr int t = std::numeric_limits<T>::digits - 2, w = std::numeric_limits<W>::digits - 2;
  constexpr int narrower = t < w ? t : w;
  return narrower < 30 ? narrower : 30;
}

/// The deepest level at which the search asks for an inside test: its leaves' pieces
/// (Policy::kPieceLevels below certified_max_level), within the time grid.
template <class Policy, class W, class T>
LWSCCD_HD int certified_inside_levels(T tolerance) {
  const int deepest = certified_max_level(tolerance) + Policy::kPieceLevels, grid = certified_grid_levels<T, W>();
  return deepest < grid ? deepest : grid;
}

/// Whether an `inside_at` evaluator runs an interval's pieces itself (`pieces(level, index,
/// depth, compute)`, all at once, as a warp's lanes do): a member `kEvaluatesPieces`.
template <class InsideAt, class = void>
struct evaluates_pieces : std::false_type {};
template <class InsideAt>
struct evaluates_pieces<InsideAt, std::void_t<decltype(InsideAt::kEvaluatesPieces)>>
    : std::bool_constant<InsideAt::kEvaluatesPieces> {};

/// The verdicts of 2^depth pieces, combined: outside when every piece is outside, outside as
/// given when every piece is one of the two, else unknown.
struct PieceVotes {
  bool all_outside = true, all_excluded = true;
  LWSCCD_HD void add(InsideVerdict v) {
    all_outside = all_outside && v == InsideVerdict::outside;
    all_excluded = all_excluded && (v == InsideVerdict::outside || v == InsideVerdict::outside_as_given);
  }
  LWSCCD_HD InsideVerdict verdict() const {
    return all_outside ? InsideVerdict::outside : (all_excluded ? InsideVerdict::outside_as_given : InsideVerdict::unknown);
  }
};

/// The verdict of an interval whose own inside test was unknown, from its pieces
/// Policy::kPieceLevels levels down (PieceVotes). Sound as any inside test is: a piece's verdict
/// holds over the piece, and the pieces cover the interval. Asked of `inside_at` like the
/// search's other tests (or of its `pieces` where it has one), so every evaluator gives the same
/// verdicts.
template <class Policy, class T, class W, class InsideAt, class Compute>
LWSCCD_HD InsideVerdict verdict_in_pieces(int level, std::uint32_t index, InsideAt& inside_at, const Compute& compute) {
  static_assert(Policy::kPieceLevels >= 0 && Policy::kPieceLevels <= 5,
                "lwsccd: CertifiedPolicy::kPieceLevels must be in [0, 5] (a warp's lanes evaluate the pieces at once)");
  int depth = certified_grid_levels<T, W>() - level;
  depth = depth < Policy::kPieceLevels ? depth : Policy::kPieceLevels;
  if (depth <= 0) return InsideVerdict::unknown;
  if constexpr (evaluates_pieces<std::decay_t<InsideAt>>::value) {
    return inside_at.pieces(level, index, depth, compute);
  } else {
    PieceVotes votes;
    for (std::uint32_t k = 0; k < (1u << depth) && votes.all_excluded; ++k)
      votes.add(inside_at(level + depth, (index << depth) | k, compute));
    return votes.verdict();
  }
}

/// The refinement's inside tests as they are asked for, one at a time (certified_refine's
/// `inside_at`: called with an interval's level and index, and a function that computes the
/// verdict there). The GPU's warp per search evaluates a whole subtree of them at once instead.
struct InsideOneByOne {
  template <class Compute>
  LWSCCD_HD InsideVerdict operator()(int level, std::uint32_t index, const Compute& compute) const {
    return compute(level, index);
  }
};
/// InsideOneByOne for a search that every lane of a GPU warp runs alike, on the same values (a
/// warp per search): its lanes need not meet before their tests (certified_search).
struct InsideOneByOneLanesAlike : InsideOneByOne {
  static constexpr bool kLanesAlike = true;
};
/// Whether a warp's lanes run an `inside_at`'s search alike: a member `kLanesAlike`, or an
/// evaluator of pieces (a warp's lanes evaluate them at once).
template <class InsideAt, class = void>
struct lanes_alike : evaluates_pieces<InsideAt> {};
template <class InsideAt>
struct lanes_alike<InsideAt, std::void_t<decltype(InsideAt::kLanesAlike)>> : std::bool_constant<InsideAt::kLanesAlike> {};

/// certified_refine's most pending intervals (its stack: one right half per level): enough for
/// the deepest search, whose levels stop at 30 (dyadic indices in 32 bits; certified_max_level),
/// with room to spare. A search that defers at level d needs d + 2.
inline constexpr int kRefineStackMax = 34;
/// certified_refine's `defer_level` for a search that never defers.
inline constexpr int kNeverDefer = 1 << 30;

/// How a certain descent ended (certain_descent).
enum class DescentEnd : std::uint8_t {
  within_tolerance,  ///< the interval is within the tolerance (or at the finest level): the hit
  past_limit,        ///< the query's root lies past the caller's time limit
  too_many_splits,   ///< Policy::kMaxSplits reached
  on_grid            ///< the middle value is within its as-given error: the interval left as it was
};

/// Certain descent (docs/NARROW_PHASE.md 3.3, step 6) from `piece`, interval `index` of `level`,
/// over which every perturbed cubic has exactly one root, f has the certain sign `first` at the
/// start, and a root is a contact of the query as given. Each halving keeps the half that holds
/// the query's root, by the sign of f at the middle (the left half's last coefficient): of
/// `first` beyond the perturbed bound, no perturbed root lies in the left half; beyond only the
/// as-given bound, the query's root is right of it but a perturbed one may not be (the lower
/// bound stops there); of the other sign, the query's root is in the left half, and what lies
/// right is later. Ends with piece, index and level at the last interval: within the tolerance
/// (its start noted as the lower bound where none was), past the time limit (right of it), or,
/// for the last two ends, the interval that could not be halved.
template <class Policy, class W, class T>
LWSCCD_HD DescentEnd certain_descent(BernsteinPiece<W>& piece, std::uint32_t& index, int& level, int first,
                                     const CcdParams<T>& params, int max_level, int& splits, T& lower, bool& has_lower) {
  for (;;) {
    const T step = exact_pow2_neg<T>(level);
    const T from = static_cast<T>(index) * step, to = static_cast<T>(index + 1u) * step;
    // Within the tolerance; an interval past the caller's time limit is narrowed to the leaves,
    // where the limit cuts as it does in the search (a root past it is no answer).
    if ((to - from <= params.tolerance && to <= params.time_limit) || level >= max_level) {
      if (!has_lower) lower = from, has_lower = true;
      return DescentEnd::within_tolerance;
    }
    if (++splits > Policy::kMaxSplits) return DescentEnd::too_many_splits;
    BernsteinPiece<W> left, right;
    bernstein_halves<Policy>(piece, left, right);
    const W middle = left.c[3];
    const int sign = sign_beyond(middle, left.exact);
    if (sign == 0) return DescentEnd::on_grid;
    ++level;
    if (sign == first) {
      if (sign_beyond(middle, left.bound) == 0 && !has_lower) lower = from, has_lower = true;
      piece = right;
      index = 2u * index + 1u;
      // The query's root is past the caller's time limit; so is everything still stacked.
      if (static_cast<T>(index) * exact_pow2_neg<T>(level) >= params.time_limit) return DescentEnd::past_limit;
    } else {
      piece = left;
      index = 2u * index;
    }
  }
}

/// Where in [0, 1] the piece's cubic has its root (one sign change certain): regula falsi on the
/// control polygon, then Newton steps, in float. Only where to look: the caller proves the leaf.
template <class W>
LWSCCD_HD float estimated_root(const BernsteinPiece<W>& p) {
  const float c0 = static_cast<float>(p.c[0]), c1 = static_cast<float>(p.c[1]), c2 = static_cast<float>(p.c[2]),
              c3 = static_cast<float>(p.c[3]);
  float t = c0 / fsub(c0, c3);
  for (int k = 0; k < 4; ++k) {
    if (!(t >= 0.0f && t <= 1.0f)) return 0.5f;
    const float s = fsub(1.0f, t);
    // f and f' in the Bernstein basis.
    const float b0 = fmul(s, fmul(s, s)), b1 = fmul(3.0f, fmul(t, fmul(s, s))), b2 = fmul(3.0f, fmul(fmul(t, t), s)), b3 = fmul(t, fmul(t, t));
    const float f = fadd(fadd(fmul(c0, b0), fmul(c1, b1)), fadd(fmul(c2, b2), fmul(c3, b3)));
    const float d = fmul(3.0f, fadd(fadd(fmul(fsub(c1, c0), fmul(s, s)), fmul(fmul(2.0f, fsub(c2, c1)), fmul(t, s))),
                                    fmul(fsub(c3, c2), fmul(t, t))));
    if (!(d != 0.0f)) break;
    t = fsub(t, f / d);
  }
  return t >= 0.0f && t <= 1.0f ? t : 0.5f;
}

/// Where single precision's search handed a contact to double (FP32 first for contacts,
/// Policy::kSingleDescent): the interval `index` of `level` over which every query within the
/// single-precision perturbation (bound B9, so the input as given and every query the double path
/// covers) has exactly one root of its cubic, f has the certain sign `first` at the interval's
/// start, a root is a contact of the input as given (inside, with that perturbation counted as
/// given), and every earlier time is excluded for all of them. docs/NARROW_PHASE.md 3.5.
struct SingleHandoff {
  bool valid = false;
  int level = 0, first = 0;
  std::uint32_t index = 0;
  float guess = -1.0f;  ///< where in [0, 1] the float cubic's root lies (estimated_root on the interval's piece)
};
/// The hand-off of interval `index` of `level`, whose float cubic is `piece`, f's sign at its
/// start `first`: the root guessed on it (estimated_root), as a time in [0, 1].
template <class W>
LWSCCD_HD SingleHandoff handoff_at(const BernsteinPiece<W>& piece, int level, std::uint32_t index, int first) {
  return {true, level, first, index, fmul(fadd(static_cast<float>(index), estimated_root(piece)), exact_pow2_neg<float>(level))};
}

/// The certified search over [0, 1] from the cubic's piece `root` of the query q (in W, m its
/// per-axis coordinate bound, `perturbation` the relative perturbation its bounds cover), as
/// certified_refine documents it. kSingle: q is single precision's query (relative_single), whose
/// "as given" means nothing of the input; its as-given bounds are then made its perturbed ones
/// (root.exact = root.bound; inside tests count the perturbation as given), so every claim holds
/// for the input, and the search stops where double must take over: a certain descent, where it
/// starts (Policy::kHandOffAtDescent) or where float can no longer halve it or it is within the
/// tolerance, sets *handoff (the answer is then undecided, for certified_descend_from); any other
/// end that is not a miss is undecided without it.
template <class Policy, int kStack, bool kSettle, bool kSingle, class QW, class W, class T>
class CertifiedSearch {
 public:
  /// A pending interval (the stack holds one right half per level).
  struct Entry {
    BernsteinPiece<W> piece;
    std::uint32_t index;
    int level;
  };
  /// `stack`: room for kStack entries, the caller's (a member array indexed at run time would
  /// keep the whole object, every scalar of the search with it, in a GPU thread's local memory).
  LWSCCD_HD CertifiedSearch(Entry* stack, const QW& q, const Vec3<W>& m, W perturbation, const BernsteinPiece<W>& root,
                            W inside_slack, const CcdParams<T>& params, int defer_level, bool* deferred, SingleHandoff* handoff)
      : stack_(stack), q_(q), m_(m), perturbation_(perturbation), inside_slack_(inside_slack), params_(params), defer_level_(defer_level),
        deferred_(deferred), handoff_(handoff), max_level_(certified_max_level(params.tolerance)),
        set_mode_(params.mode == CcdMode::set),
        descent_(Policy::kCertainDescent && !set_mode_ && (Policy::kDescentBeforeDefer || defer_level >= max_level_)) {
    static_assert(kStack >= 3 && kStack <= kRefineStackMax, "lwsccd: certified_refine holds 3 to kRefineStackMax pending intervals");
    e_ = {root, 0u, 0};
    next_held_ = !passed_over(root, 0u, 0);
  }

  /// Runs the search up to the next interval that needs its inside test (true: the test of
  /// level(), index() is asked for, and resume() continues with its verdict) or to its end
  /// (false: answer()). Why two parts: a GPU warp whose lanes each run a search reconverges after
  /// this loop, so the lanes that need a test run it together instead of one or two at a time.
  LWSCCD_HD bool advance() {
    while (!finished_) {
      if (next_held_) {
        next_held_ = false;  // e_ is the interval to visit
      } else {
        if (top_ == 0) return finish_at_end();
        e_ = stack_[--top_];
      }
      // Dyadic with at most certified_max_level(T) bits: exact in T and W.
      const T scale = exact_pow2_neg<T>(e_.level);
      lo_ = static_cast<T>(e_.index) * scale, hi_ = static_cast<T>(e_.index + 1u) * scale;
      // (passed_over was tested before this interval was held or stacked.)
      const W* c = e_.piece.c;
      const W exact = e_.piece.exact;
      if (same_sign_beyond(c, exact)) {  // no root as given; a perturbed query's may be here
        note_lower(lo_);
        continue;
      }
      // f(lo) = c[0], f(hi) = c[3]: a certain sign change proves a root of the query as given.
      crossing_ = (c[0] < -exact && c[3] > exact) || (c[0] > exact && c[3] < -exact);
      leaf_ = e_.level >= max_level_;
      // Set mode needs no tight time: a crossing interval is tried every fourth level on the way.
      try_hit_ = leaf_ || (set_mode_ && crossing_ && (e_.level & 3) == 0);
      const bool coarse = Policy::kInsideEvery > 0 && e_.level >= Policy::kInsideFrom &&
                          (e_.level - Policy::kInsideFrom) % (Policy::kInsideEvery > 0 ? Policy::kInsideEvery : 1) == 0;
      coplanar_ = all_within(c, exact);
      // Single precision leaves coplanar motion (no sign of f to follow, and long searches) and
      // searches that need many halvings before a descent to double.
      if constexpr (kSingle) {
        if (coplanar_ || splits_ >= Policy::kSingleSearchSplits) return finish(undecided());
      }
      // Both halves of one sign (a root of the control polygon, not of the cubic): no root here even
      // perturbed, so the costly inside test is skipped (before it, the interval was only split).
      if (Policy::kLookAhead && coarse && !leaf_ && !coplanar_ && halves_keep_sign<Policy>(e_.piece)) continue;
      if (try_hit_ || coarse || coplanar_) return true;
      after_inside(InsideVerdict::unknown);
    }
    return false;
  }

  /// The level and index of the interval whose inside test advance() asked for.
  LWSCCD_HD int level() const { return e_.level; }
  LWSCCD_HD std::uint32_t index() const { return e_.index; }

  /// The inside test over interval `index` of `level` (the asked one, or another that an
  /// `inside_at` evaluates ahead): the same operations on the same values, so the same verdict.
  LWSCCD_HD InsideVerdict inside(int level, std::uint32_t index) const {
    const W half_width = exact_pow2_neg<W>(level + 1);
    const T from = static_cast<T>(index) * exact_pow2_neg<T>(level);
    return inside_over<Policy>(q_, fadd(W(from), half_width), half_width, m_, perturbation_, inside_slack_, given());
  }

  /// Continues with the verdict of the asked interval's own test; `inside_at` and `compute` (as
  /// certified_search's) answer the tests of its pieces where that verdict is unknown.
  template <class InsideAt, class Compute>
  LWSCCD_HD void resume(InsideVerdict inside, InsideAt& inside_at, const Compute& compute) {
    if (inside == InsideVerdict::unknown && (leaf_ || (coplanar_ && e_.level >= Policy::kCoplanarPiecesFrom)))
      inside = verdict_in_pieces<Policy, T, W>(e_.level, e_.index, inside_at, compute);
    if (inside == InsideVerdict::outside || inside == InsideVerdict::outside_as_given) {  // roots here are no contacts
      if (inside == InsideVerdict::outside_as_given) note_lower(lo_);
      if (leaf_ && ++leaves_ > Policy::kMaxLeaves) finish(settle(has_lower_ ? lower_ : lo_));
      return;
    }
    after_inside(inside);
  }

  LWSCCD_HD const CertifiedAnswer<T>& answer() const { return answer_; }

 private:
  LWSCCD_HD static CertifiedAnswer<T> undecided() { return {Certainty::undecided, T(0), T(1)}; }
  LWSCCD_HD W given() const { return kSingle ? perturbation_ : W(0); }
  LWSCCD_HD void note_lower(T t) {
    if (!has_lower_) lower_ = t, has_lower_ = true;  // intervals come in time order
  }
  // Undecided from `from` (every earlier time excluded), unless contact within the tolerance
  // right after it settles the query. (Single precision: undecided, the double search's to answer.)
  LWSCCD_HD CertifiedAnswer<T> settle(T from) const {
    if constexpr (kSingle) return undecided();
    else if constexpr (kSettle) return certified_undecided<Policy>(q_, params_, from);
    else return CertifiedAnswer<T>{Certainty::undecided, from, T(1)};
  }
  LWSCCD_HD bool finish(const CertifiedAnswer<T>& a) {
    answer_ = a;
    finished_ = true;
    return false;
  }
  // Nothing as given; a perturbed query may still touch where only the as-given bounds excluded.
  LWSCCD_HD bool finish_at_end() {
    return finish(has_lower_ ? settle(lower_) : CertifiedAnswer<T>{Certainty::miss, T(0), T(1)});
  }

  // The rest of an interval's visit, once its inside test (if any) was not outside.
  LWSCCD_HD void after_inside(InsideVerdict inside) {
    const W* c = e_.piece.c;
    const W bound = e_.piece.bound, exact = e_.piece.exact;
    // Certain descent (certain_descent): over this interval every perturbed cubic has one root
    // and a root is a contact of the query as given. A middle value within its as-given error (a
    // root on the grid) ends it: everything it noted is undone and this interval is searched as
    // usual. Single precision hands the interval it reached to double instead.
    if (descent_ && inside == InsideVerdict::inside && !leaf_ && !has_open_ && single_crossing(c, bound)) {
      const int first = c[0] > W(0) ? 1 : -1;
      if constexpr (kSingle) {
        // Every fact the double tail needs holds from here on (B10), so the interval is handed
        // over as it is, the root guessed on it, instead of halved in float first: the tail proves
        // the same leaf. (It ends within the time limit: the descent could end nowhere else.)
        if (Policy::kHandOffAtDescent && !has_lower_ && handoff_ && hi_ <= params_.time_limit) {
          *handoff_ = handoff_at(e_.piece, e_.level, e_.index, first);
          finish(undecided());
          return;
        }
      }
      const T saved_lower = lower_;
      const bool saved_has_lower = has_lower_;
      const int saved_splits = splits_;
      BernsteinPiece<W> piece = e_.piece;
      std::uint32_t index = e_.index;
      int level = e_.level;
      const DescentEnd end = certain_descent<Policy>(piece, index, level, first, params_, max_level_, splits_, lower_, has_lower_);
      if constexpr (kSingle) {
        // Nothing is noted in single precision (its two bounds are one) but at leaves, which come
        // after any descent: the interval starts right after everything excluded.
        if (end == DescentEnd::past_limit) {
          finish({Certainty::miss, T(0), T(1)});
          return;
        }
        if ((end == DescentEnd::within_tolerance || end == DescentEnd::on_grid) && !saved_has_lower && handoff_)
          *handoff_ = handoff_at(piece, level, index, first);
        finish(undecided());
        return;
      } else {
        const T step = exact_pow2_neg<T>(level);
        const T from = static_cast<T>(index) * step, to = static_cast<T>(index + 1u) * step;
        if (end == DescentEnd::within_tolerance) {
          finish({Certainty::hit, lower_, to});
          return;
        }
        if (end == DescentEnd::too_many_splits) {
          finish(settle(has_lower_ ? lower_ : from));
          return;
        }
        if (end == DescentEnd::past_limit) {
          finish(has_lower_ ? settle(lower_) : CertifiedAnswer<T>{Certainty::miss, T(0), T(1)});
          return;
        }
        lower_ = saved_lower, has_lower_ = saved_has_lower, splits_ = saved_splits;
        descent_ = false;
        next_held_ = true;  // this interval again
        return;
      }
    }
    if (try_hit_) {
      if constexpr (kSingle) {  // leaves: the double search's
        finish(undecided());
        return;
      }
      // A root is certain across this leaf, or from the start of the unresolved leaves before it
      // (a root on the grid point between two leaves makes neither a crossing alone); those
      // leaves join the interval, which must stay within the tolerance.
      const int sign_lo = c[0] < -exact ? -1 : (c[0] > exact ? 1 : 0), sign_hi = c[3] < -exact ? -1 : (c[3] > exact ? 1 : 0);
      const bool is_inside = inside == InsideVerdict::inside;
      const bool joined = has_open_ && open_inside_ && is_inside && open_sign_ != 0 && sign_hi == -open_sign_;
      const T from = has_open_ ? open_from_ : lo_;
      if (((is_inside && crossing_) || joined) && (set_mode_ || hi_ - from <= params_.tolerance)) {
        note_lower(lo_);
        finish({Certainty::hit, lower_, hi_});
        return;
      }
      if (leaf_) {
        note_lower(lo_);  // not excluded (a wider interval tried in set mode is split instead)
        if (!has_open_) open_from_ = lo_, has_open_ = true, open_sign_ = sign_lo, open_inside_ = true;
        open_inside_ = open_inside_ && is_inside;
        if (++leaves_ > Policy::kMaxLeaves || (!set_mode_ && hi_ + (hi_ - lo_) - open_from_ > params_.tolerance))
          finish(settle(lower_));
        return;  // touching, tangent or on a boundary: look further
      }
    }
    const T open = has_lower_ ? lower_ : lo_;
    // f is zero within its error here (motion that stays coplanar): only the inside test can
    // still exclude time, when the features are apart within the plane; it was not certain over
    // this interval, so halves (with less motion each) are tried, unless they are certainly in
    // contact in the plane (no sign of f left to resolve).
    if (coplanar_ && inside == InsideVerdict::inside) {
      finish(settle(open));
      return;
    }
    if (++splits_ > Policy::kMaxSplits || top_ + 2 > kStack) {
      finish(settle(open));
      return;
    }
    if (e_.level >= defer_level_) {
      if (deferred_) *deferred_ = true;
      finish(undecided());
      return;
    }
    BernsteinPiece<W> left, right;
    bernstein_halves<Policy>(e_.piece, left, right);
    const int level = e_.level + 1;
    const std::uint32_t index = 2u * e_.index;
    // A half that would be passed over is neither held nor stacked: the same intervals are
    // visited in the same order, without storing and loading back those that end at once.
    // (The left half starts where this interval does, within the time limit.)
    const bool visit_left = !same_sign_beyond(left.c, left.bound), visit_right = !passed_over(right, index + 1u, level);
    if (visit_left && visit_right) stack_[top_++] = {right, index + 1u, level};
    if (visit_left) e_ = {left, index, level};
    else if (visit_right) e_ = {right, index + 1u, level};
    next_held_ = visit_left || visit_right;
  }
  // Whether interval `index` of `level` (piece p) is passed over, nothing noted: it starts past
  // the time limit (later than the caller still wants), or p keeps one sign beyond the perturbed
  // bound (no root there, even perturbed). Tested once for each interval, before it is held or
  // stacked (docs/NARROW_PHASE.md 5.4).
  LWSCCD_HD bool passed_over(const BernsteinPiece<W>& p, std::uint32_t index, int level) const {
    return static_cast<T>(index) * exact_pow2_neg<T>(level) >= params_.time_limit || same_sign_beyond(p.c, p.bound);
  }

  // Depth-first over dyadic intervals, earliest first: the stack holds right halves still to see;
  // the interval visited next when it is known at once (the root, a left half, an interval to
  // search again) is held in e_ instead (next_held_), not stored and loaded back: a GPU thread's
  // stack is local memory, whose stores go on to L2 (docs/NARROW_PHASE.md, 5.4). The capacity
  // check still counts both halves, as before.
  // Two bounds on everything: what a perturbed query may do (only that excludes time) and what
  // the query as given does (only that proves a contact). Between them lies rounding's share of
  // the inputs: in double about u of the geometry; in float it can move a contact by more than
  // the tolerance, and the reported lower bound is then that much earlier.
  Entry* const stack_;
  const QW& q_;
  const Vec3<W>& m_;
  const W perturbation_, inside_slack_;
  const CcdParams<T>& params_;
  const int defer_level_;
  bool* const deferred_;
  SingleHandoff* const handoff_;
  const int max_level_;
  const bool set_mode_;
  bool descent_;  // a certain descent may still be tried (one that ended on the grid is not again)
  int top_ = 0, splits_ = 0, leaves_ = 0;
  T lower_ = T(0), open_from_ = T(0);  // earliest time not excluded for a perturbed query / as given
  bool has_lower_ = false, has_open_ = false, open_inside_ = true;
  int open_sign_ = 0;  // sign of f (as given) at open_from, 0 when uncertain
  bool finished_ = false;
  CertifiedAnswer<T> answer_{};
  // The interval being visited (or, with next_held_, the one to visit next), and what advance()
  // found of it.
  Entry e_{};
  bool next_held_ = false;
  T lo_ = T(0), hi_ = T(0);
  bool crossing_ = false, leaf_ = false, try_hit_ = false, coplanar_ = false;
};

/// The search above run to its end, each interval's inside test asked of `inside_at`.
template <class Policy, int kStack, bool kSettle, bool kSingle, class QW, class W, class T, class InsideAt>
LWSCCD_HD CertifiedAnswer<T> certified_search(const QW& q, const Vec3<W>& m, W perturbation, const BernsteinPiece<W>& root,
                                              W inside_slack, const CcdParams<T>& params, int defer_level, bool* deferred,
                                              InsideAt&& inside_at, SingleHandoff* handoff) {
  using Search = CertifiedSearch<Policy, kStack, kSettle, kSingle, QW, W, T>;
  typename Search::Entry stack[kStack];
  Search search(stack, q, m, perturbation, root, inside_slack, params, defer_level, deferred, handoff);
  const auto compute = [&](int level, std::uint32_t index) { return search.inside(level, index); };
#if defined(__CUDA_ARCH__)
  // The lanes of a warp that run searches side by side meet (the loop's vote) before each round
  // of inside tests, so those that need one run it together: the test is most of a search's
  // instructions, and one lane at a time asked for it (cloth-ball's contacts: ~4 of 32 lanes).
  // (Not where the warp runs one search, whose lanes go on alike: lanes_alike.)
  if constexpr (!lanes_alike<std::decay_t<InsideAt>>::value) {
    const unsigned lanes = __activemask();
    bool running = true;
    while (__any_sync(lanes, running)) {
      running = running && search.advance();
      if (running) search.resume(inside_at(search.level(), search.index(), compute), inside_at, compute);
    }
  } else
#endif
  {
    while (search.advance()) search.resume(inside_at(search.level(), search.index(), compute), inside_at, compute);
  }
  return search.answer();
}

/// The certified classification of a query that certified_screen did not reject (see the file
/// comment); computed in W with the inputs' perturbation of T's unit roundoff. Also correct on a
/// query the screen would reject (it then finds the miss itself, at more cost).
/// `defer_level`: when an interval that deep would have to be halved, the search stops, answers
/// undecided and sets *deferred; a second call without the limit then gives the whole answer (the
/// same as one call without it). A GPU batch uses this to keep the long searches (contacts,
/// resolved at the tolerance) out of the warps that decide misses in a few levels.
/// `kStack`: pending intervals held at most (one per level; defer_level + 2 suffice): a GPU
/// thread keeps them in local memory, so a short search holds a short stack.
/// `kSettle` false: an undecided answer is returned as it is, for a batch that settles its
/// undecided queries apart (certified_undecided): the GPU keeps that test's code out of its
/// refinement kernels, whose registers it would cost on every pair.
/// `inside_at`: where the inside tests are asked for (InsideOneByOne's contract); any evaluator
/// that returns each test's own verdict gives the same answer.
template <class Policy, int kStack = kRefineStackMax, bool kSettle = true, class Q, class T, class InsideAt = InsideOneByOne>
LWSCCD_HD CertifiedAnswer<T> certified_refine(const Q& q_in, const CcdParams<T>& params, int defer_level = kNeverDefer,
                                              bool* deferred = nullptr, InsideAt&& inside_at = InsideOneByOne{}) {
  using W = typename certified_compute<T>::type;
  const auto q = q_in.template cast<W>();
  const W perturbation = unit_roundoff<T>();
  if (params.min_separation > T(0)) return {};  // the cubic only speaks of contact
  const Vec3<W> m = coordinate_magnitude(q);
  // The cubic and its coefficient bound (ccd_filters.hpp), plus underflow's share.
  const W mag = fmul(W(4), max_component(m));  // bounds every difference and its motion
  BernsteinPiece<W> root;
  if (!cubic_on_step<Policy>(q, mag, perturbation, root)) return {};
  if (same_sign_beyond(root.c, root.bound)) return {Certainty::miss, T(0), T(1)};
  const W inside_slack = underflow_slack(mag, 4);
  if (!finite_value(inside_slack)) return {};
  return certified_search<Policy, kStack, kSettle, false>(q, m, perturbation, root, inside_slack, params, defer_level, deferred,
                                                          inside_at, static_cast<SingleHandoff*>(nullptr));
}

/// FP32 first for contacts (Policy::kSingleDescent): the search in single precision on the
/// pair's float query (relative_single_in_double, bound B12), with its as-given bounds made its perturbed
/// ones. A certain miss there is the input's (as the single-precision filter's); a certain
/// descent is handed to double where it starts (or where float can no longer halve it) through
/// *handoff; anything else is undecided (the double search decides). Reads CcdParams<float>
/// (single_params): no double arithmetic.
/// kLanesAlike: every lane of a GPU warp runs this search on the same values (InsideOneByOneLanesAlike).
template <class Policy, bool kLanesAlike = false, class Q>
LWSCCD_HD CertifiedAnswer<float> certified_search_single(const Q& q_in, const CcdParams<float>& params, SingleHandoff& handoff) {
  handoff = {};
  if (params.min_separation > 0.0f || params.mode == CcdMode::set) return {};
  const auto s = relative_single_in_double(q_in);
  const float perturbation = single_input_perturbation<Policy>();
  const float mag = fmul(4.0f, max_component(s.m));
  BernsteinPiece<float> root;
  if (!cubic_on_step<Policy>(s.q, mag, perturbation, root, &s.m)) return {};
  root.exact = root.bound;  // (nothing is claimed of the float query as given)
  if (same_sign_beyond(root.c, root.bound)) return {Certainty::miss, 0.0f, 1.0f};
  const float inside_slack = underflow_slack(mag, 4);
  if (!finite_value(inside_slack)) return {};
  return certified_search<Policy, kRefineStackMax, false, true>(s.q, s.m, perturbation, root, inside_slack, params, kNeverDefer,
                                                                nullptr, std::conditional_t<kLanesAlike, InsideOneByOneLanesAlike, InsideOneByOne>{},
                                                                &handoff);
}

/// A value of the cubic and two bounds on its error, as a BernsteinPiece's: `bound` covers the
/// inputs' perturbation, `exact` rounding alone.
template <class W>
struct PointValue {
  W value, bound, exact;
};
/// The cubic of a piece at s in [0, 1] (exact in W) by de Casteljau, each of its six
/// combinations a + s (b - a) rounding three times: at most 5 u M each (M = max |c|; |b - a| <= 2 M),
/// and the inputs' errors carried as a convex combination: 16 u M + 16 denorm over the three
/// levels (B11), on top of the piece's own bounds.
template <class Policy, class W>
LWSCCD_HD LWSCCD_HOST_INLINE PointValue<W> bernstein_at(const BernsteinPiece<W>& p, W s) {
  W c[4] = {p.c[0], p.c[1], p.c[2], p.c[3]};
  W big = W(0);
  for (int i = 0; i < 4; ++i) big = std::fabs(c[i]) > big ? std::fabs(c[i]) : big;
  for (int level = 3; level > 0; --level)
    for (int i = 0; i < level; ++i) c[i] = fadd(c[i], fmul(s, fsub(c[i + 1], c[i])));
  const W added = fmul(W(Policy::kSplitBound),
                       fadd(fmul(W(16) * unit_roundoff<W>(), big), W(16) * std::numeric_limits<W>::denorm_min()));
  return {c[0], fadd(p.bound, added), fadd(p.exact, added)};
}

/// The majorant of a triple product x . (y x z) whose factors are at most a, b, c componentwise.
template <class W>
LWSCCD_HD LWSCCD_HOST_INLINE W triple_majorant(const Vec3<W>& a, const Vec3<W>& b, const Vec3<W>& c) {
  return vdot(a, abs_cross(b, c));
}

/// The coplanarity cubic f(t) of a query computed from its points at t (B15): the differences
/// X0, X1 of coplanarity_of at t = 0 and t = 1 taken once, X(t) = X0 + t (X1 - X0) and the triple
/// product P(t) . (A(t) x B(t)) at each t. Its two bounds hold for every t in [0, 1]: `exact`
/// covers the rounding (the query as given), `bound` the inputs' perturbation as well (every
/// coordinate within `perturbation` m_k). Where t is exact in W, as the dyadic leaf ends are.
template <class Policy, class W>
struct CubicAtPoints {
  Coplanarity<W> x;      // X0 and X1 of P, A, B
  Vec3<W> dp, da, db;    // X1 - X0
  W exact = W(0), bound = W(0);
  bool finite = false;

  template <class Q>
  LWSCCD_HD CubicAtPoints(const Q& q, const Vec3<W>& m, W perturbation) : x(coplanarity_of(q)) {
    dp = vsub(x.p1, x.p0), da = vsub(x.a1, x.a0), db = vsub(x.b1, x.b0);
    const W u = unit_roundoff<W>();
    // The computed X(t) within 12.01 u m_k of the exact one (B15), and above max(|X0|, |X1|) by less
    // than 10.01 u m_k: base magnitudes of every factor at any t, and their errors with the perturbation.
    const Vec3<W> e = vscale(m, W(14) * u), ep = vadd(e, vscale(m, fmul(W(2), perturbation)));
    const Vec3<W> bp = vadd(max(abs(x.p0), abs(x.p1)), e), ba = vadd(max(abs(x.a0), abs(x.a1)), e),
                  bb = vadd(max(abs(x.b0), abs(x.b1)), e);
    const W base = triple_majorant(bp, ba, bb);
    const W rounded = triple_majorant(vadd(bp, e), vadd(ba, e), vadd(bb, e));
    const W perturbed = triple_majorant(vadd(bp, ep), vadd(ba, ep), vadd(bb, ep));
    const W k = W(Policy::kPointBound), slack = underflow_slack(fmul(W(4), max_component(m)), 3);
    exact = fmul(k, fadd(fadd(fsub(rounded, base), fmul(W(24) * u, rounded)), slack));
    bound = fmul(k, fadd(fadd(fsub(perturbed, base), fmul(W(24) * u, perturbed)), slack));
    finite = finite_value(bound);
  }
  LWSCCD_HD PointValue<W> at(W t) const {
    const Vec3<W> P = vadd_scaled(x.p0, dp, t), A = vadd_scaled(x.a0, da, t), B = vadd_scaled(x.b0, db, t);
    return {vdot(P, vcross(A, B)), bound, exact};
  }
};

/// The points' indices (in Q::points() order) of coplanarity_of's differences P, A, B: each the
/// first point minus the second.
template <class T>
LWSCCD_HD constexpr int coplanarity_point(const VertexFaceQuery<T>&, int factor, int which) {
  // P = p - a, A = b - a, B = c - a (points p, a, b, c)
  return which == 1 ? 1 : (factor == 0 ? 0 : factor + 1);
}
template <class T>
LWSCCD_HD constexpr int coplanarity_point(const EdgeEdgeQuery<T>&, int factor, int which) {
  // P = c - a, A = b - a, B = d - c (points a, b, c, d)
  return factor == 0 ? (which == 0 ? 2 : 0) : factor == 1 ? (which == 0 ? 1 : 0) : (which == 0 ? 3 : 2);
}

/// Majorant x . |y| x |z| (triple_majorant) of three float vectors given as arrays.
LWSCCD_HD inline float triple_majorant_of(const float x[3], const float y[3], const float z[3]) {
  return triple_majorant(Vec3<float>{x[0], x[1], x[2]}, Vec3<float>{y[0], y[1], y[2]}, Vec3<float>{z[0], z[1], z[2]});
}

/// The coplanarity cubic at a point in pairs of floats (B17): B15's computation, every value a
/// FloatPair (no FP64), on the query's points split into pairs (split_to_pair). Its one bound,
/// `threshold`, is meant for the double tail's leaf proof: a value v with |v| > threshold has the
/// sign that the query's f has at t, and B15's double value there has that sign beyond both of
/// its bounds (as given and perturbed; `threshold` covers the pairs' error against the query as
/// given plus twice an upper bound of B15's bounds). So where these values prove a leaf, B15's
/// would prove the same leaf by the same tries: the answer is the double tail's, bit for bit.
/// `usable` is false where a coordinate is neither 0 nor within [2^-60, 2^20] in magnitude (the
/// range the underflow slack of B17 holds for); then the double tail runs as before.
template <class Policy>
struct CubicAtPointsInFloatPairs {
  FloatPair x0[3][3], dx[3][3];  // X0 and X1 - X0 of P, A, B, per axis
  float own = 0.0f;        ///< the pairs' error against the query as given (kFloatPairBound times B17's)
  float threshold = 0.0f;  ///< own plus twice an upper bound of B15's bounds, rounded up
  bool usable = false;

  template <class Q>
  LWSCCD_HD explicit CubicAtPointsInFloatPairs(const Q& q) {
    using T = std::remove_cv_t<std::remove_reference_t<decltype(q.points()->x)>>;
    const auto* points = q.points();
    FloatPair split[8][3];
    float m[3] = {0.0f, 0.0f, 0.0f};  // at least every |coordinate| per axis (B17)
    for (int i = 0; i < 8; ++i)
      for (int k = 0; k < 3; ++k) {
        if (!split_to_pair(points[i][k], split[i][k])) return;
        m[k] = fmax_of(m[k], pair_magnitude_above(split[i][k]));
      }
    if (!(fmax_of(fmax_of(m[0], m[1]), m[2]) <= 0x1p20f)) return;
    float base[3][3];  // at least max(|X0|, |X1|) per factor and axis
    for (int f = 0; f < 3; ++f) {
      const int i = coplanarity_point(q, f, 0), j = coplanarity_point(q, f, 1);
      for (int k = 0; k < 3; ++k) {
        x0[f][k] = pair_sub(split[i][k], split[j][k]);
        const FloatPair x1 = pair_sub(split[i + 4][k], split[j + 4][k]);
        dx[f][k] = pair_sub(x1, x0[f][k]);
        base[f][k] = fmax_of(pair_magnitude_above(x0[f][k]), pair_magnitude_above(x1));
      }
    }
    // The bound (B17), every term a sum and product of non-negative floats (each rounding at most
    // u low; the factor 1 + 2^-17 at the end covers them all). d: the pairs' moves per factor and
    // axis (14 units of rounding of the factor's size in X(t), and twice the split's u^2 m), b the
    // base they move from. B15's base is at most b + u^2 m (its differences are the query's as
    // given, within 2 u^2 m of the split's, and its own 14 u_d m is below u^2 m / 2); dh: B15's
    // moves (14 u_d + 2 p) m.
    const float unit_double = 0x1p-53f, given = static_cast<float>(unit_roundoff<T>());
    float d[3][3], dh[3], b[3][3], bd[3][3], b15[3][3], b15h[3][3], top[3][3];
    for (int k = 0; k < 3; ++k) {
      dh[k] = fmul(m[k], fadd(16.0f * unit_double, fmul(2.0f, given)));
      for (int f = 0; f < 3; ++f) {
        d[f][k] = fadd(fmul(base[f][k], 84.0f * 0x1p-48f), fmul(m[k], 2.0f * 0x1p-48f));
        b[f][k] = fadd(base[f][k], d[f][k]);
        bd[f][k] = fadd(b[f][k], d[f][k]);
        b15[f][k] = fadd(b[f][k], fmul(m[k], 0x1p-48f));
        b15h[f][k] = fadd(b15[f][k], dh[k]);
        top[f][k] = fmax_of(bd[f][k], b15h[f][k]);
      }
    }
    const float top_majorant = triple_majorant_of(top[0], top[1], top[2]);
    // Mag(b + d) - Mag(b) of a trilinear majorant, exactly M(d, b1 + d, b2 + d) + M(b0, d, b2 + d) + M(b0, b1, d).
    const float moved = fadd(fadd(triple_majorant_of(d[0], bd[1], bd[2]), triple_majorant_of(b[0], d[1], bd[2])),
                             triple_majorant_of(b[0], b[1], d[2]));
    const float moved_double = fadd(fadd(triple_majorant_of(dh, b15h[1], b15h[2]), triple_majorant_of(b15[0], dh, b15h[2])),
                                    triple_majorant_of(b15[0], b15[1], dh));
    own = fmul(float(Policy::kFloatPairBound),
                           fadd(fadd(moved, fmul(31.0f * 0x1p-48f, top_majorant)), 0x1p-88f));
    const float double_bounds = fmul(float(Policy::kPointBound),
                                     fadd(fadd(moved_double, fmul(36.0f * unit_double, top_majorant)), 0x1p-120f));
    threshold = fmul(fadd(own, fmul(2.0f, double_bounds)), 1.0f + 0x1p-17f);
    usable = finite_value(threshold);
  }
  /// f at t (a float, exact: a leaf end at level 24 or above), as a float of its sign no larger in
  /// magnitude, with `threshold` as both bounds.
  LWSCCD_HD PointValue<float> at(float t) const { return {pair_toward_zero(pair_at(t)), threshold, threshold}; }
  /// f at t as computed, a pair within `own` of the query's f as given.
  LWSCCD_HD FloatPair pair_at(float t) const {
    FloatPair x[3][3];
    for (int f = 0; f < 3; ++f)
      for (int k = 0; k < 3; ++k) x[f][k] = pair_add(x0[f][k], pair_scale(dx[f][k], t));
    const FloatPair(&p)[3] = x[0], (&a)[3] = x[1], (&c)[3] = x[2];
    const FloatPair cross[3] = {pair_sub(pair_mul(a[1], c[2]), pair_mul(a[2], c[1])),
                                pair_sub(pair_mul(a[2], c[0]), pair_mul(a[0], c[2])),
                                pair_sub(pair_mul(a[0], c[1]), pair_mul(a[1], c[0]))};
    return pair_add(pair_add(pair_mul(p[0], cross[0]), pair_mul(p[1], cross[1])), pair_mul(p[2], cross[2]));
  }
};

/// The double tail's leaf proof (certified_descend_from): from the leaf `guess` (a leaf index, in
/// float), up to three tries on f's values at leaf ends (`value_at(t)`: a PointValue), each try
/// moving one leaf where a certain sign puts the root. True with `answer` set where a leaf is
/// proved. `times_in_float`: the leaf ends computed in float (exact at level 24 or above; no FP64).
template <class T, class ValueAt>
LWSCCD_HD bool prove_tail_leaf(const SingleHandoff& handoff, int leaf_level, const CcdParams<T>& params, float guess,
                               bool times_in_float, const ValueAt& value_at, CertifiedAnswer<T>& answer) {
  const T width = exact_pow2_neg<T>(leaf_level);
  const std::uint32_t per = 1u << (leaf_level - handoff.level), first_leaf = handoff.index * per, last_leaf = first_leaf + per - 1u;
  std::uint32_t k = guess >= static_cast<float>(first_leaf) ? static_cast<std::uint32_t>(guess) : first_leaf;
  k = k > last_leaf ? last_leaf : k;
  for (int tries = 0; tries < 3; ++tries) {
    const T from = times_in_float ? static_cast<T>(fmul(static_cast<float>(k), exact_pow2_neg<float>(leaf_level)))
                                  : static_cast<T>(k) * width;
    const T to = times_in_float ? static_cast<T>(fmul(static_cast<float>(k + 1u), exact_pow2_neg<float>(leaf_level)))
                                : static_cast<T>(k + 1u) * width;
    if (to > params.time_limit) return false;  // the descent's rules at the limit
    const auto start = value_at(from), end = value_at(to);
    const int at_start = sign_beyond(start.value, start.exact), at_end = sign_beyond(end.value, end.exact);
    if (at_start == -handoff.first && k > first_leaf) {  // the root is left of this leaf
      --k;
      continue;
    }
    if (at_end == handoff.first && k < last_leaf) {  // right of it
      ++k;
      continue;
    }
    if (at_start != handoff.first || at_end != -handoff.first || sign_beyond(start.value, start.bound) != handoff.first)
      return false;
    answer = {Certainty::hit, from, to};
    return true;
  }
  return false;
}

/// The leaf proof in pairs of floats (B17), out of line on the device (its ~100 floats of state
/// would otherwise count in its callers' registers, where it is not asked for). Level 24 or above.
template <class Policy, class Q, class T>
LWSCCD_NOINLINE LWSCCD_HD bool tail_leaf_in_float_pairs(const Q& q, const SingleHandoff& handoff, int leaf_level,
                                                       const CcdParams<T>& params, float guess, CertifiedAnswer<T>& answer) {
  const CubicAtPointsInFloatPairs<Policy> pairs(q);
  return pairs.usable &&
         prove_tail_leaf(handoff, leaf_level, params, guess, true, [&](T t) { return pairs.at(static_cast<float>(t)); }, answer);
}

/// The double tail of a contact that single precision handed over. What the hand-off states
/// (SingleHandoff) holds for every query the double path covers, so no stack, no inside test and
/// no look at earlier time is needed: the double cubic on [0, 1] (B1) and
/// - with Policy::kDescentJump, the leaf (the first level within the tolerance) that holds the
///   root, guessed in float (estimated_root) and proved in double by f's signs at its two ends
///   (bernstein_at, B11): of the hand-off's first sign at its start beyond the perturbed bound (no
///   perturbed root before it: each has one root in the interval, after a start of that sign), of
///   the other sign at its end beyond the as-given bound (the query's root is in the leaf); a
///   guess one leaf off moves over, up to three tries;
/// - otherwise, or where those signs are not certain or the leaf passes the time limit, the
///   cubic's piece on the hand-off interval (the search's halvings along its index) and the
///   certain descent in double (certain_descent).
/// *whole is set where double must search whole instead (a value not finite, or a middle value
/// within double's own error: a root on the grid). kSettle as certified_refine's.
template <class Policy, bool kSettle = true, class Q, class T>
LWSCCD_HD CertifiedAnswer<T> certified_descend_from(const Q& q_in, const CcdParams<T>& params, const SingleHandoff& handoff,
                                                    bool& whole, bool* in_float_pairs = nullptr) {
  using W = typename certified_compute<T>::type;
  whole = true;
  if (in_float_pairs) *in_float_pairs = false;
  const auto q = q_in.template cast<W>();
  const Vec3<W> m = coordinate_magnitude(q);
  const int max_level = certified_max_level(params.tolerance);
  // The leaves: the first level at or below the hand-off's within the tolerance (or the finest),
  // as certain_descent stops.
  const int within = tolerance_level(params.tolerance);
  int leaf_level = within > handoff.level ? within : handoff.level;
  if (leaf_level > max_level) leaf_level = handoff.level > max_level ? handoff.level : max_level;
  CertifiedAnswer<T> proved;
  if constexpr (Policy::kDescentJump && Policy::kJumpAtPoints) {
    if (leaf_level <= 30 && handoff.guess >= 0.0f) {
      const float guess = fmul(handoff.guess, exact_pow2_neg<float>(-leaf_level));
      // Where asked, first in pairs of floats (B17): what they prove, B15 proves the same way. Not
      // for a query in float: B15's perturbation is then float's own rounding, which the pairs'
      // threshold doubles, and they proved none of cloth-ball's 108,879 such tails.
      if constexpr (sizeof(T) == 8) {
        if (params.leaves_in_float_pairs && leaf_level <= 24 &&
            tail_leaf_in_float_pairs<Policy>(q_in, handoff, leaf_level, params, guess, proved)) {
          whole = false;
          if (in_float_pairs) *in_float_pairs = true;
          return proved;
        }
      }
      // From the query's points, with float's own guess: no cubic is built (B15).
      const CubicAtPoints<Policy, W> points(q, m, W(unit_roundoff<T>()));
      if (points.finite &&
          prove_tail_leaf(handoff, leaf_level, params, guess, false, [&](W t) { return points.at(t); }, proved)) {
        whole = false;
        return proved;
      }
    }
  }
  BernsteinPiece<W> piece;
  if (!cubic_on_step<Policy>(q, fmul(W(4), max_component(m)), W(unit_roundoff<T>()), piece)) return {};
  if constexpr (Policy::kDescentJump) {
    if (leaf_level <= 30 &&
        prove_tail_leaf(handoff, leaf_level, params, fmul(estimated_root(piece), exact_pow2_neg<float>(-leaf_level)), false,
                        [&](W t) { return bernstein_at<Policy>(piece, t); }, proved)) {
      whole = false;
      return proved;
    }
  }
  for (int d = handoff.level - 1; d >= 0; --d) {
    BernsteinPiece<W> left, right;
    bernstein_halves<Policy>(piece, left, right);
    piece = ((handoff.index >> d) & 1u) ? right : left;
  }
  std::uint32_t index = handoff.index;
  int level = handoff.level, splits = 0;
  T lower = T(0);
  bool has_lower = false;
  const DescentEnd end = certain_descent<Policy>(piece, index, level, handoff.first, params, max_level, splits, lower, has_lower);
  if (end == DescentEnd::on_grid) return {};
  whole = false;
  const T step = exact_pow2_neg<T>(level);
  if (end == DescentEnd::within_tolerance) return {Certainty::hit, lower, static_cast<T>(index + 1u) * step};
  if (end == DescentEnd::past_limit && !has_lower) return {Certainty::miss, T(0), T(1)};
  // (Past the limit with a lower bound noted, or too many splits: undecided from there.)
  const T from = has_lower ? lower : static_cast<T>(index) * step;
  if constexpr (kSettle) return certified_undecided<Policy>(q, params, from);
  else return CertifiedAnswer<T>{Certainty::undecided, from, T(1)};
}

/// The search in single precision and its double tail, as a batch runs them first on every pair
/// that the single-precision screen and filter leave (Policy::kSingleDescent): *done is set with
/// its answer where it decides the pair (a certain miss in float, or a contact handed to double
/// and settled by certified_descend_from); otherwise the double screen and certified_refine
/// decide. A hand-off is a certain contact, which no screen rejects. kSettle as certified_refine's.
template <class Policy, bool kSettle = true, bool kLanesAlike = false, class Q, class T>
LWSCCD_HD CertifiedAnswer<T> certified_refine_single_first(const Q& q, const CcdParams<T>& params, bool& done,
                                                           bool* in_float_pairs = nullptr) {
  done = false;
  if (in_float_pairs) *in_float_pairs = false;
  if constexpr (Policy::kSingleFirst && Policy::kSingleDescent) {
    SingleHandoff handoff;
    const CertifiedAnswer<float> s = certified_search_single<Policy, kLanesAlike>(q, single_params(params), handoff);
    if (s.certainty == Certainty::miss) {
      done = true;
      return {Certainty::miss, T(0), T(1)};
    }
    if (handoff.valid) {
      bool whole = true;
      const CertifiedAnswer<T> a = certified_descend_from<Policy, kSettle>(q, params, handoff, whole, in_float_pairs);
      done = !whole;
      return a;
    }
  }
  return {};
}

/// The refinement of a pair the single-precision screen and filter left, whole:
/// certified_refine_single_first, then, where it does not decide, the double screen
/// (`double_screen`: unless the pair already passed it) and certified_refine. kSettle and
/// inside_at as certified_refine's.
template <class Policy, bool kSettle = true, class Q, class T, class InsideAt = InsideOneByOne>
LWSCCD_HD CertifiedAnswer<T> certified_refine_after_single(const Q& q, const CcdParams<T>& params, bool double_screen,
                                                           InsideAt&& inside_at = InsideOneByOne{}) {
  bool done = false;
  const CertifiedAnswer<T> a = certified_refine_single_first<Policy, kSettle>(q, params, done);
  if (done) return a;
  if (double_screen && certified_screen_after_single<Policy>(q, params)) return {Certainty::miss, T(0), T(1)};
  return certified_refine<Policy, kRefineStackMax, kSettle>(q, params, kNeverDefer, nullptr, inside_at);
}

}  // namespace lwsccd::detail
