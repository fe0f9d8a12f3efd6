// lwsccd — kernels and definitions for narrow_phase.cuh.
#pragma once

#include <cooperative_groups.h>
#include <cooperative_groups/reduce.h>
#include <cooperative_groups/scan.h>

#include <cstring>

#include "lwsccd/narrow_phase/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.cuh"

namespace lwsccd::gpu {

namespace detail {

// The items of a full test: id pairs, or (CertifiedCcd's undecided queries) FeatureHit records
// whose toi is the time before which the certified pass excluded any contact.
LWSCCD_HD inline std::pair<index_t, index_t> item_pair(const std::pair<index_t, index_t>& p) { return p; }
template <class T>
LWSCCD_HD std::pair<index_t, index_t> item_pair(const FeatureHit<T>& h) {
  return {h.first, h.second};
}
template <class T>
LWSCCD_HD CcdParams<T> item_params(const std::pair<index_t, index_t>&, const CcdParams<T>& params) {
  return params;
}
template <class T>
LWSCCD_HD CcdParams<T> item_params(const FeatureHit<T>& h, const CcdParams<T>& params) {
  CcdParams<T> p = params;
  p.time_from = h.toi > p.time_from ? h.toi : p.time_from;
  return p;
}

// The query of the feature pair p, in T: vertex-face when kVertexFace, else edge-edge.
template <bool kVertexFace, class T, class P>
LWSCCD_HD auto gather_query(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                            const std::pair<index_t, index_t>& p) {
  if constexpr (kVertexFace) return gather_vertex_face<T>(mesh, x0, x1, p.first, p.second);
  else return gather_edge_edge<T>(mesh, x0, x1, p.first, p.second);
}

// A method's test of either kind of query.
template <class Method, class T>
LWSCCD_HD CcdResult<T> run_method(const VertexFaceQuery<T>& q, const CcdParams<T>& params) {
  return Method::vertex_face(q, params);
}
template <class Method, class T>
LWSCCD_HD CcdResult<T> run_method(const EdgeEdgeQuery<T>& q, const CcdParams<T>& params) {
  return Method::edge_edge(q, params);
}

// Words of a list's counters (device, read by the host once per run).
enum NarrowCounter : int {
  kPairs = 0,       // the input's length, as read on the device
  kSurvivors,       // kept by the first pass (more than the room: the run is repeated with more)
  kSurvivorsPeak,   // the most kept by an earlier window of mode earliest (its counters are reset)
  kDeferred,        // CertifiedCcd: refinements left to the second kernel
  kCertifiedHits,
  kUndecided,       // CertifiedCcd: left to the fallback
  kOpen,            // InclusionCcd: searches left to a warp
  kHits,            // hits appended (more than the room: the run is repeated with more)
  kGaveUp,
  kEarliestBits,    // the smallest TOI of a hit, as the bits of a double (ordered like unsigned words for t >= 0)
  kIntervals,       // CertifiedCcd's filter: intervals listed for the inside test (more than the room: deferred)
  kExpanded,        // the filter's second round: intervals whose test was unknown, to split further
  kDeepIntervals,   // the second round's intervals listed for the inside test (more than the room: deferred)
  kSettled,         // CertifiedCcd: undecided queries settled as contacts within the tolerance (not the fallback's)
  kNarrowCounters
};
// Words of a run's control block, shared by both lists.
enum NarrowControl : int { kSkip = 0, kFallbackLimitBits, kNarrowControlWords };

// A time in [0, 1] as a word whose unsigned order is the time's order (-0 taken as +0).
template <class T>
LWSCCD_HD unsigned long long time_bits(T t) {
  const double d = t > T(0) ? static_cast<double>(t) : 0.0;
  unsigned long long bits = 0;
  std::memcpy(&bits, &d, sizeof d);
  return bits;
}
LWSCCD_HD inline double time_of_bits(unsigned long long bits) {
  double d = 0;
  std::memcpy(&d, &bits, sizeof d);
  return d;
}

// The next free index of a list whose length is *counter: one atomic per group of converged
// threads (they take consecutive indices).
__device__ inline unsigned long long append_index(unsigned long long* counter) {
  namespace cg = cooperative_groups;
  const cg::coalesced_group g = cg::coalesced_threads();
  unsigned long long base = 0;
  if (g.thread_rank() == 0) base = atomicAdd(counter, static_cast<unsigned long long>(g.size()));
  return g.shfl(base, 0) + g.thread_rank();
}

// A hit appended (stored where it fits; counted always, so that the host sees the room it needs),
// and the list's earliest time lowered (one atomic per converged group).
template <class T>
__device__ void push_hit(const FeatureHit<T>& hit, FeatureHit<T>* hits, std::size_t room, unsigned long long* counters) {
  namespace cg = cooperative_groups;
  const unsigned long long at = append_index(counters + kHits);
  if (at < room) hits[at] = hit;
  const cg::coalesced_group g = cg::coalesced_threads();
  const unsigned long long least = cg::reduce(g, time_bits(hit.toi), cg::less<unsigned long long>());
  if (g.thread_rank() == 0 && least < counters[kEarliestBits]) atomicMin(counters + kEarliestBits, least);
}

// The parameters of a full test: mode earliest lowers the time limit to the best certified time
// (limit_bits; null in other modes).
template <class T>
__device__ CcdParams<T> limited_params(CcdParams<T> params, const unsigned long long* limit_bits) {
  if (limit_bits) {
    const T limit = static_cast<T>(time_of_bits(*limit_bits));
    params.time_limit = limit < params.time_limit ? limit : params.time_limit;
  }
  return params;
}

#define LWSCCD_GRID_STRIDE(i, n)                                                                              \
  for (std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x; i < (n); \
       i += static_cast<std::size_t>(gridDim.x) * blockDim.x)

// Starts a window of a run (one thread). The first: clears the counters and records the inputs'
// lengths. A later one (mode earliest): skipped when an earlier window holds a hit, else the
// counters start over (the survivors' peak kept: an overflow there must still be seen).
// (Kernels in headers are templates, so that every translation unit may define them.)
template <class Word = unsigned long long>
__global__ void window_begin_kernel(unsigned long long* control, unsigned long long* vf_counters, unsigned long long* ee_counters,
                                    DeviceCount num_vf, DeviceCount num_ee, bool first) {
  if (first) {
    control[kSkip] = 0;
  } else if (control[kSkip] || vf_counters[kHits] + ee_counters[kHits] > 0) {
    control[kSkip] = 1;
    return;
  }
  control[kFallbackLimitBits] = time_bits(1.0);
  unsigned long long* lists[2] = {vf_counters, ee_counters};
  const DeviceCount sizes[2] = {num_vf, num_ee};
  for (int k = 0; k < 2; ++k) {
    unsigned long long* c = lists[k];
    const unsigned long long peak = first ? 0ull : (c[kSurvivors] > c[kSurvivorsPeak] ? c[kSurvivors] : c[kSurvivorsPeak]);
    for (int w = 0; w < kNarrowCounters; ++w) c[w] = 0;
    c[kSurvivorsPeak] = peak;
    c[kPairs] = sizes[k].get();
    c[kEarliestBits] = time_bits(1.0);
  }
}

// Mode earliest: the fallback need not look past the best certified time of either list, nor the
// window's end (one thread, after both lists' first passes).
template <class Word = unsigned long long>
__global__ void fallback_limit_kernel(unsigned long long* control, const unsigned long long* vf_counters,
                                      const unsigned long long* ee_counters, unsigned long long window_end_bits) {
  if (control[kSkip]) return;
  unsigned long long m = window_end_bits;
  m = vf_counters[kEarliestBits] < m ? vf_counters[kEarliestBits] : m;
  m = ee_counters[kEarliestBits] < m ? ee_counters[kEarliestBits] : m;
  control[kFallbackLimitBits] = m;
}

// A full test of every item (one-pass methods, and the fallbacks that are not inclusion searches).
template <class Method, bool kVertexFace, class T, class P, class Item>
__global__ void ccd_pairs_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1, const Item* items, DeviceCount count,
                                 CcdParams<T> params, const unsigned long long* control, const unsigned long long* limit_bits,
                                 unsigned long long* counters, FeatureHit<T>* hits, std::size_t hit_room) {
  if (control[kSkip]) return;
  const CcdParams<T> base = limited_params(params, limit_bits);
  const std::size_t n = count.get();
  LWSCCD_GRID_STRIDE(i, n) {
    const std::pair<index_t, index_t> p = item_pair(items[i]);
    const CcdResult<T> r = run_method<Method>(gather_query<kVertexFace, T>(mesh, x0, x1, p), item_params(items[i], base));
    if (r.hit) push_hit(FeatureHit<T>{p.first, p.second, r.toi}, hits, hit_room, counters);
    if (r.gave_up) atomicAdd(counters + kGaveUp, 1ull);
  }
}

// The first step of a two-pass method on one query: true when it certainly rejects the pair
// (CertifiedCcd: its screen; other methods: their quick_reject).
template <class Method, class Q, class T>
__device__ bool first_step_rejects(const Q& q, const CcdParams<T>& params) {
  if constexpr (lwsccd::detail::certified_of<Method>::value) return Method::screen(q, params);
  else return Method::quick_reject(q, params);
}

// Pass 1: the pairs that the method's cheap first step does not reject, appended to `kept`.
template <class Method, bool kVertexFace, class T, class P>
__global__ void screen_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1, PairList in, CcdParams<T> params,
                              const unsigned long long* control, std::pair<index_t, index_t>* kept, std::size_t room,
                              unsigned long long* counters) {
  if (control[kSkip]) return;
  const std::size_t n = in.count.get();
  LWSCCD_GRID_STRIDE(i, n) {
    const std::pair<index_t, index_t> p = in.pairs[i];
    if (first_step_rejects<Method>(gather_query<kVertexFace, T>(mesh, x0, x1, p), params)) continue;
    const unsigned long long at = append_index(counters + kSurvivors);
    if (at < room) {  // (std::pair's assignment is host-only before C++20)
      kept[at].first = p.first;
      kept[at].second = p.second;
    }
  }
}

// A refinement's answer stored: a certified hit appended to the hits, an undecided query to the
// fallback's list with the time before which contact was excluded (a certain miss: nothing).
template <class T>
__device__ void settle_refined(const CertifiedAnswer<T>& a, index_t first, index_t second, unsigned long long* counters,
                               FeatureHit<T>* hits, std::size_t hit_room, FeatureHit<T>* undecided) {
  if (a.certainty == Certainty::hit) {
    push_hit(FeatureHit<T>{first, second, a.lo}, hits, hit_room, counters);
    atomicAdd(counters + kCertifiedHits, 1ull);
  } else if (a.certainty == Certainty::undecided) {
    undecided[append_index(counters + kUndecided)] = FeatureHit<T>{first, second, a.lo};
  }
}

// CertifiedCcd's refinement of the screened pairs, first part: searches that would halve
// intervals at kDeferLevel or deeper stop (with a stack only that deep) and are listed in
// `deferred` (they are the contacts, resolved at the time tolerance, and would hold up whole warps
// of quick misses); the others settle their answer.
template <class Method, bool kVertexFace, int kDeferLevel, int kBlock, int kMinBlocks, class T, class P>
__global__ void __launch_bounds__(kBlock, kMinBlocks)
    refine_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1, const std::pair<index_t, index_t>* kept,
                  std::size_t room, CcdParams<T> params, const unsigned long long* control, unsigned long long* counters,
                  FeatureHit<T>* hits, std::size_t hit_room, FeatureHit<T>* undecided, unsigned* deferred) {
  if (control[kSkip]) return;
  const std::size_t n = counters[kSurvivors] < room ? static_cast<std::size_t>(counters[kSurvivors]) : room;
  LWSCCD_GRID_STRIDE(i, n) {
    const std::pair<index_t, index_t> p = kept[i];
    bool later = false;
    const CertifiedAnswer<T> a =
        Method::template refine_until<kDeferLevel, false>(gather_query<kVertexFace, T>(mesh, x0, x1, p), params, &later);
    if (later) deferred[append_index(counters + kDeferred)] = static_cast<unsigned>(i);
    else settle_refined(a, p.first, p.second, counters, hits, hit_room, undecided);
  }
}

// CertifiedCcd's refinement with the filter (CertifiedPolicy's CertifiedFilter), first kernel: a
// thread per screened pair runs the filter's levels; a pair to be searched whole is deferred, the
// others list their intervals for the inside test (a word each: filter_item). The list's room
// grows from run to run (kIntervals counts what was asked); a pair whose intervals do not fit is
// deferred instead, and the slots it took are marked empty, so nothing reruns.
constexpr unsigned long long kNoInterval = ~0ull;
// A listed interval: the pair's index, whether its search may take the filter's second round
// (CertifiedFilter::expandable), and the interval's heap number (< 256: levels <= 7).
__device__ inline unsigned long long filter_item(std::size_t pair, bool expandable, unsigned node) {
  return (static_cast<unsigned long long>(pair) << 9) | (expandable ? 256u : 0u) | node;
}
__device__ inline unsigned item_pair_index(unsigned long long item) { return static_cast<unsigned>(item >> 9); }
__device__ inline bool item_expandable(unsigned long long item) { return (item >> 8) & 1u; }
__device__ inline unsigned item_node(unsigned long long item) { return static_cast<unsigned>(item & 255u); }

// Appends `count` words to a list with `room` slots (one atomic per converged group) and returns
// the first one's slot; `fits` is false when they do not all fit (the slots that do are then the
// caller's to mark empty).
__device__ inline unsigned long long append_run(unsigned long long* counter, unsigned count, std::size_t room, bool& fits) {
  namespace cg = cooperative_groups;
  const cg::coalesced_group g = cg::coalesced_threads();
  const unsigned long long offset = cg::exclusive_scan(g, static_cast<unsigned long long>(count));
  unsigned long long base = 0;
  if (g.thread_rank() == g.size() - 1) base = atomicAdd(counter, offset + static_cast<unsigned long long>(count));
  base = g.shfl(base, g.size() - 1) + offset;
  fits = base + count <= room;
  return base;
}

// Defers pair `i` to the whole search once (its bit in `listed` marks it; cleared before the run).
__device__ inline void defer_once(unsigned i, unsigned* listed, unsigned long long* counters, unsigned* deferred) {
  const unsigned bit = 1u << (i & 31u);
  if (!(atomicOr(listed + (i >> 5), bit) & bit)) deferred[append_index(counters + kDeferred)] = i;
}
template <class Method, bool kVertexFace, class T, class P>
__global__ void filter_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1, const std::pair<index_t, index_t>* kept,
                              std::size_t room, CcdParams<T> params, const unsigned long long* control, unsigned long long* counters,
                              unsigned long long* intervals, std::size_t interval_room, FeatureHit<T>* undecided,
                              unsigned* deferred) {
  using Filter = lwsccd::detail::CertifiedFilter<typename Method::policy_type>;
  if (control[kSkip]) return;
  const std::size_t n = counters[kSurvivors] < room ? static_cast<std::size_t>(counters[kSurvivors]) : room;
  LWSCCD_GRID_STRIDE(i, n) {
    std::uint32_t found = 0;
    lwsccd::detail::Noted<T> noted;
    const int count = Filter::intervals(gather_query<kVertexFace, T>(mesh, x0, x1, kept[i]), params, found, noted);
    // A lower bound noted: with no interval left the search's answer is undecided from it (the
    // fallback's, once settle_undecided_kernel has looked); with some, the whole search decides (rare).
    bool whole = count < 0 || (count > 0 && noted.any);
    if (count == 0 && noted.any) undecided[append_index(counters + kUndecided)] = FeatureHit<T>{kept[i].first, kept[i].second, noted.lower};
    if (count > 0 && !whole) {
      bool fits = true;
      const unsigned long long base = append_run(counters + kIntervals, static_cast<unsigned>(count), interval_room, fits);
      whole = !fits;
      const bool expandable = Filter::expandable(count);
      for (int k = 0; k < count; ++k, found &= found - 1u)
        if (base + k < interval_room)
          intervals[base + k] = whole ? kNoInterval : filter_item(i, expandable, static_cast<unsigned>(__ffs(found) - 1));
    }
    if (whole) deferred[append_index(counters + kDeferred)] = static_cast<unsigned>(i);
  }
}

// Second kernel: a thread per listed interval runs the inside test there; a pair not certainly
// outside is deferred to the whole search, once (defer_once). In the first round
// (`expanded` not null) an interval of the filter's level whose test is unknown is listed in
// `expanded` for the second round instead, when its pair may take it; in the second round
// (`counter` kDeepIntervals) every interval must be outside.
template <class Method, bool kVertexFace, class T, class P>
__global__ void filter_inside_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                     const std::pair<index_t, index_t>* kept, CcdParams<T> params,
                                     const unsigned long long* control, unsigned long long* counters, int counter,
                                     const unsigned long long* intervals, std::size_t interval_room, unsigned* listed,
                                     unsigned* deferred, unsigned long long* expanded) {
  using Filter = lwsccd::detail::CertifiedFilter<typename Method::policy_type>;
  using lwsccd::detail::InsideVerdict;
  if (control[kSkip]) return;
  const std::size_t n = counters[counter] < interval_room ? static_cast<std::size_t>(counters[counter]) : interval_room;
  LWSCCD_GRID_STRIDE(j, n) {
    const unsigned long long item = intervals[j];
    if (item == kNoInterval) continue;
    const unsigned i = item_pair_index(item), node = item_node(item);
    const InsideVerdict verdict = Filter::inside_verdict(gather_query<kVertexFace, T>(mesh, x0, x1, kept[i]), params, node);
    if (verdict == InsideVerdict::outside) continue;
    // Its own slot in `expanded`, whose room is the first round's list's.
    if (expanded && verdict == InsideVerdict::unknown && item_expandable(item) && (node >> Filter::kLevel) == 1u)
      expanded[append_index(counters + kExpanded)] = item;
    else
      defer_once(i, listed, counters, deferred);
  }
}

// The filter's second round: a thread per interval left unknown by the first lists the intervals
// below it that the search would test next (CertifiedFilter::expand), in the list of the second
// round's inside tests; a pair already deferred is skipped, one the round cannot take (or whose
// intervals do not fit: slots marked empty, room grown for the next run) is deferred.
template <class Method, bool kVertexFace, class T, class P>
__global__ void filter_expand_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                     const std::pair<index_t, index_t>* kept, CcdParams<T> params,
                                     const unsigned long long* control, unsigned long long* counters,
                                     const unsigned long long* expanded, unsigned long long* deep, std::size_t deep_room,
                                     unsigned* listed, unsigned* deferred) {
  using Filter = lwsccd::detail::CertifiedFilter<typename Method::policy_type>;
  if (control[kSkip]) return;
  const std::size_t n = static_cast<std::size_t>(counters[kExpanded]);
  LWSCCD_GRID_STRIDE(j, n) {
    const unsigned long long item = expanded[j];
    const unsigned i = item_pair_index(item), node = item_node(item);
    if ((listed[i >> 5] >> (i & 31u)) & 1u) continue;  // deferred already (a racing read is only a missed shortcut)
    std::uint32_t below = 0;
    const int count = Filter::expand(gather_query<kVertexFace, T>(mesh, x0, x1, kept[i]), params, node, below);
    bool fits = count >= 0;
    if (count > 0) {
      const unsigned long long base = append_run(counters + kDeepIntervals, static_cast<unsigned>(count), deep_room, fits);
      for (int k = 0; k < count; ++k, below &= below - 1u)
        if (base + k < deep_room)
          deep[base + k] = fits ? filter_item(i, false, Filter::deep_node(node, static_cast<unsigned>(__ffs(below) - 1))) : kNoInterval;
    }
    if (!fits) defer_once(i, listed, counters, deferred);
  }
}

// Second part: the deferred searches, whole (a grid-stride loop keeps the warps full).
template <class Method, bool kVertexFace, class T, class P>
__global__ void refine_deferred_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                       const std::pair<index_t, index_t>* kept, const unsigned* deferred, CcdParams<T> params,
                                       const unsigned long long* control, unsigned long long* counters, FeatureHit<T>* hits,
                                       std::size_t hit_room, FeatureHit<T>* undecided, std::size_t warp_below) {
  if (control[kSkip]) return;
  const std::size_t n = static_cast<std::size_t>(counters[kDeferred]);
  if (n <= warp_below) return;  // refine_deferred_warp_kernel's
  LWSCCD_GRID_STRIDE(w, n) {
    const std::pair<index_t, index_t> p = kept[deferred[w]];
    const CertifiedAnswer<T> a = Method::template refine<false>(gather_query<kVertexFace, T>(mesh, x0, x1, p), params);
    settle_refined(a, p.first, p.second, counters, hits, hit_room, undecided);
  }
}

// The inside tests of a refinement run by a whole warp (every lane runs the same search on the
// same values, so all ask for the same test at once): a test not at hand is evaluated with its
// subtree, the interval and its descendants down to 4 levels below, a lane each (31 lanes); every
// lane keeps the 31 verdicts (2 bits each, by two ballots). The search asks next for a child or a
// later sibling most of the time: cloth-funnel's longest coplanar edge-edge search (186 tests)
// evaluates 37 subtrees (CPU count).
struct WarpInsideSubtree {
  static constexpr int kDepth = 5;  // levels of a subtree; 2^5 - 1 = 31 intervals
  int lane = 0, max_level = 0;
  int root_level = -1;
  std::uint32_t root_index = 0;
  unsigned low_bits = 0, high_bits = 0;  // verdict bit 0 and bit 1 of each subtree interval (heap order)

  template <class Compute>
  __device__ lwsccd::detail::InsideVerdict operator()(int level, std::uint32_t index, const Compute& compute) {
    using lwsccd::detail::InsideVerdict;
    const int depth = level - root_level;
    const bool held = root_level >= 0 && depth >= 0 && depth < kDepth && (index >> depth) == root_index;
    if (!held) {
      root_level = level, root_index = index;
      // This lane's interval: heap place lane + 1 = 2^d + offset, d levels below the root.
      const int d = 31 - __clz(lane + 1);
      const std::uint32_t offset = static_cast<std::uint32_t>(lane + 1 - (1 << d));
      const int lane_level = level + d;
      InsideVerdict v = InsideVerdict::unknown;
      if (lane < 31 && lane_level <= max_level) v = compute(lane_level, (index << d) | offset);
      const unsigned bits = static_cast<unsigned>(v);
      low_bits = __ballot_sync(0xffffffffu, bits & 1u);
      high_bits = __ballot_sync(0xffffffffu, bits & 2u);
    }
    const int d = level - root_level;
    const int place = (1 << d) - 1 + static_cast<int>(index - (root_index << d));
    return static_cast<InsideVerdict>(((low_bits >> place) & 1u) | (((high_bits >> place) & 1u) << 1));
  }
};

// Second part for a short list (at most `warp_below` deferred pairs): a warp per pair, the inside
// tests by subtrees (WarpInsideSubtree); the same answers as refine_deferred_kernel. Its pairs are
// the long searches (cloth-funnel's coplanar edge-edge ones: 96 halvings and ~190 inside tests one
// after the other took ~255 us in one thread on an H100).
template <class Method, bool kVertexFace, class T, class P>
__global__ void refine_deferred_warp_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                            const std::pair<index_t, index_t>* kept, const unsigned* deferred,
                                            CcdParams<T> params, const unsigned long long* control,
                                            unsigned long long* counters, FeatureHit<T>* hits, std::size_t hit_room,
                                            FeatureHit<T>* undecided, std::size_t warp_below) {
  if (control[kSkip]) return;
  const std::size_t n = static_cast<std::size_t>(counters[kDeferred]);
  if (n > warp_below) return;
  const int lane = static_cast<int>(threadIdx.x) % 32;
  const std::size_t warps = static_cast<std::size_t>(gridDim.x) * (blockDim.x / 32);
  for (std::size_t w = (static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x) / 32; w < n; w += warps) {
    const std::pair<index_t, index_t> p = kept[deferred[w]];
    WarpInsideSubtree inside;
    inside.lane = lane;
    inside.max_level = lwsccd::detail::certified_max_level(params.tolerance);
    const CertifiedAnswer<T> a = Method::template refine_with<false>(gather_query<kVertexFace, T>(mesh, x0, x1, p), params, inside);
    if (lane == 0) settle_refined(a, p.first, p.second, counters, hits, hit_room, undecided);
    __syncwarp();
  }
}

// Third part: the undecided queries, a thread each, settled as the whole search settles them
// (CertifiedCcd::undecided_from: a contact within the tolerance after the lower bound is a hit,
// counted with the certified hits). A settled query stays in the list with nothing left to search
// (from time 1), so the fallback's launches keep their count. Apart from the refinement kernels so
// that their registers do not pay for a test most pairs never reach.
template <class Method, bool kVertexFace, class T, class P>
__global__ void settle_undecided_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1, CcdParams<T> params,
                                        const unsigned long long* control, unsigned long long* counters, FeatureHit<T>* hits,
                                        std::size_t hit_room, FeatureHit<T>* undecided, std::size_t room) {
  if (control[kSkip]) return;
  const std::size_t n = counters[kUndecided] < room ? static_cast<std::size_t>(counters[kUndecided]) : room;
  LWSCCD_GRID_STRIDE(i, n) {
    FeatureHit<T>& item = undecided[i];
    const CertifiedAnswer<T> a =
        Method::undecided_from(gather_query<kVertexFace, T>(mesh, x0, x1, item_pair(item)), params, item.toi);
    if (a.certainty != Certainty::hit) continue;
    push_hit(FeatureHit<T>{item.first, item.second, a.lo}, hits, hit_room, counters);
    atomicAdd(counters + kCertifiedHits, 1ull);
    atomicAdd(counters + kSettled, 1ull);
    item.toi = T(1);
  }
}

// Second pass, first attempt: the same search in one thread per query, for a few rounds and
// little memory. Most queries end there; the others are listed in `open` for the warp search
// (which starts over and gives the answer the whole search gives). A list of at most
// `direct_below` queries goes to the warp search whole: its warps all run at once, and the
// attempt's rounds would only lengthen the longest search (cloth-funnel's fallbacks: 34-54 us).
template <class Method, bool kVertexFace, class T, class P, int kRounds, int kStore, class Item>
__global__ void inclusion_thread_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1, const Item* items,
                                        DeviceCount count, CcdParams<T> params, const unsigned long long* control,
                                        const unsigned long long* limit_bits, unsigned long long* counters, FeatureHit<T>* hits,
                                        std::size_t hit_room, unsigned* open, std::size_t direct_below) {
  using Traits = lwsccd::detail::inclusion_search_of<Method>;
  if (control[kSkip]) return;
  const CcdParams<T> base = limited_params(params, limit_bits);
  const std::size_t n = count.get();
  if (n <= direct_below) {
    LWSCCD_GRID_STRIDE(i, n) {
      if (i == 0) counters[kOpen] = n;
      open[i] = static_cast<unsigned>(i);
    }
    return;
  }
  LWSCCD_GRID_STRIDE(i, n) {
    const std::pair<index_t, index_t> p = item_pair(items[i]);
    const CcdParams<T> qp = item_params(items[i], base);
    CcdResult<T> r;
    bool done = true;
    auto attempt = [&](const auto& q) {
      if (Traits::filtered && !non_penetration_filter(q, qp)) return;
      done = lwsccd::detail::inclusion_try<typename Traits::policy, kStore>(q, qp, kRounds, r);
    };
    attempt(gather_query<kVertexFace, T>(mesh, x0, x1, p));
    if (!done) {
      open[append_index(counters + kOpen)] = static_cast<unsigned>(i);
      continue;
    }
    if (r.hit) push_hit(FeatureHit<T>{p.first, p.second, r.toi}, hits, hit_room, counters);
    if (r.gave_up) atomicAdd(counters + kGaveUp, 1ull);
  }
}

// The warp's `n` keys (n <= 64, two a lane: lane l holds places 2l and 2l + 1, the places from n
// on padded with a key after every box's) sorted by a bitonic network: in place, ascending. Half
// the stages exchange with another lane (four 64-bit shuffles), the others swap the lane's pair;
// up to 32 keys need only the first lanes' network.
__device__ inline void warp_sort_keys(lwsccd::detail::BoxOrderKey& first, lwsccd::detail::BoxOrderKey& second, int n, int lane) {
  using lwsccd::detail::BoxOrderKey;
  using lwsccd::detail::key_before;
  const int size = n <= 2 ? 2 : (n <= 4 ? 4 : (n <= 8 ? 8 : (n <= 16 ? 16 : (n <= 32 ? 32 : 64))));
  for (int k = 2; k <= size; k <<= 1) {
    const bool up = ((2 * lane) & k) == 0;  // this lane's places sort up in this stage's runs
    for (int j = k >> 1; j >= 2; j >>= 1) {
      const int mask = j >> 1;  // the partner's lane distance; both places share it
      const bool lower = (lane & mask) == 0;
      const BoxOrderKey other_first{__shfl_xor_sync(0xffffffffu, first.high, mask), __shfl_xor_sync(0xffffffffu, first.low, mask)};
      const BoxOrderKey other_second{__shfl_xor_sync(0xffffffffu, second.high, mask), __shfl_xor_sync(0xffffffffu, second.low, mask)};
      const bool keep_min = lower == up;
      if (key_before(other_first, first) == keep_min) first = other_first;
      if (key_before(other_second, second) == keep_min) second = other_second;
    }
    if (key_before(second, first) == up) {
      const BoxOrderKey x = first;
      first = second;
      second = x;
    }
  }
}

// Second pass for InclusionCcd (filtered or not): a warp per query. The rounds of
// detail::InclusionSearch with the work spread over the lanes: each lane examines one box of the
// round and makes its new boxes; the new boxes are sorted by a warp network and merged with the
// sorted live boxes along the merge path, each lane writing a run of the output. Same sets and
// answers as the one-thread search (the order is total), with a long search's latency cut to that
// of its rounds. The live boxes are kept as their order keys (BoxOrderKey: the whole box in two
// words), so that ranking and merging compare words (H100, cloth-funnel's edge-edge searches:
// comparing boxes field by field took ~22 K of a round's ~35 K cycles).
template <class Method, bool kVertexFace, class T, class P, int kWarps, class Item>
__global__ void __launch_bounds__(32 * kWarps)
    inclusion_warp_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1, const Item* items, const unsigned* which,
                          CcdParams<T> params, const unsigned long long* control, const unsigned long long* limit_bits,
                          unsigned long long* counters, FeatureHit<T>* hits, std::size_t hit_room) {
  using Traits = lwsccd::detail::inclusion_search_of<Method>;
  using Policy = typename Traits::policy;
  using lwsccd::detail::BoxOrderKey;
  using lwsccd::detail::BoxVerdict;
  using lwsccd::detail::DyadicBox;
  using lwsccd::detail::key_before;
  using Search = lwsccd::detail::InclusionSearch<Policy, T, Policy::kMaxBoxes, BoxOrderKey>;
  using Round = typename Search::Round;
  constexpr int kFresh = Search::kFresh;
  static_assert(Search::kBatch <= 32 && kFresh <= 64, "lwsccd: a round must fit in a warp");
  // Raw storage: shared variables cannot have constructors; start() initializes a search.
  __shared__ alignas(Search) unsigned char storage[kWarps * sizeof(Search)];
  __shared__ BoxOrderKey fresh[kWarps][kFresh];
  __shared__ CcdResult<T> results[kWarps];
  __shared__ unsigned long long dropped[kWarps];
  __shared__ int state[kWarps];
  if (control[kSkip]) return;
  const CcdParams<T> base = limited_params(params, limit_bits);
  const std::size_t n = static_cast<std::size_t>(counters[kOpen]);
  const int warp = static_cast<int>(threadIdx.x) / 32, lane = static_cast<int>(threadIdx.x) % 32;
  Search& search = reinterpret_cast<Search*>(storage)[warp];
  const BoxOrderKey after_all{~0ull, ~0ull};
  for (std::size_t w = static_cast<std::size_t>(blockIdx.x) * kWarps + warp; w < n;
       w += static_cast<std::size_t>(gridDim.x) * kWarps) {
    const std::size_t i = which[w];
    const std::pair<index_t, index_t> p = item_pair(items[i]);
    const CcdParams<T> qp = item_params(items[i], base);
    CcdResult<T> r;
    auto solve = [&](const auto& q) {
      if (Traits::filtered && !non_penetration_filter(q, qp)) return;
      const auto setup = lwsccd::detail::inclusion_setup(q, qp);
      if (setup.separated) return;
      if (lane == 0) search.start();
      __syncwarp();
      while (true) {
        // Search::next_round with the batch found by ballots (lane 0 alone went through it box by box).
        if (lane == 0) state[warp] = search.settle_front(results[warp]) ? 1 : 0;
        __syncwarp();
        if (state[warp] == 0) {
          if (results[warp].hit) r = results[warp];  // gave up
          return;
        }
        const bool joins = search.in_batch(lane);  // a prefix of the live boxes (they are sorted by time)
        const int joining = __popc(__ballot_sync(0xffffffffu, joins));
        const int unexamined = __popc(__ballot_sync(0xffffffffu, joins && !lwsccd::detail::is_accepted(search.live()[lane])));
        __syncwarp();  // every lane's reads of the search before lane 0 takes the batch
        if (lane == 0) state[warp] = static_cast<int>(search.take_batch(joining, unexamined, qp.max_iterations, results[warp]));
        __syncwarp();
        if (static_cast<Round>(state[warp]) != Round::examine) {
          r = results[warp];  // gave up
          return;
        }
        const int k = search.batch_size;
        const BoxOrderKey* batch = search.batch();
        BoxVerdict verdict = BoxVerdict::excluded;
        DyadicBox box{};
        if (lane < k) {
          box = lwsccd::detail::box_of_key(batch[lane]);
          verdict = lwsccd::detail::examine_box(q, setup, box, search.floor_key, search.t_floor);
        }
        // The answer: the first accepted box with no split box before it in the round.
        const unsigned accepted = __ballot_sync(0xffffffffu, lane < k && verdict == BoxVerdict::accepted);
        const unsigned split = __ballot_sync(0xffffffffu, lane < k && verdict != BoxVerdict::accepted &&
                                                                verdict != BoxVerdict::excluded);
        const int first_accepted = accepted ? __ffs(accepted) - 1 : 32, first_split = split ? __ffs(split) - 1 : 32;
        if (first_accepted < first_split) {
          r = {true, search.time_of(batch[first_accepted]), false};
          __syncwarp();
          return;
        }
        // This lane's new boxes, listed after the lower lanes' ones, then sorted by the warp.
        DyadicBox mine[2];
        const int count = lane < k ? search.fresh_boxes(box, verdict, setup.vf, mine) : 0;
        const unsigned has_one = __ballot_sync(0xffffffffu, count >= 1), has_two = __ballot_sync(0xffffffffu, count == 2);
        const unsigned lower_lanes = (1u << lane) - 1u;
        const int listed_at = __popc(has_one & lower_lanes) + __popc(has_two & lower_lanes);
        const int nf = __popc(has_one) + __popc(has_two);
        for (int c = 0; c < count; ++c) fresh[warp][listed_at + c] = lwsccd::detail::box_order_key(mine[c]);
        __syncwarp();
        BoxOrderKey first = 2 * lane < nf ? fresh[warp][2 * lane] : after_all;
        BoxOrderKey second = 2 * lane + 1 < nf ? fresh[warp][2 * lane + 1] : after_all;
        __syncwarp();
        warp_sort_keys(first, second, nf, lane);
        if (2 * lane < nf) fresh[warp][2 * lane] = first;
        if (2 * lane + 1 < nf) fresh[warp][2 * lane + 1] = second;
        __syncwarp();
        // Merge into the other buffer, keeping the earliest kKeep when over capacity (the first
        // box past them gives the dropped time): output places [from, to) are this lane's; where
        // its run starts in each list is found on the merge path (how many of the first `from`
        // outputs are live boxes).
        const BoxOrderKey* live = search.live();
        const BoxOrderKey* sorted = fresh[warp];
        const int size = search.size, total = size + nf;
        const int limit = total > Search::kCapacity ? Search::kKeep : total;
        const int outputs = total > limit ? limit + 1 : total;
        const int run = (outputs + 31) / 32;
        const int from = lane * run < outputs ? lane * run : outputs, to = from + run < outputs ? from + run : outputs;
        BoxOrderKey* out = search.items[1 - search.current];
        if (from < to) {
          int lo = from > nf ? from - nf : 0, hi = from < size ? from : size;
          while (lo < hi) {
            const int mid = (lo + hi) / 2;
            if (key_before(live[mid], sorted[from - 1 - mid])) lo = mid + 1;
            else hi = mid;
          }
          int a = lo, b = from - lo;
          BoxOrderKey next_live = a < size ? live[a] : after_all, next_fresh = b < nf ? sorted[b] : after_all;
          for (int o = from; o < to; ++o) {
            const bool take_live = key_before(next_live, next_fresh);
            const BoxOrderKey next = take_live ? next_live : next_fresh;
            if (take_live) next_live = ++a < size ? live[a] : after_all;
            else next_fresh = ++b < nf ? sorted[b] : after_all;
            if (o < limit) out[o] = next;
            else dropped[warp] = lwsccd::detail::box_time_key(next);  // o == limit: the earliest dropped box
          }
        }
        __syncwarp();
        if (lane == 0) {
          if (total > limit) search.evicted_key = dropped[warp] < search.evicted_key ? dropped[warp] : search.evicted_key;
          search.current = 1 - search.current;
          search.head = 0;
          search.size = limit;
        }
        __syncwarp();
      }
    };
    solve(gather_query<kVertexFace, T>(mesh, x0, x1, p));
    if (lane == 0) {
      if (r.hit) push_hit(FeatureHit<T>{p.first, p.second, r.toi}, hits, hit_room, counters);
      if (r.gave_up) atomicAdd(counters + kGaveUp, 1ull);
    }
    __syncwarp();
  }
}

// The sort key of a hit: (first, second) as one word, first shifted by `id_bits` (every id is
// below 2^id_bits, so the key's order is the pair's and it has 2 id_bits bits to sort).
template <class T>
__global__ void hit_keys_kernel(const FeatureHit<T>* hits, std::size_t n, int id_bits, unsigned long long* keys) {
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  assert(static_cast<unsigned long long>(static_cast<unsigned>(hits[i].first)) >> id_bits == 0 &&
         static_cast<unsigned long long>(static_cast<unsigned>(hits[i].second)) >> id_bits == 0 && "a feature id past the mesh's features");
  keys[i] = (static_cast<unsigned long long>(static_cast<unsigned>(hits[i].first)) << id_bits) | static_cast<unsigned>(hits[i].second);
}

// A sort of at most kThreads hits in one block, a thread per hit: its place is the number of
// keys below its own plus the equal ones before it (stable, as the radix sort). A step's few
// hits (horse-gallop: a handful) took a radix sort's ~14 us single-tile pass plus the key
// kernel; the block compares every pair of keys in shared memory instead.
template <class T, int kThreads>
__global__ void __launch_bounds__(kThreads)
    small_hit_sort_kernel(const FeatureHit<T>* hits, int n, int id_bits, FeatureHit<T>* sorted) {
  __shared__ unsigned long long keys[kThreads];
  const int i = static_cast<int>(threadIdx.x);
  FeatureHit<T> hit;
  unsigned long long key = 0;
  if (i < n) {
    hit = hits[i];
    assert(static_cast<unsigned long long>(static_cast<unsigned>(hit.first)) >> id_bits == 0 &&
           static_cast<unsigned long long>(static_cast<unsigned>(hit.second)) >> id_bits == 0 && "a feature id past the mesh's features");
    key = (static_cast<unsigned long long>(static_cast<unsigned>(hit.first)) << id_bits) | static_cast<unsigned>(hit.second);
    keys[i] = key;
  }
  __syncthreads();
  if (i >= n) return;
  int place = 0;
  for (int j = 0; j < n; ++j) {
    const unsigned long long other = keys[j];
    place += other < key || (other == key && j < i);
  }
  sorted[place] = hit;
}
constexpr int kSmallHitSort = 256;  ///< hits sorted by small_hit_sort_kernel (more: the radix sort)

// Bits of the largest feature id below `id_limit` (at least 1, at most 32).
inline int id_bits_below(std::size_t id_limit) {
  int bits = 1;
  while (bits < 32 && (std::size_t(1) << bits) < id_limit) ++bits;
  return bits;
}

// Room for a list that needed `needed`: a quarter more, so that a list that grows a little from
// step to step does not repeat runs.
inline std::size_t grown_room(unsigned long long needed) {
  const std::size_t n = static_cast<std::size_t>(needed);
  return n + n / 4 + 1024;
}

}  // namespace detail

template <class Method, class T, class Policy>
void NarrowPhase<Method, T, Policy>::ensure_streams() {
  if (start_) return;
  LWSCCD_CUDA_CHECK(cudaEventCreateWithFlags(&start_, cudaEventDisableTiming));
  LWSCCD_CUDA_CHECK(cudaEventCreateWithFlags(&joined_, cudaEventDisableTiming));
  int device = 0;
  LWSCCD_CUDA_CHECK(cudaGetDevice(&device));
  LWSCCD_CUDA_CHECK(cudaDeviceGetAttribute(&sms_, cudaDevAttrMultiProcessorCount, device));
  sms_ = std::max(1, sms_);
  control_.resize_discard(detail::kNarrowControlWords);
  for (auto& l : lists_) {
    l.host_counters = PinnedBuffer<unsigned long long>(detail::kNarrowCounters);
    l.counters.resize_discard(detail::kNarrowCounters);
    LWSCCD_CUDA_CHECK(cudaStreamCreateWithFlags(&l.stream, cudaStreamNonBlocking));
    LWSCCD_CUDA_CHECK(cudaEventCreateWithFlags(&l.done, cudaEventDisableTiming));
  }
}

// Blocks of a grid-stride kernel over a list with room for `room` items (0: nothing to launch).
template <class Method, class T, class Policy>
unsigned NarrowPhase<Method, T, Policy>::grid_for(std::size_t room, int block, int per_sm) const {
  const std::size_t wanted = (room + static_cast<std::size_t>(block) - 1) / static_cast<std::size_t>(block);
  return static_cast<unsigned>(std::min<std::size_t>(wanted, static_cast<std::size_t>(sms_) * static_cast<std::size_t>(per_sm)));
}

// `stream` waits for both lists' work so far; the lists then wait for `stream`.
template <class Method, class T, class Policy>
void NarrowPhase<Method, T, Policy>::join_lists(cudaStream_t stream) {
  for (auto& l : lists_) {
    LWSCCD_CUDA_CHECK(cudaEventRecord(l.done, l.stream));
    LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(stream, l.done, 0));
  }
}

template <class Method, class T, class Policy>
template <class P>
void NarrowPhase<Method, T, Policy>::enqueue(const DeviceMeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1, PairList vf,
                                             PairList ee, const CcdParams<T>& params, cudaStream_t stream) {
  ensure_streams();
  stream_ = stream;
  id_limit_ = mesh.num_features();
  const MeshFeatures view = mesh.view();
  const PairList inputs[2] = {vf, ee};
  for (int k = 0; k < 2; ++k) {
    List& l = lists_[k];
    const std::size_t room = inputs[k].count.room;
    // Hits and survivors of a run are at most its input: room for the initial capacity, or for
    // the input where that is less (grown before the launch, so an input that grew since the last
    // run costs no rerun below it); larger only where an earlier run needed more.
    const std::size_t least = std::max<std::size_t>(std::min(initial_capacity_, room), 1);
    l.hit_room = std::max(l.hit_room, least);
    l.work_room = std::max(l.work_room, least);
    if (!kTwoPass) l.work_room = std::max(l.work_room, room);  // one-pass methods test the input itself
    l.hits.resize_discard(l.hit_room);
    if (kTwoPass) l.survivors.resize_discard(l.work_room);
    if (kCertified) {
      l.undecided.resize_discard(l.work_room);
      l.deferred.resize_discard(l.work_room);
      if (Policy::kRefineFilter && params.mode != CcdMode::set) {  // mode set does not run the filter
        l.interval_room = std::max(l.interval_room, std::max<std::size_t>(l.work_room / 100 * Policy::kFilterRoomPercent, 1));
        l.intervals.resize_discard(l.interval_room);
        l.listed.resize_discard((l.work_room + 31) / 32);
        if (second_round(params.mode)) {
          l.expanded.resize_discard(l.interval_room);
          l.deep_room = std::max(l.deep_room, std::max<std::size_t>(l.work_room / 100 * Policy::kDeepRoomPercent, 1));
          l.deep.resize_discard(l.deep_room);
        }
      }
    }
    if (lwsccd::detail::inclusion_search_of<FullTest>::value) l.open.resize_discard(l.work_room);
  }
  // Mode earliest with CertifiedCcd: growing time windows (CertifiedPolicy::kEarliestFirst), each
  // screening and refining the pairs and running the fallback up to the window's end; a window
  // after one that holds a contact is skipped on the device (as the CPU backend stops there).
  // Other modes and methods: one window, the caller's.
  const bool windows = kCertified && params.mode == CcdMode::earliest;
  unsigned long long* control = control_.data();
  for (int round = 0;; ++round) {
    CcdParams<T> limited = params;
    if constexpr (kCertified)
      if (windows) limited.time_limit = Method::earliest_window(round, params.time_limit);
    detail::window_begin_kernel<><<<1, 1, 0, stream>>>(control, lists_[0].counters.data(), lists_[1].counters.data(),
                                                     vf.count, ee.count, round == 0);
    LWSCCD_CUDA_CHECK_LAUNCH();
    LWSCCD_CUDA_CHECK(cudaEventRecord(start_, stream));
    for (auto& l : lists_) LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(l.stream, start_, 0));
    enqueue_first_pass<P, true>(view, x0, x1, vf, limited, lists_[0]);
    enqueue_first_pass<P, false>(view, x0, x1, ee, limited, lists_[1]);
    const unsigned long long* limit = nullptr;
    if (kCertified && params.mode == CcdMode::earliest) {
      // The fallback need not look past the best certified time of either list (as the CPU does).
      join_lists(stream);
      detail::fallback_limit_kernel<><<<1, 1, 0, stream>>>(control, lists_[0].counters.data(), lists_[1].counters.data(),
                                                          detail::time_bits(limited.time_limit));
      LWSCCD_CUDA_CHECK_LAUNCH();
      LWSCCD_CUDA_CHECK(cudaEventRecord(start_, stream));
      for (auto& l : lists_) LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(l.stream, start_, 0));
      limit = control + detail::kFallbackLimitBits;
    }
    enqueue_full_test<P, true>(view, x0, x1, vf, limited, limit, lists_[0]);
    enqueue_full_test<P, false>(view, x0, x1, ee, limited, limit, lists_[1]);
    join_lists(stream);
    if (!windows || !(limited.time_limit < params.time_limit)) break;
  }
  for (auto& l : lists_)
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(l.host_counters.data(), l.counters.data(), detail::kNarrowCounters * sizeof(unsigned long long),
                                      cudaMemcpyDeviceToHost, stream));
  earliest_only_ = params.mode == CcdMode::earliest;
}

// Pass 1 on the list's stream: two-pass methods' cheap first step on every pair (survivors
// appended); CertifiedCcd's refinement of the survivors (hits and undecided queries appended).
template <class Method, class T, class Policy>
template <class P, bool kVertexFace>
void NarrowPhase<Method, T, Policy>::enqueue_first_pass(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                                        const PairList& in, const CcdParams<T>& params, List& l) {
  if constexpr (kTwoPass) {
    const unsigned blocks = grid_for(in.count.room, Policy::kBlock, Policy::kGridBlocksPerSm);
    if (blocks == 0) return;
    detail::screen_kernel<Method, kVertexFace, T, P><<<blocks, Policy::kBlock, 0, l.stream>>>(
        mesh, x0, x1, in, params, control_.data(), l.survivors.data(), l.work_room, l.counters.data());
    LWSCCD_CUDA_CHECK_LAUNCH();
  }
  if constexpr (kCertified) {
    const std::size_t room = std::min(l.work_room, in.count.room);
    // Mode set tries hits on the way down (from level 0), which the filter leaves to the whole
    // search: there the levels-to-kRefineDeferLevel kernel decides more at once.
    if (Policy::kRefineFilter && params.mode != CcdMode::set) {
      detail::filter_kernel<Method, kVertexFace, T, P><<<grid_for(room, Policy::kBlock, Policy::kGridBlocksPerSm), Policy::kBlock, 0, l.stream>>>(
          mesh, x0, x1, l.survivors.data(), l.work_room, params, control_.data(), l.counters.data(), l.intervals.data(),
          l.interval_room, l.undecided.data(), l.deferred.data());
      LWSCCD_CUDA_CHECK_LAUNCH();
      LWSCCD_CUDA_CHECK(cudaMemsetAsync(l.listed.data(), 0, l.listed.size() * sizeof(unsigned), l.stream));
      const unsigned interval_blocks = grid_for(l.interval_room, Policy::kBlock, Policy::kGridBlocksPerSm);
      const bool deeper = second_round(params.mode);
      detail::filter_inside_kernel<Method, kVertexFace, T, P><<<interval_blocks, Policy::kBlock, 0, l.stream>>>(
          mesh, x0, x1, l.survivors.data(), params, control_.data(), l.counters.data(), detail::kIntervals, l.intervals.data(),
          l.interval_room, l.listed.data(), l.deferred.data(), deeper ? l.expanded.data() : nullptr);
      LWSCCD_CUDA_CHECK_LAUNCH();
      if (deeper) {
        detail::filter_expand_kernel<Method, kVertexFace, T, P><<<interval_blocks, Policy::kBlock, 0, l.stream>>>(
            mesh, x0, x1, l.survivors.data(), params, control_.data(), l.counters.data(), l.expanded.data(), l.deep.data(),
            l.deep_room, l.listed.data(), l.deferred.data());
        LWSCCD_CUDA_CHECK_LAUNCH();
        detail::filter_inside_kernel<Method, kVertexFace, T, P>
            <<<grid_for(l.deep_room, Policy::kBlock, Policy::kGridBlocksPerSm), Policy::kBlock, 0, l.stream>>>(
                mesh, x0, x1, l.survivors.data(), params, control_.data(), l.counters.data(), detail::kDeepIntervals,
                l.deep.data(), l.deep_room, l.listed.data(), l.deferred.data(), nullptr);
        LWSCCD_CUDA_CHECK_LAUNCH();
      }
    } else {
      detail::refine_kernel<Method, kVertexFace, Policy::kRefineDeferLevel, Policy::kBlock, Policy::kRefineMinBlocks, T, P>
          <<<grid_for(room, Policy::kBlock, Policy::kGridBlocksPerSm), Policy::kBlock, 0, l.stream>>>(
              mesh, x0, x1, l.survivors.data(), l.work_room, params, control_.data(), l.counters.data(), l.hits.data(),
              l.hit_room, l.undecided.data(), l.deferred.data());
      LWSCCD_CUDA_CHECK_LAUNCH();
    }
    // The deferred pairs: a warp each when they are few (the long searches' latency is the
    // list's), else a thread each; each kernel returns at once where the other one's case holds.
    const auto warp_below = static_cast<std::size_t>(Policy::kRefineWarpBelow);
    detail::refine_deferred_kernel<Method, kVertexFace, T, P><<<grid_for(room, Policy::kBlock, 8), Policy::kBlock, 0, l.stream>>>(
        mesh, x0, x1, l.survivors.data(), l.deferred.data(), params, control_.data(), l.counters.data(), l.hits.data(),
        l.hit_room, l.undecided.data(), warp_below);
    LWSCCD_CUDA_CHECK_LAUNCH();
    if (warp_below > 0) {
      const std::size_t warp_room = std::min(room, warp_below);
      detail::refine_deferred_warp_kernel<Method, kVertexFace, T, P>
          <<<static_cast<unsigned>((warp_room * 32 + Policy::kBlock - 1) / Policy::kBlock), Policy::kBlock, 0, l.stream>>>(
              mesh, x0, x1, l.survivors.data(), l.deferred.data(), params, control_.data(), l.counters.data(), l.hits.data(),
              l.hit_room, l.undecided.data(), warp_below);
      LWSCCD_CUDA_CHECK_LAUNCH();
    }
    // Before mode earliest's fallback limit: a settled hit lowers it as the CPU's certified hits do.
    detail::settle_undecided_kernel<Method, kVertexFace, T, P><<<grid_for(room, Policy::kBlock, 1), Policy::kBlock, 0, l.stream>>>(
        mesh, x0, x1, params, control_.data(), l.counters.data(), l.hits.data(), l.hit_room, l.undecided.data(), l.work_room);
    LWSCCD_CUDA_CHECK_LAUNCH();
  }
}

// The full test on the list's stream, of CertifiedCcd's undecided queries, of the first pass's
// survivors, or (one-pass methods) of the input: hits appended after the list's earlier ones.
template <class Method, class T, class Policy>
template <class P, bool kVertexFace>
void NarrowPhase<Method, T, Policy>::enqueue_full_test(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                                       const PairList& in, const CcdParams<T>& params,
                                                       const unsigned long long* limit, List& l) {
  auto launch = [&](const auto* items, DeviceCount count) {
    count.room = std::min(count.room, in.count.room);
    if (count.room == 0) return;
    if constexpr (lwsccd::detail::inclusion_search_of<FullTest>::value) {
      // A thread per query for a few rounds, then a warp per query still open.
      detail::inclusion_thread_kernel<FullTest, kVertexFace, T, P, Policy::kThreadRounds, Policy::kThreadBoxes>
          <<<grid_for(count.room, Policy::kBlock, Policy::kGridBlocksPerSm), Policy::kBlock, 0, l.stream>>>(
              mesh, x0, x1, items, count, params, control_.data(), limit, l.counters.data(), l.hits.data(), l.hit_room,
              l.open.data(), static_cast<std::size_t>(Policy::kWarpSearchDirect));
      LWSCCD_CUDA_CHECK_LAUNCH();
      constexpr int kWarps = Policy::kSearchWarpsPerBlock;
      detail::inclusion_warp_kernel<FullTest, kVertexFace, T, P, kWarps>
          <<<grid_for(count.room, kWarps, Policy::kGridBlocksPerSm), 32 * kWarps, 0, l.stream>>>(
              mesh, x0, x1, items, l.open.data(), params, control_.data(), limit, l.counters.data(), l.hits.data(), l.hit_room);
    } else {
      detail::ccd_pairs_kernel<FullTest, kVertexFace, T, P>
          <<<grid_for(count.room, Policy::kBlock, Policy::kGridBlocksPerSm), Policy::kBlock, 0, l.stream>>>(
              mesh, x0, x1, items, count, params, control_.data(), limit, l.counters.data(), l.hits.data(), l.hit_room);
    }
    LWSCCD_CUDA_CHECK_LAUNCH();
  };
  const unsigned long long* counters = l.counters.data();
  if constexpr (kCertified) launch(l.undecided.data(), DeviceCount{counters + detail::kUndecided, DeviceCount::Part::whole, l.work_room});
  else if constexpr (kTwoPass) launch(l.survivors.data(), DeviceCount{counters + detail::kSurvivors, DeviceCount::Part::whole, l.work_room});
  else launch(in.pairs, in.count);
}

template <class Method, class T, class Policy>
bool NarrowPhase<Method, T, Policy>::collect() {
  bool complete = true;
  for (auto& l : lists_) {
    const unsigned long long* c = l.host_counters.data();
    const unsigned long long kept = std::max(c[detail::kSurvivors], c[detail::kSurvivorsPeak]);
    unsigned long long hits = c[detail::kHits];
    if (kTwoPass && kept > l.work_room) {
      // The run tested only the survivors that fitted: as many hits again per survivor for the
      // rest, so that their room does not cost a second rerun (cloth-ball's first step did).
      hits = std::max(hits, static_cast<unsigned long long>(static_cast<double>(hits) * static_cast<double>(kept) /
                                                            static_cast<double>(l.work_room)));
      l.work_room = detail::grown_room(kept);
      complete = false;
    }
    if (hits > l.hit_room) {
      l.hit_room = detail::grown_room(hits);
      complete = false;
    }
    // The filter's intervals that did not fit went to the whole search (same answers): more room
    // for the next run, no rerun.
    if (c[detail::kIntervals] > l.interval_room) l.interval_room = detail::grown_room(c[detail::kIntervals]);
    if (c[detail::kDeepIntervals] > l.deep_room) l.deep_room = detail::grown_room(c[detail::kDeepIntervals]);
  }
  if (!complete) {
    ++reruns_;
    return false;
  }
  gave_up_ = 0;
  earliest_ = T(1);
  for (auto& l : lists_) {
    const unsigned long long* c = l.host_counters.data();
    const auto pairs = static_cast<std::size_t>(c[detail::kPairs]);
    l.count = static_cast<std::size_t>(c[detail::kHits]);
    l.num_full = static_cast<std::size_t>(kCertified ? c[detail::kUndecided] - c[detail::kSettled] : kTwoPass ? c[detail::kSurvivors] : pairs);
    l.warp_searches = static_cast<std::size_t>(c[detail::kOpen]);
    l.whole_searches = static_cast<std::size_t>(c[detail::kDeferred]);
    l.counts = {};
    l.counts.pairs = pairs;
    l.counts.screened = kCertified ? static_cast<std::size_t>(c[detail::kSurvivors]) : 0;
    l.counts.certified_hits = static_cast<std::size_t>(c[detail::kCertifiedHits]);
    // As the CPU backend counts (NarrowPhaseCounts): a method without the certified path answers
    // every pair by its own test, its quick rejections included, so every pair is a fallback.
    l.counts.fallbacks = kCertified ? l.num_full : pairs;
    l.counts.certified_misses = kCertified ? pairs - l.counts.certified_hits - l.num_full : 0;
    gave_up_ += static_cast<std::size_t>(c[detail::kGaveUp]);
    const T list_min = static_cast<T>(detail::time_of_bits(c[detail::kEarliestBits]));
    earliest_ = list_min < earliest_ ? list_min : earliest_;
  }
  // The hits in (first, second) order, on the device: they were appended in any order. The two
  // lists sort at once, each on its stream; the run's stream waits for both.
  if (!earliest_only_) {
    for (auto& l : lists_) l.sorter.sort(l.hits, l.count, id_limit_, l.stream);
    join_lists(stream_);
  }
  return true;
}

template <class T>
void HitSorter<T>::sort(DeviceBuffer<FeatureHit<T>>& hits, std::size_t n, std::size_t id_limit, cudaStream_t stream) {
  if (n < 2) return;
  sorted_.resize_discard(std::max(n, hits.size()));
  // Only the bits the ids use are sorted: horse-gallop's 50 K features take 32 of the 64, which
  // halves the radix passes (a sort of a few dozen hits took ~24 us per list on an H100).
  const int id_bits = detail::id_bits_below(id_limit);
  if (n <= static_cast<std::size_t>(detail::kSmallHitSort)) {
    detail::small_hit_sort_kernel<T, detail::kSmallHitSort>
        <<<1, detail::kSmallHitSort, 0, stream>>>(hits.data(), static_cast<int>(n), id_bits, sorted_.data());
    LWSCCD_CUDA_CHECK_LAUNCH();
    std::swap(hits, sorted_);
    return;
  }
  keys_.resize_discard(n);
  sorted_keys_.resize_discard(n);
  detail::hit_keys_kernel<<<static_cast<unsigned>((n + 255) / 256), 256, 0, stream>>>(hits.data(), n, id_bits, keys_.data());
  LWSCCD_CUDA_CHECK_LAUNCH();
  std::size_t bytes = 0;
  LWSCCD_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, bytes, keys_.data(), sorted_keys_.data(), hits.data(),
                                                    sorted_.data(), static_cast<std::int64_t>(n), 0, 2 * id_bits, stream));
  scratch_.resize_discard(std::max({bytes, scratch_.size(), std::size_t(1)}));
  LWSCCD_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(scratch_.data(), bytes, keys_.data(), sorted_keys_.data(), hits.data(),
                                                    sorted_.data(), static_cast<std::int64_t>(n), 0, 2 * id_bits, stream));
  std::swap(hits, sorted_);  // (only the handles: the sort wrote `sorted_`, which is now `hits`)
}

template <class Method, class T, class Policy>
NarrowPhaseResult<T> NarrowPhase<Method, T, Policy>::download(cudaStream_t stream) const {
  NarrowPhaseResult<T> r;
  if (joined_ && stream != stream_) {  // the sort was enqueued on the run's stream
    LWSCCD_CUDA_CHECK(cudaEventRecord(joined_, stream_));
    LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(stream, joined_, 0));
  }
  auto fetch = [&](const DeviceBuffer<FeatureHit<T>>& buffer, std::size_t count, std::vector<FeatureHit<T>>& dst) {
    dst.resize(count);
    if (count)
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(dst.data(), buffer.data(), count * sizeof(FeatureHit<T>), cudaMemcpyDeviceToHost, stream));
  };
  fetch(lists_[0].hits, earliest_only_ ? 0 : lists_[0].count, r.vf);
  fetch(lists_[1].hits, earliest_only_ ? 0 : lists_[1].count, r.ee);
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
  r.earliest_toi = earliest_;
  r.gave_up = gave_up_;
  r.vf_counts = lists_[0].counts;
  r.ee_counts = lists_[1].counts;
  return r;
}

}  // namespace lwsccd::gpu
