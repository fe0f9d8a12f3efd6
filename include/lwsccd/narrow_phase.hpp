// lwsccd — the narrow phase over lists of candidate feature pairs: result types and the CPU
// backend (all cores). The GPU batch is in narrow_phase.cuh; both give identical answers (the
// methods round alike on host and device).
#pragma once

#include <algorithm>
#include <thread>
#include <utility>
#include <vector>

#include "lwsccd/ccd_query.hpp"
#include "lwsccd/dataset.hpp"
#include "lwsccd/detail/oracle_impl.hpp"
#include "lwsccd/oracle.hpp"
#include "lwsccd/query_io.hpp"

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

template <class T>
struct NarrowPhaseResult {
  std::vector<FeatureHit<T>> vf, ee;  ///< sorted by (first, second)
  T earliest_toi = T(1);              ///< 1 when nothing collides
  std::size_t gave_up = 0;            ///< hits answered by a method's bounded-work fallback
};

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

namespace cpu {

/// Runs Method on every pair (vf and ee lists in the dataset's id convention) on all cores.
template <class Method, class T, class P>
NarrowPhaseResult<T> test_feature_pairs(const TriangleMesh& mesh, const std::vector<Vec3<P>>& x0,
                                        const std::vector<Vec3<P>>& x1, const FeaturePairs& pairs,
                                        const CcdParams<T>& params = {}) {
  static_assert(require_ccd_method<Method>::value, "");
  const MeshFeatures features = mesh_features(mesh);
  const unsigned workers = std::max(1u, std::thread::hardware_concurrency());
  std::vector<NarrowPhaseResult<T>> parts(workers);
  detail::run_on_all_cores([&](unsigned w, unsigned n) {
    NarrowPhaseResult<T>& out = parts[w];
    for (std::size_t i = w; i < pairs.vf.size(); i += n) {
      const auto& p = pairs.vf[i];
      const CcdResult<T> r =
          Method::vertex_face(gather_vertex_face<T>(features, x0.data(), x1.data(), p.first, p.second), params);
      if (r.hit) out.vf.push_back({p.first, p.second, r.toi}), out.gave_up += r.gave_up;
    }
    for (std::size_t i = w; i < pairs.ee.size(); i += n) {
      const auto& p = pairs.ee[i];
      const CcdResult<T> r = Method::edge_edge(gather_edge_edge<T>(features, x0.data(), x1.data(), p.first, p.second), params);
      if (r.hit) out.ee.push_back({p.first, p.second, r.toi}), out.gave_up += r.gave_up;
    }
  });
  NarrowPhaseResult<T> result;
  for (auto& part : parts) {
    result.vf.insert(result.vf.end(), part.vf.begin(), part.vf.end());
    result.ee.insert(result.ee.end(), part.ee.begin(), part.ee.end());
    result.gave_up += part.gave_up;
  }
  std::sort(result.vf.begin(), result.vf.end());
  std::sort(result.ee.begin(), result.ee.end());
  for (const auto* list : {&result.vf, &result.ee})
    for (const auto& h : *list) result.earliest_toi = std::min(result.earliest_toi, h.toi);
  return result;
}

}  // namespace cpu

}  // namespace lwsccd
