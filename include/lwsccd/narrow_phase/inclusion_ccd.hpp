// lwsccd — a conservative elemental test: inclusion-based root finding on (t, u, v) with a
// rigorous floating-point error bound (after Wang et al. 2021, "Tight Inclusion").
//
// Vertex-face: F(t, u, v) = p(t) - a(t) - u (b(t) - a(t)) - v (c(t) - a(t)), u, v >= 0, u + v <= 1.
// Edge-edge:   F(t, u, v) = a(t) + u (b(t) - a(t)) - c(t) - v (d(t) - c(t)), u, v in [0, 1].
// The features come within distance d (the minimum separation, infinity norm) at time t exactly
// when some (u, v) puts every component of F in [-d, d]. F is linear in each of t, u and v, so its
// range over a box of (t, u, v) is spanned by the values at the box's eight corners: the
// inclusion test is exact up to rounding, and the rounding is bounded by eps_k = 128 u m_k per
// axis k, where m_k is the largest |coordinate| of the query on that axis and u the unit
// roundoff of T (see docs/NARROW_PHASE.md for the derivation; it also covers a relative
// perturbation of u on every input, so a query rounded to float from exact data is covered).
//
// Boxes are examined in rounds of the earliest ones (InclusionSearch), split along the dimension
// that spreads F the most. A box that passes the test is reported as the contact when F over it
// lies within contact up to the distance the features move in `tolerance` of time, or when it
// cannot be split further (resolution `tolerance` in t, u and v), and no earlier box of its
// round was split. Its lower time bound is the reported time of impact: every box with an
// earlier time was excluded, so no contact happens before it.
//
// GUARANTEE. Never answers "no collision" when the features come within `min_separation`
// (infinity norm) at some time of the step, for the query as given or perturbed relatively by u;
// the reported toi is a lower bound of the earliest such time. Bounded work: after about
// `max_iterations` boxes (checked per round) it answers "hit" at the earliest time not yet
// excluded (gave_up = true): a false positive at worst, never a miss. Bounded memory: when more
// than Policy::kMaxBoxes boxes are live it drops the latest quarter and later searches again from
// the time the excluded part reaches, so a full store costs time, not a wrong answer.
#pragma once

#include <cassert>
#include <cmath>
#include <cstdint>
#include <limits>
#include <type_traits>

#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/core/detail/rounding.hpp"
#include "lwsccd/narrow_phase/ccd_filters.hpp"
#include "lwsccd/narrow_phase/ccd_query.hpp"

namespace lwsccd {

/// Tuning knobs of InclusionCcd.
struct InclusionPolicy {
  static constexpr int kMaxBoxes = 256;  ///< live boxes per query (sorted, double-buffered: 10 KiB on the GPU)
  static constexpr int kBatch = 32;      ///< boxes examined per round: a warp's lanes on the GPU, in turn elsewhere
};

}  // namespace lwsccd

// The definitions, in the order they were written in (each part includes the one before it).
#include "lwsccd/narrow_phase/detail/inclusion_boxes.hpp"
#include "lwsccd/narrow_phase/detail/inclusion_tests.hpp"
#include "lwsccd/narrow_phase/detail/inclusion_search.hpp"

namespace lwsccd {

/// The conservative method as a policy (see the file comment for its guarantee).
template <class Policy = InclusionPolicy>
struct InclusionCcdT {
  static constexpr const char* name = "inclusion";
  static constexpr bool conservative = true;
  /// True when the method's first step (the time filter on [0, 1] and the test of the whole
  /// (t, u, v) domain) already answers "no collision": exactly the pairs for which
  /// vertex_face / edge_edge return no hit after one box. Batches use it as a cheap first pass.
  template <class Q, class T>
  LWSCCD_HD static bool quick_reject(const Q& q, const CcdParams<T>& params) {
    CcdParams<T> first = params;
    first.max_iterations = 1;
    return !detail::inclusion_solve<Policy>(q, first).hit;
  }
  template <class T>
  LWSCCD_HD static CcdResult<T> vertex_face(const VertexFaceQuery<T>& q, const CcdParams<T>& params) {
    return detail::inclusion_solve<Policy>(q, params);
  }
  template <class T>
  LWSCCD_HD static CcdResult<T> edge_edge(const EdgeEdgeQuery<T>& q, const CcdParams<T>& params) {
    return detail::inclusion_solve<Policy>(q, params);
  }
};
using InclusionCcd = InclusionCcdT<>;

namespace detail {
/// Methods whose full test is InclusionCcd's search (alone, or behind the non-penetration
/// filter): the GPU batch runs that search with a warp per query.
template <class Method>
struct inclusion_search_of : std::false_type {};
template <class Policy>
struct inclusion_search_of<InclusionCcdT<Policy>> : std::true_type {
  using policy = Policy;
  static constexpr bool filtered = false;
};
template <class Policy>
struct inclusion_search_of<Filtered<InclusionCcdT<Policy>>> : std::true_type {
  using policy = Policy;
  static constexpr bool filtered = true;
};
}  // namespace detail

template <class Policy>
struct filtered_name<InclusionCcdT<Policy>> {
  static constexpr const char* value = "filtered-inclusion";
};

}  // namespace lwsccd
