// lwsccd — Karras's independent traversal (NVIDIA blog "Thinking Parallel, Part II", 2012): the
// baseline the schedulers are measured against. One thread per leaf, in Morton order, queries
// the whole BVH with its leaf's volume and an explicit stack; a subtree whose rightmost leaf is
// not after the query leaf is skipped, so each unordered pair is found once (by its lower leaf)
// and no leaf meets itself. Same results as SelfCollisionTask (tested), no front.
#pragma once

#include <cuda_runtime.h>

#include "lwsccd/traversal/bvtt.hpp"
#include "lwsccd/traversal/gpu_traverse.cuh"

namespace lwsccd::gpu {

/// Knobs of the independent traversal.
struct IndependentTraversalPolicy {
  static constexpr int kBlockThreads = 128;
  /// Per-thread stack: deeper than any LBVH (63 code bits + 32 index bits of split levels).
  static constexpr int kStackDepth = 128;
};

namespace detail {

template <class BV, class Policy>
__global__ void __launch_bounds__(Policy::kBlockThreads)
    independent_self_kernel(SelfCollisionTask<BV> task, Outputs<SelfCollisionTask<BV>> out) {
  const BvhView<BV>& bvh = task.bvh;
  const index_t k = static_cast<index_t>(blockIdx.x * blockDim.x + threadIdx.x);
  if (k >= bvh.num_leaves) return;
  const index_t query_node = bvh.leaf_node(k);
  const BV query = bvh.bvs[query_node];
  const index_t query_primitive = bvh.leaf_primitive[k];
  // The results of this thread are appended one by one (as in the blog's list.add).
  DeviceEmitter<SelfCollisionTask<BV>> e;
  index_t stack[Policy::kStackDepth];
  int top = 0;
  index_t node = BvhView<BV>::root();
  unsigned long long visited = 0;
  if (bvh.is_leaf(node)) return;  // a single triangle has no pairs
  while (true) {
    ++visited;
    const index_t children[2] = {bvh.left[node], bvh.right[node]};
    bool descend[2] = {false, false};
    for (int c = 0; c < 2; ++c) {
      const index_t child = children[c];
      if (bvh.ranges[child].last <= k) continue;  // entirely at or before the query leaf
      if (!bv_traits<BV>::overlap(query, bvh.bvs[child])) continue;
      if (bvh.is_leaf(child)) {
        e.num_results = 0;
        task.emit_leaf_pair(query_primitive, bvh.primitive(child), e);
        if (e.num_results) {
          const unsigned long long i = atomicAdd(&out.counters[kOutputs], 1ull);  // (the low half: results)
          if (i < out.result_capacity) out.results[i] = e.results[0];
        }
      } else {
        descend[c] = true;
      }
    }
    if (descend[0] && descend[1]) {
      assert(top < Policy::kStackDepth && "independent traversal: stack depth exceeded");
      stack[top++] = children[1];
      node = children[0];
    } else if (descend[0] || descend[1]) {
      node = descend[0] ? children[0] : children[1];
    } else if (top > 0) {
      node = stack[--top];
    } else {
      break;
    }
  }
  atomicAdd(&out.counters[kProcessed], visited);
}

}  // namespace detail

/// All self-collision candidate pairs by independent per-leaf traversals. Uses `out` like
/// traverse() does (results grow and the launch reruns when they overflow); records no front.
template <class BV, class Policy = IndependentTraversalPolicy>
void independent_self_traversal(const SelfCollisionTask<BV>& task, TraversalOutput<SelfCollisionTask<BV>>& output,
                                cudaStream_t stream = nullptr) {
  detail::TraversalStorage<SelfCollisionTask<BV>>& out = detail::storage_of(output);
  detail::ensure(out.counters_, detail::kCounters);
  out.halt_on_overflow_ = false;  // (its own loop: the launch reruns with room for the count)
  if (out.results_.size() == 0) out.results_.resize_discard(1 << 16);
  if (out.front_.size() == 0) out.front_.resize_discard(1);
  out.stats_ = {};
  const index_t n = task.bvh.num_leaves;
  while (true) {
    LWSCCD_CUDA_CHECK(cudaMemsetAsync(out.counters_.data(), 0, detail::kCounters * sizeof(unsigned long long), stream));
    if (n > 1) {
      const unsigned blocks = static_cast<unsigned>((n + Policy::kBlockThreads - 1) / Policy::kBlockThreads);
      detail::independent_self_kernel<BV, Policy><<<blocks, Policy::kBlockThreads, 0, stream>>>(
          task, detail::outputs_of(out, false));
      LWSCCD_CUDA_CHECK_LAUNCH();
    }
    const auto c = detail::read_counters(out, stream);
    const std::size_t results = detail::results_of(c[detail::kOutputs]);
    out.stats_.items_processed = static_cast<std::size_t>(c[detail::kProcessed]);
    if (results <= out.results_.size()) {
      out.num_results_ = results;
      out.num_front_ = 0;
      out.stats_.results = results;
      return;
    }
    out.results_.resize_discard(results + results / 4);
    ++out.stats_.relaunches;
  }
}

}  // namespace lwsccd::gpu
