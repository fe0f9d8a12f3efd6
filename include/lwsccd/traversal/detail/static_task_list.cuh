// lwsccd — StaticTaskList: the start expanded to a cut, split evenly over the blocks, each block
// finishing its share on its own stack.
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

// StaticTaskList: block b takes its even share of the cut and runs it to completion.
template <class Task, class Policy>
__global__ void __launch_bounds__(Policy::kBlockThreads) static_list_kernel(Task task, const typename Task::item_type* work,
                                                                            std::size_t n, typename Task::item_type* stacks,
                                                                            int global_capacity, Outputs<Task> out,
                                                                            typename Task::item_type* hand_back) {
  const std::size_t begin = n * blockIdx.x / gridDim.x, end = n * (blockIdx.x + 1) / gridDim.x;
  typename Task::item_type* region = stacks + static_cast<std::size_t>(blockIdx.x) * global_capacity;
  __shared__ int region_size;
  // The share (at most ~kItemsPerBlock items) starts in the block's global stack, reversed so
  // that the first item is processed first.
  const int count = static_cast<int>(end - begin);
  for (int i = threadIdx.x; i < count; i += blockDim.x) region[count - 1 - i] = work[begin + i];
  if (threadIdx.x == 0) region_size = count;
  __syncthreads();
  __shared__ BlockStackStorage<Task, Policy> stack;
  run_block_stack<Task, Policy>(task, region, region_size, global_capacity, out, nullptr, 0, hand_back, stack);
}


// One complete attempt with the current output capacities.
template <class Task, class Policy>
void run_static(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds, TraversalStorage<Task>& out,
                bool record_front, cudaStream_t stream) {
  using Item = typename Task::item_type;
  const int max_blocks = resident_blocks(Policy::kBlocksPerSm);
  const std::size_t target = static_cast<std::size_t>(max_blocks) * Policy::kItemsPerBlock;
  int global_capacity = Policy::kGlobalStack;
  std::size_t n = expand_breadth_first(task, seeds, num_seeds, target, out, record_front, stream);
  // Blocks finish their shares; items handed back (a full global stack) are run again.
  while (n > 0) {
    const int blocks = static_cast<int>(std::min<std::size_t>(max_blocks, (n + Policy::kItemsPerBlock - 1) / Policy::kItemsPerBlock));
    while ((n + blocks - 1) / blocks > static_cast<std::size_t>(global_capacity) / 2) global_capacity *= 2;  // shares fit
    ensure(out.stacks_, static_cast<std::size_t>(blocks) * global_capacity);
    ensure(out.next_, static_cast<std::size_t>(blocks) * (global_capacity + Policy::kSharedStack));
    LWSCCD_CUDA_CHECK(cudaMemsetAsync(out.counters_.data() + kAppended, 0, 4 * sizeof(unsigned long long), stream));
    static_list_kernel<Task, Policy><<<blocks, Policy::kBlockThreads, 0, stream>>>(
        task, out.work_.data(), n, out.stacks_.data(), global_capacity, outputs_of(out, record_front), out.next_.data());
    LWSCCD_CUDA_CHECK_LAUNCH();
    const auto c = read_counters(out, stream);
    n = static_cast<std::size_t>(c[kAppended]);
    std::swap(out.work_, out.next_);
    if (c[kOverflow] != 0) {  // blocks handed back their items because the outputs were full
      if (!absorb_overflow(out, c, stream)) return;  // stopped at the output limit (incomplete)
      continue;
    }
    if (c[kHalted] > 0) {
      ++out.stats_.relaunches;
      global_capacity *= 2;  // the next launch has room to make progress
    }
  }
}

}  // namespace lwsccd::gpu::detail
