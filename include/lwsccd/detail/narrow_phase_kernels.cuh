// lwsccd — kernels and definitions for narrow_phase.cuh.
#pragma once

#include <thrust/iterator/counting_iterator.h>
#include <thrust/iterator/transform_iterator.h>

#include "lwsccd/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase.cuh"

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

template <class Method, bool kVertexFace, class T, class P, class Item>
__global__ void ccd_pairs_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1, const Item* items, std::size_t n,
                                 CcdParams<T> params, FeatureHit<T>* staged, unsigned char* flags,
                                 unsigned long long* gave_up) {
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const std::pair<index_t, index_t> p = item_pair(items[i]);
  const CcdParams<T> qp = item_params(items[i], params);
  const CcdResult<T> r = run_method<Method>(gather_query<kVertexFace, T>(mesh, x0, x1, p), qp);
  staged[i] = FeatureHit<T>{p.first, p.second, r.toi};
  flags[i] = r.hit ? 1 : 0;
  if (r.gave_up) atomicAdd(gave_up, 1ull);
}

// The first step of a two-pass method on one query: true when it certainly rejects the pair
// (CertifiedCcd: its screen; other methods: their quick_reject).
template <class Method, class Q, class T>
__device__ bool first_step_rejects(const Q& q, const CcdParams<T>& params) {
  if constexpr (lwsccd::detail::certified_of<Method>::value) return Method::screen(q, params);
  else return Method::quick_reject(q, params);
}

// Pass 1: flags the pairs that the method's cheap first step does not reject, a thread per pair.
template <class Method, bool kVertexFace, class T, class P>
__global__ void screen_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                              const std::pair<index_t, index_t>* pairs, std::size_t n, CcdParams<T> params,
                              unsigned char* keep) {
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const std::pair<index_t, index_t> p = pairs[i];
  const bool rejected = first_step_rejects<Method>(gather_query<kVertexFace, T>(mesh, x0, x1, p), params);
  keep[i] = rejected ? 0 : 1;
}

// CertifiedCcd's refinement of the screened pairs, first part: searches that would halve
// intervals at kDeferLevel or deeper stop (with a stack only that deep) and are flagged in `deferred` (they are the contacts,
// resolved at the time tolerance, and would hold up whole warps of quick misses); the others
// store their answer: certified hits staged (flag in `hit`), the undecided flagged in `keep`.
template <class Method, bool kVertexFace, int kDeferLevel, int kBlock, int kMinBlocks, class T, class P>
__global__ void __launch_bounds__(kBlock, kMinBlocks) refine_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                              const std::pair<index_t, index_t>* pairs, std::size_t n, CcdParams<T> params,
                              FeatureHit<T>* staged, unsigned char* hit, unsigned char* keep, unsigned char* deferred) {
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const std::pair<index_t, index_t> p = pairs[i];
  bool later = false;
  const CertifiedAnswer<T> a =
      Method::template refine_until<kDeferLevel>(gather_query<kVertexFace, T>(mesh, x0, x1, p), params, &later);
  staged[i] = FeatureHit<T>{p.first, p.second, a.lo};
  hit[i] = a.certainty == Certainty::hit ? 1 : 0;
  keep[i] = !later && a.certainty == Certainty::undecided ? 1 : 0;
  deferred[i] = later ? 1 : 0;
}

// Second part: the deferred searches, whole, on a compacted list of their indices (its length
// read on the device: no host sync), answers stored where the first part would have put them.
template <class Method, bool kVertexFace, class T, class P>
__global__ void refine_deferred_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                       const std::pair<index_t, index_t>* pairs, const unsigned* which,
                                       const unsigned long long* count, CcdParams<T> params, FeatureHit<T>* staged,
                                       unsigned char* hit, unsigned char* keep) {
  const std::size_t n = static_cast<std::size_t>(*count);
  for (std::size_t w = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x; w < n;
       w += static_cast<std::size_t>(gridDim.x) * blockDim.x) {
    const std::size_t i = which[w];
    const std::pair<index_t, index_t> p = pairs[i];
    const CertifiedAnswer<T> a = Method::refine(gather_query<kVertexFace, T>(mesh, x0, x1, p), params);
    staged[i] = FeatureHit<T>{p.first, p.second, a.lo};
    hit[i] = a.certainty == Certainty::hit ? 1 : 0;
    keep[i] = a.certainty == Certainty::undecided ? 1 : 0;
  }
}

struct FlagToCount {
  LWSCCD_HD unsigned long long operator()(unsigned char f) const { return f; }
};

// Second pass, first attempt: the same search in one thread per query, for a few rounds and
// little memory. Most queries end there; the others are flagged `pending` for the warp search
// (which starts over and gives the answer the whole search gives).
template <class Method, bool kVertexFace, class T, class P, int kRounds, int kStore, class Item>
__global__ void inclusion_thread_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1, const Item* items,
                                        std::size_t n, CcdParams<T> params,
                                        FeatureHit<T>* staged, unsigned char* flags, unsigned char* pending,
                                        unsigned long long* gave_up) {
  using Traits = lwsccd::detail::inclusion_search_of<Method>;
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const std::pair<index_t, index_t> p = item_pair(items[i]);
  const CcdParams<T> qp = item_params(items[i], params);
  CcdResult<T> r;
  bool done = true;
  auto attempt = [&](const auto& q) {
    if (Traits::filtered && !non_penetration_filter(q, qp)) return;
    done = lwsccd::detail::inclusion_try<typename Traits::policy, kStore>(q, qp, kRounds, r);
  };
  attempt(gather_query<kVertexFace, T>(mesh, x0, x1, p));
  pending[i] = done ? 0 : 1;
  staged[i] = FeatureHit<T>{p.first, p.second, r.toi};
  flags[i] = done && r.hit ? 1 : 0;
  if (done && r.gave_up) atomicAdd(gave_up, 1ull);
}

// The rank of `x` among the n sorted boxes at `sorted` (how many come before it).
LWSCCD_HD inline int rank_in(const lwsccd::detail::DyadicBox* sorted, int n, const lwsccd::detail::DyadicBox& x) {
  int lo = 0, hi = n;
  while (lo < hi) {
    const int mid = (lo + hi) / 2;
    if (lwsccd::detail::box_before(sorted[mid], x)) lo = mid + 1;
    else hi = mid;
  }
  return lo;
}

// Second pass for InclusionCcd (filtered or not): a warp per query. The rounds of
// detail::InclusionSearch with the work spread over the lanes: each lane examines one box of the
// round and makes its new boxes; the new boxes are ranked among themselves and merged into the
// sorted live boxes by rank, every lane placing its own. Same sets and answers as the one-thread
// search (the order is total), with a long search's latency cut to that of its rounds.
template <class Method, bool kVertexFace, class T, class P, int kWarps, class Item>
__global__ void __launch_bounds__(32 * kWarps)
    inclusion_warp_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1, const Item* items, const unsigned* which,
                          std::size_t n, CcdParams<T> params, FeatureHit<T>* staged,
                          unsigned char* flags, unsigned long long* gave_up) {
  using Traits = lwsccd::detail::inclusion_search_of<Method>;
  using Search = lwsccd::detail::InclusionSearch<typename Traits::policy, T>;
  using Round = typename Search::Round;
  using lwsccd::detail::BoxVerdict;
  using lwsccd::detail::DyadicBox;
  constexpr int kFresh = Search::kFresh;
  static_assert(Search::kBatch <= 32, "lwsccd: a round must fit in a warp");
  // Raw storage: shared variables cannot have constructors; start() initializes a search.
  __shared__ alignas(Search) unsigned char storage[kWarps * sizeof(Search)];
  __shared__ DyadicBox fresh_raw[kWarps][kFresh], fresh_sorted[kWarps][kFresh];
  __shared__ CcdResult<T> results[kWarps];
  __shared__ unsigned long long dropped[kWarps];
  __shared__ int state[kWarps];
  const int warp = static_cast<int>(threadIdx.x) / 32, lane = static_cast<int>(threadIdx.x) % 32;
  Search& search = reinterpret_cast<Search*>(storage)[warp];
  for (std::size_t w = static_cast<std::size_t>(blockIdx.x) * kWarps + warp; w < n;
       w += static_cast<std::size_t>(gridDim.x) * kWarps) {
    const std::size_t i = which[w];
    const std::pair<index_t, index_t> p = item_pair(items[i]);
    const CcdParams<T> qp = item_params(items[i], params);
    CcdResult<T> r;
    auto solve = [&](const auto& q) {
      if (Traits::filtered && !non_penetration_filter(q, qp)) return;
      const auto setup = lwsccd::detail::inclusion_setup(q, qp);
      if (setup.separated) return;
      if (lane == 0) search.start();
      __syncwarp();
      while (true) {
        if (lane == 0) state[warp] = static_cast<int>(search.next_round(qp.max_iterations, results[warp]));
        __syncwarp();
        const Round round = static_cast<Round>(state[warp]);
        if (round != Round::examine) {
          if (round == Round::gave_up) r = results[warp];
          return;
        }
        const int k = search.batch_size;
        const DyadicBox* batch = search.batch();
        BoxVerdict verdict = BoxVerdict::excluded;
        if (lane < k) verdict = lwsccd::detail::examine_box(q, setup, batch[lane], search.floor_key, search.t_floor);
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
        // This lane's new boxes, then their ranks among all the round's new boxes.
        DyadicBox mine[2];
        const int count = lane < k ? search.fresh_boxes(batch[lane], verdict, setup.vf, mine) : 0;
        fresh_raw[warp][2 * lane] = mine[0];
        fresh_raw[warp][2 * lane + 1] = mine[1];
        const unsigned has_one = __ballot_sync(0xffffffffu, count >= 1), has_two = __ballot_sync(0xffffffffu, count == 2);
        const int nf = __popc(has_one) + __popc(has_two);
        __syncwarp();
        for (int c = 0; c < count; ++c) {
          int rank = 0;
          for (int other = 0; other < 32; ++other) {
            const int other_count = ((has_one >> other) & 1u) + ((has_two >> other) & 1u);
            for (int oc = 0; oc < other_count; ++oc)
              rank += lwsccd::detail::box_before(fresh_raw[warp][2 * other + oc], mine[c]) ? 1 : 0;
          }
          fresh_sorted[warp][rank] = mine[c];
        }
        __syncwarp();
        // Merge by rank into the other buffer, keeping the earliest kKeep when over capacity.
        const DyadicBox* live = search.live();
        const int size = search.size, total = size + nf;
        const int limit = total > Search::kCapacity ? Search::kKeep : total;
        DyadicBox* out = search.items[1 - search.current];
        for (int a = lane; a < size; a += 32) {
          const int pos = a + rank_in(fresh_sorted[warp], nf, live[a]);
          if (pos < limit) out[pos] = live[a];
          else if (pos == limit) dropped[warp] = lwsccd::detail::box_time_key(live[a]);
        }
        for (int b = lane; b < nf; b += 32) {
          const int pos = b + rank_in(live, size, fresh_sorted[warp][b]);
          if (pos < limit) out[pos] = fresh_sorted[warp][b];
          else if (pos == limit) dropped[warp] = lwsccd::detail::box_time_key(fresh_sorted[warp][b]);
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
      staged[i] = FeatureHit<T>{p.first, p.second, r.toi};
      flags[i] = r.hit ? 1 : 0;
      if (r.gave_up) atomicAdd(gave_up, 1ull);
    }
    __syncwarp();
  }
}

template <class T>
struct HitToi {
  LWSCCD_HD T operator()(const FeatureHit<T>& h) const { return h.toi; }
};

// The sort key of a hit: (first, second) as one 64-bit word (ids are non-negative 32-bit).
template <class T>
__global__ void hit_keys_kernel(const FeatureHit<T>* hits, std::size_t n, unsigned long long* keys) {
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < n) keys[i] = (static_cast<unsigned long long>(hits[i].first) << 32) | static_cast<unsigned>(hits[i].second);
}

template <class T>
struct MinOp {
  LWSCCD_HD T operator()(T a, T b) const { return b < a ? b : a; }
};

}  // namespace detail

template <class Method, class T, class Policy>
void NarrowPhase<Method, T, Policy>::ensure_streams() {
  if (start_) return;
  LWSCCD_CUDA_CHECK(cudaEventCreateWithFlags(&start_, cudaEventDisableTiming));
  // The deferred searches run in a grid that fills the device a few times over.
  int device = 0, sms = 0;
  LWSCCD_CUDA_CHECK(cudaGetDevice(&device));
  LWSCCD_CUDA_CHECK(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, device));
  deferred_grid_ = std::max(1, sms) * 8;
  for (auto& l : lists_) {
    void* pinned = nullptr;  // pinned, so that copies of counts are asynchronous
    LWSCCD_CUDA_CHECK(cudaMallocHost(&pinned, 4 * sizeof(unsigned long long)));
    l.host_counts = static_cast<unsigned long long*>(pinned);
    LWSCCD_CUDA_CHECK(cudaStreamCreateWithFlags(&l.stream, cudaStreamNonBlocking));
    LWSCCD_CUDA_CHECK(cudaEventCreateWithFlags(&l.done, cudaEventDisableTiming));
  }
}

template <class Method, class T, class Policy>
template <class P>
void NarrowPhase<Method, T, Policy>::run(const DeviceMeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                         const Pair* vf, std::size_t num_vf, const Pair* ee, std::size_t num_ee,
                                         const CcdParams<T>& params, cudaStream_t stream) {
  ensure_streams();
  gave_up_ = 0;
  earliest_ = T(1);
  const MeshFeatures view = mesh.view();
  // The lists start once `stream`'s work (positions, pairs) is done.
  LWSCCD_CUDA_CHECK(cudaEventRecord(start_, stream));
  for (auto& l : lists_) {
    l.count = l.tested = l.warp_searches = 0;
    l.counts = {};
    l.counters.resize_discard(4);
    LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(l.stream, start_, 0));
    LWSCCD_CUDA_CHECK(cudaMemsetAsync(l.counters.data(), 0, 4 * sizeof(unsigned long long), l.stream));
  }
  lists_[0].counts.pairs = num_vf;
  lists_[1].counts.pairs = num_ee;
  // Mode earliest with CertifiedCcd: growing time windows (CertifiedPolicy::kEarliestFirst), each
  // screening and refining the pairs and running the fallback up to the window's end, until one
  // holds a contact (as the CPU backend does). Other modes and methods: one window, the caller's.
  const bool windows = kCertified && params.mode == CcdMode::earliest;
  for (int round = 0;; ++round) {
    CcdParams<T> limited = params;
    if constexpr (kCertified)
      if (windows) limited.time_limit = Method::earliest_window(round, params.time_limit);
    if (round > 0) {  // a window that held no contact: start over with the next one
      gave_up_ = 0;
      earliest_ = T(1);
      for (auto& l : lists_) {
        l.count = l.tested = l.warp_searches = 0;
        l.counts.certified_hits = l.counts.certified_misses = l.counts.fallbacks = l.counts.screened = 0;
        LWSCCD_CUDA_CHECK(cudaMemsetAsync(l.counters.data() + 1, 0, sizeof(unsigned long long), l.stream));
      }
    }
    // Pass 1, both lists at once: the screen (of the window: CertifiedCcd's screen also drops the
    // pairs whose cubic keeps its sign up to the window's end), then the survivors compacted.
    screen<P, true>(view, x0, x1, vf, num_vf, limited, lists_[0]);
    screen<P, false>(view, x0, x1, ee, num_ee, limited, lists_[1]);
    for (auto& l : lists_) {
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(l.stream));
      compact_screened(l);
    }
    // CertifiedCcd: the refinement of the screened pairs, a chunk of each list at a time.
    if constexpr (kCertified) {
      while (lists_[0].refined < lists_[0].num_survivors || lists_[1].refined < lists_[1].num_survivors) {
        const std::size_t launched[2] = {refine_chunk<P, true>(view, x0, x1, limited, lists_[0]),
                                         refine_chunk<P, false>(view, x0, x1, limited, lists_[1])};
        for (int k = 0; k < 2; ++k) {
          if (!launched[k]) continue;
          LWSCCD_CUDA_CHECK(cudaStreamSynchronize(lists_[k].stream));
          collect_refined(lists_[k], launched[k]);
        }
      }
      for (auto& l : lists_) {
        l.num_survivors = l.num_undecided;
        l.to_test = nullptr;  // the fallback reads the undecided records instead
      }
    }
    // Mode earliest: the fallback need not look past the best certified time (as the CPU does).
    CcdParams<T> full = limited;
    if (kCertified && params.mode == CcdMode::earliest)
      for (auto& l : lists_) {
        const T m = list_minimum(l, l.stream);
        full.time_limit = m < full.time_limit ? m : full.time_limit;
      }
    for (auto& l : lists_) {
      l.counts.fallbacks = l.num_survivors;
      l.counts.certified_misses = l.counts.pairs - l.counts.certified_hits - l.num_survivors;
      // Two-pass methods: room for every survivor at once; one-pass methods grow chunk by chunk.
      grow_hits(l, std::max(initial_capacity_, l.count + (kTwoPass ? l.num_survivors : 0)));
    }
    // The full test, a chunk of each list at a time on its stream: the lists overlap, and a list's
    // long searches hold up only its own chunk.
    while (lists_[0].tested < lists_[0].num_survivors || lists_[1].tested < lists_[1].num_survivors) {
      std::size_t launched[2] = {0, 0};
      for (int k = 0; k < 2; ++k) {
        List& l = lists_[k];
        const std::size_t m = std::min(chunk_, l.num_survivors - l.tested);
        if (m == 0) continue;
        if (k == 0) launch_chunk<P, true>(view, x0, x1, full, l, l.tested, m);
        else launch_chunk<P, false>(view, x0, x1, full, l, l.tested, m);
        LWSCCD_CUDA_CHECK(cudaMemcpyAsync(l.host_counts, l.counters.data(), sizeof(unsigned long long), cudaMemcpyDeviceToHost,
                                          l.stream));
        launched[k] = m;
      }
      for (int k = 0; k < 2; ++k) {
        if (!launched[k]) continue;
        List& l = lists_[k];
        LWSCCD_CUDA_CHECK(cudaStreamSynchronize(l.stream));
        l.count += static_cast<std::size_t>(l.host_counts[0]);
        l.tested += launched[k];
      }
    }
    // Earliest TOI over both lists, and the bounded-work count.
    for (auto& l : lists_)
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(l.host_counts + 1, l.counters.data() + 1, sizeof(unsigned long long),
                                        cudaMemcpyDeviceToHost, l.stream));
    for (auto& l : lists_) {
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(l.stream));
      gave_up_ += static_cast<std::size_t>(l.host_counts[1]);
      const T list_min = list_minimum(l, stream);
      earliest_ = list_min < earliest_ ? list_min : earliest_;
    }
    if (!windows || !(limited.time_limit < params.time_limit) || lists_[0].count + lists_[1].count > 0) break;
  }
  earliest_only_ = params.mode == CcdMode::earliest;
  // The hits in (first, second) order, on the device: the pairs came in any order, and sorting
  // here is far cheaper than on the host after the download.
  if (!earliest_only_)
    for (auto& l : lists_) sort_hits(l, stream);
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
}

template <class Method, class T, class Policy>
void NarrowPhase<Method, T, Policy>::sort_hits(List& l, cudaStream_t stream) {
  if (l.count < 2) return;
  const std::size_t n = l.count;
  l.keys.resize_discard(n);
  l.sorted_keys.resize_discard(n);
  l.sorted.resize_discard(std::max(n, l.hits.size()));
  detail::hit_keys_kernel<<<static_cast<unsigned>((n + 255) / 256), 256, 0, stream>>>(l.hits.data(), n, l.keys.data());
  LWSCCD_CUDA_CHECK_LAUNCH();
  std::size_t bytes = 0;
  LWSCCD_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, bytes, l.keys.data(), l.sorted_keys.data(), l.hits.data(),
                                                    l.sorted.data(), static_cast<std::int64_t>(n), 0, 64, stream));
  l.scratch.resize_discard(std::max({bytes, l.scratch.size(), std::size_t(1)}));
  LWSCCD_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(l.scratch.data(), bytes, l.keys.data(), l.sorted_keys.data(), l.hits.data(),
                                                    l.sorted.data(), static_cast<std::int64_t>(n), 0, 64, stream));
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
  std::swap(l.hits, l.sorted);
}

// The hits' buffer with room for `room`, keeping the first `count`.
template <class Method, class T, class Policy>
void NarrowPhase<Method, T, Policy>::grow_hits(List& list, std::size_t room) {
  if (list.hits.size() >= room) return;
  DeviceBuffer<FeatureHit<T>> bigger(std::max(room, 2 * list.hits.size()));
  if (list.count)
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(bigger.data(), list.hits.data(), list.count * sizeof(FeatureHit<T>),
                                      cudaMemcpyDeviceToDevice, list.stream));
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(list.stream));
  list.hits = std::move(bigger);
}

// The smallest TOI among a list's hits so far (1 when none), ordered after `stream`'s work.
template <class Method, class T, class Policy>
T NarrowPhase<Method, T, Policy>::list_minimum(const List& l, cudaStream_t stream) {
  if (l.count == 0) return T(1);
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(l.stream));
  toi_.resize_discard(1);
  const auto tois = thrust::make_transform_iterator(l.hits.data(), detail::HitToi<T>{});
  std::size_t bytes = 0;
  LWSCCD_CUDA_CHECK(cub::DeviceReduce::Reduce(nullptr, bytes, tois, toi_.data(), static_cast<std::int64_t>(l.count),
                                              detail::MinOp<T>{}, T(1), stream));
  reduce_scratch_.resize_discard(std::max(bytes, reduce_scratch_.size()));
  LWSCCD_CUDA_CHECK(cub::DeviceReduce::Reduce(reduce_scratch_.data(), bytes, tois, toi_.data(),
                                              static_cast<std::int64_t>(l.count), detail::MinOp<T>{}, T(1), stream));
  T list_min = T(1);
  LWSCCD_CUDA_CHECK(cudaMemcpyAsync(&list_min, toi_.data(), sizeof(T), cudaMemcpyDeviceToHost, stream));
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
  return list_min;
}

// Selects the flagged items of in[0, n) into out (appended: the count lands in *count).
template <class Method, class T, class Policy>
template <class In, class Out>
void NarrowPhase<Method, T, Policy>::select_flagged(List& list, In in, const unsigned char* flags, Out out,
                                                    unsigned long long* count, std::size_t n) {
  std::size_t bytes = 0;
  LWSCCD_CUDA_CHECK(cub::DeviceSelect::Flagged(nullptr, bytes, in, flags, out, count, static_cast<std::int64_t>(n), list.stream));
  list.scratch.resize_discard(std::max(bytes, list.scratch.size()));
  LWSCCD_CUDA_CHECK(cub::DeviceSelect::Flagged(list.scratch.data(), bytes, in, flags, out, count, static_cast<std::int64_t>(n),
                                               list.stream));
}

// Pass 1 of two-pass methods, on the list's stream: the cheap first step (CertifiedCcd: its
// screen; others: quick_reject) on every pair at once, a thread per pair with a byte of output
// each, and the survivors counted into host_counts[0] (read after a sync, by compact_screened).
// One-pass methods test the input pairs directly.
template <class Method, class T, class Policy>
template <class P, bool kVertexFace>
void NarrowPhase<Method, T, Policy>::screen(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1, const Pair* pairs,
                                            std::size_t n, const CcdParams<T>& params, List& list) {
  list.num_survivors = n;
  list.to_test = pairs;
  if constexpr (kTwoPass) {
    if (n == 0) return;
    list.flags.resize_discard(std::max(list.flags.size(), n));
    const unsigned blocks = static_cast<unsigned>((n + Policy::kBlock - 1) / Policy::kBlock);
    detail::screen_kernel<Method, kVertexFace, T, P><<<blocks, Policy::kBlock, 0, list.stream>>>(mesh, x0, x1, pairs, n, params,
                                                                                               list.flags.data());
    LWSCCD_CUDA_CHECK_LAUNCH();
    const auto ones = thrust::make_transform_iterator(list.flags.data(), detail::FlagToCount{});
    std::size_t bytes = 0;
    LWSCCD_CUDA_CHECK(cub::DeviceReduce::Sum(nullptr, bytes, ones, list.counters.data(), static_cast<std::int64_t>(n), list.stream));
    list.scratch.resize_discard(std::max(bytes, list.scratch.size()));
    LWSCCD_CUDA_CHECK(cub::DeviceReduce::Sum(list.scratch.data(), bytes, ones, list.counters.data(),
                                             static_cast<std::int64_t>(n), list.stream));
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(list.host_counts, list.counters.data(), sizeof(unsigned long long),
                                      cudaMemcpyDeviceToHost, list.stream));
  }
}

// After screen and a sync of the list's stream: the survivors compacted into a list of exactly
// their number (as 64-bit words: std::pair's assignment is host-only, and a pair of 32-bit ids
// is 8 bytes, 8-byte aligned), which the refinement or the full test then reads.
template <class Method, class T, class Policy>
void NarrowPhase<Method, T, Policy>::compact_screened(List& list) {
  static_assert(sizeof(Pair) == sizeof(unsigned long long), "lwsccd: a feature pair must be two 32-bit ids");
  if (!kTwoPass || list.counts.pairs == 0) return;
  const std::size_t n = list.counts.pairs, screened = static_cast<std::size_t>(list.host_counts[0]);
  list.survivors.resize_discard(std::max(list.survivors.size(), screened));
  select_flagged(list, reinterpret_cast<const unsigned long long*>(list.to_test), list.flags.data(), list.survivors.data(),
                 list.counters.data(), n);
  list.num_survivors = screened;
  list.to_test = reinterpret_cast<const Pair*>(list.survivors.data());
  list.counts.screened = kCertified ? screened : 0;
  list.refined = 0;
  list.num_undecided = 0;
}

// CertifiedCcd: refines the next chunk of the screened pairs on the list's stream: hits appended
// to the list's hits, undecided pairs to `undecided` (the full test's input); their counts land in
// host_counts[0] and [3] (read by collect_refined after a sync).
template <class Method, class T, class Policy>
template <class P, bool kVertexFace>
std::size_t NarrowPhase<Method, T, Policy>::refine_chunk(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                                         const CcdParams<T>& params, List& list) {
  const std::size_t m = std::min(chunk_, list.num_survivors - list.refined);
  if (m == 0) return 0;
  const Pair* pairs = list.to_test + list.refined;
  list.staged.resize_discard(std::max(list.staged.size(), m));
  list.hit_flags.resize_discard(std::max(list.hit_flags.size(), m));
  list.flags.resize_discard(std::max(list.flags.size(), m));
  list.pending.resize_discard(std::max(list.pending.size(), m));
  list.pending_index.resize_discard(std::max(list.pending_index.size(), m));
  const unsigned blocks = static_cast<unsigned>((m + Policy::kBlock - 1) / Policy::kBlock);
  detail::refine_kernel<Method, kVertexFace, Policy::kRefineDeferLevel, Policy::kBlock, Policy::kRefineMinBlocks, T, P><<<blocks, Policy::kBlock, 0, list.stream>>>(
      mesh, x0, x1, pairs, m, params, list.staged.data(), list.hit_flags.data(), list.flags.data(),
      list.pending.data());
  LWSCCD_CUDA_CHECK_LAUNCH();
  select_flagged(list, thrust::counting_iterator<unsigned>(0), list.pending.data(), list.pending_index.data(),
                 list.counters.data() + 2, m);
  const unsigned deferred_blocks = static_cast<unsigned>(
      std::min<std::size_t>((m + Policy::kBlock - 1) / Policy::kBlock, static_cast<std::size_t>(deferred_grid_)));
  detail::refine_deferred_kernel<Method, kVertexFace, T, P><<<deferred_blocks, Policy::kBlock, 0, list.stream>>>(
      mesh, x0, x1, pairs, list.pending_index.data(), list.counters.data() + 2, params, list.staged.data(), list.hit_flags.data(),
      list.flags.data());
  LWSCCD_CUDA_CHECK_LAUNCH();
  // Room for every pair of this chunk after those kept so far (grown keeping them). An undecided
  // query is kept with the time before which the refinement excluded contact (staged toi): the
  // fallback need not search there.
  if (list.undecided.size() < list.num_undecided + m) {
    DeviceBuffer<FeatureHit<T>> bigger(std::max(list.num_undecided + m, 2 * list.undecided.size()));
    if (list.num_undecided)
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(bigger.data(), list.undecided.data(), list.num_undecided * sizeof(FeatureHit<T>),
                                        cudaMemcpyDeviceToDevice, list.stream));
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(list.stream));
    list.undecided = std::move(bigger);
  }
  grow_hits(list, list.count + m);
  select_flagged(list, list.staged.data(), list.flags.data(), list.undecided.data() + list.num_undecided, list.counters.data(), m);
  select_flagged(list, list.staged.data(), list.hit_flags.data(), list.hits.data() + list.count, list.counters.data() + 3, m);
  LWSCCD_CUDA_CHECK(cudaMemcpyAsync(list.host_counts, list.counters.data(), 4 * sizeof(unsigned long long),
                                    cudaMemcpyDeviceToHost, list.stream));
  return m;
}

template <class Method, class T, class Policy>
void NarrowPhase<Method, T, Policy>::collect_refined(List& list, std::size_t m) {
  list.refined += m;
  list.num_undecided += static_cast<std::size_t>(list.host_counts[0]);
  list.count += static_cast<std::size_t>(list.host_counts[3]);
  list.counts.certified_hits += static_cast<std::size_t>(list.host_counts[3]);
}

// The full test of to_test[begin, begin + m) on the list's stream, hits compacted after the
// list's earlier ones (hits has room for every survivor).
template <class Method, class T, class Policy>
template <class P, bool kVertexFace>
void NarrowPhase<Method, T, Policy>::launch_chunk(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                                  const CcdParams<T>& params, List& list, std::size_t begin, std::size_t m) {
  list.staged.resize_discard(std::max(list.staged.size(), m));
  list.flags.resize_discard(std::max(list.flags.size(), m));
  auto launch = [&](const auto* items) {
    if constexpr (lwsccd::detail::inclusion_search_of<FullTest>::value) {
      // A thread per query for a few rounds, then a warp per query still open.
      list.pending.resize_discard(std::max(list.pending.size(), m));
      list.pending_index.resize_discard(std::max(list.pending_index.size(), m));
      const unsigned thread_blocks = static_cast<unsigned>((m + Policy::kBlock - 1) / Policy::kBlock);
      detail::inclusion_thread_kernel<FullTest, kVertexFace, T, P, Policy::kThreadRounds, Policy::kThreadBoxes>
          <<<thread_blocks, Policy::kBlock, 0, list.stream>>>(mesh, x0, x1, items, m, params, list.staged.data(),
                                                              list.flags.data(), list.pending.data(), list.counters.data() + 1);
      LWSCCD_CUDA_CHECK_LAUNCH();
      select_flagged(list, thrust::counting_iterator<unsigned>(0), list.pending.data(), list.pending_index.data(),
                     list.counters.data() + 2, m);
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(list.host_counts + 2, list.counters.data() + 2, sizeof(unsigned long long),
                                        cudaMemcpyDeviceToHost, list.stream));
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(list.stream));
      const unsigned long long open = list.host_counts[2];
      list.warp_searches += static_cast<std::size_t>(open);
      if (open) {
        constexpr int kWarps = Policy::kSearchWarpsPerBlock;
        const unsigned blocks = static_cast<unsigned>((open + kWarps - 1) / kWarps);
        detail::inclusion_warp_kernel<FullTest, kVertexFace, T, P, kWarps><<<blocks, 32 * kWarps, 0, list.stream>>>(
            mesh, x0, x1, items, list.pending_index.data(), static_cast<std::size_t>(open), params, list.staged.data(),
            list.flags.data(), list.counters.data() + 1);
      }
    } else {
      const unsigned blocks = static_cast<unsigned>((m + Policy::kBlock - 1) / Policy::kBlock);
      detail::ccd_pairs_kernel<FullTest, kVertexFace, T, P><<<blocks, Policy::kBlock, 0, list.stream>>>(
          mesh, x0, x1, items, m, params, list.staged.data(), list.flags.data(), list.counters.data() + 1);
    }
    LWSCCD_CUDA_CHECK_LAUNCH();
  };
  if constexpr (kCertified) launch(list.undecided.data() + begin);
  else launch(list.to_test + begin);
  grow_hits(list, list.count + m);  // (one-pass methods: grown keeping the hits)
  select_flagged(list, list.staged.data(), list.flags.data(), list.hits.data() + list.count, list.counters.data(), m);
}

template <class Method, class T, class Policy>
NarrowPhaseResult<T> NarrowPhase<Method, T, Policy>::download(cudaStream_t stream) const {
  NarrowPhaseResult<T> r;
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
