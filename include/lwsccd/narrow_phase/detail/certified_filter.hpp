// lwsccd — the certified filter (the first levels of the refinement as a pass over the screened
// pairs, noting lower bounds) and certified_classify (screen, then refine).
// Part of certified_ccd.hpp: include <lwsccd/narrow_phase/certified_ccd.hpp>, not this file.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/core/detail/rounding.hpp"
#include "lwsccd/narrow_phase/detail/certified_refine.hpp"
#include "lwsccd/narrow_phase/detail/certified_single.hpp"

namespace lwsccd::detail {

/// The refinement's first levels as a filter without a stack, for batches that run the inside
/// tests apart (a GPU thread per test keeps its warp's lanes busy; the search proper diverges).
/// The cubic's pieces down to level Policy::kInsideFrom are pruned exactly as certified_refine
/// prunes them (past the time limit, or of one sign beyond the perturbed bound); a piece it would
/// treat otherwise before that level (set mode's early hit test) makes the whole search necessary;
/// a piece excluded only as given lowers `lower` as it would there. What is left are the intervals that certified_refine tests for inside
/// next: those of that level, less the ones whose halves both keep a sign (it skips their test),
/// and pieces of coplanar motion above it. A query whose every such interval is `outside` is a
/// miss there too (undecided from `lower` when `noted`: the fallback's case), by the same tests on
/// the same values; any other query is searched whole. Returns -1 (search whole) or the number of those intervals, as the bits of `mask`: bit
/// 2^level + k for interval [k, k + 1] 2^-level (a binary heap's numbering).
/// A lower bound noted by CertifiedFilter: the earliest piece excluded only for the query as given.
template <class T>
struct Noted {
  bool any = false;
  T lower = T(0);
};

/// The index of x's lowest set bit (x != 0).
LWSCCD_HD inline unsigned lowest_bit(std::uint32_t x) {
#if defined(__CUDA_ARCH__)
  return static_cast<unsigned>(__ffs(static_cast<int>(x)) - 1);
#elif defined(__GNUC__)
  return static_cast<unsigned>(__builtin_ctz(x));
#else
  unsigned k = 0;
  while (!((x >> k) & 1u)) ++k;
  return k;
#endif
}

/// Where the single-precision filter sends a pair it does not decide (CertifiedFilter::route_single).
enum class SingleRoute : unsigned char {
  miss,           ///< every interval certainly outside in float: a miss of the input as given
  double_filter,  ///< to the double filter
  whole_search,   ///< an interval inside in float (a contact, nearly always): to the whole search
};

template <class Policy>
struct CertifiedFilter {
  static constexpr int kLevel = Policy::kInsideFrom;
  static constexpr int kMaxIntervals = 1 << kLevel;
  /// The number of the interval [0, 1] (the whole step): a mask of only this interval's bit means
  /// the cubic stays within its bound over the whole step (motion coplanar all along).
  static constexpr unsigned kWholeStepNode = 1u;
  static_assert(kLevel >= 1 && kLevel <= 4, "lwsccd: the certified filter runs to levels 1 to 4 (kInsideFrom)");
  static_assert(Policy::kInsideEvery > 0, "lwsccd: the certified filter needs the inside tests at kInsideFrom");

  template <int kAt, class W, class T>
  LWSCCD_HD static bool visit(const BernsteinPiece<W>& p, std::uint32_t index, const CcdParams<T>& params, std::uint32_t& mask,
                              Noted<T>& noted) {
    const T lo = static_cast<T>(index) * exact_pow2_neg<T>(kAt);
    if (lo >= params.time_limit) return true;
    if (same_sign_beyond(p.c, p.bound)) return true;
    if (same_sign_beyond(p.c, p.exact)) {  // the search notes a lower bound here and goes on
      if (!noted.any || lo < noted.lower) noted = {true, lo};
      return true;
    }
    const bool coplanar = all_within(p.c, p.exact);  // tested for inside at any level
    if constexpr (kAt == kLevel) {
      if (Policy::kLookAhead && !coplanar && halves_keep_sign<Policy>(p)) return true;
      mask |= 1u << ((1u << kAt) + index);
      return true;
    } else {
      if (coplanar) {
        mask |= 1u << ((1u << kAt) + index);
        return true;
      }
      const bool crossing = (p.c[0] < -p.exact && p.c[3] > p.exact) || (p.c[0] > p.exact && p.c[3] < -p.exact);
      if ((kAt & 3) == 0 && params.mode == CcdMode::set && crossing) return false;  // set mode's hit test
      BernsteinPiece<W> left, right;
      bernstein_halves<Policy>(p, left, right);
      return visit<kAt + 1>(left, 2u * index, params, mask, noted) && visit<kAt + 1>(right, 2u * index + 1u, params, mask, noted);
    }
  }

  template <class Q, class T>
  LWSCCD_HD static int intervals(const Q& q_in, const CcdParams<T>& params, std::uint32_t& mask, Noted<T>& noted) {
    using W = typename certified_compute<T>::type;
    mask = 0;
    noted = {};
    if (params.min_separation > T(0)) return -1;
    if (certified_max_level(params.tolerance) <= kLevel) return -1;  // leaves within the filter's levels
    const auto q = q_in.template cast<W>();
    const W perturbation = unit_roundoff<T>();
    const Vec3<W> m = coordinate_magnitude(q);
    const W mag = fmul(W(4), max_component(m));
    BernsteinPiece<W> root;
    if (!cubic_on_step<Policy>(q, mag, perturbation, root)) return -1;
    if (same_sign_beyond(root.c, root.bound)) return 0;
    if (!finite_value(underflow_slack(mag, 4))) return -1;
    if (!visit<0>(root, 0u, params, mask, noted)) return -1;
    int n = 0;
    for (std::uint32_t b = mask; b; b &= b - 1u) ++n;
    return n;
  }

  /// The inside test certified_refine runs over the interval numbered `node`, on the same values.
  template <class Q, class T>
  LWSCCD_HD static InsideVerdict inside_verdict(const Q& q_in, const CcdParams<T>& /*params: their T*/, unsigned node) {
    int level = 0;
    while ((node >> (level + 1)) != 0u) ++level;
    const unsigned index = node - (1u << level);
    using W = typename certified_compute<T>::type;
    const auto q = q_in.template cast<W>();
    const W perturbation = unit_roundoff<T>();
    const Vec3<W> m = coordinate_magnitude(q);
    const W inside_slack = underflow_slack(fmul(W(4), max_component(m)), 4);
    const T lo = static_cast<T>(index) * exact_pow2_neg<T>(level);
    const W half = exact_pow2_neg<W>(level + 1);
    return inside_over<Policy>(q, fadd(W(lo), half), half, m, perturbation, inside_slack);
  }
  /// True when the query is certainly outside over the interval numbered `node`.
  template <class Q, class T>
  LWSCCD_HD static bool excluded(const Q& q, const CcdParams<T>& params, unsigned node) {
    return inside_verdict(q, params, node) == InsideVerdict::outside;
  }

  /// The second round, below one interval of level kLevel whose inside test was `unknown` (not
  /// inside, not outside as given): certified_refine halves it there and runs the next inside
  /// tests kInsideEvery levels down. Its pieces to that level (kDeepLevel) are pruned as the search
  /// prunes them; returns -1 (search whole: a lower bound would be noted) or the number of
  /// intervals left, the bits of `mask` numbered within the subtree (bit 2^d + k: level
  /// kLevel + d, the k-th below `node`; deep_node() gives the global number). With every such
  /// interval `outside`, the search excludes the interval `node` after these very splits.
  static constexpr int kDeepLevel = kLevel + Policy::kInsideEvery;
  static_assert(kDeepLevel <= 7, "lwsccd: the certified filter's second round numbers intervals to level 7 (one byte)");
  /// Whether the search can split every interval of this round without passing kMaxSplits: the
  /// levels above kLevel (2^kLevel - 1 splits) and, for each of `count` intervals, its subtree to
  /// the level above kDeepLevel. A query with more intervals is searched whole.
  LWSCCD_HD static constexpr bool expandable(int count) {
    return (1 << kLevel) - 1 + count * ((1 << Policy::kInsideEvery) - 1) <= Policy::kMaxSplits;
  }
  LWSCCD_HD static constexpr unsigned deep_node(unsigned node, unsigned local) {
    unsigned depth = 0;
    while ((local >> (depth + 1)) != 0u) ++depth;
    return (node << depth) + (local - (1u << depth));
  }

  template <int kAt, class W, class T>
  LWSCCD_HD static bool visit_deep(const BernsteinPiece<W>& p, std::uint32_t index, std::uint32_t local, const CcdParams<T>& params,
                                   std::uint32_t& mask) {
    const T lo = static_cast<T>(index) * exact_pow2_neg<T>(kAt);
    if (lo >= params.time_limit) return true;
    if (same_sign_beyond(p.c, p.bound)) return true;
    if (same_sign_beyond(p.c, p.exact)) return false;  // the search notes a lower bound here: whole
    if constexpr (kAt == kDeepLevel) {
      if (Policy::kLookAhead && !all_within(p.c, p.exact) && halves_keep_sign<Policy>(p)) return true;
      mask |= 1u << local;
      return true;
    } else {
      if (all_within(p.c, p.exact)) {  // coplanar: tested for inside at any level
        mask |= 1u << local;
        return true;
      }
      BernsteinPiece<W> left, right;
      bernstein_halves<Policy>(p, left, right);
      return visit_deep<kAt + 1>(left, 2u * index, 2u * local, params, mask) &&
             visit_deep<kAt + 1>(right, 2u * index + 1u, 2u * local + 1u, params, mask);
    }
  }

  template <class Q, class T>
  LWSCCD_HD static int expand(const Q& q_in, const CcdParams<T>& params, unsigned node, std::uint32_t& mask) {
    using W = typename certified_compute<T>::type;
    mask = 0;
    if (params.mode == CcdMode::set || node < (1u << kLevel) || node >= (2u << kLevel)) return -1;
    if (certified_max_level(params.tolerance) <= kDeepLevel) return -1;  // leaves within these levels
    const auto q = q_in.template cast<W>();
    const W perturbation = unit_roundoff<T>();
    const Vec3<W> m = coordinate_magnitude(q);
    const W mag = fmul(W(4), max_component(m));
    BernsteinPiece<W> piece;
    if (!cubic_on_step<Policy>(q, mag, perturbation, piece)) return -1;
    return expand_piece(piece, params, node, mask);
  }

  /// Whether the single-precision passes take a pair of these parameters: FP32 first, no
  /// minimum separation (the cubic speaks of contact only), and leaves below the filter's levels
  /// (a tolerance of at least 2^-(kLevel - 1) has its leaves within them: the double path's; a
  /// tolerance that rounds up to the limit is only declined, which is always sound).
  LWSCCD_HD static bool single_passes_apply(const CcdParams<float>& params) {
    return Policy::kSingleFirst && !(params.min_separation > 0.0f) && params.tolerance < exact_pow2_neg<float>(kLevel - 1);
  }
  /// The single-precision filter (FP32 first): both rounds in float, as a proof of a miss on its
  /// own. The pair relative to its first point, rounded to float (relative_single, bound B9);
  /// the cubic's pieces down to kLevel pruned as `intervals` prunes them, with only the perturbed
  /// bound (the float query is not the query as given: nothing is claimed of it as given, so no
  /// lower bound is noted); an interval left whose inside test in float is `unknown` may be split
  /// once more to kDeepLevel (expand_single, as `expand`), and every interval left must be
  /// certainly outside. Together the pieces pruned and the intervals outside cover the step: no
  /// query within the perturbation, the input as given among them, touches in it.
  /// intervals_single lists the first round's intervals (-1: single precision cannot decide the
  /// pair; 0: a miss), inside_single tests one (of either round), expand_single lists the second
  /// round's below one; decides_single is all of them on one thread (the CPU batch and the tests;
  /// a GPU batch runs the tests a thread each). They read CcdParams<float> (single_params): no
  /// double arithmetic. True: a certain miss of the input as given (and within the double path's
  /// perturbation); false: the double path decides.
  /// `separation_tried`: the caller already ran separates_single on the pair (the GPU screen
  /// does, so that the pairs it separates are never listed), so the directions are not tried again.
  template <class Q>
  LWSCCD_HD static int intervals_single(const Q& q, const CcdParams<float>& params, std::uint32_t& mask, bool separation_tried = false) {
    mask = 0;
    if (!single_passes_apply(params)) return -1;
    return intervals_of(relative_single(q), params, mask, nullptr, !separation_tried);
  }
  /// True when decides_single decides the pair by its separating directions alone (B13), before
  /// any interval: the same conditions and the same test.
  template <class Q, class T>
  LWSCCD_HD static bool separates_single(const Q& q, const CcdParams<T>& params_in) {
    if (!Policy::kSeparatingDirections || !single_passes_apply(single_params(params_in))) return false;
    return swept_hulls_apart<Policy>(relative_single(q), single_input_perturbation<Policy>());
  }
  template <class Q>
  LWSCCD_HD static InsideVerdict inside_single(const Q& q, unsigned node) {
    return verdict_of(relative_single(q), node);
  }
  /// The second round's intervals below `node` (a first-round interval), numbered as `expand`
  /// numbers them; -1 when the round cannot take it (then the double path decides the pair).
  template <class Q>
  LWSCCD_HD static int expand_single(const Q& q, const CcdParams<float>& params, unsigned node, std::uint32_t& mask) {
    mask = 0;
    if (!Policy::kSingleSecondRound || params.tolerance >= exact_pow2_neg<float>(kDeepLevel - 1)) return -1;
    return expand_of(relative_single(q), params, node, mask);
  }
  template <class Q, class T>
  LWSCCD_HD static bool decides_single(const Q& q, const CcdParams<T>& params_in) {
    // (intervals_single, inside_single and expand_single on one thread: the relative query and the
    // cubic's piece on the step are computed once for all of them, the same values.)
    return route_single(q, single_params(params_in), false, false) == SingleRoute::miss;
  }
  /// decides_single with where a pair it does not decide goes (the GPU's one-thread form):
  /// SingleRoute::miss exactly where every interval is certainly outside in float, as the listed
  /// form's tests find (intervals_single, inside_single, expand_single); otherwise the first
  /// interval (by its number) not certainly outside in float, or not outside below it in the
  /// second round, sends the pair to the whole search where it is inside in float and
  /// `inside_whole`, else to the double filter. (Any route gives the same answer: the double
  /// filter decides only what the search decides alike.) `separation_tried` as intervals_single's.
  /// `whole_step`, when given, is set where the one interval left is the whole step and is not
  /// certainly outside (motion coplanar in float over the step).
  template <class Q>
  LWSCCD_HD static SingleRoute route_single(const Q& q, const CcdParams<float>& params, bool separation_tried, bool inside_whole,
                                            bool* whole_step = nullptr) {
    if (whole_step) *whole_step = false;
    if (!single_passes_apply(params)) return SingleRoute::double_filter;
    const auto s = relative_single(q);
    BernsteinPiece<float> root;
    std::uint32_t mask = 0;
    const int count = intervals_of(s, params, mask, &root, !separation_tried);
    if (count < 0) return SingleRoute::double_filter;
    const bool deeper = single_deeper(count, params);
    const auto route = [inside_whole](InsideVerdict v) {
      return inside_whole && v == InsideVerdict::inside ? SingleRoute::whole_search : SingleRoute::double_filter;
    };
    for (std::uint32_t left = mask; left != 0u; left &= left - 1u) {
      const unsigned node = lowest_bit(left);
      const InsideVerdict v = verdict_of(s, node);
      if (v == InsideVerdict::outside) continue;
      if (whole_step && count == 1 && node == kWholeStepNode) *whole_step = true;
      if (v != InsideVerdict::unknown || !deeper || node < (1u << kLevel) || node >= (2u << kLevel)) return route(v);
      std::uint32_t deep = 0;
      if (expand_piece(root, params, node, deep) < 0) return SingleRoute::double_filter;
      for (; deep != 0u; deep &= deep - 1u) {
        const InsideVerdict d = verdict_of(s, deep_node(node, lowest_bit(deep)));
        if (d != InsideVerdict::outside) return route(d);
      }
    }
    return SingleRoute::miss;
  }

  // The same steps on a relative query made once (relative_single) and the cubic's piece on the
  // step kept beside it, for a batch that runs them apart on other threads (the GPU's block form:
  // a block's pairs and their intervals in shared memory). The answers are route_single's: every
  // interval intervals_of_single lists certainly outside (inside_of_single), or, where
  // single_deeper holds and an interval of level kLevel is unknown, every interval that
  // expand_of_single lists below it.
  /// The first round's intervals of `s` as intervals_single lists them (-1: the double path
  /// decides; 0: a miss), and the cubic's piece on the step in `root` (where the count is >= 0).
  template <class QF>
  LWSCCD_HD static int intervals_of_single(const SingleQuery<QF>& s, const CcdParams<float>& params, std::uint32_t& mask,
                                           BernsteinPiece<float>& root, bool separation_tried) {
    mask = 0;
    if (!single_passes_apply(params)) return -1;
    return intervals_of(s, params, mask, &root, !separation_tried);
  }
  template <class QF>
  LWSCCD_HD static InsideVerdict inside_of_single(const SingleQuery<QF>& s, unsigned node) {
    return verdict_of(s, node);
  }
  /// Whether an unknown interval of the first round (of level kLevel) of a pair with `count`
  /// intervals takes the second round (else the pair goes to the double path).
  LWSCCD_HD static bool single_deeper(int count, const CcdParams<float>& params) {
    return Policy::kSingleSecondRound && expandable(count) && params.mode != CcdMode::set &&
           !(params.tolerance >= exact_pow2_neg<float>(kDeepLevel - 1));
  }
  /// The second round's intervals below `node` (of level kLevel) from the piece on the step, as
  /// expand_single lists them (-1: the double path decides).
  template <class T>
  LWSCCD_HD static int expand_of_single(const BernsteinPiece<float>& root, const CcdParams<T>& params, unsigned node,
                                        std::uint32_t& mask) {
    mask = 0;
    if (node < (1u << kLevel) || node >= (2u << kLevel)) return -1;
    return expand_piece(root, params, node, mask);
  }

 private:
  // The cubic on the step for a single-precision query: perturbed bound only (halvings add the
  // same to both bounds).
  template <class QF>
  LWSCCD_HD static bool single_cubic(const SingleQuery<QF>& s, BernsteinPiece<float>& root) {
    const float mag = fmul(4.0f, max_component(s.m));  // bounds every difference and its motion
    if (!cubic_on_step<Policy>(s.q, mag, single_input_perturbation<Policy>(), root, &s.m)) return false;
    root.exact = root.bound;
    return true;
  }
  // (T is float: a deduced parameter keeps the calls below dependent, which GCC 12's host pass of
  // nvcc needs to compile them.)
  // `root_out`, when given, receives the cubic's piece on the step (expand_piece's start).
  template <class QF, class T>
  LWSCCD_HD static int intervals_of(const SingleQuery<QF>& s, const CcdParams<T>& params, std::uint32_t& mask,
                                    BernsteinPiece<float>* root_out = nullptr, bool try_separation = true) {
    if (Policy::kSeparatingDirections && try_separation && swept_hulls_apart<Policy>(s, single_input_perturbation<Policy>())) return 0;
    BernsteinPiece<float> root;
    if (!single_cubic(s, root)) return -1;
    if (root_out) *root_out = root;
    if (same_sign_beyond(root.c, root.bound)) return 0;
    if (!finite_value(underflow_slack(fmul(4.0f, max_component(s.m)), 4))) return -1;
    Noted<T> noted;
    if (!visit<0>(root, 0u, params, mask, noted)) return -1;
    int n = 0;
    for (std::uint32_t b = mask; b; b &= b - 1u) ++n;
    return n;
  }
  template <class QF, class T>
  LWSCCD_HD static int expand_of(const SingleQuery<QF>& s, const CcdParams<T>& params, unsigned node, std::uint32_t& mask) {
    if (params.mode == CcdMode::set || node < (1u << kLevel) || node >= (2u << kLevel)) return -1;
    BernsteinPiece<float> piece;
    if (!single_cubic(s, piece)) return -1;
    return expand_piece(piece, params, node, mask);
  }
  template <class QF>
  LWSCCD_HD static InsideVerdict verdict_of(const SingleQuery<QF>& s, unsigned node) {
    const float perturbation = single_input_perturbation<Policy>();
    const float slack = underflow_slack(fmul(4.0f, max_component(s.m)), 4);
    int level = 0;
    while ((node >> (level + 1)) != 0u) ++level;
    const float half = exact_pow2_neg<float>(level + 1);
    const float mid = fadd(static_cast<float>(node - (1u << level)) * exact_pow2_neg<float>(level), half);
    return inside_over<Policy>(s.q, mid, half, s.m, perturbation, slack);
  }
  // The second round below `node` from the cubic's piece on the step (either precision): the
  // interval's piece by the halvings the search made on the way (the same values), halved once
  // more and visited to kDeepLevel.
  template <class W, class T>
  LWSCCD_HD static int expand_piece(BernsteinPiece<W> piece, const CcdParams<T>& params, unsigned node, std::uint32_t& mask) {
    for (int d = kLevel - 1; d >= 0; --d) {
      BernsteinPiece<W> left, right;
      bernstein_halves<Policy>(piece, left, right);
      piece = ((node >> d) & 1u) ? right : left;
    }
    BernsteinPiece<W> left, right;
    bernstein_halves<Policy>(piece, left, right);
    const std::uint32_t index = node - (1u << kLevel);
    if (!visit_deep<kLevel + 1>(left, 2u * index, 2u, params, mask) || !visit_deep<kLevel + 1>(right, 2u * index + 1u, 3u, params, mask))
      return -1;
    int n = 0;
    for (std::uint32_t b = mask; b; b &= b - 1u) ++n;
    return n;
  }

 public:
  /// Both rounds on one thread, as a GPU batch runs them apart (the tests' reference): true when
  /// the filter decides the query (then certified_refine answers a miss, or undecided from
  /// noted.lower when noted.any); false when the whole search must run.
  template <class Q, class T>
  static bool decides(const Q& q, const CcdParams<T>& params, Noted<T>& noted, bool second_round = true) {
    std::uint32_t mask = 0;
    const int count = intervals(q, params, mask, noted);
    if (count < 0 || (count > 0 && noted.any)) return false;
    for (unsigned node = 0; node < 32; ++node) {
      if (!((mask >> node) & 1u)) continue;
      const InsideVerdict v = inside_verdict(q, params, node);
      if (v == InsideVerdict::outside) continue;
      std::uint32_t deep = 0;
      if (!second_round || v != InsideVerdict::unknown || !expandable(count) || expand(q, params, node, deep) < 0) return false;
      for (unsigned local = 0; local < 32; ++local)
        if (((deep >> local) & 1u) && !excluded(q, params, deep_node(node, local))) return false;
    }
    return true;
  }
};

/// The whole certified classification of one query, in the order batches run it: the first
/// screen, the single-precision filter, then the refinement of what they leave (the search in
/// single precision, and the double screen and search on what that leaves).
template <class Policy, class Q, class T>
LWSCCD_HD CertifiedAnswer<T> certified_classify(const Q& q, const CcdParams<T>& params) {
  if (certified_first_screen<Policy>(q, params) != ScreenVerdict::passed) return {Certainty::miss, T(0), T(1)};
  if (CertifiedFilter<Policy>::decides_single(q, params)) return {Certainty::miss, T(0), T(1)};
  return certified_refine_after_single<Policy>(q, params, true);
}

}  // namespace lwsccd::detail
