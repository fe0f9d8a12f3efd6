// lwsccd — the traversal engine's CPU backend: runs any traversal task (traversal_task.hpp) to
// completion, serially or on all cores with work stealing. It is the oracle the GPU schedulers
// (traverse.cuh) are compared with, and the default where there is no GPU.
#pragma once

#include <algorithm>
#include <cassert>
#include <vector>

#include "lwsccd/core/parallel.hpp"
#include "lwsccd/traversal/traversal_task.hpp"

namespace lwsccd {

/// What a traversal produced: results, and (when recorded) the front to restart from.
template <class Task>
struct TraversalResult {
  std::vector<typename Task::result_type> results;
  std::vector<typename Task::item_type> front;
  TraversalStats stats;
};

namespace detail {

template <class Task>
struct VectorEmitter {
  std::vector<typename Task::item_type>* items;
  std::vector<typename Task::result_type>* results;
  std::vector<typename Task::item_type>* front;  ///< null: not recorded
  // (Large lists grow on huge pages: lwsccd::detail::push_back_large.)
  void push_item(const typename Task::item_type& x) { push_back_large(*items, x); }
  void push_result(const typename Task::result_type& r) { push_back_large(*results, r); }
  void push_front(const typename Task::item_type& x) {
    if (front) push_back_large(*front, x);
  }
};

}  // namespace detail

namespace cpu {

/// One thread, one explicit stack (depth first).
struct SerialScheduler {};

/// All cores: the seeds (a kept front holds millions), or, when they are fewer than the threads
/// can share, a breadth-first cut below them, are dealt in ranges to the threads of the pool,
/// each range traversed depth first on the thread's private stack; oneTBB's work stealing moves
/// ranges between threads (without it, threads take ranges from a shared counter). No lock or
/// shared counter per item. (The loop that shared single items through per-thread deques before
/// it did not scale: 16 threads were slower than one on a front of 6.8 M seeds, docs/PIPELINE.md.)
struct WorkStealingScheduler {
  unsigned threads = 0;  ///< 0: the threads the caller may use (cpu::ThreadLimit; default every core)
};

/// The memory a work-stealing traversal keeps for the next one: its threads' lists. A caller that
/// traverses every step (a pipeline) passes the same workspace and result to traverse_into, so
/// that a warm step allocates nothing (fresh pages cost page faults, which serialise threads).
template <class Task>
struct TraversalWorkspace {
  std::vector<std::vector<typename Task::result_type>> results;
  std::vector<std::vector<typename Task::item_type>> fronts;
};

template <class Task>
TraversalResult<Task> traverse(const Task& task, const std::vector<typename Task::item_type>& seeds,
                               bool record_front = false, SerialScheduler = {}) {
  static_assert(require_traversal_task<Task>::value, "");
  TraversalResult<Task> out;
  std::vector<typename Task::item_type> stack(seeds.rbegin(), seeds.rend());
  detail::VectorEmitter<Task> emit{&stack, &out.results, record_front ? &out.front : nullptr};
  while (!stack.empty()) {
    const auto item = stack.back();
    stack.pop_back();
    task.process(item, emit);
    ++out.stats.items_processed;
  }
  out.stats.results = out.results.size();
  out.stats.front = out.front.size();
  return out;
}

/// Expands the seeds breadth first, a level at a time, until at least `target` items remain (or
/// none): they form a cut of the traversal (returned in `cut`), so traversing them in any grouping
/// gives the results and front of traversing the seeds, less those met on the way (returned).
/// As gpu::expand: a traversal split into independent parts.
template <class Task>
TraversalResult<Task> expand(const Task& task, const std::vector<typename Task::item_type>& seeds, std::size_t target,
                             bool record_front, std::vector<typename Task::item_type>& cut) {
  static_assert(require_traversal_task<Task>::value, "");
  TraversalResult<Task> out;
  cut = seeds;
  std::vector<typename Task::item_type> next;
  detail::VectorEmitter<Task> emit{&next, &out.results, record_front ? &out.front : nullptr};
  while (!cut.empty() && cut.size() < target) {
    next.clear();
    for (const auto& item : cut) task.process(item, emit);
    out.stats.items_processed += cut.size();
    cut.swap(next);
  }
  out.stats.results = out.results.size();
  out.stats.front = out.front.size();
  return out;
}

/// As traverse() with the WorkStealingScheduler, into `out` (its lists' memory reused), the
/// threads' lists kept in `workspace` for the next call.
template <class Task>
void traverse_into(const Task& task, const std::vector<typename Task::item_type>& seeds, bool record_front,
                   WorkStealingScheduler scheduler, TraversalResult<Task>& out, TraversalWorkspace<Task>& workspace) {
  static_assert(require_traversal_task<Task>::value, "");
  if (scheduler.threads) {  // a limit of its own: run under it
    cpu::ThreadLimit(scheduler.threads).run([&] { traverse_into(task, seeds, record_front, WorkStealingScheduler{}, out, workspace); });
    return;
  }
  using Item = typename Task::item_type;
  const unsigned n = lwsccd::detail::worker_count();
  workspace.results.resize(n);
  workspace.fronts.resize(n);
  for (unsigned w = 0; w < n; ++w) workspace.results[w].clear(), workspace.fronts[w].clear();
  out.stats = {};
  // Few seeds (the root): a cut below them, expanded breadth first on this thread (its results
  // and front items go to thread 0's lists), with enough items for every thread to take many.
  const std::size_t wanted = n > 1 ? std::size_t(n) * 1024 : 0;
  const std::vector<Item>* items = &seeds;
  std::vector<Item> cut, next;
  if (seeds.size() < wanted) {
    cut = seeds;
    detail::VectorEmitter<Task> emit{&next, &workspace.results[0], record_front ? &workspace.fronts[0] : nullptr};
    while (!cut.empty() && cut.size() < wanted) {
      next.clear();
      for (const Item& item : cut) task.process(item, emit);
      out.stats.items_processed += cut.size();
      cut.swap(next);
    }
    items = &cut;
  }
  // Items processed, per thread (apart: one cache line each).
  struct alignas(64) Count {
    std::size_t processed = 0;
  };
  std::vector<Count> counts(n);
  const std::size_t grain = std::max<std::size_t>(8, items->size() / (std::size_t(n) * 64 + 1));
  lwsccd::detail::parallel_ranges_by_worker(items->size(), grain, [&](std::size_t begin, std::size_t end, unsigned w) {
    assert(w < n && "a thread of the pool outside the arena's slots");
    // The thread's lists moved to this frame while the range runs: the workspace's list headers
    // sit side by side, and pushing through them would bounce their cache line between threads.
    std::vector<typename Task::result_type> results;
    std::vector<Item> front, stack;
    results.swap(workspace.results[w]);
    front.swap(workspace.fronts[w]);
    detail::VectorEmitter<Task> emit{&stack, &results, record_front ? &front : nullptr};
    std::size_t processed = 0;
    for (std::size_t i = begin; i < end; ++i) {
      stack.push_back((*items)[i]);
      while (!stack.empty()) {
        const Item item = stack.back();
        stack.pop_back();
        task.process(item, emit);
        ++processed;
      }
    }
    workspace.results[w].swap(results);
    workspace.fronts[w].swap(front);
    counts[w].processed += processed;
  });
  for (const Count& c : counts) out.stats.items_processed += c.processed;
  // The threads' lists, concatenated in thread order (copies in parallel), then kept.
  lwsccd::detail::concatenate_in_parallel(workspace.results, out.results);
  lwsccd::detail::concatenate_in_parallel(workspace.fronts, out.front);
  out.stats.results = out.results.size();
  out.stats.front = out.front.size();
}

template <class Task>
TraversalResult<Task> traverse(const Task& task, const std::vector<typename Task::item_type>& seeds, bool record_front,
                               WorkStealingScheduler scheduler) {
  TraversalResult<Task> out;
  TraversalWorkspace<Task> workspace;
  traverse_into(task, seeds, record_front, scheduler, out, workspace);
  return out;
}

}  // namespace cpu

}  // namespace lwsccd
