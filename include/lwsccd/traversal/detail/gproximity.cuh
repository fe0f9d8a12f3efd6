// lwsccd — GProximityBalancer: per-block queues, a traversal kernel that stops when too many
// blocks idle, and a balancing kernel that spreads the queues again, looped from the host
// (dissertation Algorithms 3.1-3.4).
// Part of traverse_kernels.cuh: include <lwsccd/traverse.cuh>, not this file.
#pragma once

#include <cub/block/block_reduce.cuh>
#include <cub/block/block_scan.cuh>
#include <cuda/atomic>

#include <algorithm>
#include <atomic>
#include <cassert>
#include <string>
#include <type_traits>

#include "lwsccd/core/error.hpp"
#include "lwsccd/traversal/gpu_traverse.cuh"
#include "lwsccd/traversal/detail/block_rounds.cuh"
#include "lwsccd/traversal/detail/launch.cuh"

namespace lwsccd::gpu::detail {

// gProximity traversal kernel: each block runs its queue until it is empty (then counts itself
// idle and leaves) or until enough blocks idle; what remains stays in its queue.
template <class Task, class Policy>
__global__ void __launch_bounds__(Policy::kBlockThreads) balanced_traverse_kernel(Task task, typename Task::item_type* queues,
                                                                                  int* sizes, int queue_capacity,
                                                                                  unsigned idle_limit, Outputs<Task> out,
                                                                                  typename Task::item_type* hand_back) {
  typename Task::item_type* region = queues + static_cast<std::size_t>(blockIdx.x) * queue_capacity;
  __shared__ int region_size;
  if (threadIdx.x == 0) region_size = sizes[blockIdx.x];
  __syncthreads();
  __shared__ BlockStackStorage<Task, Policy> stack;
  run_block_stack<Task, Policy>(task, region, region_size, queue_capacity, out, &out.counters[kIdle], idle_limit, hand_back,
                                stack);
  __syncthreads();
  if (threadIdx.x == 0) {
    sizes[blockIdx.x] = region_size;
    if (region_size == 0) atomicAdd(&out.counters[kIdle], 1ull);
  }
}

// Moves each block's queue (its first sizes[b] items) into queues of a larger capacity. Only the
// items are read: the rest of a queue was never written (compute-sanitizer's initcheck flagged
// the whole-queue copy this replaced).
template <class Item>
__global__ void grow_queues_kernel(const Item* queues, const int* sizes, int capacity, Item* grown, int grown_capacity) {
  const int b = blockIdx.x, n = sizes[b];
  for (int i = threadIdx.x; i < n; i += blockDim.x)
    grown[static_cast<std::size_t>(b) * grown_capacity + i] = queues[static_cast<std::size_t>(b) * capacity + i];
}

// gProximity balancing kernel (one block): prefix sums of the queue sizes, then every item moves
// to its even share in the other set of queues; handed-back items are appended after the queues.
template <class Item>
__global__ void balance_kernel(const Item* queues, const int* sizes, int blocks, int queue_capacity, const Item* extra,
                               const unsigned long long* extra_count, Item* new_queues, int* new_sizes,
                               unsigned long long* total_out) {
  __shared__ unsigned long long total;
  extern __shared__ unsigned long long prefix[];  // blocks + 1
  if (threadIdx.x == 0) {
    prefix[0] = 0;
    for (int b = 0; b < blocks; ++b) prefix[b + 1] = prefix[b] + static_cast<unsigned long long>(sizes[b]);
    total = prefix[blocks] + *extra_count;
    *total_out = total;
  }
  __syncthreads();
  for (int b = threadIdx.x; b < blocks; b += blockDim.x)
    new_sizes[b] = static_cast<int>(total * (b + 1) / blocks - total * b / blocks);
  // Item k of the concatenation goes to block b with k in [total*b/blocks, total*(b+1)/blocks).
  for (unsigned long long k = threadIdx.x; k < total; k += blockDim.x) {
    Item x;
    if (k < prefix[blocks]) {
      int lo = 0, hi = blocks - 1;  // block holding k
      while (lo < hi) {
        const int mid = (lo + hi + 1) / 2;
        if (prefix[mid] <= k) lo = mid;
        else hi = mid - 1;
      }
      x = queues[static_cast<std::size_t>(lo) * queue_capacity + (k - prefix[lo])];
    } else {
      x = extra[k - prefix[blocks]];
    }
    int owner = static_cast<int>(k * blocks / total);
    while (owner > 0 && total * owner / blocks > k) --owner;
    while (total * (owner + 1) / blocks <= k) ++owner;
    new_queues[static_cast<std::size_t>(owner) * queue_capacity + (k - total * owner / blocks)] = x;
  }
}


template <class Task, class Policy>
void run_balanced(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds, TraversalStorage<Task>& out,
                  bool record_front, cudaStream_t stream) {
  using Item = typename Task::item_type;
  const int blocks = resident_blocks(Policy::kBlocksPerSm);
  int capacity = Policy::kGlobalStack + Policy::kSharedStack;  // a queue always takes a block's leftovers
  while (static_cast<std::size_t>(capacity) * blocks < num_seeds) capacity *= 2;
  ensure(out.stacks_, static_cast<std::size_t>(blocks) * capacity);
  ensure(out.stacks_alt_, static_cast<std::size_t>(blocks) * capacity);
  ensure(out.sizes_, blocks);
  ensure(out.sizes_alt_, blocks);
  ensure(out.next_, std::max<std::size_t>(num_seeds, static_cast<std::size_t>(blocks) * (capacity + Policy::kSharedStack)));
  // The seeds enter through the balancing kernel as "extra" items.
  if (num_seeds)
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(out.next_.data(), seeds, num_seeds * sizeof(Item), cudaMemcpyDeviceToDevice, stream));
  LWSCCD_CUDA_CHECK(cudaMemsetAsync(out.sizes_.data(), 0, blocks * sizeof(int), stream));
  unsigned long long extra = num_seeds;
  const unsigned idle_limit = std::max(1u, static_cast<unsigned>(blocks * Policy::kIdlePercent / 100));
  while (true) {
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(out.counters_.data() + kAppended, &extra, sizeof extra, cudaMemcpyHostToDevice, stream));
    const std::size_t shared_bytes = (blocks + 1) * sizeof(unsigned long long);
    balance_kernel<Item><<<1, 1024, shared_bytes, stream>>>(out.stacks_.data(), out.sizes_.data(), blocks, capacity,
                                                            out.next_.data(), out.counters_.data() + kAppended,
                                                            out.stacks_alt_.data(), out.sizes_alt_.data(),
                                                            out.counters_.data() + kIdle);
    LWSCCD_CUDA_CHECK_LAUNCH();
    std::swap(out.stacks_, out.stacks_alt_);
    std::swap(out.sizes_, out.sizes_alt_);
    const auto c = read_counters(out, stream);
    const unsigned long long total = c[kIdle];  // the balancing kernel left the total there
    if (total == 0) break;
    LWSCCD_CUDA_CHECK(cudaMemsetAsync(out.counters_.data() + kAppended, 0, 3 * sizeof(unsigned long long), stream));
    ensure(out.next_, static_cast<std::size_t>(blocks) * (capacity + Policy::kSharedStack));  // hand-backs fit
    balanced_traverse_kernel<Task, Policy><<<blocks, Policy::kBlockThreads, 0, stream>>>(
        task, out.stacks_.data(), out.sizes_.data(), capacity, idle_limit, outputs_of(out, record_front), out.next_.data());
    LWSCCD_CUDA_CHECK_LAUNCH();
    const auto after = read_counters(out, stream);
    extra = after[kAppended];
    if (after[kOverflow] != 0) {  // blocks handed back their items because the outputs were full
      if (!absorb_overflow(out, after, stream)) return;  // stopped at the output limit (incomplete)
      continue;
    }
    if (after[kHalted] > 0) {
      // Queues too small for the work: grow them (contents move through the balancing kernel).
      ++out.stats_.relaunches;
      const int grown = capacity * 2;
      DeviceBuffer<Item> bigger(static_cast<std::size_t>(blocks) * grown);
      grow_queues_kernel<Item><<<blocks, 256, 0, stream>>>(out.stacks_.data(), out.sizes_.data(), capacity, bigger.data(), grown);
      LWSCCD_CUDA_CHECK_LAUNCH();
      out.stacks_ = std::move(bigger);
      out.stacks_alt_ = DeviceBuffer<Item>(static_cast<std::size_t>(blocks) * grown);
      capacity = grown;
    }
  }
}

}  // namespace lwsccd::gpu::detail
