// lwsccd — kernels and host loops of traverse.cuh.
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

namespace lwsccd::gpu {

namespace detail {

enum Counter : int {
  kResults = 0,    ///< results appended (may exceed the capacity: then the output grows)
  kFront = 1,      ///< front items appended (same)
  kProcessed = 2,  ///< items processed
  kAppended = 3,   ///< items appended to the next list (expansion) or handed back (resume)
  kIdle = 4,       ///< blocks that ran out of work (gProximity)
  kHalted = 5,     ///< blocks that stopped because their global stack was full
  kLevels = 6,     ///< breadth-first levels one block expanded in one launch (expand_small_levels_kernel)
  kPending = 7,    ///< LazyStealScheduler: the live items of a launch (see the termination note)
  kStartItems = 8,  ///< LazyStealScheduler: the length of the launch's start list
  kStartTaken = 9,  ///< LazyStealScheduler: how much of the start list blocks have taken
  kLost = 10,       ///< LazyStealScheduler: items a list had no room for (the pass is rerun with more)
  kHungry = 11,     ///< LazyStealScheduler: blocks in a search for work (kShareWhenHungry)
  kCounters = 12
};

template <class Task>
struct Outputs {
  typename Task::result_type* results;
  std::size_t result_capacity;
  typename Task::item_type* front;
  std::size_t front_capacity;
  unsigned long long* counters;
  bool record_front;
};

// Collects one item's children, results and front entry in registers; the block appends them
// together afterwards (flush_outputs), one atomic per block and round.
template <class Task>
struct DeviceEmitter {
  using Item = typename Task::item_type;
  using Result = typename Task::result_type;
  Item children[Task::kMaxChildren];
  Result results[Task::kMaxResults];
  Item front;
  int count = 0, num_results = 0, num_front = 0;
  bool record_front = false;

  __device__ void push_item(const Item& x) {
    assert(count < Task::kMaxChildren && "a task pushed more than kMaxChildren items");
    children[count++] = x;
  }
  __device__ void push_result(const Result& r) {
    assert(num_results < Task::kMaxResults && "a task pushed more than kMaxResults results");
    results[num_results++] = r;
  }
  __device__ void push_front(const Item& x) {
    assert(num_front == 0 && "a task pushed two front entries in one call");
    if (!record_front) return;
    front = x;
    num_front = 1;
  }
};

// Appends the block's results and front entries: a block scan, one atomic, coalesced writes.
// All threads of the block must call it.
template <class Task, class Scan>
__device__ void flush_outputs(const DeviceEmitter<Task>& e, const Outputs<Task>& out, typename Scan::TempStorage& storage,
                              unsigned long long& base) {
  int offset = 0, total = 0;
  Scan(storage).ExclusiveSum(e.num_results, offset, total);
  if (threadIdx.x == 0 && total) base = atomicAdd(&out.counters[kResults], static_cast<unsigned long long>(total));
  __syncthreads();
  for (int r = 0; r < e.num_results; ++r)
    if (base + offset + r < out.result_capacity) out.results[base + offset + r] = e.results[r];
  if (!out.record_front) {
    __syncthreads();
    return;
  }
  __syncthreads();
  Scan(storage).ExclusiveSum(e.num_front, offset, total);
  if (threadIdx.x == 0 && total) base = atomicAdd(&out.counters[kFront], static_cast<unsigned long long>(total));
  __syncthreads();
  if (e.num_front && base + offset < out.front_capacity) out.front[base + offset] = e.front;
  __syncthreads();
}

// One breadth-first level: every item processed once, children appended to `next`, which holds
// `next_room` (kAppended counts them all: a caller that sized it below n * kMaxChildren checks).
template <class Task, int kThreads>
__global__ void __launch_bounds__(kThreads) expand_kernel(Task task, const typename Task::item_type* in, std::size_t n,
                                                          typename Task::item_type* next, std::size_t next_room,
                                                          Outputs<Task> out) {
  using Scan = cub::BlockScan<int, kThreads>;
  __shared__ typename Scan::TempStorage storage;
  __shared__ unsigned long long base;
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  DeviceEmitter<Task> e;
  e.record_front = out.record_front;
  if (i < n) task.process(in[i], e);
  int offset = 0, total = 0;
  Scan(storage).ExclusiveSum(e.count, offset, total);
  if (threadIdx.x == 0 && total) base = atomicAdd(&out.counters[kAppended], static_cast<unsigned long long>(total));
  __syncthreads();
  for (int c = 0; c < e.count; ++c)
    if (base + offset + c < next_room) next[base + offset + c] = e.children[c];
  __syncthreads();
  flush_outputs<Task, Scan>(e, out, storage, base);
}

// The first breadth-first levels of a small start (the root) in one block and one launch:
// level after level, from `a` into `b` and back, while a level holds fewer than `stop_at` items
// (a level per launch cost a launch and a host synchronisation each: 6-7 of them from a root).
// Writes the last level's size to kAppended and the number of levels to kLevels (odd: the last
// level is in `b`). Both buffers hold `room` items, at least stop_at * kMaxChildren.
template <class Task, int kThreads>
__global__ void __launch_bounds__(kThreads)
    expand_small_levels_kernel(Task task, typename Task::item_type* a, typename Task::item_type* b, std::size_t n,
                               std::size_t stop_at, std::size_t room, Outputs<Task> out) {
  using Item = typename Task::item_type;
  using Scan = cub::BlockScan<int, kThreads>;
  __shared__ typename Scan::TempStorage storage;
  __shared__ unsigned long long level_size, flush_base;
  Item* in = a;
  Item* next = b;
  unsigned long long levels = 0;
  while (n > 0 && n < stop_at) {
    assert(n * Task::kMaxChildren <= room && "expand_small_levels_kernel: a level's children overflow their buffer");
    if (threadIdx.x == 0) level_size = 0;
    __syncthreads();
    for (std::size_t first = 0; first < n; first += kThreads) {
      const std::size_t i = first + threadIdx.x;
      DeviceEmitter<Task> e;
      e.record_front = out.record_front;
      if (i < n) task.process(in[i], e);
      int offset = 0, total = 0;
      Scan(storage).ExclusiveSum(e.count, offset, total);
      const unsigned long long base = level_size;  // read by all before thread 0 moves it on
      __syncthreads();
      if (threadIdx.x == 0) level_size += static_cast<unsigned long long>(total);
      for (int c = 0; c < e.count; ++c) next[base + offset + c] = e.children[c];
      flush_outputs<Task, Scan>(e, out, storage, flush_base);  // synchronises the block
    }
    if (threadIdx.x == 0) out.counters[kProcessed] += n;
    n = static_cast<std::size_t>(level_size);
    Item* done = in;
    in = next;
    next = done;
    ++levels;
    __syncthreads();  // level_size read by all before the next level resets it
  }
  if (threadIdx.x == 0) {
    out.counters[kAppended] = n;
    out.counters[kLevels] = levels;
  }
}

// Drops the `count` oldest items of a shared stack (they were copied elsewhere): the rest moves
// down, staged through registers so that overlapping ranges are safe. All threads call it.
template <class Item, int kShared, int kThreads>
__device__ void drop_oldest(Item* s_items, int& s_size, int count) {
  constexpr int kPerThread = (kShared + kThreads - 1) / kThreads;
  Item keep[kPerThread];
  const int remaining = s_size - count;
  for (int j = 0; j < kPerThread; ++j) {
    const int i = threadIdx.x + j * kThreads;
    if (i < remaining) keep[j] = s_items[i + count];
  }
  __syncthreads();
  for (int j = 0; j < kPerThread; ++j) {
    const int i = threadIdx.x + j * kThreads;
    if (i < remaining) s_items[i] = keep[j];
  }
  __syncthreads();
  if (threadIdx.x == 0) s_size = remaining;
  __syncthreads();
}

// One round: the top `take` items of the shared stack are processed, one per thread; their
// children go back on the stack, results and front entries to the outputs. Returns (on every
// thread) how many children were pushed. All threads call it; Scan is a cub::BlockScan of 64-bit words.
//
// A round is latency-bound where a block holds few items (a subtree's last levels, one level a
// round), so it is kept short: the three counts of a thread (children, results, front entries)
// go through one block scan as fields of one word, and the results' and the front's places are
// reserved by two threads at once - instead of a scan and a synchronisation per list and two
// atomics one after the other.
template <class Task, class Scan>
__device__ int process_round(const Task& task, typename Task::item_type* s_items, int& s_size, int take,
                             typename Scan::TempStorage& storage, unsigned long long (&out_base)[2], const Outputs<Task>& out) {
  constexpr int kField = 21;  // bits per count: a block's totals stay far below 2^21
  constexpr unsigned long long kMask = (1ull << kField) - 1;
  static_assert(Task::kMaxChildren < 1024 && Task::kMaxResults < 1024, "lwsccd: process_round packs counts in 21-bit fields");
  DeviceEmitter<Task> e;
  e.record_front = out.record_front;
  typename Task::item_type item;
  const bool active = static_cast<int>(threadIdx.x) < take;
  if (active) item = s_items[s_size - take + threadIdx.x];
  __syncthreads();  // taken: the children may overwrite those slots
  if (threadIdx.x == 0) s_size -= take;
  if (active) task.process(item, e);
  const unsigned long long counts = static_cast<unsigned long long>(e.count) |
                                    (static_cast<unsigned long long>(e.num_results) << kField) |
                                    (static_cast<unsigned long long>(e.num_front) << (2 * kField));
  unsigned long long offsets = 0, totals = 0;
  Scan(storage).ExclusiveSum(counts, offsets, totals);
  const int total_children = static_cast<int>(totals & kMask), total_results = static_cast<int>((totals >> kField) & kMask),
            total_front = static_cast<int>(totals >> (2 * kField));
  if (threadIdx.x == 0 && total_results)
    out_base[0] = atomicAdd(&out.counters[kResults], static_cast<unsigned long long>(total_results));
  if (threadIdx.x == 32 % blockDim.x && total_front)
    out_base[1] = atomicAdd(&out.counters[kFront], static_cast<unsigned long long>(total_front));
  __syncthreads();  // s_size updated, places reserved, scan storage free
  const int child_at = s_size + static_cast<int>(offsets & kMask);
  for (int c = 0; c < e.count; ++c) s_items[child_at + c] = e.children[c];
  const unsigned long long result_at = out_base[0] + ((offsets >> kField) & kMask);
  for (int r = 0; r < e.num_results; ++r)
    if (result_at + r < out.result_capacity) out.results[result_at + r] = e.results[r];
  const unsigned long long front_at = out_base[1] + (offsets >> (2 * kField));
  if (e.num_front && front_at < out.front_capacity) out.front[front_at] = e.front;
  __syncthreads();  // children stored (and out_base read) before the stack grows
  if (threadIdx.x == 0) {
    s_size += total_children;
    atomicAdd(&out.counters[kProcessed], static_cast<unsigned long long>(take));
  }
  return total_children;
}

// The per-block two-level stack loop shared by the schedulers. `region` is this block's global
// stack (capacity `global_capacity`), holding `region_size` items on entry. Returns with every
// remaining item in the region (its new size in `region_size`) unless `hand_back` is set, in which
// case the items left go to hand_back (when the region would overflow).
template <class Task, class Policy>
__device__ void run_block_stack(const Task& task, typename Task::item_type* region, int& region_size, int global_capacity,
                                const Outputs<Task>& out, const unsigned long long* idle_blocks, unsigned idle_limit,
                                typename Task::item_type* hand_back) {
  using Item = typename Task::item_type;
  constexpr int kThreads = Policy::kBlockThreads;
  constexpr int kShared = Policy::kSharedStack;
  constexpr int kK = Task::kMaxChildren;
  static_assert(kShared >= 2 * kThreads * kK, "lwsccd: kSharedStack must hold at least 2 * kBlockThreads * kMaxChildren items");
  using Scan = cub::BlockScan<unsigned long long, kThreads>;
  __shared__ Item s_items[kShared];
  __shared__ typename Scan::TempStorage scan_storage;
  __shared__ int s_size, g_size, take, refill, spill, stop;  // stop: 0 run, 1 done, 2 pause, 3 full
  __shared__ unsigned long long out_base[2];
  const int t = threadIdx.x;
  if (t == 0) {
    s_size = 0;
    g_size = region_size;
  }
  __syncthreads();
  while (true) {
    if (t == 0) {
      refill = 0;
      spill = 0;
      stop = 0;
      if (s_size == 0 && g_size == 0) stop = 1;
      else if (idle_blocks && *reinterpret_cast<const volatile unsigned long long*>(idle_blocks) >= idle_limit) stop = 2;
      else {
        if (s_size == 0) refill = ::min(g_size, kShared / 2);
        const int size = s_size + refill;
        take = ::min(size, kThreads);
        const int need = size - take + take * kK;
        if (need > kShared) {
          spill = need - kShared;
          if (g_size - refill + spill > global_capacity) stop = 3;
        }
      }
    }
    __syncthreads();
    if (stop) break;
    if (refill) {  // bring the global stack's top into shared memory
      for (int i = t; i < refill; i += kThreads) s_items[i] = region[g_size - refill + i];
      __syncthreads();
      if (t == 0) {
        g_size -= refill;
        s_size = refill;
      }
      __syncthreads();
    }
    if (spill) {  // oldest shared items to the global stack, the rest shifted down
      for (int i = t; i < spill; i += kThreads) region[g_size + i] = s_items[i];
      drop_oldest<Item, kShared, kThreads>(s_items, s_size, spill);  // synchronizes: copies done
      if (t == 0) g_size += spill;
      __syncthreads();
    }
    process_round<Task, Scan>(task, s_items, s_size, take, scan_storage, out_base, out);
  }
  // Leave every remaining item in the region, or hand everything back when it would not fit.
  if (stop == 1) {
    if (t == 0) region_size = 0;
    return;
  }
  __shared__ unsigned long long base;
  if (stop == 3 || g_size + s_size > global_capacity) {
    if (t == 0) {
      base = atomicAdd(&out.counters[kAppended], static_cast<unsigned long long>(g_size + s_size));
      atomicAdd(&out.counters[kHalted], 1ull);
    }
    __syncthreads();
    for (int i = t; i < g_size; i += kThreads) hand_back[base + i] = region[i];
    for (int i = t; i < s_size; i += kThreads) hand_back[base + g_size + i] = s_items[i];
    if (t == 0) region_size = 0;
    return;
  }
  for (int i = t; i < s_size; i += kThreads) region[g_size + i] = s_items[i];
  if (t == 0) region_size = g_size + s_size;
}

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
  run_block_stack<Task, Policy>(task, region, region_size, global_capacity, out, nullptr, 0, hand_back);
}

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
  run_block_stack<Task, Policy>(task, region, region_size, queue_capacity, out, &out.counters[kIdle], idle_limit, hand_back);
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

template <class T>
void ensure(DeviceBuffer<T>& b, std::size_t n) {
  if (b.size() < n) b.resize_discard(n);
}

inline int resident_blocks(int blocks_per_sm) {
  int device = 0, sms = 0;
  LWSCCD_CUDA_CHECK(cudaGetDevice(&device));
  LWSCCD_CUDA_CHECK(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, device));
  return std::max(1, sms * blocks_per_sm);
}

// Blocks of `kernel` that are resident at once, at most blocks_per_sm per SM: persistent blocks
// beyond that would wait for a slot (registers or shared memory) and start only when others end.
// `cache` (one per kernel, per device id; 0: not asked yet) spares the query on later calls
// (a traversal from a small front takes tens of microseconds).
template <class Kernel, int kDevices>
int co_resident_blocks(Kernel kernel, int threads, int blocks_per_sm, std::atomic<int> (&cache)[kDevices]) {
  int device = 0;
  LWSCCD_CUDA_CHECK(cudaGetDevice(&device));
  int fit = device < kDevices ? cache[device].load(std::memory_order_relaxed) : 0;
  if (fit == 0) {
    LWSCCD_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&fit, kernel, threads, 0));
    if (fit < 1) throw Error("lwsccd: LazyStealScheduler: its kernel cannot run a block of " + std::to_string(threads) +
                             " threads on this GPU (registers or shared memory)");
    if (device < kDevices) cache[device].store(fit, std::memory_order_relaxed);
  }
  return resident_blocks(std::min(fit, blocks_per_sm));
}

// Enqueues the counters' copy into host_counters_ (pinned: the copy does not block).
template <class Task>
void enqueue_counter_read(TraversalOutput<Task>& out, cudaStream_t stream) {
  if (out.host_counters_.size() < static_cast<std::size_t>(kCounters))
    out.host_counters_ = PinnedBuffer<unsigned long long>(kCounters);
  LWSCCD_CUDA_CHECK(cudaMemcpyAsync(out.host_counters_.data(), out.counters_.data(), kCounters * sizeof(unsigned long long),
                                    cudaMemcpyDeviceToHost, stream));
}

// Reads the counters (one synchronisation). The reading stays in host_counters_, so that
// traverse() need not read again what the scheduler's last read saw.
template <class Task>
std::vector<unsigned long long> read_counters(TraversalOutput<Task>& out, cudaStream_t stream) {
  enqueue_counter_read(out, stream);
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
  ++out.counter_reads_;
  return std::vector<unsigned long long>(out.host_counters_.data(), out.host_counters_.data() + kCounters);
}

template <class Task>
Outputs<Task> outputs_of(TraversalOutput<Task>& out, bool record_front) {
  return {out.results_.data(), out.results_.size(), out.front_.data(), out.front_.size(), out.counters_.data(), record_front};
}

// One breadth-first level in one launch, a thread per item: in[0, n) processed, their children
// left in out.work_ (`in` may be out.work_ itself); returns how many (one host synchronisation).
template <class Task>
std::size_t expand_level(const Task& task, const typename Task::item_type* in, std::size_t n, TraversalOutput<Task>& out,
                         bool record_front, cudaStream_t stream) {
  ensure(out.next_, n * Task::kMaxChildren);
  LWSCCD_CUDA_CHECK(cudaMemsetAsync(out.counters_.data() + kAppended, 0, sizeof(unsigned long long), stream));
  expand_kernel<Task, 256><<<static_cast<unsigned>((n + 255) / 256), 256, 0, stream>>>(
      task, in, n, out.next_.data(), n * Task::kMaxChildren, outputs_of(out, record_front));
  LWSCCD_CUDA_CHECK_LAUNCH();
  const auto c = read_counters(out, stream);
  out.stats_.items_processed += n;
  std::swap(out.work_, out.next_);
  return static_cast<std::size_t>(c[kAppended]);
}

// Breadth-first expansion of the seeds (copied to out.work_) until there are at least `target`
// items or none; returns their count (in out.work_).
template <class Task>
std::size_t expand_breadth_first(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds,
                                 std::size_t target, TraversalOutput<Task>& out, bool record_front, cudaStream_t stream) {
  using Item = typename Task::item_type;
  std::size_t n = num_seeds;
  const std::size_t stop_at = target / Task::kMaxChildren;
  // Small levels in one launch (a single block of kOneBlockThreads), up to a few items per thread.
  constexpr int kOneBlockThreads = 512;
  const std::size_t one_block_stop = std::min<std::size_t>(stop_at, 4 * kOneBlockThreads);
  const bool one_block = n > 0 && n < one_block_stop;
  const std::size_t room = one_block ? one_block_stop * Task::kMaxChildren : 0;
  ensure(out.work_, std::max<std::size_t>({num_seeds, room, 1}));
  if (num_seeds)
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(out.work_.data(), seeds, num_seeds * sizeof(Item), cudaMemcpyDeviceToDevice, stream));
  if (one_block) {
    ensure(out.next_, room);
    expand_small_levels_kernel<Task, kOneBlockThreads><<<1, kOneBlockThreads, 0, stream>>>(
        task, out.work_.data(), out.next_.data(), n, one_block_stop, room, outputs_of(out, record_front));
    LWSCCD_CUDA_CHECK_LAUNCH();
    const auto c = read_counters(out, stream);
    n = static_cast<std::size_t>(c[kAppended]);
    if (c[kLevels] % 2 == 1) std::swap(out.work_, out.next_);
  }
  while (n > 0 && n < stop_at) n = expand_level(task, out.work_.data(), n, out, record_front, stream);
  return n;
}

// One complete attempt with the current output capacities.
template <class Task, class Policy>
void run_static(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds, TraversalOutput<Task>& out,
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
    if (c[kHalted] > 0) {
      ++out.stats_.relaunches;
      global_capacity *= 2;  // the next launch has room to make progress
    }
    std::swap(out.work_, out.next_);
  }
}

template <class Task, class Policy>
void run_balanced(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds, TraversalOutput<Task>& out,
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


// ---------------------------------------------------------------------------------------------
// LazyStealScheduler.
//
// Termination: `pending` counts the items that exist in this launch (in deques, in shared
// stacks, or being processed). A round adds its children and retires its parents in one atomic
// update made after the children are in the shared stack, so the count never drops to zero while
// any item exists or can still be created (only processing an item creates items, and that item
// is counted until then). Items handed back to the host leave the count when they are handed
// back. A block exits only after finding its own deque and every other deque empty and reading
// pending == 0 (acquire), so no block leaves while work is in flight anywhere. The rounds' updates
// are relaxed (and skipped when a round adds as many as it retires): the count is only ever read
// for its value - a block that reads zero leaves without reading anything else, one that reads
// more looks in the deques, whose contents their locks order - and an acquire-release update
// cost each round a wait for the atomic's return (a round is latency-bound near a subtree's end).
//
// ABA: the deques' ends are monotonic 64-bit counters (positions in a ring are taken modulo the
// capacity), never reused, and every change of a deque's ends happens under that deque's lock,
// held by one thread of one block; a block holds at most one lock at a time, so there is no
// deadlock either. The lock is taken with an acquire exchange and released with a release store,
// which orders the items written or read inside the critical section for the next holder.

struct LargerOf {
  __device__ unsigned long long operator()(unsigned long long a, unsigned long long b) const { return a < b ? b : a; }
};

__device__ inline void lock_deque(int* lock) {
  cuda::atomic_ref<int, cuda::thread_scope_device> l(*lock);
  while (l.exchange(1, cuda::memory_order_acquire) != 0) __nanosleep(64);
}
// A thief's lock: up to `attempts` tries (0: until it has it). One that cannot get the lock soon
// looks again instead of queueing: at the end of a traversal every idle block queues on the lock
// of the one deque it saw fullest, each finding it empty in turn (100-180 us on cloth-ball's front,
// seen in the timelines). LazyStealScheduler::kStealLockAttempts (16 by default, with victims
// drawn at random among the fullest: alone, the retries cost OBB fronts more than they saved).
__device__ inline bool lock_deque_within(int* lock, int attempts) {
  if (attempts <= 0) {
    lock_deque(lock);
    return true;
  }
  cuda::atomic_ref<int, cuda::thread_scope_device> l(*lock);
  for (int i = 0; i < attempts; ++i) {
    if (l.exchange(1, cuda::memory_order_acquire) == 0) return true;
    __nanosleep(64);
  }
  return false;
}
__device__ inline void unlock_deque(int* lock) {
  cuda::atomic_ref<int, cuda::thread_scope_device>(*lock).store(0, cuda::memory_order_release);
}

// Readies a lazy launch on the device: every deque empty and unlocked, the start list's length
// (`n`, or where n is kCountOnDevice the count the last expansion left in kAppended, which the
// host has not read) made the live count, and the hand-back counters zeroed.
constexpr unsigned long long kCountOnDevice = ~0ull;
template <int kThreads>
__global__ void __launch_bounds__(kThreads) lazy_start_kernel(unsigned long long* counters, unsigned long long* ends, int* locks, int blocks,
                                         unsigned long long n, unsigned long long room) {
  for (int b = static_cast<int>(threadIdx.x); b < blocks; b += static_cast<int>(blockDim.x)) {
    ends[2 * b] = ends[2 * b + 1] = 0;
    locks[b] = 0;
  }
  if (threadIdx.x == 0) {
    unsigned long long items = n == kCountOnDevice ? counters[kAppended] : n;
    if (items > room) {  // the expansion's children outgrew their list: a rerun has more room
      counters[kLost] += items - room;
      items = room;
    }
    counters[kStartItems] = items;
    counters[kPending] = items;
    counters[kStartTaken] = 0;
    counters[kAppended] = counters[kHalted] = 0;
    counters[kHungry] = 0;
  }
}

// A minimum of 0 blocks per SM is no minimum (no .minnctapersm): the compiler's own choice, which
// differs from an explicit 1 (AABB: 64 registers against 93).
template <class Task, class Policy>
__global__ void __launch_bounds__(Policy::kBlockThreads, Policy::kFitBlocksPerSm ? Policy::kBlocksPerSm : 0)
    lazy_steal_kernel(Task task, const typename Task::item_type* start_list, typename Task::item_type* deques,
                      unsigned long long* ends, int* locks, int capacity, Outputs<Task> out,
                      typename Task::item_type* hand_back, std::size_t hand_back_room, BlockActivity* activity,
                      TimelineSink timeline) {
  using Item = typename Task::item_type;
  constexpr int kThreads = Policy::kBlockThreads;
  constexpr int kShared = Policy::kSharedStack;
  constexpr int kK = Task::kMaxChildren;
  constexpr int kPop = Policy::kPopSize;
  constexpr int kPushAbove = Policy::kPushThreshold;
  static_assert(kPushAbove + kThreads * kK <= kShared, "lwsccd: kSharedStack must hold kPushThreshold plus one round of children");
  static_assert(kPop <= kPushAbove, "lwsccd: kPopSize must not exceed kPushThreshold");
  static_assert(Policy::kShareWhenHungry >= 0 && Policy::kShareWhenHungry < kPushAbove,
                "lwsccd: LazyStealScheduler: kShareWhenHungry must be 0 (off) or below kPushThreshold");
  using Scan = cub::BlockScan<unsigned long long, kThreads>;
  using Reduce = cub::BlockReduce<unsigned long long, kThreads>;
  __shared__ Item s_items[kShared];
  __shared__ typename Scan::TempStorage scan_storage;
  __shared__ typename Reduce::TempStorage reduce_storage;
  __shared__ int s_size, take, action, count, source, moved;
  __shared__ bool share_now;  // kShareWhenHungry: thread 0's reading at the end of the last round
  __shared__ unsigned long long from, out_base[2];
  const int t = threadIdx.x, me = blockIdx.x, blocks = static_cast<int>(gridDim.x);
  cuda::atomic_ref<unsigned long long, cuda::thread_scope_device> live(out.counters[kPending]);
  // The start list (written by earlier launches on the stream) is handed out in slices of about
  // an even share per block, at most a pop: the first look of every block finds its share there.
  const unsigned long long start_items = out.counters[kStartItems];
  const unsigned long long slice = start_items == 0 ? 1
                                   : (start_items + blocks - 1) / blocks < static_cast<unsigned long long>(kPop)
                                       ? (start_items + blocks - 1) / blocks
                                       : static_cast<unsigned long long>(kPop);
  bool start_open = start_items > 0;  // thread 0: the start list may still hold items
  long long busy = 0, idle = 0;
  unsigned long long steals = 0, failed_steals = 0;
  bool seeking = false;  // thread 0: in a search for work (for the timeline: one event per search)
  unsigned backoff = 256;  // thread 0: the next sleep after a failed search (ns)
  std::uint32_t looks = 0;  // thread 0: looks for work in the current search
  static_assert(Policy::kMaxBackoffNs >= 256, "lwsccd: LazyStealScheduler: kMaxBackoffNs must be at least 256");
  if (t == 0) {
    s_size = 0;
    share_now = false;
  }
  __syncthreads();
  cuda::atomic_ref<unsigned long long, cuda::thread_scope_device> hungry(out.counters[kHungry]);
  while (true) {
    if (s_size == 0) {  // find work: own deque first, then a lazy steal
      const long long start = clock64();
      if (t == 0) {
        if (!seeking) {
          timeline.record(me, BlockPhase::seek, 0), looks = 0;
          if (Policy::kShareWhenHungry > 0) hungry.fetch_add(1, cuda::memory_order_relaxed);
        }
        seeking = true;
        ++looks;
        action = 0;
        // Only this block adds to its deque and thieves only take, so a deque it sees empty
        // without the lock is empty: no lock then. (At the end of a traversal idle blocks queued
        // on the lock of the deque they saw fullest, and its owner, done, waited behind them for
        // its own lock to see it empty: 100-180 us on cloth-ball's front, found with the timelines.)
        using Word = cuda::atomic_ref<unsigned long long, cuda::thread_scope_device>;
        const bool maybe_items = Word(ends[2 * me + 1]).load(cuda::memory_order_relaxed) > Word(ends[2 * me]).load(cuda::memory_order_relaxed);
        if (maybe_items) lock_deque(&locks[me]);
        const unsigned long long top = maybe_items ? ends[2 * me] : 0, bottom = maybe_items ? ends[2 * me + 1] : 0;
        if (bottom > top) {
          count = static_cast<int>(bottom - top < kPop ? bottom - top : kPop);
          from = bottom - count;
          ends[2 * me + 1] = from;  // newest items, from the owner's end
          source = me;
          action = 1;
        } else {
          if (maybe_items) unlock_deque(&locks[me]);
          if (start_open) {  // then the start list
            const unsigned long long first = atomicAdd(&out.counters[kStartTaken], slice);
            if (first < start_items) {
              count = static_cast<int>(start_items - first < slice ? start_items - first : slice);
              from = first;
              source = -1;
              action = 1;
            } else {
              start_open = false;
            }
          }
          // Nothing pending anywhere: done, without reading every deque (all blocks do this at the
          // end); counted as a search that found nothing.
          if (action == 0 && live.load(cuda::memory_order_acquire) == 0) {
            action = 3;
            ++failed_steals;
          }
        }
      }
      __syncthreads();
      if (action == 0) {
        // The lazy steal reads every deque's size at once: the whole block reads them (a thread
        // alone would wait on hundreds of loads one after another) and picks the fullest, ties to
        // the nearest after this block (so that thieves spread over equal victims). With
        // kRandomVictim, any of those within a factor of two of the fullest, at random: thieves
        // that all saw the same fullest deque no longer all queue on its lock.
        unsigned long long key = 0;
        const unsigned salt = static_cast<unsigned>(clock64()) * 0x9E3779B1u ^ static_cast<unsigned>(me) * 0x85EBCA77u;
        for (int v = t; v < blocks; v += kThreads) {
          if (v == me) continue;
          const unsigned long long vt =
              cuda::atomic_ref<unsigned long long, cuda::thread_scope_device>(ends[2 * v]).load(cuda::memory_order_relaxed);
          const unsigned long long vb =
              cuda::atomic_ref<unsigned long long, cuda::thread_scope_device>(ends[2 * v + 1]).load(cuda::memory_order_relaxed);
          if (vb <= vt) continue;
          const unsigned long long distance = static_cast<unsigned long long>((v - me + blocks) % blocks);
          unsigned long long candidate = ((vb - vt) << 24) | (0xFFFFFFull - distance);
          if (Policy::kRandomVictim) {  // size class (bit length), a random tie-break, the distance
            unsigned h = salt ^ static_cast<unsigned>(v) * 0xC2B2AE3Du;
            h = (h ^ (h >> 15)) * 0x2C1B3C6Du;
            h ^= h >> 13;
            candidate = (static_cast<unsigned long long>(64 - __clzll(vb - vt)) << 48) |
                        (static_cast<unsigned long long>(h & 0xFFFFFFu) << 24) | (0xFFFFFFull - distance);
          }
          key = candidate > key ? candidate : key;
        }
        const unsigned long long best_key = Reduce(reduce_storage).Reduce(key, LargerOf{});
        if (t == 0) {
          if (best_key != 0) {
            const int best = static_cast<int>((me + static_cast<int>(0xFFFFFFull - (best_key & 0xFFFFFFull))) % blocks);
            const bool locked = lock_deque_within(&locks[best], Policy::kStealLockAttempts);
            const unsigned long long vt = locked ? ends[2 * best] : 0, vb = locked ? ends[2 * best + 1] : 0;
            if (vb > vt) {  // half of the oldest items (the largest subtrees), at most a pop's worth
              count = static_cast<int>((vb - vt + 1) / 2 < kPop ? (vb - vt + 1) / 2 : kPop);
              from = vt;
              ends[2 * best] = vt + count;
              source = best;
              action = 2;
              ++steals;
            } else if (locked) {
              unlock_deque(&locks[best]);
            }
          }
          if (action == 0) {
            ++failed_steals;
            action = live.load(cuda::memory_order_acquire) == 0 ? 3 : 4;
          }
        }
      }
      __syncthreads();
      if (action == 3) {
        idle += clock64() - start;
        if (t == 0) {
          timeline.record(me, BlockPhase::done, looks);
          if (Policy::kShareWhenHungry > 0) hungry.fetch_sub(1, cuda::memory_order_relaxed);
        }
        break;
      }
      if (action == 4) {
        if (t == 0) {
          __nanosleep(backoff);
          backoff = backoff * 2 < static_cast<unsigned>(Policy::kMaxBackoffNs) ? backoff * 2 : static_cast<unsigned>(Policy::kMaxBackoffNs);
        }
        idle += clock64() - start;
        __syncthreads();
        continue;
      }
      if (source < 0) {
        for (int i = t; i < count; i += kThreads) s_items[i] = start_list[from + i];
      } else {
        const Item* deque = deques + static_cast<std::size_t>(source) * capacity;
        for (int i = t; i < count; i += kThreads) s_items[i] = deque[(from + i) % capacity];
      }
      __syncthreads();
      if (t == 0) {
        s_size = count;
        if (source >= 0) unlock_deque(&locks[source]);
        timeline.record(me, action == 1 ? BlockPhase::own : BlockPhase::steal, static_cast<std::uint32_t>(count));
        if (Policy::kShareWhenHungry > 0) hungry.fetch_sub(1, cuda::memory_order_relaxed);
        seeking = false;
        backoff = 256;
      }
      idle += clock64() - start;
      __syncthreads();
    }
    const long long start = clock64();
    if (s_size > kPushAbove || share_now) {  // the oldest batch goes to this block's deque, for thieves
      if (t == 0) {
        moved = s_size > kPushAbove ? s_size - kPushAbove / 2 : s_size / 2;
        lock_deque(&locks[me]);
        const unsigned long long top = ends[2 * me], bottom = ends[2 * me + 1];
        if (bottom - top + moved > static_cast<unsigned long long>(capacity)) {
          unlock_deque(&locks[me]);  // full: hand the batch back to the host instead
          from = atomicAdd(&out.counters[kAppended], static_cast<unsigned long long>(moved));
          atomicAdd(&out.counters[kHalted], 1ull);
          if (from + moved > hand_back_room)  // no room to hand them back: the pass reruns with more
            atomicAdd(&out.counters[kLost], from + moved - (from > hand_back_room ? from : hand_back_room));
          live.fetch_sub(static_cast<unsigned long long>(moved), cuda::memory_order_acq_rel);
          action = 5;
        } else {
          from = bottom;
          action = 6;
        }
      }
      __syncthreads();
      if (action == 5) {
        for (int i = t; i < moved; i += kThreads)
          if (from + i < hand_back_room) hand_back[from + i] = s_items[i];
      } else {
        Item* deque = deques + static_cast<std::size_t>(me) * capacity;
        for (int i = t; i < moved; i += kThreads) deque[(from + i) % capacity] = s_items[i];
      }
      __syncthreads();
      if (t == 0 && action == 6) {
        ends[2 * me + 1] = from + moved;
        unlock_deque(&locks[me]);
      }
      drop_oldest<Item, kShared, kThreads>(s_items, s_size, moved);
    }
    // One round: up to a block of items from the top of the shared stack.
    if (t == 0) take = s_size < kThreads ? s_size : kThreads;
    __syncthreads();
    const int total = process_round<Task, Scan>(task, s_items, s_size, take, scan_storage, out_base, out);
    if (t == 0 && total != take) {
      // Children counted and parents retired in one update (see the termination note above).
      live.fetch_add(static_cast<unsigned long long>(static_cast<long long>(total) - take), cuda::memory_order_relaxed);
    }
    if (Policy::kShareWhenHungry > 0 && t == 0) {  // share next round? (own deque empty, a block searching)
      using Word = cuda::atomic_ref<unsigned long long, cuda::thread_scope_device>;
      share_now = s_size > Policy::kShareWhenHungry && s_size <= kPushAbove &&
                  Word(ends[2 * me + 1]).load(cuda::memory_order_relaxed) <= Word(ends[2 * me]).load(cuda::memory_order_relaxed) &&
                  hungry.load(cuda::memory_order_relaxed) > 0;
    }
    busy += clock64() - start;
    __syncthreads();
  }
  if (t == 0)
    activity[me] = {static_cast<unsigned long long>(busy), static_cast<unsigned long long>(idle), steals, failed_steals};
}

// The launch shape of the lazy kernel (persistent blocks that fit at once) and its timeline's
// storage; sizes the per-block arrays.
template <class Task, class Policy>
int prepare_lazy(TraversalOutput<Task>& out, TimelineSink& timeline, cudaStream_t stream) {
  static std::atomic<int> fit_per_device[16];  // zero-initialized (static storage)
  const int blocks =
      co_resident_blocks(lazy_steal_kernel<Task, Policy>, Policy::kBlockThreads, Policy::kBlocksPerSm, fit_per_device);
  out.launched_blocks_ = blocks;
  ensure(out.locks_, blocks);
  ensure(out.deque_ends_, 2 * static_cast<std::size_t>(blocks));
  ensure(out.block_activity_, static_cast<std::size_t>(blocks));
  if (out.timeline_capacity_ > 0) {
    // Zeroed when (re)allocated: download_timeline copies whole rows, whose tails no launch writes
    // (compute-sanitizer's initcheck flagged the copy of never-written bytes).
    const std::size_t events = static_cast<std::size_t>(blocks) * out.timeline_capacity_;
    if (out.timeline_.size() < events) {
      out.timeline_.resize_discard(events);
      LWSCCD_CUDA_CHECK(cudaMemsetAsync(out.timeline_.data(), 0, events * sizeof(TimelineEvent), stream));
    }
    ensure(out.timeline_counts_, static_cast<std::size_t>(blocks));
    timeline = {out.timeline_.data(), out.timeline_counts_.data(), out.timeline_capacity_};
  }
  return blocks;
}

// One launch of the lazy kernel over the start list out.work_ of `n` items (kCountOnDevice: the
// count the flat launch left on the device, at most out.list_room_ of them kept), deques of
// `capacity` items per block. What halted blocks hand back goes to out.next_ (count in kAppended;
// past out.list_room_ they are counted in kLost and the pass must run again).
template <class Task, class Policy>
void launch_lazy(const Task& task, TraversalOutput<Task>& out, unsigned long long n, int blocks, int capacity,
                 const TimelineSink& timeline, bool record_front, cudaStream_t stream) {
  ensure(out.stacks_, static_cast<std::size_t>(blocks) * capacity);
  ensure(out.next_, out.list_room_);
  if (timeline.events) LWSCCD_CUDA_CHECK(cudaMemsetAsync(timeline.counts, 0, blocks * sizeof(unsigned), stream));
  const unsigned long long start_room = n == kCountOnDevice ? out.list_room_ : n;
  lazy_start_kernel<256><<<1, 256, 0, stream>>>(out.counters_.data(), out.deque_ends_.data(), out.locks_.data(), blocks, n,
                                                start_room);
  LWSCCD_CUDA_CHECK_LAUNCH();
  lazy_steal_kernel<Task, Policy><<<blocks, Policy::kBlockThreads, 0, stream>>>(
      task, out.work_.data(), out.stacks_.data(), out.deque_ends_.data(), out.locks_.data(), capacity,
      outputs_of(out, record_front), out.next_.data(), out.list_room_, out.block_activity_.data(), timeline);
  LWSCCD_CUDA_CHECK_LAUNCH();
}

// Whether a start of `num_seeds` items is processed first by one flat launch
// (LazyStealScheduler::kFlatStartPerBlock).
template <class Policy>
bool lazy_flat_start(std::size_t num_seeds, int blocks) {
  return Policy::kFlatStartPerBlock > 0 &&
         num_seeds >= static_cast<std::size_t>(blocks) * static_cast<std::size_t>(Policy::kFlatStartPerBlock);
}

// The lists the lazy scheduler's start and hand-backs use hold out.list_room_ items: at first a
// shared stack's worth per block, then what earlier passes needed (a front's children are few:
// horse-gallop's 911 K front items leave ~54 K, where a bound of kMaxChildren per item took 29 MB).
template <class Task, class Policy>
void size_lazy_lists(TraversalOutput<Task>& out, int blocks) {
  if (out.list_room_ == 0) out.list_room_ = static_cast<std::size_t>(blocks) * Policy::kSharedStack;
}

// The flat launch of a front's start: every seed processed once, the children into out.work_
// (their count left on the device, in kAppended; past out.list_room_ only counted).
template <class Task>
void enqueue_flat_start(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds,
                        TraversalOutput<Task>& out, bool record_front, cudaStream_t stream) {
  ensure(out.next_, out.list_room_);
  expand_kernel<Task, 256><<<static_cast<unsigned>((num_seeds + 255) / 256), 256, 0, stream>>>(
      task, seeds, num_seeds, out.next_.data(), out.list_room_, outputs_of(out, record_front));
  LWSCCD_CUDA_CHECK_LAUNCH();
  std::swap(out.work_, out.next_);
  out.stats_.flat_start_items = num_seeds;
  out.stats_.items_processed += num_seeds;  // the lazy launch counts its own
}

template <class Task, class Policy>
void run_lazy_steal(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds,
                    TraversalOutput<Task>& out, bool record_front, cudaStream_t stream) {
  TimelineSink timeline;
  const int blocks = prepare_lazy<Task, Policy>(out, timeline, stream);
  size_lazy_lists<Task, Policy>(out, blocks);
  int capacity = Policy::kDequeCapacity;
  // A few items for every block to start with (a fresh traversal starts from one root item); a
  // start of many items (a front) is processed once by a flat launch instead, and the blocks
  // share only what it left (LazyStealScheduler::kFlatStartPerBlock), its count read on the device.
  unsigned long long n = kCountOnDevice;
  if (lazy_flat_start<Policy>(num_seeds, blocks)) {
    enqueue_flat_start(task, seeds, num_seeds, out, record_front, stream);
    // The host waits here (traverse_async does not): a front whose items all ended at once (no
    // children, as is common) then needs no lazy launch (~14 us on cloth-funnel's front). The
    // lazy launch still takes the count from the device, which keeps only what the list held.
    if (read_counters(out, stream)[kAppended] == 0) return;
  } else {
    n = expand_breadth_first(task, seeds, num_seeds, static_cast<std::size_t>(blocks) * Policy::kSeedsPerBlock, out,
                             record_front, stream);
    out.stats_.flat_start_items = 0;
    if (n == 0) return;
    out.list_room_ = std::max<std::size_t>(out.list_room_, n);
  }
  while (true) {
    launch_lazy<Task, Policy>(task, out, n, blocks, capacity, timeline, record_front, stream);
    const auto c = read_counters(out, stream);
    if (c[kLost] > 0) return;  // a list had no room: run_until_outputs_fit grows it and runs the pass again
    std::swap(out.work_, out.next_);
    n = c[kAppended];
    if (n == 0) return;
    ++out.stats_.relaunches;  // halted blocks handed items back: they start the next launch
    capacity *= 2;
  }
}

// A start that the flat launch takes (see lazy_flat_start) enqueued whole, without a host round
// trip: the flat launch leaves its children's count on the device and the lazy launch reads it
// there. Returns false (nothing enqueued) for other starts. What the host would have done between
// the launches - relaunch what halted blocks handed back, grow outputs or lists that overflowed -
// is left to TraversalOutput::collect(), which reports it.
template <class Task, class Policy>
bool enqueue_lazy_steal(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds,
                        TraversalOutput<Task>& out, bool record_front, cudaStream_t stream) {
  TimelineSink timeline;
  const int blocks = prepare_lazy<Task, Policy>(out, timeline, stream);
  if (!lazy_flat_start<Policy>(num_seeds, blocks)) return false;
  size_lazy_lists<Task, Policy>(out, blocks);
  enqueue_flat_start(task, seeds, num_seeds, out, record_front, stream);
  launch_lazy<Task, Policy>(task, out, kCountOnDevice, blocks, Policy::kDequeCapacity, timeline, record_front, stream);
  return true;
}

// After a pass that lost `lost` items for want of list room: room for them and a quarter more
// (at least twice the room: hand-backs vary from run to run).
template <class Task>
void grow_lazy_lists(TraversalOutput<Task>& out, unsigned long long lost) {
  const std::size_t needed = out.list_room_ + static_cast<std::size_t>(lost);
  out.list_room_ = std::max(2 * out.list_room_, needed + needed / 4);
}

template <class S, class = void>
struct is_lazy_steal : std::false_type {};
template <class S>
struct is_lazy_steal<S, std::void_t<decltype(S::kIsLazySteal)>> : std::bool_constant<S::kIsLazySteal> {};

}  // namespace detail

namespace detail {

// Outputs sized for a traversal (first use: room for 2^16 entries each), counters allocated.
template <class Task>
void prepare_outputs(TraversalOutput<Task>& out, bool record_front) {
  ensure(out.counters_, kCounters);
  if (out.results_.size() == 0) out.results_.resize_discard(1 << 16);
  if (out.front_.size() == 0) out.front_.resize_discard(record_front ? (1 << 16) : 1);
  out.stats_ = {};
  out.complete_ = true;
  out.front_complete_ = true;
  out.awaiting_collect_ = false;  // what an earlier traverse_async() left uncollected is superseded
}

// Grows the outputs that `results` and `front` entries overflowed to those counts and a quarter
// more; false (nothing grown) where that would pass out's output limit.
template <class Task>
bool grow_outputs(TraversalOutput<Task>& out, std::size_t results, std::size_t front) {
  using Item = typename Task::item_type;
  using Result = typename Task::result_type;
  const std::size_t results_room = results > out.results_.size() ? results + results / 4 : out.results_.size();
  const std::size_t front_room = front > out.front_.size() ? front + front / 4 : out.front_.size();
  if (out.output_limit_ && results_room * sizeof(Result) + front_room * sizeof(Item) > out.output_limit_) return false;
  out.results_.resize_discard(results_room);
  out.front_.resize_discard(front_room);
  return true;
}

// Runs `attempt` (one complete pass that leaves the final counters in out.host_counters_ when it
// read them) until the results and front fit their outputs, growing them in between (tasks are
// deterministic, so a pass again from the same seeds gives the same outputs); stops without
// growing past out's output limit (complete_ false).
template <class Task, class Attempt>
void run_until_outputs_fit(TraversalOutput<Task>& out, bool record_front, cudaStream_t stream, Attempt attempt) {
  prepare_outputs(out, record_front);
  while (true) {
    LWSCCD_CUDA_CHECK(cudaMemsetAsync(out.counters_.data(), 0, kCounters * sizeof(unsigned long long), stream));
    out.stats_.items_processed = 0;
    const std::uint64_t reads = out.counter_reads_;
    attempt();
    // Every scheduler's last device operation is a reading of the counters (when it made one):
    // that reading is final, and another would only cost a synchronisation.
    const auto c = out.counter_reads_ != reads
                       ? std::vector<unsigned long long>(out.host_counters_.data(), out.host_counters_.data() + kCounters)
                       : read_counters(out, stream);
    out.stats_.items_processed += static_cast<std::size_t>(c[kProcessed]);
    const std::size_t results = static_cast<std::size_t>(c[kResults]);
    const std::size_t front = record_front ? static_cast<std::size_t>(c[kFront]) : 0;
    if (c[kLost] > 0) {  // the lazy scheduler's lists had no room for some items: longer ones, again
      grow_lazy_lists(out, c[kLost]);
      if (!grow_outputs(out, results, front)) {
        out.complete_ = false;
        return;
      }
      ++out.stats_.relaunches;
      continue;
    }
    if (results <= out.results_.size() && front <= out.front_.size()) {
      out.num_results_ = results;
      out.num_front_ = front;
      out.stats_.results = results;
      out.stats_.front = front;
      return;
    }
    // An output overflowed: grow it to what was counted (a quarter more) and run again.
    if (!grow_outputs(out, results, front)) {
      out.complete_ = false;
      out.num_results_ = std::min(results, out.results_.size());
      out.num_front_ = std::min(front, out.front_.size());
      return;
    }
    ++out.stats_.relaunches;
  }
}

}  // namespace detail

template <class Scheduler, class Task>
void traverse(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds, TraversalOutput<Task>& out,
              bool record_front, cudaStream_t stream) {
  static_assert(require_traversal_task<Task>::value, "");
  detail::run_until_outputs_fit(out, record_front, stream, [&] {
    if constexpr (Scheduler::kIsStatic) detail::run_static<Task, Scheduler>(task, seeds, num_seeds, out, record_front, stream);
    else if constexpr (detail::is_lazy_steal<Scheduler>::value)
      detail::run_lazy_steal<Task, Scheduler>(task, seeds, num_seeds, out, record_front, stream);
    else detail::run_balanced<Task, Scheduler>(task, seeds, num_seeds, out, record_front, stream);
  });
}

template <class Scheduler, class Task>
void traverse_async(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds, TraversalOutput<Task>& out,
                    bool record_front, cudaStream_t stream) {
  static_assert(require_traversal_task<Task>::value, "");
  if constexpr (detail::is_lazy_steal<Scheduler>::value) {
    if (out.output_limit_ == 0) {  // a limit needs the host between launches to keep to it
      detail::prepare_outputs(out, record_front);
      LWSCCD_CUDA_CHECK(cudaMemsetAsync(out.counters_.data(), 0, detail::kCounters * sizeof(unsigned long long), stream));
      if (detail::enqueue_lazy_steal<Task, Scheduler>(task, seeds, num_seeds, out, record_front, stream)) {
        detail::enqueue_counter_read(out, stream);
        out.awaiting_collect_ = true;
        out.awaiting_front_ = record_front;
        return;
      }
    }
  }
  traverse<Scheduler>(task, seeds, num_seeds, out, record_front, stream);  // (clears awaiting_collect_)
}

template <class Task>
bool TraversalOutput<Task>::collect() {
  if (!awaiting_collect_) return true;
  awaiting_collect_ = false;
  const unsigned long long* c = host_counters_.data();
  const std::size_t results = static_cast<std::size_t>(c[detail::kResults]);
  const std::size_t front = awaiting_front_ ? static_cast<std::size_t>(c[detail::kFront]) : 0;
  stats_.items_processed += static_cast<std::size_t>(c[detail::kProcessed]);
  const bool results_fit = results <= results_.size();
  front_complete_ = front <= front_.size();
  num_results_ = std::min(results, results_.size());
  num_front_ = front_complete_ ? front : 0;  // (growing the output discards what it held)
  stats_.results = num_results_;
  stats_.front = num_front_;
  // Grown so that traverse() from the same seeds, or the next traversal, fits.
  if (!results_fit || !front_complete_) detail::grow_outputs(*this, results, front);
  if (c[detail::kLost] > 0) detail::grow_lazy_lists(*this, c[detail::kLost]);
  return results_fit && c[detail::kHalted] == 0 && c[detail::kLost] == 0;
}

template <class Task>
DeviceCount TraversalOutput<Task>::result_count() const {
  return {counters_.data() + detail::kResults, DeviceCount::Part::whole, results_.size()};
}

template <class Task>
std::size_t expand(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds, std::size_t target,
                   TraversalOutput<Task>& out, bool record_front, cudaStream_t stream) {
  static_assert(require_traversal_task<Task>::value, "");
  std::size_t items = 0;
  // expand_breadth_first stops once a level holds target / kMaxChildren items; asking for
  // target * kMaxChildren makes the cut at least `target` items (or the seeds' whole tree).
  detail::run_until_outputs_fit(out, record_front, stream, [&] {
    items = detail::expand_breadth_first(task, seeds, num_seeds, std::max<std::size_t>(target, 1) * Task::kMaxChildren, out,
                                         record_front, stream);
  });
  return items;
}

}  // namespace lwsccd::gpu
