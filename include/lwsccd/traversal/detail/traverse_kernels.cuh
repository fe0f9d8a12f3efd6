// lwsccd — the GPU traversal engine's definitions (traversal/gpu_traverse.cuh): a file per
// scheduler beside what they share, then the outputs grown until a traversal fits and traverse()
// / traverse_async() choosing the scheduler's host loop.
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
#include "lwsccd/traversal/detail/gproximity.cuh"
#include "lwsccd/traversal/detail/launch.cuh"
#include "lwsccd/traversal/detail/lazy_steal.cuh"
#include "lwsccd/traversal/detail/static_task_list.cuh"

namespace lwsccd::gpu {

namespace detail {

// Outputs sized for a traversal (first use: room for 2^16 entries each), counters allocated.
// `halt`: blocks whose outputs are full hand their items back (traverse()), or only count
// (traverse_async()).
template <class Task>
void prepare_outputs(TraversalStorage<Task>& out, bool record_front, bool halt) {
  ensure(out.counters_, kCounters);
  out.halt_on_overflow_ = halt;
  if (out.results_.size() == 0) out.results_.resize_discard(1 << 16);
  if (out.front_.size() == 0) out.front_.resize_discard(record_front ? (1 << 16) : 1);
  out.stats_ = {};
  out.complete_ = true;
  out.launched_blocks_ = 0;  // until a lazy launch: a start the flat launch ends, or another scheduler, has none
  out.front_complete_ = true;
  out.awaiting_collect_ = false;  // what an earlier traverse_async() left uncollected is superseded
}

// Grows the outputs that `results` and `front` entries overflowed to those counts and a quarter
// more; false (nothing grown) where that would pass out's output limit.
template <class Task>
bool grow_outputs(TraversalStorage<Task>& out, std::size_t results, std::size_t front) {
  using Item = typename Task::item_type;
  using Result = typename Task::result_type;
  const std::size_t results_room =
      results > out.results_.size() ? std::min(results + results / 4, kMaxOutputRoom) : out.results_.size();
  const std::size_t front_room = front > out.front_.size() ? std::min(front + front / 4, kMaxOutputRoom) : out.front_.size();
  check_output_counts(results, front);
  if (out.output_limit_ && results_room * sizeof(Result) + front_room * sizeof(Item) > out.output_limit_) return false;
  out.results_.resize_discard(results_room);
  out.front_.resize_discard(front_room);
  return true;
}

// Runs `attempt` (one complete pass that leaves the final counters in out.host_counters_ when it
// read them) until the results and front fit their outputs. Within a pass, blocks whose outputs
// are full hand their items back and the schedulers' loops grow the outputs and go on
// (absorb_overflow); a pass that lost items for want of list room runs again from the same seeds
// with longer lists (tasks are deterministic, so it gives the same outputs). Stops without
// growing past out's output limit (complete_ false).
template <class Task, class Attempt>
void run_until_outputs_fit(TraversalStorage<Task>& out, bool record_front, cudaStream_t stream, Attempt attempt) {
  prepare_outputs(out, record_front, true);
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
    if (!out.complete_) return;  // stopped at the output limit: num_results_, num_front_ hold what was stored
    const std::size_t results = results_of(c[kOutputs]);
    const std::size_t front = record_front ? front_of(c[kOutputs]) : 0;
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
void traverse(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds, TraversalOutput<Task>& output,
              bool record_front, cudaStream_t stream) {
  static_assert(require_traversal_task<Task>::value, "");
  static_assert(detail::require_scheduler_policy<Scheduler>::value, "");
  detail::TraversalStorage<Task>& out = detail::storage_of(output);
  detail::run_until_outputs_fit(out, record_front, stream, [&] {
    using Kind = typename Scheduler::scheduler_kind;
    if constexpr (std::is_same<Kind, static_task_list_kind>::value)
      detail::run_static<Task, Scheduler>(task, seeds, num_seeds, out, record_front, stream);
    else if constexpr (std::is_same<Kind, lazy_steal_kind>::value)
      detail::run_lazy_steal<Task, Scheduler>(task, seeds, num_seeds, out, record_front, stream);
    else detail::run_balanced<Task, Scheduler>(task, seeds, num_seeds, out, record_front, stream);
  });
}

template <class Scheduler, class Task>
void traverse_async(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds,
                    TraversalOutput<Task>& output, bool record_front, cudaStream_t stream) {
  static_assert(require_traversal_task<Task>::value, "");
  static_assert(detail::require_scheduler_policy<Scheduler>::value, "");
  if constexpr (std::is_same<typename Scheduler::scheduler_kind, lazy_steal_kind>::value) {
    detail::TraversalStorage<Task>& out = detail::storage_of(output);
    if (out.output_limit_ == 0) {  // a limit needs the host between launches to keep to it
      detail::prepare_outputs(out, record_front, false);
      LWSCCD_CUDA_CHECK(cudaMemsetAsync(out.counters_.data(), 0, detail::kCounters * sizeof(unsigned long long), stream));
      if (detail::enqueue_lazy_steal<Task, Scheduler>(task, seeds, num_seeds, out, record_front, stream)) {
        detail::enqueue_counter_read(out, stream);
        out.awaiting_collect_ = true;
        out.awaiting_front_ = record_front;
        return;
      }
    }
  }
  traverse<Scheduler>(task, seeds, num_seeds, output, record_front, stream);  // (clears awaiting_collect_)
}

template <class Task>
bool TraversalOutput<Task>::collect() {
  if (!s_.awaiting_collect_) return true;
  s_.awaiting_collect_ = false;
  const unsigned long long* c = s_.host_counters_.data();
  const std::size_t results = detail::results_of(c[detail::kOutputs]);
  const std::size_t front = s_.awaiting_front_ ? detail::front_of(c[detail::kOutputs]) : 0;
  s_.stats_.items_processed += static_cast<std::size_t>(c[detail::kProcessed]);
  const bool results_fit = results <= s_.results_.size();
  s_.front_complete_ = front <= s_.front_.size();
  s_.num_results_ = std::min(results, s_.results_.size());
  s_.num_front_ = s_.front_complete_ ? front : 0;  // (growing the output discards what it held)
  s_.stats_.results = s_.num_results_;
  s_.stats_.front = s_.num_front_;
  // Outputs that overflowed grow (to the counts and a quarter); lists that lost items, likewise.
  if (!results_fit || !s_.front_complete_) detail::grow_outputs(s_, results, front);
  if (c[detail::kLost] > 0) detail::grow_lazy_lists(s_, c[detail::kLost]);
  return results_fit && c[detail::kHalted] == 0 && c[detail::kLost] == 0;
}

template <class Task>
DeviceCount TraversalOutput<Task>::result_count() const {
  return {s_.counters_.data() + detail::kOutputs, DeviceCount::Part::low, s_.results_.size()};
}

template <class Task>
std::size_t expand(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds, std::size_t target,
                   TraversalOutput<Task>& output, bool record_front, cudaStream_t stream) {
  static_assert(require_traversal_task<Task>::value, "");
  detail::TraversalStorage<Task>& out = detail::storage_of(output);
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
