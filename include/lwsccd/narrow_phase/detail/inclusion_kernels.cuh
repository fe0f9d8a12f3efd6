// lwsccd — the inclusion search on the GPU: a first attempt a thread per query, then a warp per
// query (boxes sorted by order key, merged, tested by the lanes together).
// Part of narrow_phase_kernels.cuh: include <lwsccd/narrow_phase/narrow_phase.cuh>, not this file.
#pragma once

#include <cooperative_groups.h>
#include <cooperative_groups/reduce.h>
#include <cooperative_groups/scan.h>
#include <cstring>

#include "lwsccd/narrow_phase/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.cuh"
#include "lwsccd/narrow_phase/detail/narrow_lists.cuh"

namespace lwsccd::gpu::detail {

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
  lwsccd::detail::start_after_previous_grids();
  if (control[kSkip]) return;
  const std::size_t n = count.get();
  if (n <= direct_below) {
    LWSCCD_GRID_STRIDE(i, n) {
      if (i == 0) counters[kOpen] = n;
      open[i] = static_cast<unsigned>(i);
    }
    return;
  }
  // (After the list's length: threads of a launch sized for the list's room that hold no query
  // need not compute the limit.)
  const CcdParams<T> base = limited_params(params, limit_bits);
  LWSCCD_GRID_STRIDE(i, n) {
    const std::pair<index_t, index_t> p = item_pair(items[i]);
    const CcdParams<T> qp = item_params(items[i], base);
    // Nothing after the step's end (a query the certified path settled stays listed from time 1):
    // every box ends by then, so the search would drop them all.
    if (!(qp.time_from < T(1))) continue;
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
  lwsccd::detail::start_after_previous_grids();
  if (control[kSkip]) return;
  const std::size_t n = static_cast<std::size_t>(counters[kOpen]);
  if (static_cast<std::size_t>(blockIdx.x) * kWarps >= n) return;  // no search for this block (as above)
  const CcdParams<T> base = limited_params(params, limit_bits);
  const int warp = static_cast<int>(threadIdx.x) / 32, lane = static_cast<int>(threadIdx.x) % 32;
  Search& search = reinterpret_cast<Search*>(storage)[warp];
  const BoxOrderKey after_all{~0ull, ~0ull};
  for (std::size_t w = static_cast<std::size_t>(blockIdx.x) * kWarps + warp; w < n;
       w += static_cast<std::size_t>(gridDim.x) * kWarps) {
    const std::size_t i = which[w];
    const std::pair<index_t, index_t> p = item_pair(items[i]);
    const CcdParams<T> qp = item_params(items[i], base);
    if (!(qp.time_from < T(1))) continue;  // nothing after the step's end (as the thread kernel)
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

}  // namespace lwsccd::gpu::detail
