// lwsccd — LazyStealScheduler on the device: persistent blocks, shared stacks, per-block deques
// in global memory and lazy steals (dissertation Algorithms 3.7-3.13); why it terminates and why
// ABA cannot occur is below. The host side (launch shape, start, the loop over passes) is in
// lazy_steal.cuh.
// Part of traverse_kernels.cuh: include <lwsccd/traverse.cuh>, not this file.
#pragma once

#include <cub/block/block_reduce.cuh>
#include <cub/block/block_scan.cuh>
#include <cuda/atomic>

#include <cstddef>
#include <cstdint>

#include "lwsccd/traversal/gpu_traverse.cuh"
#include "lwsccd/traversal/detail/block_rounds.cuh"

namespace lwsccd::gpu::detail {

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
  static_assert(share_when_hungry<Policy>() >= 0 && share_when_hungry<Policy>() < kPushAbove,
                "lwsccd: LazyStealScheduler: kShareWhenHungry must be 0 (off) or below kPushThreshold");
  using Scan = cub::BlockScan<unsigned long long, kThreads>;
  using Reduce = cub::BlockReduce<unsigned long long, kThreads>;
  __shared__ Item s_items[kShared];
  __shared__ typename Scan::TempStorage scan_storage;
  __shared__ typename Reduce::TempStorage reduce_storage;
  __shared__ int s_size, take, action, count, source, moved;
  __shared__ bool share_now;  // kShareWhenHungry: thread 0's reading at the end of the last round
  __shared__ bool draining;   // halting traversal: thread 0 saw the outputs full
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
  // Every item of the shared stack to the host's hand-back list (out of the live count); all
  // threads call it.
  auto hand_back_all = [&]() {
    if (t == 0) {
      moved = s_size;
      from = atomicAdd(&out.counters[kAppended], static_cast<unsigned long long>(moved));
      atomicAdd(&out.counters[kHalted], 1ull);
      if (from + moved > hand_back_room)  // no room to hand them back: the pass reruns with more
        atomicAdd(&out.counters[kLost], from + moved - (from > hand_back_room ? from : hand_back_room));
      live.fetch_sub(static_cast<unsigned long long>(moved), cuda::memory_order_acq_rel);
    }
    __syncthreads();
    for (int i = t; i < moved; i += kThreads)
      if (from + i < hand_back_room) hand_back[from + i] = s_items[i];
    __syncthreads();
    if (t == 0) s_size = 0;
    __syncthreads();
  };
  while (true) {
    if (s_size == 0) {  // find work: own deque first, then a lazy steal
      const long long start = clock64();
      if (t == 0) {
        if (!seeking) {
          timeline.record(me, BlockPhase::seek, 0), looks = 0;
          if (share_when_hungry<Policy>() > 0) hungry.fetch_add(1, cuda::memory_order_relaxed);
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
          if (share_when_hungry<Policy>() > 0) hungry.fetch_sub(1, cuda::memory_order_relaxed);
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
        if (share_when_hungry<Policy>() > 0) hungry.fetch_sub(1, cuda::memory_order_relaxed);
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
    // A halting traversal whose outputs are full (this block's or another's round did not fit):
    // what the block holds goes back to the host unprocessed; the host grows the outputs and
    // relaunches with it (traverse()). The block goes on draining what it finds until none is left.
    if (t == 0) {
      take = s_size < kThreads ? s_size : kThreads;
      draining = out.halt_on_overflow && *reinterpret_cast<const volatile unsigned long long*>(&out.counters[kOverflow]) != 0;
    }
    __syncthreads();
    if (draining) {
      hand_back_all();
      busy += clock64() - start;
      continue;
    }
    const int total = process_round<Task, Scan>(task, s_items, s_size, take, scan_storage, out_base, out);
    if (total == kRoundUndone) {  // (the items are back on the stack)
      hand_back_all();
      busy += clock64() - start;
      continue;
    }
    if (t == 0 && total != take) {
      // Children counted and parents retired in one update (see the termination note above).
      live.fetch_add(static_cast<unsigned long long>(static_cast<long long>(total) - take), cuda::memory_order_relaxed);
    }
    if (share_when_hungry<Policy>() > 0 && t == 0) {  // share next round? (own deque empty, a block searching)
      using Word = cuda::atomic_ref<unsigned long long, cuda::thread_scope_device>;
      share_now = s_size > share_when_hungry<Policy>() && s_size <= kPushAbove &&
                  Word(ends[2 * me + 1]).load(cuda::memory_order_relaxed) <= Word(ends[2 * me]).load(cuda::memory_order_relaxed) &&
                  hungry.load(cuda::memory_order_relaxed) > 0;
    }
    busy += clock64() - start;
    __syncthreads();
  }
  if (t == 0)
    activity[me] = {static_cast<unsigned long long>(busy), static_cast<unsigned long long>(idle), steals, failed_steals};
}

}  // namespace lwsccd::gpu::detail
