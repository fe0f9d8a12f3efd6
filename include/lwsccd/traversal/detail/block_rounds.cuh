// lwsccd — what every GPU scheduler shares on the device: the launch counters, the outputs a
// block appends to, a round of items processed by a block (children scanned into its stack), the
// breadth-first and flat kernels, and the two-level (shared, then global) stack loop.
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

namespace lwsccd::gpu::detail {

enum Counter : int {
  kOutputs = 0,    ///< results (low 32 bits) and front items (high 32 bits) appended, one word (pack_outputs)
  kOverflow = 1,   ///< halting traversals: ~(kOutputs before the first append that did not fit), 0 while all fit
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
  kRequeued = 12,   ///< halting flat launches: items put back unprocessed (an output was full)
  kCounters = 13
};

// Results and front entries are counted in one word, so that one atomic reserves both: the
// reservations are then totally ordered, and once one does not fit, none after it does (what a
// halting traversal keeps is a prefix of both outputs). Each count stays below 2^31 (the outputs'
// rooms are capped there, so the halves never carry into each other).
LWSCCD_HD constexpr unsigned long long pack_outputs(unsigned long long results, unsigned long long front) {
  return results | (front << 32);
}
LWSCCD_HD constexpr std::size_t results_of(unsigned long long outputs) { return static_cast<std::size_t>(outputs & 0xffffffffull); }
LWSCCD_HD constexpr std::size_t front_of(unsigned long long outputs) { return static_cast<std::size_t>(outputs >> 32); }
inline constexpr std::size_t kMaxOutputRoom = std::size_t(1) << 31;
// Throws where one traversal asks for more results or front entries than an output may hold.
inline void check_output_counts(std::size_t results, std::size_t front) {
  if (results > kMaxOutputRoom || front > kMaxOutputRoom)
    throw Error("lwsccd: traversal: more than 2^31 results or front entries (" + std::to_string(results) + ", " +
                std::to_string(front) + ") in one traversal; split it (gpu::expand) or use a memory budget");
}

template <class Task>
struct Outputs {
  typename Task::result_type* results;
  std::size_t result_capacity;
  typename Task::item_type* front;
  std::size_t front_capacity;
  unsigned long long* counters;
  bool record_front;
  /// A block whose outputs do not fit stops and hands its items back, keeping what fitted
  /// (traverse(): the host grows the outputs and goes on from there); false: appends past the
  /// room are only counted and the traversal goes on (traverse_async(): collect() asks for a rerun).
  bool halt_on_overflow;
};

// Reserves `results` and `front` places (thread 0 of a block; nothing to reserve is a success).
// Returns the packed base; `fits` says whether both fit. A halting traversal's first reservation
// that does not fit is recorded in kOverflow (the smallest base: reservations only grow).
template <class Task>
__device__ unsigned long long reserve_outputs(const Outputs<Task>& out, int results, int front, bool& fits) {
  fits = true;
  if (results == 0 && front == 0) return pack_outputs(0, 0);
  const unsigned long long base =
      atomicAdd(&out.counters[kOutputs], pack_outputs(static_cast<unsigned long long>(results), static_cast<unsigned long long>(front)));
  fits = results_of(base) + results <= out.result_capacity && front_of(base) + front <= out.front_capacity;
  if (!fits && out.halt_on_overflow) atomicMax(&out.counters[kOverflow], ~base);
  return base;
}

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
// Returns (on every thread) whether they fitted; a halting traversal then writes nothing.
// All threads of the block must call it; `flag` is the block's shared word for the answer.
template <class Task, class Scan>
__device__ bool flush_outputs(const DeviceEmitter<Task>& e, const Outputs<Task>& out, typename Scan::TempStorage& storage,
                              unsigned long long& base, unsigned long long& flag) {
  constexpr int kField = 21;  // (as process_round: the block's totals stay far below 2^21)
  const unsigned long long counts = static_cast<unsigned long long>(e.num_results) |
                                    (static_cast<unsigned long long>(e.num_front) << kField);
  unsigned long long offsets = 0, totals = 0;
  Scan(storage).ExclusiveSum(counts, offsets, totals);
  if (threadIdx.x == 0) {
    bool fits = true;
    base = reserve_outputs(out, static_cast<int>(totals & ((1ull << kField) - 1)), static_cast<int>(totals >> kField), fits);
    flag = fits;
  }
  __syncthreads();
  const bool fits = flag != 0;
  if (fits || !out.halt_on_overflow) {
    const std::size_t result_at = results_of(base) + static_cast<std::size_t>(offsets & ((1ull << kField) - 1));
    for (int r = 0; r < e.num_results; ++r)
      if (result_at + r < out.result_capacity) out.results[result_at + r] = e.results[r];
    const std::size_t front_at = front_of(base) + static_cast<std::size_t>(offsets >> kField);
    if (e.num_front && front_at < out.front_capacity) out.front[front_at] = e.front;
  }
  __syncthreads();  // base and flag read by all, scan storage free
  return fits;
}

// One breadth-first level: every item processed once, children appended to `next`, which holds
// `next_room` (kAppended counts them all: a caller that sized it below n * kMaxChildren checks).
// A halting traversal's block whose outputs do not fit appends its items themselves instead of
// their children (counted in kRequeued): the next level processes them again.
template <class Task, int kThreads>
__global__ void __launch_bounds__(kThreads) expand_kernel(Task task, const typename Task::item_type* in, std::size_t n,
                                                          typename Task::item_type* next, std::size_t next_room,
                                                          Outputs<Task> out) {
  using Scan = cub::BlockScan<unsigned long long, kThreads>;
  __shared__ typename Scan::TempStorage storage;
  __shared__ unsigned long long base, flag;
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  DeviceEmitter<Task> e;
  e.record_front = out.record_front;
  if (i < n) task.process(in[i], e);
  const bool fits = flush_outputs<Task, Scan>(e, out, storage, base, flag);
  const bool requeue = !fits && out.halt_on_overflow;
  const int count = requeue ? (i < n ? 1 : 0) : e.count;
  unsigned long long offset = 0, total = 0;
  Scan(storage).ExclusiveSum(static_cast<unsigned long long>(count), offset, total);
  if (threadIdx.x == 0 && total) {
    base = atomicAdd(&out.counters[kAppended], total);
    if (requeue) atomicAdd(&out.counters[kRequeued], total);
  }
  __syncthreads();
  for (int c = 0; c < count; ++c)
    if (base + offset + c < next_room) next[base + offset + c] = requeue ? in[i] : e.children[c];
}

// The first breadth-first levels of a small start (the root) in one block and one launch:
// level after level, from `a` into `b` and back, while a level holds fewer than `stop_at` items
// (a level per launch cost a launch and a host synchronisation each: 6-7 of them from a root).
// Writes the last level's size to kAppended and the number of levels to kLevels (odd: the last
// level is in `b`). Both buffers hold `room` items, at least stop_at * kMaxChildren. A halting
// traversal whose outputs do not fit puts the level's unprocessed items after the children and
// stops there (the host grows the outputs and expands on).
template <class Task, int kThreads>
__global__ void __launch_bounds__(kThreads)
    expand_small_levels_kernel(Task task, typename Task::item_type* a, typename Task::item_type* b, std::size_t n,
                               std::size_t stop_at, std::size_t room, Outputs<Task> out) {
  using Item = typename Task::item_type;
  using Scan = cub::BlockScan<unsigned long long, kThreads>;
  __shared__ typename Scan::TempStorage storage;
  __shared__ unsigned long long level_size, flush_base, flag;
  Item* in = a;
  Item* next = b;
  unsigned long long levels = 0;
  bool full = false;
  while (n > 0 && n < stop_at && !full) {
    assert(n * Task::kMaxChildren <= room && "expand_small_levels_kernel: a level's children overflow their buffer");
    if (threadIdx.x == 0) level_size = 0;
    __syncthreads();
    std::size_t processed = n;
    for (std::size_t first = 0; first < n; first += kThreads) {
      const std::size_t i = first + threadIdx.x;
      DeviceEmitter<Task> e;
      e.record_front = out.record_front;
      if (i < n) task.process(in[i], e);
      if (!flush_outputs<Task, Scan>(e, out, storage, flush_base, flag) && out.halt_on_overflow) {  // (synchronises)
        const unsigned long long at = level_size;
        for (std::size_t j = first + threadIdx.x; j < n; j += kThreads) next[at + (j - first)] = in[j];
        processed = first;
        full = true;
        __syncthreads();  // level_size read by all
        if (threadIdx.x == 0) level_size += n - first;
        break;
      }
      unsigned long long offset = 0, total = 0;
      Scan(storage).ExclusiveSum(static_cast<unsigned long long>(e.count), offset, total);
      const unsigned long long base = level_size;  // read by all before thread 0 moves it on
      __syncthreads();
      if (threadIdx.x == 0) level_size += total;
      for (int c = 0; c < e.count; ++c) next[base + offset + c] = e.children[c];
    }
    if (threadIdx.x == 0) out.counters[kProcessed] += processed;
    __syncthreads();  // level_size final
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
// thread) how many children were pushed, or kRoundUndone when the outputs had no room for the
// round's in a halting traversal: then nothing was written and the items are back on the stack.
// All threads call it; Scan is a cub::BlockScan of 64-bit words. `out_base` is shared: [0] the
// outputs' packed base, [1] whether they fitted.
//
// A round is latency-bound where a block holds few items (a subtree's last levels, one level a
// round), so it is kept short: the three counts of a thread (children, results, front entries)
// go through one block scan as fields of one word, and the results' and the front's places are
// reserved with one atomic - instead of a scan and a synchronisation per list.
inline constexpr int kRoundUndone = -1;
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
  if (threadIdx.x == 0) {
    bool fits = true;
    out_base[0] = reserve_outputs(out, total_results, total_front, fits);
    out_base[1] = fits;
  }
  __syncthreads();  // s_size updated, places reserved, scan storage free
  if (out_base[1] == 0 && out.halt_on_overflow) {  // undone: the items stay where they were
    __syncthreads();  // out_base read by all
    if (threadIdx.x == 0) s_size += take;
    __syncthreads();
    return kRoundUndone;
  }
  const int child_at = s_size + static_cast<int>(offsets & kMask);
  for (int c = 0; c < e.count; ++c) s_items[child_at + c] = e.children[c];
  const std::size_t result_at = results_of(out_base[0]) + ((offsets >> kField) & kMask);
  for (int r = 0; r < e.num_results; ++r)
    if (result_at + r < out.result_capacity) out.results[result_at + r] = e.results[r];
  const std::size_t front_at = front_of(out_base[0]) + (offsets >> (2 * kField));
  if (e.num_front && front_at < out.front_capacity) out.front[front_at] = e.front;
  __syncthreads();  // children stored (and out_base read) before the stack grows
  if (threadIdx.x == 0) {
    s_size += total_children;
    atomicAdd(&out.counters[kProcessed], static_cast<unsigned long long>(take));
  }
  return total_children;
}

// The shared memory of run_block_stack, declared by the kernel that calls it (CUB's TempStorage
// habit: a kernel sees what its block holds in shared memory, and could alias it with its own).
template <class Task, class Policy>
struct BlockStackStorage {
  using Scan = cub::BlockScan<unsigned long long, Policy::kBlockThreads>;
  typename Task::item_type items[Policy::kSharedStack];  ///< the stack's hot top
  typename Scan::TempStorage scan;
  int size, global_size, take, refill, spill, stop;  ///< stop: 0 run, 1 done, 2 pause, 3 stack full, 4 outputs full
  unsigned long long out_base[2];
  unsigned long long hand_back_base;  ///< where a halted block's items go in the hand-back list
};

// The per-block two-level stack loop shared by the schedulers. `region` is this block's global
// stack (capacity `global_capacity`), holding `region_size` items on entry. Returns with every
// remaining item in the region (its new size in `region_size`) unless `hand_back` is set, in which
// case the items left go to hand_back (when the region would overflow). `shared` is the block's
// __shared__ BlockStackStorage.
template <class Task, class Policy>
__device__ void run_block_stack(const Task& task, typename Task::item_type* region, int& region_size, int global_capacity,
                                const Outputs<Task>& out, const unsigned long long* idle_blocks, unsigned idle_limit,
                                typename Task::item_type* hand_back, BlockStackStorage<Task, Policy>& shared) {
  using Item = typename Task::item_type;
  constexpr int kThreads = Policy::kBlockThreads;
  constexpr int kShared = Policy::kSharedStack;
  constexpr int kK = Task::kMaxChildren;
  static_assert(kShared >= 2 * kThreads * kK, "lwsccd: kSharedStack must hold at least 2 * kBlockThreads * kMaxChildren items");
  using Scan = typename BlockStackStorage<Task, Policy>::Scan;
  Item* s_items = shared.items;
  int &s_size = shared.size, &g_size = shared.global_size, &take = shared.take, &refill = shared.refill,
      &spill = shared.spill, &stop = shared.stop;
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
    if (process_round<Task, Scan>(task, s_items, s_size, take, shared.scan, shared.out_base, out) == kRoundUndone) {
      if (t == 0) stop = 4;  // the outputs are full: everything goes back to the host
      __syncthreads();
      break;
    }
  }
  // Leave every remaining item in the region, or hand everything back when it would not fit.
  if (stop == 1) {
    if (t == 0) region_size = 0;
    return;
  }
  unsigned long long& base = shared.hand_back_base;
  if (stop == 3 || stop == 4 || g_size + s_size > global_capacity) {
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

}  // namespace lwsccd::gpu::detail
