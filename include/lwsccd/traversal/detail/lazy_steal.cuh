// lwsccd — LazyStealScheduler on the host: the lazy kernel's launch shape (persistent blocks that
// fit at once), a front's flat start, and the loop over passes until nothing is handed back. The
// kernels are in lazy_steal_kernel.cuh.
// Part of traverse_kernels.cuh: include <lwsccd/traverse.cuh>, not this file.
#pragma once

#include <algorithm>
#include <atomic>
#include <string>
#include <type_traits>

#include "lwsccd/core/error.hpp"
#include "lwsccd/traversal/gpu_traverse.cuh"
#include "lwsccd/traversal/detail/launch.cuh"
#include "lwsccd/traversal/detail/lazy_steal_kernel.cuh"

namespace lwsccd::gpu::detail {

// The launch shape of the lazy kernel (persistent blocks that fit at once) and its timeline's
// storage; sizes the per-block arrays.
template <class Task, class Policy>
int prepare_lazy(TraversalStorage<Task>& out, TimelineSink& timeline, cudaStream_t stream) {
  static std::atomic<int> fit_per_device[16];  // zero-initialized (static storage)
  const int blocks =
      co_resident_blocks(lazy_steal_kernel<Task, Policy>, Policy::kBlockThreads, Policy::kBlocksPerSm, fit_per_device);
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
void launch_lazy(const Task& task, TraversalStorage<Task>& out, unsigned long long n, int blocks, int capacity,
                 const TimelineSink& timeline, bool record_front, cudaStream_t stream) {
  ensure(out.stacks_, static_cast<std::size_t>(blocks) * capacity);
  ensure(out.next_, out.list_room_);
  out.launched_blocks_ = blocks;  // what download_block_activity / download_timeline read
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
void size_lazy_lists(TraversalStorage<Task>& out, int blocks) {
  if (out.list_room_ == 0) out.list_room_ = static_cast<std::size_t>(blocks) * Policy::kSharedStack;
}

// The flat launch of a front's start: every seed processed once, the children into out.work_
// (their count left on the device, in kAppended; past out.list_room_ only counted).
template <class Task>
void enqueue_flat_start(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds,
                        TraversalStorage<Task>& out, bool record_front, cudaStream_t stream) {
  ensure(out.next_, out.list_room_);
  LWSCCD_CUDA_CHECK(cudaMemsetAsync(out.counters_.data() + kRequeued, 0, sizeof(unsigned long long), stream));
  expand_kernel<Task, kFlatLaunchThreads><<<static_cast<unsigned>((num_seeds + kFlatLaunchThreads - 1) / kFlatLaunchThreads),
                                             kFlatLaunchThreads, 0, stream>>>(
      task, seeds, num_seeds, out.next_.data(), out.list_room_, outputs_of(out, record_front));
  LWSCCD_CUDA_CHECK_LAUNCH();
  std::swap(out.work_, out.next_);
  out.stats_.flat_start_items = num_seeds;
  out.stats_.items_processed += num_seeds;  // the lazy launch counts its own
}

template <class Task, class Policy>
void run_lazy_steal(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds,
                    TraversalStorage<Task>& out, bool record_front, cudaStream_t stream) {
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
    const auto c = read_counters(out, stream);
    out.stats_.items_processed -= static_cast<std::size_t>(c[kRequeued]);  // (processed again below)
    if (!absorb_overflow(out, c, stream)) return;  // stopped at the output limit (incomplete)
    if (c[kAppended] == 0) return;
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
    const bool outputs_were_full = c[kOverflow] != 0;
    if (!absorb_overflow(out, c, stream)) return;  // stopped at the output limit (incomplete)
    if (n == 0) return;
    if (outputs_were_full) continue;  // (absorb_overflow counted the relaunch; the deques were not the cause)
    ++out.stats_.relaunches;  // halted blocks handed items back: they start the next launch
    // Larger deques, fewer relaunches; under an output limit (a memory budget planned around
    // these deques) they keep their size: each launch still processes items before a block halts.
    if (out.output_limit_ == 0) capacity *= 2;
  }
}

// A start that the flat launch takes (see lazy_flat_start) enqueued whole, without a host round
// trip: the flat launch leaves its children's count on the device and the lazy launch reads it
// there. Returns false (nothing enqueued) for other starts. What the host would have done between
// the launches - relaunch what halted blocks handed back, grow outputs or lists that overflowed -
// is left to TraversalOutput::collect(), which reports it.
template <class Task, class Policy>
bool enqueue_lazy_steal(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds,
                        TraversalStorage<Task>& out, bool record_front, cudaStream_t stream) {
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
void grow_lazy_lists(TraversalStorage<Task>& out, unsigned long long lost) {
  const std::size_t needed = out.list_room_ + static_cast<std::size_t>(lost);
  out.list_room_ = std::max(2 * out.list_room_, needed + needed / 4);
}

}  // namespace lwsccd::gpu::detail
