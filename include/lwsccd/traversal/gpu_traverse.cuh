// lwsccd — the traversal engine on the GPU and its scheduler policies (card; users include it
// through <lwsccd/traverse.cuh>): one kernel composed from a task (BVTT self or inter collision,
// ray casting, ...) and a scheduler policy:
//
//   lwsccd::gpu::TraversalOutput<Task> out;
//   lwsccd::gpu::traverse<lwsccd::gpu::StaticTaskList<>>(task, seeds, num_seeds, out, record_front, stream);
//
// Schedulers (tuning knobs are static constexpr members of their policy structs):
// - StaticTaskList: the seeds are expanded breadth first into a cut of the BVTT, split evenly
//   over the blocks before launch; each block finishes its share with its own stack.
// - GProximityBalancer: per-block queues in global memory; the traversal kernel stops when too
//   many blocks are idle, a balancing kernel redistributes the queues evenly, looped from the
//   host (dissertation Algorithms 3.1-3.4).
// - LazyStealScheduler: persistent blocks with shared stacks and global deques, lazy stealing
//   (Algorithms 3.7-3.13); see detail/lazy_steal_kernel.cuh for why it terminates and why ABA
//   cannot occur.
//
// Every block works on a two-level stack: a shared-memory stack holds the hot top, its oldest
// items spill to the block's region of global memory and come back when the shared part runs
// dry. Nothing is lost: a block whose global region would overflow stops before it processes
// more and hands all its items back; the host relaunches with them (TraversalStats::relaunches).
// Results and front items are appended with atomics to outputs that grow: when a launch
// produced more than fit, the output grows to the count and the traversal runs again from the
// same seeds (tasks are deterministic), so the answer is complete.
#pragma once

#include <cub/block/block_scan.cuh>
#include <cuda_runtime.h>

#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <vector>

#include "lwsccd/core/device_buffer.cuh"
#include "lwsccd/traversal/traversal_task.hpp"

namespace lwsccd::gpu {

/// Static split of a BVTT cut over the blocks, no balancing.
template <int BlockThreads = 128, int SharedStack = 1024, int GlobalStack = 16384, int ItemsPerBlock = 256>
struct StaticTaskList {
  static constexpr int kBlockThreads = BlockThreads;
  static constexpr int kSharedStack = SharedStack;  ///< items per block in shared memory
  static constexpr int kGlobalStack = GlobalStack;  ///< items per block in global memory (spill)
  static constexpr int kItemsPerBlock = ItemsPerBlock;  ///< size of the initial cut per block
  static constexpr int kBlocksPerSm = 2;
  static constexpr bool kIsStatic = true;
};

/// gProximity-style balancing: traverse until too many blocks idle, then rebalance.
template <int BlockThreads = 128, int SharedStack = 1024, int GlobalStack = 16384, int IdlePercent = 50>
struct GProximityBalancer {
  static constexpr int kBlockThreads = BlockThreads;
  static constexpr int kSharedStack = SharedStack;
  static constexpr int kGlobalStack = GlobalStack;
  static constexpr int kIdlePercent = IdlePercent;  ///< stop the traversal kernel when this share of blocks idles
  static constexpr int kBlocksPerSm = 2;
  static constexpr bool kIsStatic = false;
};

/// Lazy work stealing (dissertation Algorithms 3.7-3.13): persistent blocks, a shared-memory
/// stack per block, a deque per block in global memory that the owner fills and drains in
/// batches, and, when a block runs dry, a lazy steal: it reads every deque's size at once and
/// takes half of the fullest one's oldest items.
///
/// Defaults measured on an H100 (lwsccd-bench-traverse, docs/TRAVERSAL.md): 512-thread blocks, two
/// per SM, batches of 512, a start from the root expanded to only 8 items per block. Blocks of 128
/// threads left most of each SM's latency unhidden (busy 16-35%, 4-6x slower from the root).
template <int BlockThreads = 512, int SharedStack = 4096, int DequeCapacity = 8192, int PopSize = 512,
          int PushThreshold = 1024, int BlocksPerSm = 2, int SeedsPerBlock = 8, int MaxBackoffNs = 256,
          int StealLockAttempts = 16, bool RandomVictim = true, bool FitBlocksPerSm = true, int FlatStartPerBlock = 512,
          int ShareWhenHungry = -1>
struct LazyStealScheduler {
  static constexpr int kBlockThreads = BlockThreads;
  static constexpr int kSharedStack = SharedStack;
  static constexpr int kDequeCapacity = DequeCapacity;  ///< items per block deque (global memory)
  static constexpr int kPopSize = PopSize;              ///< items moved from a deque into shared memory at once
  static constexpr int kPushThreshold = PushThreshold;  ///< shared stack size above which a batch goes to the deque
  static constexpr int kBlocksPerSm = BlocksPerSm;      ///< persistent blocks per SM (occupancy hides memory latency)
  /// A start from few seeds (the root) first expands them breadth first to about this many items
  /// per block (levels under 2,048 items in one single-block launch, larger ones a launch and a
  /// host sync each); stealing spreads the rest.
  static constexpr int kSeedsPerBlock = SeedsPerBlock;
  /// A block that found nothing to steal sleeps before it looks again, from 256 ns, doubling up
  /// to this (ns). Doubling up to 4 or 16 us was no faster on an H100 (docs/TRAVERSAL.md), so
  /// the default keeps a fixed 256 ns.
  static constexpr int kMaxBackoffNs = MaxBackoffNs;
  /// A thief tries its victim's lock this many times (64 ns apart) before it looks again (0: it
  /// waits for the lock). With kRandomVictim, 16 tries removed the
  /// end-of-traversal convoy and made every traversal of the benchmark as fast or faster on an
  /// H100 (fronts 1.2-1.8x); alone it made OBB fronts slower (docs/TRAVERSAL.md).
  static constexpr int kStealLockAttempts = StealLockAttempts;
  /// A thief picks its victim at random among the deques within a factor of two of the fullest
  /// (false: the fullest, ties to the nearest after it), so that thieves
  /// that all saw the same fullest deque do not all contend for its lock.
  static constexpr bool kRandomVictim = RandomVictim;
  /// Whether the kernel is compiled to fit kBlocksPerSm blocks per SM (__launch_bounds__ with that
  /// minimum: registers capped, spilled if need be; false: the compiler's choice). Either way the
  /// launch has only as many blocks as can be resident at once (at most kBlocksPerSm per SM, by
  /// cudaOccupancyMaxActiveBlocksPerMultiprocessor): a persistent block waiting for a slot would
  /// start only when the others were done: without either, the kernels that take more than 64
  /// registers (OBB: 113, rays: 88-94) ran half their blocks after the others.
  /// Fitting (OBB: 64 registers, 104 bytes spilled) was faster than one block per SM on every
  /// OBB traversal and ray set on an H100 (docs/TRAVERSAL.md); AABB takes 64 either way.
  static constexpr bool kFitBlocksPerSm = FitBlocksPerSm;
  /// A start of at least this many items per launched block (a front kept from the last step)
  /// is processed first by one flat launch, a thread per item, and the blocks share only the
  /// children it leaves (0: never). From a front most items end at once
  /// (leaf pairs, or boxes that no longer overlap: horse-gallop processes ~1.06 items per front
  /// item), so the persistent blocks' rounds of kPopSize items were the cost. On an H100 (AABB
  /// fronts): cloth-ball 0.56 -> 0.21 ms, cloth-funnel 0.058 -> 0.030 (512 per block; 2,048
  /// left it out), horse-gallop 0.32 -> 0.23 (docs/TRAVERSAL.md).
  static constexpr int kFlatStartPerBlock = FlatStartPerBlock;
  /// A block holding more than this many items (and at most kPushThreshold) moves the older half
  /// to its deque when its deque is empty and some block is looking for work (a count of the
  /// blocks in a search, read once a round), instead of only above kPushThreshold: the CPU
  /// scheduler's rule (share when the deque is empty) asked for by demand. 0: never; negative
  /// (the default): half of kPushThreshold. On an H100 (docs/TRAVERSAL.md, "Sharing on demand",
  /// five runs) half of the default's 1,024 took cloth-funnel from the root below Karras's
  /// per-leaf traversal (AABB 0.32-0.35 -> 0.28-0.29 ms, Karras 0.29-0.31; OBB 0.57-0.62 ->
  /// 0.53-0.54) and was as fast or faster on the other OBB traversals and every front; AABB from
  /// the root paid 8% on armadillo-rollers and 0-11% on cloth-ball. A quarter or an eighth was
  /// slower than half everywhere; three quarters (AABB only) cost nothing there but only tied
  /// Karras on cloth-funnel.
  static constexpr int kShareWhenHungry = ShareWhenHungry < 0 ? PushThreshold / 2 : ShareWhenHungry;
  static constexpr bool kIsStatic = false;
  static constexpr bool kIsLazySteal = true;
};

/// LazyStealScheduler with room for 16 children per thread and round (RayWalkTask<>'s items):
/// 128-thread blocks, six per SM, a shared stack of 4,096 items. The fastest shape for ray walks
/// on an H100 among those lwsccd-bench-rays --walks weighs (docs/RAYTRACING.md).
using RayWalkLazySteal = LazyStealScheduler<128, 4096, 8192, 512, 2048, 6>;

/// LazyStealScheduler: what one persistent block did in a launch (clock64 cycles of its SM).
struct BlockActivity {
  unsigned long long busy_cycles = 0;    ///< processing items (rounds, batches moved to its deque)
  unsigned long long idle_cycles = 0;    ///< looking for work: its own deque, steals, waiting for others
  unsigned long long steals = 0;         ///< batches taken from another block's deque
  unsigned long long failed_steals = 0;  ///< searches that found nothing to take (or lost the race for it)
};

/// LazyStealScheduler with TraversalOutput::record_timeline: what a persistent block turned to,
/// and when (the GPU's global timer, ns, comparable across SMs). A block's phase lasts until its
/// next event: `seek` (out of items: its own deque, then steals, then waiting), `own` / `steal`
/// (found `items` there and works on them, pushing surplus to its deque), `done` (no work left;
/// `items`: how many looks its last search took).
enum class BlockPhase : std::uint32_t { seek = 0, own = 1, steal = 2, done = 3 };
struct TimelineEvent {
  unsigned long long time_ns = 0;
  BlockPhase phase = BlockPhase::seek;
  std::uint32_t items = 0;
};
/// One block's events in the last launch; `recorded` can exceed events.size() when the room per
/// block ran out (the later events are dropped).
struct BlockTimeline {
  std::vector<TimelineEvent> events;
  std::size_t recorded = 0;
};

namespace detail {
/// Where the lazy kernel writes the timeline (events null: off).
struct TimelineSink {
  TimelineEvent* events = nullptr;
  unsigned* counts = nullptr;
  int capacity = 0;
#ifdef __CUDACC__
  __device__ void record(int block, BlockPhase phase, std::uint32_t items) const {
    if (!events) return;
    unsigned long long now = 0;
    asm volatile("mov.u64 %0, %%globaltimer;" : "=l"(now));
    const unsigned k = counts[block]++;  // one thread per block records
    if (k < static_cast<unsigned>(capacity)) events[static_cast<std::size_t>(block) * capacity + k] = {now, phase, items};
  }
#endif
};
}  // namespace detail

/// Owning device outputs of a traversal (reused across calls; they only grow).
template <class Task>
class TraversalOutput {
 public:
  using item_type = typename Task::item_type;
  using result_type = typename Task::result_type;

  std::size_t num_results() const { return num_results_; }
  std::size_t num_front() const { return num_front_; }
  const result_type* results() const { return results_.data(); }
  const item_type* front() const { return front_.data(); }
  const TraversalStats& stats() const { return stats_; }
  /// LazyStealScheduler: what each persistent block did in the last launch of the lazy kernel in
  /// the last traversal (empty when it launched none: a start that the flat launch ended, as a
  /// front restarted on unchanged positions is, or another scheduler).
  std::vector<BlockActivity> download_block_activity(cudaStream_t stream = nullptr) const {
    return prefix(block_activity_, std::min<std::size_t>(launched_blocks_, block_activity_.size()), stream);
  }
  /// LazyStealScheduler: the persistent blocks of the last launch in the last traversal (SMs x the
  /// blocks per SM that its kernel can keep resident, at most the policy's kBlocksPerSm; 0 when
  /// that traversal launched the lazy kernel not at all).
  int launched_blocks() const { return launched_blocks_; }
  /// LazyStealScheduler: record every block's timeline in the following traversals, up to
  /// `events_per_block` events per block (0, the default: off). Costs a global-timer read and a
  /// store per phase change; for measuring, not for production runs.
  void record_timeline(int events_per_block) {
    if (events_per_block < 0) throw std::invalid_argument("lwsccd: record_timeline: events_per_block must be >= 0");
    timeline_capacity_ = events_per_block;
  }
  /// The timelines of the last launch of the lazy kernel in the last traversal (empty when not
  /// recorded, or when that traversal launched none).
  std::vector<BlockTimeline> download_timeline(cudaStream_t stream = nullptr) const {
    std::vector<BlockTimeline> blocks;
    if (timeline_capacity_ == 0 || timeline_counts_.size() == 0 || launched_blocks_ == 0) return blocks;
    const std::vector<unsigned> counts =
        prefix(timeline_counts_, std::min<std::size_t>(launched_blocks_, timeline_counts_.size()), stream);
    const std::vector<TimelineEvent> events = prefix(timeline_, timeline_.size(), stream);
    const auto room = static_cast<std::size_t>(timeline_capacity_);
    blocks.resize(counts.size());
    for (std::size_t b = 0; b < counts.size(); ++b) {
      blocks[b].recorded = counts[b];
      const std::size_t kept = std::min<std::size_t>(counts[b], room);
      blocks[b].events.assign(events.begin() + static_cast<std::ptrdiff_t>(b * room),
                              events.begin() + static_cast<std::ptrdiff_t>(b * room + kept));
    }
    return blocks;
  }
  std::vector<result_type> download_results(cudaStream_t stream = nullptr) const { return prefix(results_, num_results_, stream); }
  std::vector<item_type> download_front(cudaStream_t stream = nullptr) const { return prefix(front_, num_front_, stream); }
  std::size_t device_bytes() const {
    return results_.capacity_bytes() + front_.capacity_bytes() + work_.capacity_bytes() + next_.capacity_bytes() +
           stacks_.capacity_bytes() + stacks_alt_.capacity_bytes() + sizes_.capacity_bytes() + sizes_alt_.capacity_bytes() +
           locks_.capacity_bytes() + deque_ends_.capacity_bytes() + block_activity_.capacity_bytes() +
           timeline_.capacity_bytes() + timeline_counts_.capacity_bytes() + counters_.capacity_bytes();
  }
  /// Caps the bytes the results and front outputs may grow to (0: no cap). A traversal whose
  /// outputs would need more stops without growing them and reports complete() == false; the
  /// caller runs fewer seeds at a time (gpu::CcdPipeline streams its seeds so under a budget).
  void set_output_limit(std::size_t bytes) { output_limit_ = bytes; }
  std::size_t output_limit() const { return output_limit_; }
  /// False when the last traversal stopped at the output limit (its outputs are then incomplete).
  bool complete() const { return complete_; }
  /// gpu::expand: the items of the cut it produced (valid until the next traversal).
  const item_type* expanded() const { return work_.data(); }

  /// The number of results as the device holds it (capped at the output's room): what a later
  /// stage on the same stream reads where traverse_async() left the count on the device.
  DeviceCount result_count() const;
  /// After traverse_async() and a synchronisation of its stream: reads the counts (num_results(),
  /// num_front(), stats()). Returns whether the results are complete: false when the results'
  /// output overflowed (it is grown now) or blocks handed items back (a full deque, a full list):
  /// run traverse() from the same seeds. A front that outgrew its output leaves the results
  /// complete and the front unusable (front_complete() false, num_front() 0; the output is grown
  /// for the next traversal): start the next traversal from elsewhere, e.g. this one's seeds,
  /// which are as valid a cut. True, with nothing to do, after traverse().
  bool collect();
  /// False after a collect() whose front did not fit its output; true after traverse().
  bool front_complete() const { return front_complete_; }

  // Storage used by the schedulers.
  DeviceBuffer<result_type> results_;
  DeviceBuffer<item_type> front_, work_, next_, stacks_, stacks_alt_;
  DeviceBuffer<int> sizes_, sizes_alt_, locks_;
  DeviceBuffer<unsigned long long> deque_ends_;    ///< per block: top, bottom (monotonic)
  DeviceBuffer<BlockActivity> block_activity_;  ///< per block (LazyStealScheduler)
  DeviceBuffer<TimelineEvent> timeline_;         ///< per block, timeline_capacity_ each (record_timeline)
  DeviceBuffer<unsigned> timeline_counts_;       ///< events per block in the last launch
  int timeline_capacity_ = 0;
  int launched_blocks_ = 0;  ///< LazyStealScheduler: blocks of the last launch
  std::size_t list_room_ = 0;  ///< LazyStealScheduler: items its start and hand-back lists hold (grown on overflow)
  DeviceBuffer<unsigned long long> counters_;  ///< see detail::Counter
  PinnedBuffer<unsigned long long> host_counters_;  ///< their last reading (pinned: the copy does not block)
  std::uint64_t counter_reads_ = 0;                 ///< readings so far (traverse() reuses a final one)
  std::size_t num_results_ = 0, num_front_ = 0;
  std::size_t output_limit_ = 0;
  bool complete_ = true;
  bool front_complete_ = true;
  bool awaiting_collect_ = false;  ///< traverse_async() left the counts on the device
  bool awaiting_front_ = false;    ///< and recorded a front
  TraversalStats stats_;

 private:
  template <class T>
  static std::vector<T> prefix(const DeviceBuffer<T>& b, std::size_t n, cudaStream_t stream) {
    std::vector<T> out(n);
    if (n) {
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(out.data(), b.data(), n * sizeof(T), cudaMemcpyDeviceToHost, stream));
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
    }
    return out;
  }
};

/// Runs `task` from the device array of seeds to completion with Scheduler. Synchronizes.
template <class Scheduler, class Task>
void traverse(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds, TraversalOutput<Task>& out,
              bool record_front, cudaStream_t stream = nullptr);

/// As traverse(), without a host round trip where the scheduler allows it: LazyStealScheduler
/// from a start that its flat launch takes (at least kFlatStartPerBlock items per block, e.g. a
/// front kept from the last step) with no output limit. The counts then stay on the device
/// (out.result_count() for a later stage on `stream`); call out.collect() once `stream` has been
/// synchronized, and traverse() again where it returns false. Other starts and schedulers run as
/// traverse() does (synchronizing; collect() returns true).
template <class Scheduler, class Task>
void traverse_async(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds,
                    TraversalOutput<Task>& out, bool record_front, cudaStream_t stream = nullptr);

/// Expands the seeds breadth first (levels under 2,048 items in one launch) until at least
/// `target` items remain (or none): returns their number; they are at out.expanded() and form a
/// cut of the traversal, so traversing them (in any grouping) gives the results that traversing
/// the seeds would, less the results and front entries met on the way, which are in
/// out.results() and out.front(). Splits one traversal into independent parts
/// (gpu::CcdPipeline's streaming under a memory budget).
/// Honours out's output limit as traverse() does. Synchronizes.
template <class Task>
std::size_t expand(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds, std::size_t target,
                   TraversalOutput<Task>& out, bool record_front, cudaStream_t stream = nullptr);

}  // namespace lwsccd::gpu

#include "lwsccd/traversal/detail/traverse_kernels.cuh"
