// lwsccd — CertifiedCcd on the GPU: the screen (pass 1), the refinement in parts (searches deferred
// past a level, the filter and its second round, whole searches a thread or a warp per pair) and the
// undecided queries settled.
// Part of narrow_phase_kernels.cuh: include <lwsccd/narrow_phase/narrow_phase.cuh>, not this file.
#pragma once

#include <cooperative_groups.h>
#include <cooperative_groups/reduce.h>
#include <cooperative_groups/scan.h>
#include <cstring>

#include "lwsccd/core/launch.cuh"
#include "lwsccd/narrow_phase/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.cuh"
#include "lwsccd/narrow_phase/detail/narrow_lists.cuh"

namespace lwsccd::gpu::detail {

// The first step of a two-pass method on one query: true when it certainly rejects the pair
// (CertifiedCcd: its screen; other methods: their quick_reject).
template <class Method, class Q, class T>
__device__ bool first_step_rejects(const Q& q, const CcdParams<T>& params) {
  if constexpr (lwsccd::detail::certified_of<Method>::value) return Method::screen(q, params);
  else return Method::quick_reject(q, params);
}

// A pair the first pass keeps, appended to `kept` where it has room (always counted, so that the
// host sees the room it needs).
__device__ inline void keep_survivor(std::pair<index_t, index_t> p, std::pair<index_t, index_t>* kept, std::size_t room,
                                     unsigned long long* counters) {
  const unsigned long long at = append_index(counters + kSurvivors);
  if (at < room) {  // (std::pair's assignment is host-only before C++20)
    kept[at].first = p.first;
    kept[at].second = p.second;
  }
}

// How the screen's tail ended for a pair.
enum class TailVerdict : unsigned char { missed, separated, kept };

// The screen's tail for one pair the tests in space left, in single precision: the cubic's signs,
// then the filter's separating directions where the policy asks for them (off by default; so
// that the pairs they decide are never kept: the filter's threads would diverge on them; counted
// as screened and decided in float); what is
// left is kept (appended here). The caller counts the other two.
template <class Method, bool kVertexFace, class T>
__device__ TailVerdict screen_single_tail(const MeshFeatures& mesh, const SingleVertex* single, std::pair<index_t, index_t> p,
                                          const CcdParams<T>& params, std::pair<index_t, index_t>* kept, std::size_t room,
                                          unsigned long long* counters) {
  using Policy = typename Method::policy_type;
  const auto q = gather_single_query<kVertexFace>(mesh, single, p);
  if (lwsccd::detail::single_screen_by_cubic<Policy>(lwsccd::detail::relative_single(q), params)) return TailVerdict::missed;
  if (lwsccd::detail::CertifiedFilter<Policy>::separates_single(q, params)) return TailVerdict::separated;
  keep_survivor(p, kept, room, counters);
  return TailVerdict::kept;
}

// Pass 1 of a certified method, FP32 first: every pair through the single-precision screen.
// Its tests in space (swept boxes, the differences of the features' points) end most pairs of a
// real step, but nearly every warp holds a pair they leave (cloth-ball: 17% of the pairs), and the
// cubic and the separating directions would then run with a lane or two active. So a warp gathers
// the pairs they leave in shared memory and screens them 32 at a time, full warps, as it goes and
// once more at the end: the same verdicts and counts, in another order. A warp counts its misses
// and separated pairs by ballots and adds them once at its end (an atomic per pair, even
// warp-aggregated, took ~30 instructions a round and an eighth of the kernel's stalls on
// cloth-ball). kBlock: the launch's threads per block.
template <class Method, bool kVertexFace, int kBlock, class T>
__device__ void screen_single_first(const MeshFeatures& mesh, const SingleVertex* single, const std::pair<index_t, index_t>* pairs,
                                    std::size_t n, const CcdParams<T>& params, std::pair<index_t, index_t>* kept,
                                    std::size_t room, unsigned long long* counters) {
  using Policy = typename Method::policy_type;
  static_assert(kBlock % 32 == 0, "lwsccd: the screen's blocks are whole warps");
  __shared__ index_t gathered_first[kBlock / 32][64], gathered_second[kBlock / 32][64];
  const int lane = static_cast<int>(threadIdx.x % 32), warp = static_cast<int>(threadIdx.x / 32);
  index_t* firsts = gathered_first[warp];
  index_t* seconds = gathered_second[warp];
  const std::size_t warps = static_cast<std::size_t>(gridDim.x) * (kBlock / 32);
  unsigned long long misses = 0, separated = 0;  // the warp's (the same on every lane)
  auto count_tail = [&](TailVerdict v) {
    misses += static_cast<unsigned>(__popc(__ballot_sync(0xffffffffu, v == TailVerdict::missed)));
    separated += static_cast<unsigned>(__popc(__ballot_sync(0xffffffffu, v == TailVerdict::separated)));
  };
  int count = 0;  // pairs gathered, below 32 between rounds
  for (std::size_t base = (static_cast<std::size_t>(blockIdx.x) * (kBlock / 32) + warp) * 32; base < n; base += warps * 32) {
    const std::size_t i = base + static_cast<std::size_t>(lane);
    bool left = false;
    index_t first = 0, second = 0;
    if (i < n) {
      const std::pair<index_t, index_t> p = pairs[i];
      first = p.first, second = p.second;
      const auto q = gather_single_query<kVertexFace>(mesh, single, p);
      left = !lwsccd::detail::single_screen_in_space<Policy>(lwsccd::detail::relative_single(q), params);
    }
    const unsigned mask = __ballot_sync(0xffffffffu, left);
    const std::size_t in_range = n - base < 32 ? n - base : 32;  // (base < n: the warp's pairs this round)
    misses += static_cast<unsigned>(in_range) - static_cast<unsigned>(__popc(mask));
    if (left) {
      const int at = count + __popc(mask & ((1u << lane) - 1u));
      firsts[at] = first;
      seconds[at] = second;
    }
    count += __popc(mask);
    __syncwarp();
    if (count >= 32) {
      count -= 32;
      const std::pair<index_t, index_t> g{firsts[count + lane], seconds[count + lane]};
      __syncwarp();  // read before the next round writes there
      count_tail(screen_single_tail<Method, kVertexFace>(mesh, single, g, params, kept, room, counters));
    }
  }
  TailVerdict last = TailVerdict::kept;  // (lanes past the gathered pairs: counted as neither)
  if (lane < count) last = screen_single_tail<Method, kVertexFace>(mesh, single, {firsts[lane], seconds[lane]}, params, kept, room, counters);
  count_tail(last);
  if (lane == 0) {
    if (misses) atomicAdd(counters + kSingleMisses, misses);
    if (separated) atomicAdd(counters + kSeparated, separated);
  }
}

// Pass 1 of two-pass methods: the cheap first step on every pair of a list whose length is read
// on the device; survivors appended to `kept` (if it has room; always counted). A certified
// method FP32 first: screen_single_first.
template <class Method, bool kVertexFace, int kBlock, class T, class P>
__global__ void screen_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1, const SingleVertex* single, PairList in,
                              CcdParams<T> params, const unsigned long long* control, std::pair<index_t, index_t>* kept,
                              std::size_t room, unsigned long long* counters) {
  lwsccd::detail::start_after_previous_grids();  // (launched by NarrowPhase::chain)
  if (control[kSkip]) return;
  const std::size_t n = in.count.get();
  if constexpr (lwsccd::detail::single_first_of<Method>::value) {
    screen_single_first<Method, kVertexFace, kBlock>(mesh, single, in.pairs, n, params, kept, room, counters);
  } else {
    LWSCCD_GRID_STRIDE(i, n) {
      const std::pair<index_t, index_t> p = in.pairs[i];
      if (!first_step_rejects<Method>(gather_query<kVertexFace, T>(mesh, x0, x1, p), params)) keep_survivor(p, kept, room, counters);
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

// FP32 first's search in single precision on a pair the single passes left
// (Method::refine_single_first): where it decides the pair, its answer is settled and counted
// (a miss in single precision, or a contact with a double tail) and true returned; `store` false
// only computes (a warp's other lanes). kLanesAlike: every lane of the warp runs it on the same pair.
template <class Method, bool kLanesAlike = false, class Q, class T>
__device__ bool settled_in_single(const Q& q, const CcdParams<T>& params, std::pair<index_t, index_t> p, unsigned long long* counters,
                                  FeatureHit<T>* hits, std::size_t hit_room, FeatureHit<T>* undecided, bool store = true) {
  bool done = false, in_float_pairs = false;
  const CertifiedAnswer<T> a = Method::template refine_single_first<false, kLanesAlike>(q, params, done, &in_float_pairs);
  if (!done || !store) return done;
  if (a.certainty == Certainty::miss) atomicAdd(counters + kSingleSearchMisses, 1ull);
  if (a.certainty == Certainty::hit) atomicAdd(counters + kSingleDescents, 1ull);
  if (in_float_pairs) atomicAdd(counters + kFloatPairLeaves, 1ull);
  settle_refined(a, p.first, p.second, counters, hits, hit_room, undecided);
  return true;
}

// CertifiedCcd's refinement of the screened pairs, first part: searches that would halve
// intervals at kDeferLevel or deeper stop (with a stack only that deep) and are listed in
// `deferred` (they are the contacts, resolved at the time tolerance, and would hold up whole warps
// of quick misses); the others settle their answer.
template <class Method, bool kVertexFace, int kDeferLevel, int kBlock, int kMinBlocks, class T, class P>
__global__ void __launch_bounds__(kBlock, kMinBlocks)
    refine_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1, const SingleVertex* single,
                  const std::pair<index_t, index_t>* kept, std::size_t room, CcdParams<T> params,
                  const unsigned long long* control, unsigned long long* counters, FeatureHit<T>* hits,
                  std::size_t hit_room, FeatureHit<T>* undecided, unsigned* deferred) {
  lwsccd::detail::start_after_previous_grids();  // (launched by NarrowPhase::chain)
  if (control[kSkip]) return;
  const std::size_t n = counters[kSurvivors] < room ? static_cast<std::size_t>(counters[kSurvivors]) : room;
  LWSCCD_GRID_STRIDE(i, n) {
    const std::pair<index_t, index_t> p = kept[i];
    if constexpr (lwsccd::detail::single_first_of<Method>::value) {
      if (Method::filter_single(gather_single_query<kVertexFace>(mesh, single, p), params)) {  // counted, as the CPU batch
        append_index(counters + kSingleMisses);
        continue;
      }
    }
    const auto q = gather_query<kVertexFace, T>(mesh, x0, x1, p);
    if (settled_in_single<Method>(q, params, p, counters, hits, hit_room, undecided)) continue;  // (as everywhere)
    if (Method::screen_after_single(q, params)) continue;
    bool later = false;
    const CertifiedAnswer<T> a = Method::template refine_until<kDeferLevel, false>(q, params, &later);
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
// Appends a pair at the list's next index (the caller made sure it fits).
__device__ inline void append_pair(unsigned long long* counter, std::pair<index_t, index_t>* list, const std::pair<index_t, index_t>& p) {
  const unsigned long long at = append_index(counter);
  list[at].first = p.first;  // (std::pair's assignment is host-only before C++20)
  list[at].second = p.second;
}
// FP32 first: a slot of the double filter's list (`room` slots, shared by both its ends). Every
// slot asked for is counted (kKeptSlots); one past the room is not taken, and the host runs the
// narrow phase again with more (NarrowPhase::collect). The list holds only what single precision
// leaves (~2-5% of the screened pairs), so it is sized from that count rather than the screen's.
__device__ inline bool take_kept_slot(unsigned long long* counters, std::size_t room) {
  return append_index(counters + kKeptSlots) < room;
}
// A pair single precision leaves, appended to the double filter's list.
__device__ inline void keep_for_double(unsigned long long* counters, std::pair<index_t, index_t>* double_kept, std::size_t room,
                                       const std::pair<index_t, index_t>& p) {
  if (take_kept_slot(counters, room)) append_pair(counters + kDoubleKept, double_kept, p);
}

// FP32 first, before the double filter: the single-precision filter's two rounds as the double
// filter's (CertifiedFilter::intervals_single, inside_single, expand_single), a thread per pair,
// then per interval. A pair every one of whose intervals is outside in float is a miss (counted:
// kSingleMisses at once, else kSingleListed less kSingleFailed); any other goes once (its bit in
// `failed`, cleared before the run) to the double filter: appended to `double_kept`. With `whole`
// (an interval inside in float: a contact, which the double filter would only pass on) it goes
// straight to the whole search instead: listed from the top of `double_kept` (both ends take
// their slots from the list's `room`, so they never meet) and deferred; refine_deferred_kernel
// runs the double screen on it first, as the double filter would have.
__device__ inline void send_on_from_single(const std::pair<index_t, index_t>& p, unsigned long long* counters,
                                           std::pair<index_t, index_t>* double_kept, std::size_t room, unsigned* deferred,
                                           bool whole) {
  if (!take_kept_slot(counters, room)) return;  // (the run is repeated with more room)
  if (!whole) {
    append_pair(counters + kDoubleKept, double_kept, p);
    return;
  }
  const auto at = static_cast<unsigned>(room - 1 - append_index(counters + kSingleWhole));
  double_kept[at].first = p.first;  // (std::pair's assignment is host-only before C++20)
  double_kept[at].second = p.second;
  deferred[append_index(counters + kDeferred)] = at;
}
// send_on_from_single for a block's pairs at once, called by every thread of the block (it holds
// barriers): the block's sends take their slots with one atomic on each counter instead of one per
// converged group of each warp (up to three dependent ones a group: slot, whole, deferred, all on
// the same counters for every block of the grid). The same pairs listed at the same ends and the
// same counts; only their order within a list differs. `tally` is the block's shared scratch.
struct BlockSendTally {
  unsigned kept[32], whole[32];  // a warp's sends of each kind; then its first places among the block's
  unsigned long long double_at, whole_at, deferred_at;  // the block's first places in the lists
  unsigned kept_total;  // the block's sends to the double filter (their places come first)
  unsigned fitting;     // the block's sends that took a slot within the room
};
template <int kBlock>
__device__ void send_on_from_single_in_block(bool send, bool whole, const std::pair<index_t, index_t>& p, unsigned long long* counters,
                                             std::pair<index_t, index_t>* double_kept, std::size_t room, unsigned* deferred,
                                             BlockSendTally& tally) {
  static_assert(kBlock % 32 == 0 && kBlock <= 1024, "lwsccd: a block of whole warps");
  constexpr int kWarps = kBlock / 32;
  const unsigned lane = threadIdx.x % 32u, warp = threadIdx.x / 32u;
  const unsigned kept_mask = __ballot_sync(0xffffffffu, send && !whole), whole_mask = __ballot_sync(0xffffffffu, send && whole);
  if (lane == 0) {
    tally.kept[warp] = static_cast<unsigned>(__popc(kept_mask));
    tally.whole[warp] = static_cast<unsigned>(__popc(whole_mask));
  }
  __syncthreads();
  if (threadIdx.x == 0) {
    // The warps' first places among the block's sends: every kept send, then every whole one.
    unsigned kept_total = 0, whole_total = 0;
    for (int w = 0; w < kWarps; ++w) {
      const unsigned k = tally.kept[w], h = tally.whole[w];
      tally.kept[w] = kept_total;
      tally.whole[w] = whole_total;
      kept_total += k;
      whole_total += h;
    }
    const unsigned total = kept_total + whole_total;
    unsigned fitting = 0;
    if (total > 0) {
      const unsigned long long slot = atomicAdd(counters + kKeptSlots, static_cast<unsigned long long>(total));
      fitting = slot >= room ? 0u : (room - slot < total ? static_cast<unsigned>(room - slot) : total);
    }
    // (Sends past the room take no place: the run is repeated with more.)
    const unsigned kept_fitting = kept_total < fitting ? kept_total : fitting, whole_fitting = fitting - kept_fitting;
    if (kept_fitting > 0) tally.double_at = atomicAdd(counters + kDoubleKept, static_cast<unsigned long long>(kept_fitting));
    if (whole_fitting > 0) {
      tally.whole_at = atomicAdd(counters + kSingleWhole, static_cast<unsigned long long>(whole_fitting));
      tally.deferred_at = atomicAdd(counters + kDeferred, static_cast<unsigned long long>(whole_fitting));
    }
    tally.kept_total = kept_total;
    tally.fitting = fitting;
  }
  __syncthreads();
  if (send) {
    const unsigned below = (1u << lane) - 1u;
    if (!whole) {
      const unsigned k = tally.kept[warp] + static_cast<unsigned>(__popc(kept_mask & below));
      if (k < tally.fitting) {
        const unsigned long long at = tally.double_at + k;
        double_kept[at].first = p.first;  // (std::pair's assignment is host-only before C++20)
        double_kept[at].second = p.second;
      }
    } else {
      const unsigned k = tally.whole[warp] + static_cast<unsigned>(__popc(whole_mask & below));
      if (tally.kept_total + k < tally.fitting) {
        const auto at = static_cast<unsigned>(room - 1 - (tally.whole_at + k));
        double_kept[at].first = p.first;
        double_kept[at].second = p.second;
        deferred[tally.deferred_at + k] = at;
      }
    }
  }
}
__device__ inline void fail_single(unsigned i, unsigned* failed, unsigned long long* counters,
                                   const std::pair<index_t, index_t>* kept, std::pair<index_t, index_t>* double_kept,
                                   std::size_t room, unsigned* deferred = nullptr, bool whole = false) {
  const unsigned bit = 1u << (i & 31u);
  if (atomicOr(failed + (i >> 5), bit) & bit) return;
  append_index(counters + kSingleFailed);
  send_on_from_single(kept[i], counters, double_kept, room, deferred, whole);
}
// Whether entry `at` of the double filter's list came straight from the single-precision filter.
__device__ inline bool sent_whole(unsigned at, std::size_t room, const unsigned long long* counters) {
  const unsigned long long whole = counters[kSingleWhole];
  return whole > 0 && at >= room - whole;
}

// A pair single precision leaves whose search is expected to be long, listed for
// refine_early_kernel (past `early_room`: appended to the double filter's list, as any other). It
// takes a slot of the double filter's list all the same, so that the lists sized by those slots
// (the undecided) have room for what its search appends.
__device__ inline void send_early(unsigned long long* counters, std::pair<index_t, index_t>* early, std::size_t early_room,
                                  std::pair<index_t, index_t>* double_kept, std::size_t kept_room,
                                  const std::pair<index_t, index_t>& p) {
  if (!take_kept_slot(counters, kept_room)) return;  // (the run is repeated with more room)
  const unsigned long long k = append_index(counters + kEarlySearches);
  if (k < early_room) {
    early[k].first = p.first;  // (std::pair's assignment is host-only before C++20)
    early[k].second = p.second;
  } else {
    append_pair(counters + kDoubleKept, double_kept, p);
  }
}

// First kernel: a thread per screened pair lists its first round's intervals in `intervals` for
// single_inside_kernel. A pair whose intervals do not fit is decided on its thread
// (decides_single: the same answer), and the room grows for the next run.
// With `early_room` > 0, a pair whose cubic is within float's bound over the whole step (its one
// interval is the step: motion that stays coplanar in float) takes that interval's inside test
// here; not certainly outside, it goes to the early searches (send_early): the double filter could
// only defer it, and its search is the list's longest (cloth-funnel: seams sliding in the cloth's
// plane), so it starts now, beside the rest of the list's chain.
template <class Method, bool kVertexFace, class T>
__global__ void single_filter_kernel(MeshFeatures mesh, const SingleVertex* single,
                                     const std::pair<index_t, index_t>* kept, std::size_t room, CcdParams<T> params,
                                     const unsigned long long* control, unsigned long long* counters,
                                     unsigned long long* intervals, std::size_t interval_room,
                                     std::pair<index_t, index_t>* double_kept, std::size_t kept_room,
                                     std::pair<index_t, index_t>* early, std::size_t early_room) {
  using Filter = lwsccd::detail::CertifiedFilter<typename Method::policy_type>;
  lwsccd::detail::start_after_previous_grids();  // (launched by NarrowPhase::chain)
  if (control[kSkip]) return;
  const CcdParams<float> single_params = lwsccd::detail::single_params(params);
  const std::size_t n = counters[kSurvivors] < room ? static_cast<std::size_t>(counters[kSurvivors]) : room;
  LWSCCD_GRID_STRIDE(i, n) {
    const auto q = gather_single_query<kVertexFace>(mesh, single, kept[i]);
    std::uint32_t found = 0;
    const int count = Filter::intervals_single(q, single_params, found, true);  // (the screen tried the separating directions)
    if (count == 1 && found == (1u << Filter::kWholeStepNode)) {
      // (decides_single's verdict: the step outside in float, else the double path.)
      const bool outside = Filter::inside_single(q, Filter::kWholeStepNode) == lwsccd::detail::InsideVerdict::outside;
      if (!outside) append_index(counters + kEarlyCandidates);  // (whatever the route: the next run's plan)
      if (early_room > 0) {
        if (outside) append_index(counters + kSingleMisses);
        else send_early(counters, early, early_room, double_kept, kept_room, kept[i]);
        continue;
      }
    }
    bool decided = count == 0;
    if (count > 0) {
      bool fits = true;
      const unsigned long long base = append_run(counters + kSingleIntervals, static_cast<unsigned>(count), interval_room, fits);
      const bool expandable = Filter::expandable(count);
      for (int k = 0; k < count; ++k, found &= found - 1u)
        if (base + k < interval_room)
          intervals[base + k] = fits ? filter_item(i, expandable, static_cast<unsigned>(__ffs(found) - 1)) : kNoInterval;
      if (fits) {
        append_index(counters + kSingleListed);
        continue;
      }
      decided = Filter::decides_single(q, params);
    }
    if (decided) append_index(counters + kSingleMisses);
    else keep_for_double(counters, double_kept, kept_room, kept[i]);
  }
}

// The single-precision filter on one thread a pair (NarrowPhasePolicy::kSingleFilterOneThreadPerSm):
// CertifiedFilter::route_single, both rounds' inside tests on the pair's float query as the thread
// holds it. A miss is counted (kSingleMisses); any other pair goes to the double filter, or with
// kInsideWhole, one inside in float straight to the whole search. A pair coplanar over the whole
// step in float and not outside there goes to the early searches where they have room, as in
// single_filter_kernel.
template <class Method, bool kVertexFace, class T, bool kInsideWhole>
__global__ void single_route_kernel(MeshFeatures mesh, const SingleVertex* single, const std::pair<index_t, index_t>* kept,
                                    std::size_t room, CcdParams<T> params, const unsigned long long* control,
                                    unsigned long long* counters, std::pair<index_t, index_t>* double_kept, std::size_t kept_room,
                                    unsigned* deferred, std::pair<index_t, index_t>* early, std::size_t early_room) {
  using Filter = lwsccd::detail::CertifiedFilter<typename Method::policy_type>;
  using lwsccd::detail::SingleRoute;
  lwsccd::detail::start_after_previous_grids();  // (launched by NarrowPhase::chain)
  if (control[kSkip]) return;
  const CcdParams<float> single_params = lwsccd::detail::single_params(params);
  const std::size_t n = counters[kSurvivors] < room ? static_cast<std::size_t>(counters[kSurvivors]) : room;
  LWSCCD_GRID_STRIDE(i, n) {
    bool whole_step = false;
    // (The screen tried the separating directions.)
    const SingleRoute route =
        Filter::route_single(gather_single_query<kVertexFace>(mesh, single, kept[i]), single_params, true, kInsideWhole, &whole_step);
    if (whole_step) {
      append_index(counters + kEarlyCandidates);  // (whatever the route: the next run's plan)
      if (early_room > 0) {
        send_early(counters, early, early_room, double_kept, kept_room, kept[i]);
        continue;
      }
    }
    if (route == SingleRoute::miss) append_index(counters + kSingleMisses);
    else send_on_from_single(kept[i], counters, double_kept, kept_room, deferred, route == SingleRoute::whole_search);
  }
}

// The single-precision filter's two rounds in one kernel, a block's pairs and their intervals in
// shared memory (NarrowPhasePolicy::kSingleFilterInBlocks): a thread per pair gathers its float
// query once, lists its first round's intervals and keeps the query and the cubic's piece on the
// step in shared memory; then the block's threads take the intervals one each (the inside tests),
// the unknown ones one each (the second round's pieces, from the kept piece), and those pieces one
// each, and last a thread per pair sends it on. The same tests on the same values as route_single
// (the CPU's decides_single), each phase with its lanes full, one gather and one launch instead
// of four. A pair goes to the whole search where an interval of it is inside in float (with
// kInsideWhole), else to the double filter; a pair whose pieces overflow the block's room is
// routed on its thread (route_single). The early searches as in single_filter_kernel.
template <int kBlock, int kDeepPerPair>
struct SingleBlockRoom {
  static constexpr int kFirst = kBlock * 8;  // first-round intervals: at most 8 a pair (levels <= 3, heap bits < 16)
  static constexpr int kDeep = kBlock * kDeepPerPair;  // second-round pieces (a pair past it is routed on its thread)
  static constexpr int kDeepArray = kDeep > 0 ? kDeep : 1;
};
// A block's task: its pair's number in the block (high byte) and the interval's heap number.
constexpr std::uint16_t kNoBlockItem = 0xffffu;
enum SingleBlockFlag : unsigned {
  kBlockToDouble = 1u,  // an interval not certainly outside: to the double filter
  kBlockInside = 2u,    // an interval inside in float: to the whole search (kInsideWhole)
  kBlockOnThread = 4u,  // its pieces did not fit: routed on its thread
  kBlockListed = 8u,    // its intervals were listed (a miss unless flagged otherwise)
  kBlockDeeper = 16u,   // an unknown interval of level kLevel takes the second round
};
template <class Method, bool kVertexFace, int kBlock, int kMinBlocks, int kDeepPerPair, class T, bool kInsideWhole>
__global__ void __launch_bounds__(kBlock, kMinBlocks) single_block_filter_kernel(
    MeshFeatures mesh, const SingleVertex* single, const std::pair<index_t, index_t>* kept, std::size_t room, CcdParams<T> params,
    const unsigned long long* control, unsigned long long* counters, std::pair<index_t, index_t>* double_kept, std::size_t kept_room,
    unsigned* deferred, std::pair<index_t, index_t>* early, std::size_t early_room) {
  using Filter = lwsccd::detail::CertifiedFilter<typename Method::policy_type>;
  using lwsccd::detail::InsideVerdict;
  using lwsccd::detail::SingleRoute;
  using Query = decltype(lwsccd::detail::relative_single(gather_single_query<kVertexFace>(mesh, single, kept[0])));
  using Piece = lwsccd::detail::BernsteinPiece<float>;
  using Room = SingleBlockRoom<kBlock, kDeepPerPair>;
  static_assert(kBlock < 256, "lwsccd: single_block_filter_kernel numbers a block's pairs in a byte (255: no pair)");
  // (Raw storage: __shared__ variables take no constructors.)
  __shared__ alignas(16) unsigned char query_words[kBlock * sizeof(Query)];
  __shared__ alignas(16) unsigned char piece_words[kBlock * sizeof(Piece)];
  __shared__ unsigned flags[kBlock];
  __shared__ std::uint16_t first[Room::kFirst], deep[Room::kDeepArray], expand[Room::kFirst];
  __shared__ unsigned first_count, expand_count, deep_count, misses;
  __shared__ BlockSendTally tally;
  Query* queries = reinterpret_cast<Query*>(query_words);
  Piece* pieces = reinterpret_cast<Piece*>(piece_words);
  lwsccd::detail::start_after_previous_grids();  // (launched by NarrowPhase::chain)
  if (control[kSkip]) return;
  const CcdParams<float> single_params = lwsccd::detail::single_params(params);
  const std::size_t n = counters[kSurvivors] < room ? static_cast<std::size_t>(counters[kSurvivors]) : room;
  const unsigned t = threadIdx.x;
  const auto fail = [&](unsigned local, InsideVerdict v) {
    atomicOr(flags + local, kInsideWhole && v == InsideVerdict::inside ? kBlockInside : kBlockToDouble);
  };
  for (std::size_t base = static_cast<std::size_t>(blockIdx.x) * kBlock; base < n; base += static_cast<std::size_t>(gridDim.x) * kBlock) {
    if (t == 0) first_count = expand_count = deep_count = misses = 0;
    __syncthreads();
    // A thread per pair: its intervals listed, its query and piece kept.
    const std::size_t i = base + t;
    unsigned flag = 0;
    if (i < n) {
      const Query s = lwsccd::detail::relative_single(gather_single_query<kVertexFace>(mesh, single, kept[i]));
      Piece root;
      std::uint32_t found = 0;
      // (The screen tried the separating directions.)
      const int count = Filter::intervals_of_single(s, single_params, found, root, true);
      if (count == 1 && found == (1u << Filter::kWholeStepNode)) {
        // (route_single's verdict: the step outside in float, else the double path; early_room > 0:
        // the early searches, as single_filter_kernel sends it.)
        const InsideVerdict v = Filter::inside_of_single(s, Filter::kWholeStepNode);
        if (v != InsideVerdict::outside) append_index(counters + kEarlyCandidates);  // (the next run's plan)
        if (v == InsideVerdict::outside) atomicAdd(&misses, 1u);
        else if (early_room > 0) send_early(counters, early, early_room, double_kept, kept_room, kept[i]);
        else send_on_from_single(kept[i], counters, double_kept, kept_room, deferred, kInsideWhole && v == InsideVerdict::inside);
      } else if (count == 0) {
        atomicAdd(&misses, 1u);
      } else if (count < 0) {
        send_on_from_single(kept[i], counters, double_kept, kept_room, deferred, false);
      } else {
        queries[t] = s;
        pieces[t] = root;
        flag = kBlockListed | (Filter::single_deeper(count, single_params) ? kBlockDeeper : 0u);
        const unsigned at = atomicAdd(&first_count, static_cast<unsigned>(count));  // (count <= 8: always fits)
        for (int k = 0; k < count; ++k, found &= found - 1u)
          first[at + k] = static_cast<std::uint16_t>((t << 8) | lwsccd::detail::lowest_bit(found));
      }
    }
    flags[t] = flag;
    __syncthreads();
    // A thread per first-round interval: the inside test.
    for (unsigned k = t; k < first_count; k += kBlock) {
      const unsigned local = first[k] >> 8, node = first[k] & 255u;
      const InsideVerdict v = Filter::inside_of_single(queries[local], node);
      if (v == InsideVerdict::outside) continue;
      if (v == InsideVerdict::unknown && (flags[local] & kBlockDeeper) && (node >> Filter::kLevel) == 1u)
        expand[atomicAdd(&expand_count, 1u)] = first[k];
      else
        fail(local, v);
    }
    __syncthreads();
    // A thread per unknown interval: the second round's pieces below it.
    for (unsigned k = t; k < expand_count; k += kBlock) {
      const unsigned local = expand[k] >> 8, node = expand[k] & 255u;
      if (flags[local] & (kBlockToDouble | kBlockInside | kBlockOnThread)) continue;  // decided already (a racing read only costs time)
      std::uint32_t below = 0;
      const int count = Filter::expand_of_single(pieces[local], single_params, node, below);
      if (count < 0) {
        atomicOr(flags + local, kBlockToDouble);
        continue;
      }
      if (count == 0) continue;
      const unsigned at = atomicAdd(&deep_count, static_cast<unsigned>(count));
      if (at + static_cast<unsigned>(count) > static_cast<unsigned>(Room::kDeep)) {
        atomicOr(flags + local, kBlockOnThread);
        if constexpr (Room::kDeep > 0)
          for (unsigned d = at; d < static_cast<unsigned>(Room::kDeep); ++d) deep[d] = kNoBlockItem;  // (slots it took, empty)
        continue;
      }
      for (int d = 0; d < count; ++d, below &= below - 1u)
        deep[at + d] = static_cast<std::uint16_t>((local << 8) | Filter::deep_node(node, lwsccd::detail::lowest_bit(below)));
    }
    __syncthreads();
    // A thread per second-round piece: the inside test (pieces past the room were not written).
    const unsigned deep_n = ::min(deep_count, static_cast<unsigned>(Room::kDeep));
    for (unsigned k = t; k < deep_n; k += kBlock) {
      if (deep[k] == kNoBlockItem) continue;
      const unsigned local = deep[k] >> 8, node = deep[k] & 255u;
      if (flags[local] & (kBlockToDouble | kBlockInside | kBlockOnThread)) continue;
      const InsideVerdict v = Filter::inside_of_single(queries[local], node);
      if (v != InsideVerdict::outside) fail(local, v);
    }
    __syncthreads();
    // A thread per pair: sent on (the block's sends together).
    bool send = false, whole = false;
    if (i < n && (flags[t] & kBlockListed)) {
      const unsigned f = flags[t];
      if (f & kBlockOnThread) {
        // (From the pair's query as gathered: relative_single's bound is the input's.)
        const SingleRoute route =
            Filter::route_single(gather_single_query<kVertexFace>(mesh, single, kept[i]), single_params, true, kInsideWhole);
        send = route != SingleRoute::miss;
        whole = route == SingleRoute::whole_search;
      } else if (f & (kBlockToDouble | kBlockInside)) {
        send = true;
        whole = (f & kBlockInside) != 0u;
      }
      if (!send) atomicAdd(&misses, 1u);
    }
    send_on_from_single_in_block<kBlock>(send, whole, send ? kept[i] : std::pair<index_t, index_t>{}, counters, double_kept,
                                         kept_room, deferred, tally);
    __syncthreads();
    if (t == 0 && misses > 0) atomicAdd(counters + kSingleMisses, static_cast<unsigned long long>(misses));
  }
}

// A thread per listed interval (the first round's, counter kSingleIntervals, or the second's,
// kSingleDeepIntervals): the inside test in float. In the first round (`expanded` not null) an
// interval whose test is unknown is listed in `expanded` for the second round when its pair may
// take it; any other interval not certainly outside sends its pair to the double filter, or with
// kInsideWhole, one inside in float straight to the whole search (fail_single).
template <class Method, bool kVertexFace, class T, bool kInsideWhole>
__global__ void single_inside_kernel(MeshFeatures mesh, const SingleVertex* single, const std::pair<index_t, index_t>* kept,
                                     std::size_t kept_room, const unsigned long long* control,
                                     unsigned long long* counters, int counter, const unsigned long long* intervals,
                                     std::size_t interval_room, unsigned* failed, std::pair<index_t, index_t>* double_kept,
                                     unsigned* deferred, unsigned long long* expanded) {
  using Filter = lwsccd::detail::CertifiedFilter<typename Method::policy_type>;
  using lwsccd::detail::InsideVerdict;
  lwsccd::detail::start_after_previous_grids();  // (launched by NarrowPhase::chain)
  if (control[kSkip]) return;
  const std::size_t n = counters[counter] < interval_room ? static_cast<std::size_t>(counters[counter]) : interval_room;
  LWSCCD_GRID_STRIDE(j, n) {
    const unsigned long long item = intervals[j];
    if (item == kNoInterval) continue;
    const unsigned i = item_pair_index(item), node = item_node(item);
    const InsideVerdict verdict = Filter::inside_single(gather_single_query<kVertexFace>(mesh, single, kept[i]), node);
    if (verdict == InsideVerdict::outside) continue;
    // Its own slot in `expanded`, whose room is the first round's list's.
    if (expanded && verdict == InsideVerdict::unknown && item_expandable(item) && (node >> Filter::kLevel) == 1u)
      expanded[append_index(counters + kSingleExpanded)] = item;
    else
      fail_single(i, failed, counters, kept, double_kept, kept_room, deferred, kInsideWhole && verdict == InsideVerdict::inside);
  }
}

// The second round: a thread per interval left unknown by the first lists the intervals below it
// (CertifiedFilter::expand_single) for single_inside_kernel; a pair already failed is skipped, one
// the round cannot take goes to the double filter, one whose pieces do not fit (slots marked
// empty, room grown for the next run) is decided on the thread.
template <class Method, bool kVertexFace, class T>
__global__ void single_expand_kernel(MeshFeatures mesh, const SingleVertex* single,
                                     const std::pair<index_t, index_t>* kept, CcdParams<T> params,
                                     const unsigned long long* control, unsigned long long* counters,
                                     const unsigned long long* expanded, unsigned long long* deep, std::size_t deep_room,
                                     unsigned* failed, std::pair<index_t, index_t>* double_kept, std::size_t kept_room) {
  using Filter = lwsccd::detail::CertifiedFilter<typename Method::policy_type>;
  lwsccd::detail::start_after_previous_grids();  // (launched by NarrowPhase::chain)
  if (control[kSkip]) return;
  const CcdParams<float> single_params = lwsccd::detail::single_params(params);
  const std::size_t n = static_cast<std::size_t>(counters[kSingleExpanded]);
  LWSCCD_GRID_STRIDE(j, n) {
    const unsigned long long item = expanded[j];
    const unsigned i = item_pair_index(item), node = item_node(item);
    if ((failed[i >> 5] >> (i & 31u)) & 1u) continue;  // failed already (a racing read is only a missed shortcut)
    std::uint32_t below = 0;
    const auto q = gather_single_query<kVertexFace>(mesh, single, kept[i]);
    const int count = Filter::expand_single(q, single_params, node, below);
    if (count < 0) {
      fail_single(i, failed, counters, kept, double_kept, kept_room);
      continue;
    }
    if (count == 0) continue;
    bool fits = true;
    const unsigned long long base = append_run(counters + kSingleDeepIntervals, static_cast<unsigned>(count), deep_room, fits);
    for (int k = 0; k < count; ++k, below &= below - 1u)
      if (base + k < deep_room)
        deep[base + k] = fits ? filter_item(i, false, Filter::deep_node(node, static_cast<unsigned>(__ffs(below) - 1))) : kNoInterval;
    // Pieces that do not fit: the pair decided on this thread (both rounds, the same answer as
    // every interval's test: a miss leaves its other intervals outside too).
    if (!fits && !Filter::decides_single(q, params)) fail_single(i, failed, counters, kept, double_kept, kept_room);
  }
}

// The double filter on pair i of `kept`: FP32 first, the search in single precision (its misses,
// and contacts with a double tail), as the CPU batch runs it on every pair the single passes leave;
// then the double screen, and the intervals listed for filter_inside_kernel (or the pair deferred).
template <class Method, bool kVertexFace, class T, class P>
__device__ void filter_pair(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1, const std::pair<index_t, index_t>* kept,
                            std::size_t i, const CcdParams<T>& params, unsigned long long* counters, unsigned long long* intervals,
                            std::size_t interval_room, FeatureHit<T>* hits, std::size_t hit_room, FeatureHit<T>* undecided,
                            unsigned* deferred) {
  using Filter = lwsccd::detail::CertifiedFilter<typename Method::policy_type>;
  const auto q = gather_query<kVertexFace, T>(mesh, x0, x1, kept[i]);
  if (settled_in_single<Method>(q, params, kept[i], counters, hits, hit_room, undecided)) return;
  if (Method::screen_after_single(q, params)) return;
  std::uint32_t found = 0;
  lwsccd::detail::Noted<T> noted;
  const int count = Filter::intervals(q, params, found, noted);
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

// The whole search of deferred entry w (refine_deferred_kernel's, a thread each). The pairs sent
// whole take the search in single precision and the double screen here; the double filter's pairs
// took them in filter_pair (or refine_kernel). kHand: the search in double is handed on (w
// appended to `handed`, counted in counters[kHandedToWarps]) instead of run here.
template <class Method, bool kVertexFace, bool kHand, class T, class P>
__device__ void refine_deferred_entry(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                      const std::pair<index_t, index_t>* kept, std::size_t room, const unsigned* deferred,
                                      std::size_t w, const CcdParams<T>& params, unsigned long long* counters, FeatureHit<T>* hits,
                                      std::size_t hit_room, FeatureHit<T>* undecided, unsigned* handed) {
  const unsigned at = deferred[w];
  const std::pair<index_t, index_t> p = kept[at];
  const auto q = gather_query<kVertexFace, T>(mesh, x0, x1, p);
  if (sent_whole(at, room, counters) &&
      (settled_in_single<Method>(q, params, p, counters, hits, hit_room, undecided) || Method::screen_after_single(q, params)))
    return;
  if constexpr (kHand) {
    handed[append_index(counters + kHandedToWarps)] = static_cast<unsigned>(w);
  } else {
    settle_refined(Method::template refine<false>(q, params), p.first, p.second, counters, hits, hit_room, undecided);
  }
}

// The deferred entries the single-precision filter sent whole that a thread each searches (the
// first counters[kSingleWhole] of `deferred`, since the single-precision kernels list them before
// any other; none where the whole list would fit refine_deferred_warp_kernel's warps, which take
// every entry): FP32 first's contacts, which filter_kernel searches beside the double filter's
// pairs (filter_kernel with kWithWhole), and refine_deferred_kernel then skips.
__device__ inline std::size_t whole_searched_early(const unsigned long long* counters, std::size_t warp_below) {
  const auto whole = static_cast<std::size_t>(counters[kSingleWhole]);
  return whole > warp_below ? whole : 0;
}

// The double filter: a thread per pair of `kept` (its length in counters[kept_counter]), and with
// kWithWhole, past those, a thread per deferred entry the single-precision filter sent whole
// (whole_searched_early, refine_deferred_entry). Why together: the double filter's pairs are few
// and long (cloth-ball: ~6 of a warp's lanes busy, under 7% of the SMs' warps on an H200), and the
// contacts sent whole need nothing it does, so their searches fill the SMs beside it instead of
// waiting for it and its inside tests.
template <class Method, bool kVertexFace, bool kWithWhole, bool kHand, class T, class P>
__global__ void filter_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1, const std::pair<index_t, index_t>* kept,
                              int kept_counter, std::size_t room, CcdParams<T> params, const unsigned long long* control,
                              unsigned long long* counters, unsigned long long* intervals, std::size_t interval_room,
                              FeatureHit<T>* hits, std::size_t hit_room, FeatureHit<T>* undecided, unsigned* deferred,
                              std::size_t warp_below, unsigned* handed, unsigned* listed, std::size_t listed_words) {
  lwsccd::detail::start_after_previous_grids();  // (launched by NarrowPhase::chain)
  if (control[kSkip]) return;
  // filter_inside_kernel's bits, cleared here rather than by a memset between the two kernels,
  // which would hold the next one's launch until this one ends (no launch ahead, NarrowPhase::chain).
  LWSCCD_GRID_STRIDE(w, listed_words) { listed[w] = 0u; }
  const std::size_t n = counters[kept_counter] < room ? static_cast<std::size_t>(counters[kept_counter]) : room;
  const std::size_t whole = kWithWhole ? whole_searched_early(counters, warp_below) : 0;
  LWSCCD_GRID_STRIDE(i, n + whole) {
    if (i < n) {
      filter_pair<Method, kVertexFace>(mesh, x0, x1, kept, i, params, counters, intervals, interval_room, hits, hit_room, undecided,
                                       deferred);
    } else if constexpr (kWithWhole) {
      refine_deferred_entry<Method, kVertexFace, kHand>(mesh, x0, x1, kept, room, deferred, i - n, params, counters, hits, hit_room,
                                                        undecided, handed);
    }
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
  lwsccd::detail::start_after_previous_grids();  // (launched by NarrowPhase::chain)
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
  lwsccd::detail::start_after_previous_grids();  // (launched by NarrowPhase::chain)
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

// Second part: the deferred searches, whole (a grid-stride loop keeps the warps full). kHand: the
// search in double of a pair single precision left (the double filter's pairs, and those the
// search in float did not decide) is not run here but handed on (its entry listed in `handed`;
// refine_handed_kernel searches it): those searches are the long ones
// (cloth-ball: 3.4 K of 106 K edge-edge pairs, up to ~50x the median's work on the CPU), and one of
// them on a thread held the whole kernel up; the kernel also holds no code for them.
// `after_whole`: the entries filter_kernel searched (whole_searched_early) are skipped.
template <class Method, bool kVertexFace, bool kHand, class T, class P>
__global__ void refine_deferred_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                       const std::pair<index_t, index_t>* kept, std::size_t room, const unsigned* deferred,
                                       CcdParams<T> params, const unsigned long long* control, unsigned long long* counters,
                                       FeatureHit<T>* hits, std::size_t hit_room, FeatureHit<T>* undecided, std::size_t warp_below,
                                       unsigned* handed, bool after_whole) {
  lwsccd::detail::start_after_previous_grids();  // (launched by NarrowPhase::chain)
  if (control[kSkip]) return;
  const std::size_t n = static_cast<std::size_t>(counters[kDeferred]);
  if (n <= warp_below) return;  // refine_deferred_warp_kernel's
  const std::size_t from = after_whole ? whole_searched_early(counters, warp_below) : 0;
  LWSCCD_GRID_STRIDE(i, from < n ? n - from : 0) {
    refine_deferred_entry<Method, kVertexFace, kHand>(mesh, x0, x1, kept, room, deferred, from + i, params, counters, hits, hit_room,
                                                      undecided, handed);
  }
}

// The inside tests of a refinement run by a whole warp (every lane runs the same search on the
// same values, so all ask for the same test at once): a test not at hand is evaluated with its
// subtree, the interval and its descendants down to 4 levels below, a lane each (31 lanes); every
// lane keeps the 31 verdicts (2 bits each, by two ballots). The search asks next for a child or a
// later sibling most of the time: cloth-funnel's longest coplanar edge-edge search (186 tests)
// evaluates 37 subtrees (CPU count).
struct WarpInsideSubtree {
  static constexpr int kDepth = 5;                         // levels of a subtree
  static constexpr int kIntervals = (1 << kDepth) - 1;     // its intervals, a lane each
  static_assert(kIntervals < 32, "lwsccd: WarpInsideSubtree: a subtree's intervals must fit a warp's lanes (and its ballots' bits)");
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
      if (lane < kIntervals && lane_level <= max_level) v = compute(lane_level, (index << d) | offset);
      const unsigned bits = static_cast<unsigned>(v);
      low_bits = __ballot_sync(0xffffffffu, bits & 1u);
      high_bits = __ballot_sync(0xffffffffu, bits & 2u);
    }
    const int d = level - root_level;
    const int place = (1 << d) - 1 + static_cast<int>(index - (root_index << d));
    return static_cast<InsideVerdict>(((low_bits >> place) & 1u) | (((high_bits >> place) & 1u) << 1));
  }

  // An interval's 2^depth pieces `depth` levels down, a lane each, combined as
  // lwsccd::detail::PieceVotes combines them (certified_refine's verdict_in_pieces): the subtree
  // held stays held, so the search goes on reading its ballots.
  static constexpr bool kEvaluatesPieces = true;
  template <class Compute>
  __device__ lwsccd::detail::InsideVerdict pieces(int level, std::uint32_t index, int depth, const Compute& compute) const {
    using lwsccd::detail::InsideVerdict;
    InsideVerdict v = InsideVerdict::outside;
    if (lane < (1 << depth)) v = compute(level + depth, (index << depth) | static_cast<std::uint32_t>(lane));
    const unsigned not_outside = __ballot_sync(0xffffffffu, v != InsideVerdict::outside);
    const unsigned not_excluded = __ballot_sync(0xffffffffu, v != InsideVerdict::outside && v != InsideVerdict::outside_as_given);
    if (not_outside == 0u) return InsideVerdict::outside;
    return not_excluded == 0u ? InsideVerdict::outside_as_given : InsideVerdict::unknown;
  }
};

// The search in double of pair p by the whole warp (every lane runs it on the same values, the
// inside tests by subtrees: WarpInsideSubtree); lane 0 stores the answer.
template <class Method, class Q, class T>
__device__ void warp_refine(const Q& q, const CcdParams<T>& params, std::pair<index_t, index_t> p, int lane,
                            unsigned long long* counters, FeatureHit<T>* hits, std::size_t hit_room, FeatureHit<T>* undecided) {
  WarpInsideSubtree inside;
  inside.lane = lane;
  inside.max_level = lwsccd::detail::certified_inside_levels<typename Method::policy_type, double>(params.tolerance);
  const CertifiedAnswer<T> a = Method::template refine_with<false>(q, params, inside);
  if (lane == 0) settle_refined(a, p.first, p.second, counters, hits, hit_room, undecided);
  __syncwarp();
}

// The warp's next ticket from `counter` (lane 0 takes it, every lane gets it).
__device__ inline unsigned long long warp_ticket(unsigned long long* counter, int lane) {
  unsigned long long k = 0;
  if (lane == 0) k = atomicAdd(counter, 1ull);
  return __shfl_sync(0xffffffffu, k, 0);
}

// The whole search of pair p by the whole warp: with `after_single_filter` (a pair that skipped
// the double filter) the search in single precision and the double screen first, as
// refine_deferred_entry runs them, then the search in double (warp_refine).
template <class Method, class Q, class T>
__device__ void warp_search_whole(const Q& q, const CcdParams<T>& params, std::pair<index_t, index_t> p, bool after_single_filter,
                                  int lane, unsigned long long* counters, FeatureHit<T>* hits, std::size_t hit_room,
                                  FeatureHit<T>* undecided) {
  // (Every lane runs the same single-precision search and double screen on the same values, so
  // all go on alike; lane 0 stores.)
  if (after_single_filter && (settled_in_single<Method, true>(q, params, p, counters, hits, hit_room, undecided, lane == 0) ||
                              Method::screen_after_single(q, params)))
    return;
  warp_refine<Method>(q, params, p, lane, counters, hits, hit_room, undecided);
}

// Second part for a short list (at most `warp_below` deferred pairs): a warp per pair, the inside
// tests by subtrees (WarpInsideSubtree); the same answers as refine_deferred_kernel. Its pairs are
// the long searches (cloth-funnel's coplanar edge-edge ones: 96 halvings and ~190 inside tests one
// after the other took ~255 us in one thread on an H100).
template <class Method, bool kVertexFace, class T, class P>
__global__ void refine_deferred_warp_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                            const std::pair<index_t, index_t>* kept, std::size_t room, const unsigned* deferred,
                                            CcdParams<T> params, const unsigned long long* control,
                                            unsigned long long* counters, FeatureHit<T>* hits, std::size_t hit_room,
                                            FeatureHit<T>* undecided, std::size_t warp_below) {
  lwsccd::detail::start_after_previous_grids();  // (launched by NarrowPhase::chain)
  if (control[kSkip]) return;
  const std::size_t n = static_cast<std::size_t>(counters[kDeferred]);
  if (n > warp_below) return;
  const int lane = static_cast<int>(threadIdx.x) % 32;
  const std::size_t warps = static_cast<std::size_t>(gridDim.x) * (blockDim.x / 32);
  for (std::size_t w = (static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x) / 32; w < n; w += warps) {
    const unsigned at = deferred[w];
    const std::pair<index_t, index_t> p = kept[at];
    warp_search_whole<Method>(gather_query<kVertexFace, T>(mesh, x0, x1, p), params, p, sent_whole(at, room, counters), lane,
                              counters, hits, hit_room, undecided);
  }
}

// The early searches (single_filter_kernel's `early` list, its length in
// counters[kEarlySearches], at most `early_room` kept): a warp per pair, each searched whole as a
// pair sent whole is (warp_search_whole), on a stream of the list's own from the single-precision
// filter's first kernel on, beside the rest of the list's chain; settle_undecided_kernel waits for
// it. A warp takes the next pair by a ticket (counters[kEarlyTaken]) when its own search ends. The
// same answers as the route through the double filter.
template <class Method, bool kVertexFace, class T, class P>
__global__ void refine_early_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1, const std::pair<index_t, index_t>* early,
                                    std::size_t early_room, CcdParams<T> params, const unsigned long long* control,
                                    unsigned long long* counters, FeatureHit<T>* hits, std::size_t hit_room,
                                    FeatureHit<T>* undecided) {
  if (control[kSkip]) return;
  const std::size_t n = counters[kEarlySearches] < early_room ? static_cast<std::size_t>(counters[kEarlySearches]) : early_room;
  const int lane = static_cast<int>(threadIdx.x) % 32;
  for (;;) {
    const unsigned long long k = warp_ticket(counters + kEarlyTaken, lane);
    if (k >= n) break;
    const std::pair<index_t, index_t> p = early[k];
    warp_search_whole<Method>(gather_query<kVertexFace, T>(mesh, x0, x1, p), params, p, true, lane, counters, hits, hit_room,
                              undecided);
  }
}

// The searches refine_deferred_kernel handed on (the deferred entries listed in `handed`, their
// number in counters[kHandedToWarps]: past the search in single precision and the double screen).
// At most `warp_limit` handed searches (a few waves of warps) run a warp each (kWarpEach), as
// refine_deferred_warp_kernel searches; a warp takes the next search when its own ends (a ticket,
// counters[kHandedTaken]), so the few long ones do not queue behind each other on the warps a fixed
// share would give them. More run a thread each (!kWarpEach), the list's entries in order, since a
// warp's search costs ~30 lanes' work for a few long ones. Both forms are launched; the one whose
// case does not hold returns at once.
template <class Method, bool kVertexFace, bool kWarpEach, class T, class P>
__global__ void refine_handed_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                     const std::pair<index_t, index_t>* kept, const unsigned* deferred, const unsigned* handed,
                                     CcdParams<T> params, const unsigned long long* control, unsigned long long* counters,
                                     FeatureHit<T>* hits, std::size_t hit_room, FeatureHit<T>* undecided, std::size_t warp_below,
                                     std::size_t warp_limit) {
  lwsccd::detail::start_after_previous_grids();  // (launched by NarrowPhase::chain)
  if (control[kSkip]) return;
  const std::size_t n = static_cast<std::size_t>(counters[kDeferred]), count = static_cast<std::size_t>(counters[kHandedToWarps]);
  if (n <= warp_below || (count <= warp_limit) != kWarpEach) return;  // (the other kernels' lists)
  if constexpr (kWarpEach) {
    const int lane = static_cast<int>(threadIdx.x) % 32;
    for (;;) {
      const unsigned long long k = warp_ticket(counters + kHandedTaken, lane);
      if (k >= count) break;
      const std::pair<index_t, index_t> p = kept[deferred[handed[k]]];
      warp_refine<Method>(gather_query<kVertexFace, T>(mesh, x0, x1, p), params, p, lane, counters, hits, hit_room, undecided);
    }
  } else {
    LWSCCD_GRID_STRIDE(k, count) {
      const std::pair<index_t, index_t> p = kept[deferred[handed[k]]];
      settle_refined(Method::template refine<false>(gather_query<kVertexFace, T>(mesh, x0, x1, p), params), p.first, p.second,
                     counters, hits, hit_room, undecided);
    }
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
  lwsccd::detail::start_after_previous_grids();  // (launched by NarrowPhase::chain)
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

}  // namespace lwsccd::gpu::detail
