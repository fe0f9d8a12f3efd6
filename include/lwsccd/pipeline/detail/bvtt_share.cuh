// lwsccd — a share of the self-collision BVTT for one of several devices: a cut of the BVTT made
// from the tree's topology alone (no volume is tested, so the cut is the same on every device that
// holds the same tree, whatever its positions), dealt out a node pair at a time.
//
// Every node pair of the BVTT lies under exactly one pair of the cut, and the cut's pairs are the
// BVTT's own (self pairs split into their children's self pairs and their mutual pair; other pairs
// split the node over more leaves), so traversing the shares of all devices finds each candidate
// triangle pair once. Levels are made breadth first in a fixed order (a count, a scan, a write), so
// the k-th pair of the cut is the same pair everywhere; pair k goes to share k mod count (pairs
// that are close in the tree, whose work is alike, go to different devices).
//
// Part of pipeline/gpu_pipeline.cuh: include that header, not this file.
#pragma once

#include <cub/device/device_scan.cuh>

#include "lwsccd/core/cuda_check.cuh"
#include "lwsccd/core/device_buffer.cuh"
#include "lwsccd/traversal/bvtt.hpp"

namespace lwsccd::gpu::detail {

// The children of `p` in the topology cut, written to `out` (at most 3); returns how many. A pair
// of two leaves is kept as it is (its one child is itself); pruned pairs and a leaf's self pair
// have none (the traversal would find nothing under them).
template <class BV>
LWSCCD_HD int topology_children(const BvhView<BV>& bvh, const LeafFilter& filter, const NodePair& p, NodePair* out) {
  if (filter.prunes(p.a, p.b)) return 0;
  if (p.a == p.b) {
    if (bvh.is_leaf(p.a)) return 0;
    const index_t l = bvh.left[p.a], r = bvh.right[p.a];
    out[0] = NodePair{l, l};
    out[1] = NodePair{r, r};
    out[2] = NodePair{l, r};
    return 3;
  }
  const bool leaf_a = bvh.is_leaf(p.a), leaf_b = bvh.is_leaf(p.b);
  if (leaf_a && leaf_b) {
    out[0] = p;
    return 1;
  }
  auto leaves = [&](index_t node) { return bvh.ranges[node].last - bvh.ranges[node].first + 1; };
  if (leaf_a || (!leaf_b && leaves(p.b) > leaves(p.a))) {
    out[0] = NodePair{p.a, bvh.left[p.b]};
    out[1] = NodePair{p.a, bvh.right[p.b]};
  } else {
    out[0] = NodePair{bvh.left[p.a], p.b};
    out[1] = NodePair{bvh.right[p.a], p.b};
  }
  return 2;
}

// Per pair of the level: its number of children (low half) and whether it changed (high half: all
// but a kept pair of leaves), packed for one scan.
template <class BV>
__global__ void cut_count_kernel(BvhView<BV> bvh, LeafFilter filter, const NodePair* level, std::size_t n,
                                 unsigned long long* counts) {
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  NodePair children[3];
  const int k = topology_children(bvh, filter, level[i], children);
  const bool kept = k == 1 && children[0].a == level[i].a && children[0].b == level[i].b;
  counts[i] = (static_cast<unsigned long long>(kept ? 0 : 1) << 32) | static_cast<unsigned>(k);
}

// Writes each pair's children at its place (the inclusive scan less its own count).
template <class BV>
__global__ void cut_write_kernel(BvhView<BV> bvh, LeafFilter filter, const NodePair* level, std::size_t n,
                                 const unsigned long long* inclusive, NodePair* next) {
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  NodePair children[3];
  const int k = topology_children(bvh, filter, level[i], children);
  const std::size_t at = static_cast<std::size_t>(inclusive[i] & 0xffffffffull) - static_cast<std::size_t>(k);
  for (int c = 0; c < k; ++c) next[at + c] = children[c];
}

// Share `index` of `count`: pairs index, index + count, index + 2 count, ... of the cut.
template <class Pair>
__global__ void cut_share_kernel(const Pair* cut, std::size_t index, std::size_t count, std::size_t n, Pair* share) {
  const std::size_t j = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (j < n) share[j] = cut[index + j * count];
}

/// Makes the topology cut and hands out one device's share of it. Owns its level lists (reused).
class BvttShareCut {
 public:
  /// Expands the root breadth first until a level holds at least `target` pairs (or nothing more
  /// splits), writes share `index` of `count` of that level to `share` and returns its length.
  /// Waits for each level's count (a step from the root only; ~one level per doubling).
  template <class BV>
  std::size_t make(const BvhView<BV>& bvh, const LeafFilter& filter, std::size_t target, std::size_t index,
                   std::size_t count, DeviceBuffer<NodePair>& share, cudaStream_t stream) {
    constexpr int kThreads = 256;
    std::size_t n = bvh.num_leaves > 1 ? 1 : 0;  // a one-triangle tree has no pair
    level_[0].resize_discard(1);
    const NodePair root{0, 0};
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(level_[0].data(), &root, sizeof(NodePair), cudaMemcpyHostToDevice, stream));
    total_.ensure(1);
    int at = 0;
    while (n > 0 && n < target) {
      counts_.resize_discard(n);
      const unsigned blocks = static_cast<unsigned>((n + kThreads - 1) / kThreads);
      cut_count_kernel<<<blocks, kThreads, 0, stream>>>(bvh, filter, level_[at].data(), n, counts_.data());
      LWSCCD_CUDA_CHECK_LAUNCH();
      std::size_t bytes = 0;
      LWSCCD_CUDA_CHECK(cub::DeviceScan::InclusiveSum(nullptr, bytes, counts_.data(), counts_.data(), static_cast<std::int64_t>(n), stream));
      scratch_.resize_discard(std::max<std::size_t>(bytes, 1));
      LWSCCD_CUDA_CHECK(
          cub::DeviceScan::InclusiveSum(scratch_.data(), bytes, counts_.data(), counts_.data(), static_cast<std::int64_t>(n), stream));
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(total_.data(), counts_.data() + n - 1, sizeof(unsigned long long), cudaMemcpyDeviceToHost, stream));
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
      const std::size_t next = static_cast<std::size_t>(total_[0] & 0xffffffffull);
      if ((total_[0] >> 32) == 0) break;  // only pairs of leaves left: the cut is the whole BVTT's leaves
      level_[1 - at].resize_discard(std::max<std::size_t>(next, 1));
      cut_write_kernel<<<blocks, kThreads, 0, stream>>>(bvh, filter, level_[at].data(), n, counts_.data(), level_[1 - at].data());
      LWSCCD_CUDA_CHECK_LAUNCH();
      at = 1 - at;
      n = next;
    }
    const std::size_t mine = n > index ? (n - index + count - 1) / count : 0;
    share.resize_discard(std::max<std::size_t>(mine, 1));
    if (mine) {
      cut_share_kernel<<<static_cast<unsigned>((mine + kThreads - 1) / kThreads), kThreads, 0, stream>>>(level_[at].data(), index,
                                                                                                      count, mine, share.data());
      LWSCCD_CUDA_CHECK_LAUNCH();
    }
    cut_size_ = n;
    return mine;
  }
  /// The whole cut's length at the last make() (every share's seeds together).
  std::size_t cut_size() const { return cut_size_; }
  std::size_t device_bytes() const {
    return level_[0].capacity_bytes() + level_[1].capacity_bytes() + counts_.capacity_bytes() + scratch_.capacity_bytes();
  }

 private:
  DeviceBuffer<NodePair> level_[2];
  DeviceBuffer<unsigned long long> counts_;
  DeviceBuffer<unsigned char> scratch_;
  PinnedBuffer<unsigned long long> total_;
  std::size_t cut_size_ = 0;
};

}  // namespace lwsccd::gpu::detail
