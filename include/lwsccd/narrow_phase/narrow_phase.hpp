// lwsccd — the narrow phase over lists of candidate feature pairs: result types and the CPU
// backend (all cores). The GPU batch is in narrow_phase.cuh; both give identical answers (the
// methods round alike on host and device).
#pragma once

#include <algorithm>
#include <atomic>
#include <utility>
#include <vector>

#include "lwsccd/core/parallel.hpp"
#include "lwsccd/features/detail/oracle_impl.hpp"
#include "lwsccd/features/oracle.hpp"
#include "lwsccd/features/representative.hpp"
#include "lwsccd/io/dataset.hpp"
#include "lwsccd/io/query_io.hpp"
#include "lwsccd/narrow_phase/ccd_query.hpp"
#include "lwsccd/narrow_phase/certified_ccd.hpp"
#include "lwsccd/narrow_phase/detail/certified_screen_lanes.hpp"

namespace lwsccd {

/// A colliding feature pair (ids as in FeaturePairs) and its time of impact.
template <class T>
struct FeatureHit {
  index_t first, second;
  T toi;
  friend bool operator<(const FeatureHit& a, const FeatureHit& b) {
    return a.first != b.first ? a.first < b.first : a.second < b.second;
  }
};

/// How one list's pairs were answered. For CertifiedCcd: certified hits and misses, and the
/// pairs left to the fallback; for other methods every pair counts as a fallback.
struct NarrowPhaseCounts {
  std::size_t pairs = 0, certified_hits = 0, certified_misses = 0, fallbacks = 0;
  std::size_t screened = 0;  ///< CertifiedCcd: pairs its screen passed on to the refinement
  /// CertifiedCcd: pairs decided in single precision (certain misses of its FP32 screen or filter;
  /// part of certified_misses). The rest of the certain answers took double; `fallbacks` the search.
  std::size_t single_misses = 0;
  /// CertifiedCcd: certain hits whose search ran in single precision, with only the certain
  /// descent's last levels in double (part of certified_hits; CertifiedPolicy::kSingleDescent).
  std::size_t single_descents = 0;
  /// CertifiedCcd with CcdParams::leaves_in_float_pairs: of single_descents, the contacts whose
  /// leaf pairs of floats proved, with no FP64 at all (the answers are the same either way).
  std::size_t float_pair_leaves = 0;
};

/// Adds b's numbers to a's.
inline void add_counts(NarrowPhaseCounts& a, const NarrowPhaseCounts& b) {
  a.pairs += b.pairs;
  a.certified_hits += b.certified_hits;
  a.certified_misses += b.certified_misses;
  a.fallbacks += b.fallbacks;
  a.screened += b.screened;
  a.single_misses += b.single_misses;
  a.single_descents += b.single_descents;
  a.float_pair_leaves += b.float_pair_leaves;
}

template <class T>
struct NarrowPhaseResult {
  std::vector<FeatureHit<T>> vf, ee;  ///< sorted by (first, second); empty in mode `earliest`
  T earliest_toi = T(1);              ///< 1 when nothing collides
  std::size_t gave_up = 0;            ///< hits answered by a method's bounded-work fallback
  NarrowPhaseCounts vf_counts, ee_counts;
};

/// Adds a part's result to a step's (a step split into parts): hits appended (unsorted: sort
/// with sort_by_pair once every part is in), the earliest time kept, the numbers summed.
template <class T>
void add_narrow_phase_part(const NarrowPhaseResult<T>& part, NarrowPhaseResult<T>& all) {
  all.vf.insert(all.vf.end(), part.vf.begin(), part.vf.end());
  all.ee.insert(all.ee.end(), part.ee.begin(), part.ee.end());
  all.earliest_toi = std::min(all.earliest_toi, part.earliest_toi);
  all.gave_up += part.gave_up;
  add_counts(all.vf_counts, part.vf_counts);
  add_counts(all.ee_counts, part.ee_counts);
}

/// Sorts hits by (first, second), the order every result is given in.
template <class T>
void sort_by_pair(std::vector<FeatureHit<T>>& hits) {
  std::sort(hits.begin(), hits.end(), [](const FeatureHit<T>& a, const FeatureHit<T>& b) {
    return a.first != b.first ? a.first < b.first : a.second < b.second;
  });
}

/// Contacts against a scene's exact ground truth (the pairs it lists, not every pair tested).
struct TruthScore {
  std::size_t true_contacts = 0;    ///< listed pairs that do touch
  std::size_t false_negatives = 0;  ///< of those, not among the contacts
  std::size_t false_positives = 0;  ///< listed pairs that do not touch but are among the contacts
};

/// Scores `contacts` (sorted, as every backend returns them) against `truth`.
template <class T>
TruthScore score_against_truth(const GroundTruth& truth, const NarrowPhaseResult<T>& contacts) {
  TruthScore score;
  auto count = [&](const std::vector<std::pair<index_t, index_t>>& pairs, const std::vector<bool>& collides,
                   const std::vector<FeatureHit<T>>& hits) {
    for (std::size_t i = 0; i < pairs.size(); ++i) {
      const bool hit = std::binary_search(hits.begin(), hits.end(), FeatureHit<T>{pairs[i].first, pairs[i].second, T(0)});
      score.true_contacts += collides[i];
      score.false_negatives += collides[i] && !hit;
      score.false_positives += !collides[i] && hit;
    }
  };
  count(truth.vf, truth.vf_collides, contacts.vf);
  count(truth.ee, truth.ee_collides, contacts.ee);
  return score;
}

namespace detail {
/// One list on all cores: certified methods classify every pair first and run the fallback on
/// the undecided ones with `time_limit` (mode earliest: the best certified time of both lists,
/// so that the answer does not depend on the order of work); other methods run as they are.
/// Item i of the list is the pair `pair_of(i)` and the query `gather(i)`, with no contact before
/// `from_of(i)`; `undecided` (first pass of a certified method) receives the items left to the
/// fallback, each with the time before which the certified pass excluded contact. A certified
/// method that decides in single precision first takes its first pass's float query from
/// `gather_single(i)` (the pair's points rounded to float: gather_single_vertex_face), as the GPU
/// batch does, and gathers the double query only for the pairs that pass it.
template <class Method, class T, class Gather, class GatherSingle, class PairOf, class FromOf>
void test_list(std::size_t n, Gather&& gather, GatherSingle&& gather_single, PairOf&& pair_of, FromOf&& from_of,
               const CcdParams<T>& params,
               std::enable_if_t<true, std::vector<std::pair<std::size_t, T>>>* undecided,  // (not deduced: may be nullptr)
               std::vector<FeatureHit<T>>& hits,
               NarrowPhaseCounts& counts, std::size_t& gave_up) {
  const unsigned workers = worker_count();
  struct Part {
    std::vector<FeatureHit<T>> hits;
    std::vector<std::pair<std::size_t, T>> open;
    NarrowPhaseCounts counts;
    std::size_t gave_up = 0;
  };
  std::vector<Part> parts(workers);
  // (Short lists, such as the fallback's few expensive queries, in short runs.)
  const std::size_t kRun = std::max<std::size_t>(1, std::min<std::size_t>(1024, n / (std::size_t(workers) * 64)));
  std::atomic<std::size_t> next{0};
  for_each_worker([&](unsigned w, unsigned) {
    // A local part, moved out at the end: the workers' counters side by side in `parts` would
    // share cache lines, and every query bumps one.
    Part out;
    struct MoveOut {
      Part& from;
      Part& to;
      ~MoveOut() { to = std::move(from); }
    } move_out{out, parts[w]};
    // FP32 first's screen, kScreenLanes pairs at once where it applies (the same verdicts as one
    // pair at a time): `screened_miss[i - chunk]` holds the verdicts of the pairs from `chunk` on.
    constexpr bool kScreenInLanes = lwsccd::detail::single_first_of<Method>::value;
    const bool in_lanes = kScreenInLanes && undecided && screen_in_lanes_applies(params);
    using LaneQuery = std::decay_t<decltype(gather_single(std::size_t{0}))>;
    LaneQuery lane_queries[kScreenLanes];
    bool screened_miss[kScreenLanes] = {};
    std::size_t chunk = 0;
    // Runs of consecutive pairs (neighbours in space: they share vertices and cache lines), taken
    // as workers free up (contacts cluster, so a fixed split would leave one worker the hard part).
    for (std::size_t begin = next.fetch_add(kRun); begin < n; begin = next.fetch_add(kRun))
    for (std::size_t i = begin, end = std::min(n, begin + kRun); i < end; ++i) {
      if constexpr (lwsccd::detail::certified_of<Method>::value) {
        if (undecided) {  // first pass: the screen, then the refinement of what it passes
          if constexpr (lwsccd::detail::single_first_of<Method>::value) {
            if (in_lanes && (i == begin || i - chunk == kScreenLanes)) {
              const int lanes = static_cast<int>(std::min<std::size_t>(kScreenLanes, end - i));
              for (int lane = 0; lane < lanes; ++lane) lane_queries[lane] = gather_single(i + lane);
              screen_single_in_lanes<typename Method::policy_type>(lane_queries, lanes, params, screened_miss);
              chunk = i;
            }
            const LaneQuery s = in_lanes ? lane_queries[i - chunk] : gather_single(i);
            const bool miss = in_lanes ? screened_miss[i - chunk]
                                       : Method::screen_verdict(s, params) != lwsccd::detail::ScreenVerdict::passed;
            if (miss) {
              ++out.counts.certified_misses;
              ++out.counts.single_misses;
              continue;
            }
            ++out.counts.screened;
            if (Method::filter_single(s, params)) {
              ++out.counts.certified_misses;
              ++out.counts.single_misses;
              continue;
            }
          } else {
            if (Method::screen_verdict(gather(i), params) != lwsccd::detail::ScreenVerdict::passed) {
              ++out.counts.certified_misses;
              continue;
            }
            ++out.counts.screened;
          }
          // The search in single precision first (its misses, and contacts with a double tail),
          // then the double screen and search on what it leaves.
          const auto q = gather(i);
          bool done = false, in_float_pairs = false;
          CertifiedAnswer<T> a = Method::refine_single_first(q, params, done, &in_float_pairs);
          if (done) {
            out.counts.single_misses += a.certainty == Certainty::miss;
            out.counts.single_descents += a.certainty == Certainty::hit;
            out.counts.float_pair_leaves += in_float_pairs;
          } else if (Method::screen_after_single(q, params)) {
            a = {Certainty::miss, T(0), T(1)};
          } else {
            a = Method::refine(q, params);
          }
          if (a.certainty == Certainty::hit) out.hits.push_back({pair_of(i).first, pair_of(i).second, a.lo}), ++out.counts.certified_hits;
          else if (a.certainty == Certainty::miss) ++out.counts.certified_misses;
          else out.open.push_back({i, a.lo});
          continue;
        }
      }
      const auto q = gather(i);
      CcdResult<T> r;
      CcdParams<T> item_params = params;
      item_params.time_from = std::max(params.time_from, static_cast<T>(from_of(i)));
      if constexpr (std::is_same_v<std::decay_t<decltype(q)>, VertexFaceQuery<T>>) {
        if constexpr (lwsccd::detail::certified_of<Method>::value) r = lwsccd::detail::certified_of<Method>::fallback::vertex_face(q, item_params);
        else r = Method::vertex_face(q, item_params);
      } else {
        if constexpr (lwsccd::detail::certified_of<Method>::value) r = lwsccd::detail::certified_of<Method>::fallback::edge_edge(q, item_params);
        else r = Method::edge_edge(q, item_params);
      }
      ++out.counts.fallbacks;
      if (r.hit) out.hits.push_back({pair_of(i).first, pair_of(i).second, r.toi}), out.gave_up += r.gave_up;
    }
  }, workers);
  for (auto& part : parts) {
    hits.insert(hits.end(), part.hits.begin(), part.hits.end());
    if (undecided) undecided->insert(undecided->end(), part.open.begin(), part.open.end());
    counts.certified_hits += part.counts.certified_hits;
    counts.certified_misses += part.counts.certified_misses;
    counts.fallbacks += part.counts.fallbacks;
    counts.screened += part.counts.screened;
    counts.single_misses += part.counts.single_misses;
    counts.single_descents += part.counts.single_descents;
    counts.float_pair_leaves += part.counts.float_pair_leaves;
    gave_up += part.gave_up;
  }
}

// test_feature_pairs over any sequences of pairs with size() and operator[] (one list, or the
// lists threads filled: ConcatenatedLists).
template <class Method, class T, class P, class VfPairs, class EePairs>
NarrowPhaseResult<T> test_pair_sequences(const TriangleMesh& mesh, const std::vector<Vec3<P>>& x0,
                                         const std::vector<Vec3<P>>& x1, const VfPairs& vf_pairs,
                                         const EePairs& ee_pairs, const CcdParams<T>& params) {
  struct {
    const VfPairs& vf;
    const EePairs& ee;
  } pairs{vf_pairs, ee_pairs};
  const MeshFeatures features = mesh_features(mesh);
  auto vf_query = [&](std::size_t i) {
    return gather_vertex_face<T>(features, x0.data(), x1.data(), pairs.vf[i].first, pairs.vf[i].second);
  };
  auto ee_query = [&](std::size_t i) {
    return gather_edge_edge<T>(features, x0.data(), x1.data(), pairs.ee[i].first, pairs.ee[i].second);
  };
  // FP32 first: the first pass's float queries, from every vertex rounded to float once.
  std::vector<SingleVertex> single;
  if constexpr (lwsccd::detail::single_first_of<Method>::value) single = single_vertices(x0, x1);
  auto vf_single = [&](std::size_t i) { return gather_single_vertex_face(features, single.data(), pairs.vf[i].first, pairs.vf[i].second); };
  auto ee_single = [&](std::size_t i) { return gather_single_edge_edge(features, single.data(), pairs.ee[i].first, pairs.ee[i].second); };
  NarrowPhaseResult<T> result;
  result.vf_counts.pairs = pairs.vf.size();
  result.ee_counts.pairs = pairs.ee.size();
  auto vf_pair = [&](std::size_t i) { return pairs.vf[i]; };
  auto ee_pair = [&](std::size_t i) { return pairs.ee[i]; };
  auto from_zero = [](std::size_t) { return T(0); };
  if constexpr (lwsccd::detail::certified_of<Method>::value) {
    // The certified pass over every pair, then the fallback on the undecided ones, with the time
    // limit limited.time_limit; into `out` (its counts' pairs already set).
    auto certified_pass = [&](const CcdParams<T>& limited, NarrowPhaseResult<T>& out) {
      std::vector<std::pair<std::size_t, T>> open_vf, open_ee;
      lwsccd::detail::test_list<Method>(pairs.vf.size(), vf_query, vf_single, vf_pair, from_zero, limited, &open_vf, out.vf,
                                        out.vf_counts, out.gave_up);
      lwsccd::detail::test_list<Method>(pairs.ee.size(), ee_query, ee_single, ee_pair, from_zero, limited, &open_ee, out.ee,
                                        out.ee_counts, out.gave_up);
      CcdParams<T> fallback_params = limited;
      if (limited.mode == CcdMode::earliest)
        for (const auto* list : {&out.vf, &out.ee})
          for (const auto& h : *list) fallback_params.time_limit = std::min(fallback_params.time_limit, h.toi);
      lwsccd::detail::test_list<Method>(
          open_vf.size(), [&](std::size_t k) { return vf_query(open_vf[k].first); }, vf_single,
          [&](std::size_t k) { return pairs.vf[open_vf[k].first]; }, [&](std::size_t k) { return open_vf[k].second; },
          fallback_params, nullptr, out.vf, out.vf_counts, out.gave_up);
      lwsccd::detail::test_list<Method>(
          open_ee.size(), [&](std::size_t k) { return ee_query(open_ee[k].first); }, ee_single,
          [&](std::size_t k) { return pairs.ee[open_ee[k].first]; }, [&](std::size_t k) { return open_ee[k].second; },
          fallback_params, nullptr, out.ee, out.ee_counts, out.gave_up);
    };
    if (params.mode != CcdMode::earliest) {
      certified_pass(params, result);
    } else {
      // Growing windows [0, limit) until one holds a contact (CertifiedPolicy::kEarliestFirst);
      // the counts are the last window's.
      for (int round = 0;; ++round) {
        CcdParams<T> limited = params;
        limited.time_limit = Method::earliest_window(round, params.time_limit);
        NarrowPhaseResult<T> attempt;
        attempt.vf_counts.pairs = pairs.vf.size();
        attempt.ee_counts.pairs = pairs.ee.size();
        certified_pass(limited, attempt);
        const bool last = !(limited.time_limit < params.time_limit);
        if (last || !attempt.vf.empty() || !attempt.ee.empty()) {
          result = std::move(attempt);
          break;
        }
      }
    }
  } else {
    lwsccd::detail::test_list<Method>(pairs.vf.size(), vf_query, vf_single, vf_pair, from_zero, params, nullptr, result.vf,
                                      result.vf_counts, result.gave_up);
    lwsccd::detail::test_list<Method>(pairs.ee.size(), ee_query, ee_single, ee_pair, from_zero, params, nullptr, result.ee,
                                      result.ee_counts, result.gave_up);
  }
  lwsccd::detail::parallel_sort(result.vf.begin(), result.vf.end());
  lwsccd::detail::parallel_sort(result.ee.begin(), result.ee.end());
  for (const auto* list : {&result.vf, &result.ee})
    for (const auto& h : *list) result.earliest_toi = std::min(result.earliest_toi, h.toi);
  if (params.mode == CcdMode::earliest) result.vf.clear(), result.ee.clear();
  return result;
}
}  // namespace detail

namespace cpu {

/// Runs Method on every pair (vf and ee lists in the dataset's id convention) on all cores, in
/// the mode params.mode. CertifiedCcd runs in two passes (certified classification, then the
/// fallback on the undecided pairs); the GPU batch does the same, so both give the same answers.
template <class Method, class T, class P>
NarrowPhaseResult<T> test_feature_pairs(const TriangleMesh& mesh, const std::vector<Vec3<P>>& x0,
                                        const std::vector<Vec3<P>>& x1, const FeaturePairs& pairs,
                                        const CcdParams<T>& params = {}) {
  static_assert(require_ccd_method<Method>::value, "");
  return lwsccd::detail::test_pair_sequences<Method>(mesh, x0, x1, pairs.vf, pairs.ee, params);
}

/// The same for feature pairs left in the lists that emitted them (emit_feature_pairs_into over
/// candidate lists), read where they lie: the answer of test_feature_pairs(pairs.joined()).
template <class Method, class T, class P>
NarrowPhaseResult<T> test_feature_pairs(const TriangleMesh& mesh, const std::vector<Vec3<P>>& x0,
                                        const std::vector<Vec3<P>>& x1, const FeaturePairParts& pairs,
                                        const CcdParams<T>& params = {}) {
  static_assert(require_ccd_method<Method>::value, "");
  using Pair = std::pair<index_t, index_t>;
  return lwsccd::detail::test_pair_sequences<Method>(mesh, x0, x1, lwsccd::detail::ConcatenatedLists<Pair>(pairs.vf_lists()),
                                                     lwsccd::detail::ConcatenatedLists<Pair>(pairs.ee_lists()), params);
}

}  // namespace cpu

}  // namespace lwsccd
