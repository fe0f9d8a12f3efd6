// lwsccd — what the narrow phase's kernels share: the items and queries of a list, the words of its
// counters and of a run's control block, hits appended, the windows of a run, and the full test
// of every item (one-pass methods).
// Part of narrow_phase_kernels.cuh: include <lwsccd/narrow_phase/narrow_phase.cuh>, not this file.
#pragma once

#include <cooperative_groups.h>
#include <cooperative_groups/reduce.h>
#include <cooperative_groups/scan.h>
#include <cstring>

#include "lwsccd/narrow_phase/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.cuh"

namespace lwsccd::gpu::detail {

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

// The pair's float query for the single-precision passes (FP32 first), from SingleVertex records.
template <bool kVertexFace>
__device__ auto gather_single_query(const MeshFeatures& mesh, const SingleVertex* x, const std::pair<index_t, index_t>& p) {
  if constexpr (kVertexFace) return gather_single_vertex_face(mesh, x, p.first, p.second);
  else return gather_single_edge_edge(mesh, x, p.first, p.second);
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
  kSingleMisses,    // CertifiedCcd: pairs single precision decided at once (the screen, a filter without intervals)
  kSingleIntervals, // the single-precision filter's intervals listed for the inside test (more than the room: on one thread)
  kSingleListed,    // pairs whose intervals it listed
  kSingleFailed,    // of those, pairs with an interval not certainly outside in float (to the double filter)
  kDoubleKept,      // pairs the double filter takes (kept by the screen, not decided in single precision)
  kSingleExpanded,  // the single-precision filter's second round: intervals whose test was unknown
  kSingleDeepIntervals,  // its intervals listed for the inside test (more than the room: the pair to double)
  kSingleWhole,     // pairs it sends straight to the whole search (listed from the top of the double filter's list)
  kSingleSearchMisses,  // the search in single precision: certain misses (pairs the single passes left)
  kSingleDescents,  // its contacts settled by a double tail (certain hits)
  kFloatPairLeaves, // of those, the ones whose leaf pairs of floats proved (no FP64)
  kHandedToWarps,   // deferred searches in double a thread handed on (to a warp each, or a thread each past the limit)
  kHandedTaken,     // of those, the ones a warp took (refine_handed_kernel's tickets)
  kKeptSlots,       // FP32 first: slots of the double filter's list asked for (more than the room: the run is repeated with more)
  kKeptSlotsPeak,   // the most asked for by an earlier window of mode earliest
  kSeparated,       // FP32 first: pairs the screen passed and the filter's separating directions decided there
  kHitSortOverflow, // the hits' sort ahead by buckets: buckets past detail::kBucketRankMax hits (then sorted by radix)
  kEarlyCandidates, // FP32 first: pairs coplanar over the whole step in float and not outside there, whatever their route (plans the next run's early searches)
  kEarlySearches,   // of those, pairs listed for the early searches (past the room: the double filter's)
  kEarlyTaken,      // of those, the ones a warp took (refine_early_kernel's tickets)
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

// Every vertex's SingleVertex record (the positions of both times rounded to float).
template <class P>
__global__ void single_vertices_kernel(const Vec3<P>* x0, const Vec3<P>* x1, std::size_t n, SingleVertex* out) {
  LWSCCD_GRID_STRIDE(i, n) out[i] = single_vertex(x0[i], x1[i]);
}

// Float positions widened to P into x0, x1, and (out not null) each vertex's SingleVertex record
// of the widened values, in one pass.
template <class P>
__global__ void widened_vertices_kernel(const Vec3<float>* f0, const Vec3<float>* f1, std::size_t n, Vec3<P>* x0, Vec3<P>* x1,
                                        SingleVertex* out) {
  LWSCCD_GRID_STRIDE(i, n) {
    const Vec3<P> a = f0[i].template cast<P>(), b = f1[i].template cast<P>();
    x0[i] = a;
    x1[i] = b;
    if (out) out[i] = single_vertex(a, b);
  }
}

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
    const unsigned long long slots_peak = first ? 0ull : (c[kKeptSlots] > c[kKeptSlotsPeak] ? c[kKeptSlots] : c[kKeptSlotsPeak]);
    for (int w = 0; w < kNarrowCounters; ++w) c[w] = 0;
    c[kSurvivorsPeak] = peak;
    c[kKeptSlotsPeak] = slots_peak;
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
  lwsccd::detail::start_after_previous_grids();
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

}  // namespace lwsccd::gpu::detail
