// lwsccd — kernels and definitions for narrow_phase.cuh.
#pragma once

#include <thrust/iterator/transform_iterator.h>

#include "lwsccd/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase.cuh"

namespace lwsccd::gpu {

namespace detail {

template <class Method, bool kVertexFace, class T, class P>
__global__ void ccd_pairs_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                 const std::pair<index_t, index_t>* pairs, std::size_t n, CcdParams<T> params,
                                 FeatureHit<T>* staged, unsigned char* flags, unsigned long long* gave_up) {
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const std::pair<index_t, index_t> p = pairs[i];
  CcdResult<T> r;
  if constexpr (kVertexFace) {
    r = Method::vertex_face(gather_vertex_face<T>(mesh, x0, x1, p.first, p.second), params);
  } else {
    r = Method::edge_edge(gather_edge_edge<T>(mesh, x0, x1, p.first, p.second), params);
  }
  staged[i] = FeatureHit<T>{p.first, p.second, r.toi};
  flags[i] = r.hit ? 1 : 0;
  if (r.gave_up) atomicAdd(gave_up, 1ull);
}

// First pass: flags the pairs that the method's first step does not already reject.
template <class Method, bool kVertexFace, class T, class P>
__global__ void quick_reject_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                    const std::pair<index_t, index_t>* pairs, std::size_t n, CcdParams<T> params,
                                    unsigned char* keep) {
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const std::pair<index_t, index_t> p = pairs[i];
  bool rejected;
  if constexpr (kVertexFace) {
    rejected = Method::quick_reject(gather_vertex_face<T>(mesh, x0, x1, p.first, p.second), params);
  } else {
    rejected = Method::quick_reject(gather_edge_edge<T>(mesh, x0, x1, p.first, p.second), params);
  }
  keep[i] = rejected ? 0 : 1;
}

// Second pass for InclusionCcd (filtered or not): a warp per query. Lane 0 keeps the search's
// heap in shared memory and forms each round; the lanes examine the round's boxes at once. Same
// rounds as the one-thread search, hence the same answers, with a long search's latency cut by up
// to the round size.
template <class Method, bool kVertexFace, class T, class P, int kWarps>
__global__ void __launch_bounds__(32 * kWarps)
    inclusion_warp_kernel(MeshFeatures mesh, const Vec3<P>* x0, const Vec3<P>* x1, const std::pair<index_t, index_t>* pairs,
                          std::size_t n, CcdParams<T> params, FeatureHit<T>* staged, unsigned char* flags,
                          unsigned long long* gave_up) {
  using Traits = lwsccd::detail::inclusion_search_of<Method>;
  using Search = lwsccd::detail::InclusionSearch<typename Traits::policy, T>;
  using Round = typename Search::Round;
  using lwsccd::detail::BoxVerdict;
  static_assert(Traits::policy::kBatch <= 32, "lwsccd: a round must fit in a warp");
  // Raw storage: shared variables cannot have constructors; start() initializes a search.
  __shared__ alignas(Search) unsigned char storage[kWarps * sizeof(Search)];
  __shared__ BoxVerdict verdicts[kWarps][32];
  __shared__ CcdResult<T> results[kWarps];
  __shared__ int state[kWarps];
  const int warp = static_cast<int>(threadIdx.x) / 32, lane = static_cast<int>(threadIdx.x) % 32;
  Search& search = reinterpret_cast<Search*>(storage)[warp];
  for (std::size_t i = static_cast<std::size_t>(blockIdx.x) * kWarps + warp; i < n;
       i += static_cast<std::size_t>(gridDim.x) * kWarps) {
    const std::pair<index_t, index_t> p = pairs[i];
    CcdResult<T> r;
    auto solve = [&](const auto& q) {
      if (Traits::filtered && !non_penetration_filter(q, params)) return;
      const auto setup = lwsccd::detail::inclusion_setup(q, params);
      if (setup.separated) return;
      if (lane == 0) search.start();
      __syncwarp();
      while (true) {
        if (lane == 0) state[warp] = static_cast<int>(search.next_round(params.max_iterations, results[warp]));
        __syncwarp();
        const Round round = static_cast<Round>(state[warp]);
        if (round != Round::examine) {
          if (round == Round::gave_up) r = results[warp];
          return;
        }
        if (lane < search.batch_size)
          verdicts[warp][lane] = lwsccd::detail::examine_box(q, setup, search.batch[lane], search.floor_key, search.t_floor);
        __syncwarp();
        if (lane == 0) state[warp] = search.apply(verdicts[warp], setup.vf, results[warp]) ? 1 : 0;
        __syncwarp();
        const bool done = state[warp] != 0;
        if (done) r = results[warp];
        __syncwarp();  // everyone has read before lane 0 writes again
        if (done) return;
      }
    };
    if constexpr (kVertexFace) solve(gather_vertex_face<T>(mesh, x0, x1, p.first, p.second));
    else solve(gather_edge_edge<T>(mesh, x0, x1, p.first, p.second));
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

template <class T>
struct MinOp {
  LWSCCD_HD T operator()(T a, T b) const { return b < a ? b : a; }
};

}  // namespace detail

template <class Method, class T, class Policy>
template <class P>
void NarrowPhase<Method, T, Policy>::run(const DeviceMeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                         const Pair* vf, std::size_t num_vf, const Pair* ee, std::size_t num_ee,
                                         const CcdParams<T>& params, cudaStream_t stream) {
  vf_count_ = ee_count_ = gave_up_ = 0;
  earliest_ = T(1);
  counters_.resize_discard(2);
  LWSCCD_CUDA_CHECK(cudaMemsetAsync(counters_.data(), 0, 2 * sizeof(unsigned long long), stream));
  run_list<P, true>(mesh.view(), x0, x1, vf, num_vf, params, vf_hits_, vf_count_, stream);
  run_list<P, false>(mesh.view(), x0, x1, ee, num_ee, params, ee_hits_, ee_count_, stream);
  unsigned long long gave = 0;
  LWSCCD_CUDA_CHECK(cudaMemcpyAsync(&gave, counters_.data() + 1, sizeof gave, cudaMemcpyDeviceToHost, stream));
  // Earliest TOI over both lists.
  toi_.resize_discard(1);
  for (int list = 0; list < 2; ++list) {
    const std::size_t count = list == 0 ? vf_count_ : ee_count_;
    if (count == 0) continue;
    const FeatureHit<T>* hits = list == 0 ? vf_hits_.data() : ee_hits_.data();
    const auto tois = thrust::make_transform_iterator(hits, detail::HitToi<T>{});
    std::size_t bytes = 0;
    LWSCCD_CUDA_CHECK(cub::DeviceReduce::Reduce(nullptr, bytes, tois, toi_.data(), static_cast<std::int64_t>(count),
                                                detail::MinOp<T>{}, T(1), stream));
    scratch_.resize_discard(std::max(bytes, scratch_.size()));
    LWSCCD_CUDA_CHECK(cub::DeviceReduce::Reduce(scratch_.data(), bytes, tois, toi_.data(),
                                                static_cast<std::int64_t>(count), detail::MinOp<T>{}, T(1), stream));
    T list_min = T(1);
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(&list_min, toi_.data(), sizeof(T), cudaMemcpyDeviceToHost, stream));
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
    earliest_ = list_min < earliest_ ? list_min : earliest_;
  }
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
  gave_up_ = static_cast<std::size_t>(gave);
}

template <class Method, class T, class Policy>
template <class P, bool kVertexFace>
void NarrowPhase<Method, T, Policy>::run_list(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                              const Pair* pairs, std::size_t n, const CcdParams<T>& params,
                                              DeviceBuffer<FeatureHit<T>>& out, std::size_t& count,
                                              cudaStream_t stream) {
  count = 0;
  if (n == 0) return;
  const std::size_t chunk = std::min(chunk_, n);
  staged_.resize_discard(std::max(staged_.size(), chunk));
  flags_.resize_discard(std::max(flags_.size(), chunk));
  if (out.size() < initial_capacity_) out.resize_discard(initial_capacity_);
  std::size_t select_bytes = 0;
  LWSCCD_CUDA_CHECK(cub::DeviceSelect::Flagged(nullptr, select_bytes, staged_.data(), flags_.data(), out.data(),
                                               counters_.data(), static_cast<std::int64_t>(chunk), stream));
  scratch_.resize_discard(std::max(select_bytes, scratch_.size()));
  for (std::size_t begin = 0; begin < n; begin += chunk) {
    const std::size_t m = std::min(chunk, n - begin);
    // Grow (keeping what is there) until a whole chunk of hits fits: nothing is ever dropped.
    if (out.size() - count < m) {
      std::size_t capacity = out.size();
      while (capacity - count < m) capacity *= 2;
      DeviceBuffer<FeatureHit<T>> bigger(capacity);
      if (count)
        LWSCCD_CUDA_CHECK(cudaMemcpyAsync(bigger.data(), out.data(), count * sizeof(FeatureHit<T>),
                                          cudaMemcpyDeviceToDevice, stream));
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
      out = std::move(bigger);
    }
    const Pair* chunk_pairs = pairs + begin;
    std::size_t tested = m;
    if constexpr (lwsccd::detail::has_quick_reject<Method>::value) {
      // Two passes: the cheap first step for every pair, then the full method on the survivors
      // only, compacted so that whole warps run the long searches together.
      survivors_.resize_discard(std::max(survivors_.size(), chunk));
      const unsigned quick_blocks = static_cast<unsigned>((m + Policy::kBlock - 1) / Policy::kBlock);
      detail::quick_reject_kernel<Method, kVertexFace, T, P><<<quick_blocks, Policy::kBlock, 0, stream>>>(
          mesh, x0, x1, chunk_pairs, m, params, flags_.data());
      LWSCCD_CUDA_CHECK_LAUNCH();
      // Compacted as 64-bit words: std::pair's assignment is host-only (a pair of 32-bit ids is
      // 8 bytes, and device allocations and chunk offsets are 8-byte aligned).
      static_assert(sizeof(Pair) == sizeof(unsigned long long), "lwsccd: a feature pair must be two 32-bit ids");
      const auto* words = reinterpret_cast<const unsigned long long*>(chunk_pairs);
      std::size_t pair_bytes = 0;
      LWSCCD_CUDA_CHECK(cub::DeviceSelect::Flagged(nullptr, pair_bytes, words, flags_.data(), survivors_.data(),
                                                   counters_.data(), static_cast<std::int64_t>(m), stream));
      pair_scratch_.resize_discard(std::max(pair_bytes, pair_scratch_.size()));
      LWSCCD_CUDA_CHECK(cub::DeviceSelect::Flagged(pair_scratch_.data(), pair_bytes, words, flags_.data(),
                                                   survivors_.data(), counters_.data(), static_cast<std::int64_t>(m), stream));
      unsigned long long kept = 0;
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(&kept, counters_.data(), sizeof kept, cudaMemcpyDeviceToHost, stream));
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
      chunk_pairs = reinterpret_cast<const Pair*>(survivors_.data());
      tested = static_cast<std::size_t>(kept);
    }
    if (tested == 0) continue;
    if constexpr (lwsccd::detail::inclusion_search_of<Method>::value) {
      constexpr int kWarps = Policy::kSearchWarpsPerBlock;
      const unsigned blocks = static_cast<unsigned>((tested + kWarps - 1) / kWarps);
      detail::inclusion_warp_kernel<Method, kVertexFace, T, P, kWarps><<<blocks, 32 * kWarps, 0, stream>>>(
          mesh, x0, x1, chunk_pairs, tested, params, staged_.data(), flags_.data(), counters_.data() + 1);
    } else {
      const unsigned blocks = static_cast<unsigned>((tested + Policy::kBlock - 1) / Policy::kBlock);
      detail::ccd_pairs_kernel<Method, kVertexFace, T, P><<<blocks, Policy::kBlock, 0, stream>>>(
          mesh, x0, x1, chunk_pairs, tested, params, staged_.data(), flags_.data(), counters_.data() + 1);
    }
    LWSCCD_CUDA_CHECK_LAUNCH();
    std::size_t bytes = scratch_.size();
    LWSCCD_CUDA_CHECK(cub::DeviceSelect::Flagged(scratch_.data(), bytes, staged_.data(), flags_.data(), out.data() + count,
                                                 counters_.data(), static_cast<std::int64_t>(tested), stream));
    unsigned long long selected = 0;
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(&selected, counters_.data(), sizeof selected, cudaMemcpyDeviceToHost, stream));
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
    count += static_cast<std::size_t>(selected);
  }
}

template <class Method, class T, class Policy>
NarrowPhaseResult<T> NarrowPhase<Method, T, Policy>::download(cudaStream_t stream) const {
  NarrowPhaseResult<T> r;
  auto fetch = [&](const DeviceBuffer<FeatureHit<T>>& buffer, std::size_t count, std::vector<FeatureHit<T>>& dst) {
    dst.resize(count);
    if (count)
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(dst.data(), buffer.data(), count * sizeof(FeatureHit<T>), cudaMemcpyDeviceToHost, stream));
  };
  fetch(vf_hits_, vf_count_, r.vf);
  fetch(ee_hits_, ee_count_, r.ee);
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
  std::sort(r.vf.begin(), r.vf.end());
  std::sort(r.ee.begin(), r.ee.end());
  r.earliest_toi = earliest_;
  r.gave_up = gave_up_;
  return r;
}

}  // namespace lwsccd::gpu
