// lwsccd — the traversal engine on the GPU and its scheduler policies (card; users include it
// through <lwsccd/traverse.cuh>): one kernel composed from a task (BVTT self or inter collision,
// ray casting, ...) and a scheduler policy:
//
//   lwsccd::gpu::TraversalOutput<Task> out;
//   lwsccd::gpu::traverse<lwsccd::gpu::StaticTaskList>(task, seeds, num_seeds, out, record_front, stream);
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
#include <type_traits>
#include <vector>

#include "lwsccd/core/device_buffer.cuh"
#include "lwsccd/traversal/scheduler_policies.hpp"
#include "lwsccd/traversal/traversal_task.hpp"

namespace lwsccd::gpu {

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

template <class Task>
class TraversalOutput;

namespace detail {
/// A traversal's device storage: the outputs and the schedulers' own lists, which the scheduler
/// files (detail/) fill. TraversalOutput owns one privately; the schedulers reach it through
/// storage_of(), and their kernels get trivially copyable views of it (Outputs, raw pointers).
template <class Task>
struct TraversalStorage {
  using item_type = typename Task::item_type;
  using result_type = typename Task::result_type;

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
  bool halt_on_overflow_ = true;  ///< Outputs::halt_on_overflow of the launches (prepare_outputs)
  bool awaiting_collect_ = false;  ///< traverse_async() left the counts on the device
  bool awaiting_front_ = false;    ///< and recorded a front
  TraversalStats stats_;

  std::size_t device_bytes() const {
    return results_.capacity_bytes() + front_.capacity_bytes() + work_.capacity_bytes() + next_.capacity_bytes() +
           stacks_.capacity_bytes() + stacks_alt_.capacity_bytes() + sizes_.capacity_bytes() + sizes_alt_.capacity_bytes() +
           locks_.capacity_bytes() + deque_ends_.capacity_bytes() + block_activity_.capacity_bytes() +
           timeline_.capacity_bytes() + timeline_counts_.capacity_bytes() + counters_.capacity_bytes();
  }
};

/// The storage of `out`, for the scheduler files and the traversal's entry points.
template <class Task>
TraversalStorage<Task>& storage_of(TraversalOutput<Task>& out);
template <class Task>
const TraversalStorage<Task>& storage_of(const TraversalOutput<Task>& out);
}  // namespace detail

/// Owning device outputs of a traversal (reused across calls; they only grow). Its storage is
/// private: read it through the accessors below, pass it to traverse() and its kin.
template <class Task>
class TraversalOutput {
 public:
  using item_type = typename Task::item_type;
  using result_type = typename Task::result_type;

  std::size_t num_results() const { return s_.num_results_; }
  std::size_t num_front() const { return s_.num_front_; }
  const result_type* results() const { return s_.results_.data(); }
  const item_type* front() const { return s_.front_.data(); }
  const TraversalStats& stats() const { return s_.stats_; }
  /// LazyStealScheduler: what each persistent block did in the last launch of the lazy kernel in
  /// the last traversal (empty when it launched none: a start that the flat launch ended, as a
  /// front restarted on unchanged positions is, or another scheduler).
  std::vector<BlockActivity> download_block_activity(cudaStream_t stream = nullptr) const {
    return prefix(s_.block_activity_, std::min<std::size_t>(s_.launched_blocks_, s_.block_activity_.size()), stream);
  }
  /// LazyStealScheduler: the persistent blocks of the last launch in the last traversal (SMs x the
  /// blocks per SM that its kernel can keep resident, at most the policy's kBlocksPerSm; 0 when
  /// that traversal launched the lazy kernel not at all).
  int launched_blocks() const { return s_.launched_blocks_; }
  /// LazyStealScheduler: record every block's timeline in the following traversals, up to
  /// `events_per_block` events per block (0, the default: off). Costs a global-timer read and a
  /// store per phase change; for measuring, not for production runs.
  void record_timeline(int events_per_block) {
    if (events_per_block < 0) throw std::invalid_argument("lwsccd: record_timeline: events_per_block must be >= 0");
    s_.timeline_capacity_ = events_per_block;
  }
  /// The timelines of the last launch of the lazy kernel in the last traversal (empty when not
  /// recorded, or when that traversal launched none).
  std::vector<BlockTimeline> download_timeline(cudaStream_t stream = nullptr) const {
    std::vector<BlockTimeline> blocks;
    if (s_.timeline_capacity_ == 0 || s_.timeline_counts_.size() == 0 || s_.launched_blocks_ == 0) return blocks;
    const std::vector<unsigned> counts =
        prefix(s_.timeline_counts_, std::min<std::size_t>(s_.launched_blocks_, s_.timeline_counts_.size()), stream);
    const std::vector<TimelineEvent> events = prefix(s_.timeline_, s_.timeline_.size(), stream);
    const auto room = static_cast<std::size_t>(s_.timeline_capacity_);
    blocks.resize(counts.size());
    for (std::size_t b = 0; b < counts.size(); ++b) {
      blocks[b].recorded = counts[b];
      const std::size_t kept = std::min<std::size_t>(counts[b], room);
      blocks[b].events.assign(events.begin() + static_cast<std::ptrdiff_t>(b * room),
                              events.begin() + static_cast<std::ptrdiff_t>(b * room + kept));
    }
    return blocks;
  }
  std::vector<result_type> download_results(cudaStream_t stream = nullptr) const {
    return prefix(s_.results_, s_.num_results_, stream);
  }
  std::vector<item_type> download_front(cudaStream_t stream = nullptr) const { return prefix(s_.front_, s_.num_front_, stream); }
  /// Device bytes held (every buffer's capacity).
  std::size_t device_bytes() const { return s_.device_bytes(); }
  /// Of those, the results' and the front's outputs; the lists the seeds are expanded into.
  std::size_t output_bytes() const { return results_bytes() + front_bytes(); }
  std::size_t results_bytes() const { return s_.results_.capacity_bytes(); }
  std::size_t front_bytes() const { return s_.front_.capacity_bytes(); }
  std::size_t seed_list_bytes() const { return s_.work_.capacity_bytes() + s_.next_.capacity_bytes(); }

  /// Trades the front's buffer for `buffer` (its contents become the caller's: num_front() items;
  /// the output then has `buffer`'s old storage, resized to `room` items): keeps a front, e.g. as
  /// the next traversal's seeds, without a copy.
  void exchange_front(DeviceBuffer<item_type>& buffer, std::size_t room) {
    std::swap(buffer, s_.front_);
    s_.front_.resize_discard(room);
  }
  /// Frees the front's output (a traversal that records one allocates it again).
  void release_front() { s_.front_ = DeviceBuffer<item_type>(); }
  /// Frees the schedulers' own lists and stacks (scratch between traversals; the next traversal
  /// allocates them again at the sizes they had reached). The outputs stay.
  void release_scratch() {
    s_.work_ = DeviceBuffer<item_type>();
    s_.next_ = DeviceBuffer<item_type>();
    s_.stacks_ = DeviceBuffer<item_type>();
    s_.stacks_alt_ = DeviceBuffer<item_type>();
    s_.sizes_ = DeviceBuffer<int>();
    s_.sizes_alt_ = DeviceBuffer<int>();
  }

  /// Caps the bytes the results and front outputs may grow to (0: no cap). A traversal whose
  /// outputs would need more stops without growing them and reports complete() == false; the
  /// caller runs fewer seeds at a time (gpu::CcdPipeline streams its seeds so under a budget).
  void set_output_limit(std::size_t bytes) { s_.output_limit_ = bytes; }
  std::size_t output_limit() const { return s_.output_limit_; }
  /// False when the last traversal stopped at the output limit (its outputs are then incomplete).
  bool complete() const { return s_.complete_; }
  /// gpu::expand: the items of the cut it produced (valid until the next traversal).
  const item_type* expanded() const { return s_.work_.data(); }

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
  bool front_complete() const { return s_.front_complete_; }

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

  detail::TraversalStorage<Task> s_;
  friend detail::TraversalStorage<Task>& detail::storage_of<Task>(TraversalOutput<Task>&);
  friend const detail::TraversalStorage<Task>& detail::storage_of<Task>(const TraversalOutput<Task>&);
};

namespace detail {
template <class Task>
TraversalStorage<Task>& storage_of(TraversalOutput<Task>& out) {
  return out.s_;
}
template <class Task>
const TraversalStorage<Task>& storage_of(const TraversalOutput<Task>& out) {
  return out.s_;
}
}  // namespace detail

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
