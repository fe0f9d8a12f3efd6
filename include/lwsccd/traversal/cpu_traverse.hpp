// lwsccd — the traversal engine's CPU backend: runs any traversal task (traversal_task.hpp) to
// completion, serially or on all cores with work stealing. It is the oracle the GPU schedulers
// (traverse.cuh) are compared with, and the default where there is no GPU.
#pragma once

#include <algorithm>
#include <cassert>
#include <initializer_list>
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

/// All cores: the seeds (a kept front holds millions) are dealt in ranges to the threads of the
/// pool, each range traversed depth first on the thread's private stack; oneTBB's work stealing
/// moves ranges between threads (without it, threads take ranges from a shared counter). Seeds
/// fewer than the threads can share (the root) are first expanded breadth first into a cut, whose
/// items' subtrees differ widely in size: there a thread hands the older half of its stack on to
/// the pool every kHandOnItems items. No lock or shared counter per item. (The loop that shared
/// single items through per-thread deques before it did not scale: 16 threads were slower than
/// one on a front of 6.8 M seeds, docs/PIPELINE.md.)
struct WorkStealingScheduler {
  /// From a cut below the root, a thread hands half of its stack on every this many items.
  static constexpr std::size_t kHandOnItems = 1024;
  unsigned threads = 0;  ///< 0: the threads the caller may use (cpu::ThreadLimit; default every core)
};

/// A sequence held in several lists, in their order: what a work-stealing traversal's threads
/// wrote (its results, its front), read where it lies instead of being copied into one list first.
template <class T>
struct ListsOf {
  std::vector<std::vector<T>> lists;

  ListsOf() = default;
  /// One list holding `items`.
  ListsOf(std::initializer_list<T> items) : lists{std::vector<T>(items)} {}
  std::size_t size() const {
    std::size_t n = 0;
    for (const auto& l : lists) n += l.size();
    return n;
  }
  bool empty() const { return size() == 0; }
  /// Empties every list, keeping its memory.
  void clear() {
    for (auto& l : lists) l.clear();
  }
  void swap(ListsOf& other) noexcept { lists.swap(other.lists); }
  /// fn(element) for the elements [begin, end) of the sequence, in order.
  template <class Fn>
  void for_each_in(std::size_t begin, std::size_t end, Fn&& fn) const {
    lwsccd::detail::for_each_in_lists(lists, begin, end, fn);
  }
  /// The sequence in one list.
  std::vector<T> joined() const {
    std::vector<T> out;
    lwsccd::detail::concatenate_in_parallel(lists, out);
    return out;
  }
};

/// The memory a work-stealing traversal keeps for the next one: its threads' lists of results
/// and front items. A caller that traverses every step (a pipeline) passes the same workspace to
/// traverse_into or traverse_in_lists, so that a warm step allocates nothing (fresh pages cost
/// page faults, which serialise threads).
template <class Task>
struct TraversalWorkspace {
  ListsOf<typename Task::result_type> results;
  ListsOf<typename Task::item_type> fronts;
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

}  // namespace cpu

namespace detail {

// A work-stealing traversal from `seeds` (a ListsOf, or one list as a ListsOf-like view), its
// results and front left in the workspace's lists, one per thread.
template <class Task, class Seeds>
TraversalStats traverse_in_threads_lists(const Task& task, const Seeds& seeds, bool record_front, cpu::TraversalWorkspace<Task>& workspace) {
  using Item = typename Task::item_type;
  constexpr std::size_t kHandOnItems = cpu::WorkStealingScheduler::kHandOnItems;
  const unsigned n = worker_count();
  auto& results_of = workspace.results.lists;
  auto& fronts_of = workspace.fronts.lists;
  results_of.resize(n);
  fronts_of.resize(n);
  workspace.results.clear();
  workspace.fronts.clear();
  TraversalStats stats;
  // Items processed, per thread (apart: one cache line each).
  struct alignas(64) Count {
    std::size_t processed = 0, handed_on = 0;
  };
  std::vector<Count> counts(n);
  // Seeds traversed depth first on the thread's stack, into the thread's lists, moved to this
  // frame while it runs: the workspace's list headers sit side by side, and pushing through them
  // would bounce their cache line between threads. each_seed(visit) calls visit(seed) for each;
  // hand_on(stack), called every kHandOnItems items, may take part of the stack.
  auto traverse_seeds = [&](unsigned w, auto&& each_seed, auto&& hand_on) {
    assert(w < n && "a thread of the pool outside the arena's slots");
    std::vector<typename Task::result_type> results;
    std::vector<Item> front, stack;
    results.swap(results_of[w]);
    front.swap(fronts_of[w]);
    VectorEmitter<Task> emit{&stack, &results, record_front ? &front : nullptr};
    std::size_t processed = 0;
    each_seed([&](const Item& seed) {
      stack.push_back(seed);
      while (!stack.empty()) {
        const Item item = stack.back();
        stack.pop_back();
        task.process(item, emit);
        if (++processed % kHandOnItems == 0) hand_on(stack);
      }
    });
    results_of[w].swap(results);
    fronts_of[w].swap(front);
    counts[w].processed += processed;
  };
  const std::size_t num_seeds = seeds.size();
  const std::size_t wanted = n > 1 ? std::size_t(n) * 1024 : 0;
  if (num_seeds >= wanted) {
    // Many seeds (a kept front): their subtrees are small, ranges balance the threads.
    const std::size_t grain = std::max<std::size_t>(8, num_seeds / (std::size_t(n) * 64 + 1));
    parallel_ranges_by_worker(num_seeds, grain, [&](std::size_t begin, std::size_t end, unsigned w) {
      traverse_seeds(w, [&](auto&& visit) { seeds.for_each_in(begin, end, visit); }, [](std::vector<Item>&) {});
    });
  } else {
    // Few seeds (the root): a cut below them, expanded breadth first on this thread (its results
    // and front items go to thread 0's lists), with enough items for every thread to take many.
    std::vector<Item> cut, next;
    seeds.for_each_in(0, num_seeds, [&](const Item& seed) { cut.push_back(seed); });
    VectorEmitter<Task> emit{&next, &results_of[0], record_front ? &fronts_of[0] : nullptr};
    while (!cut.empty() && cut.size() < wanted) {
      next.clear();
      for (const Item& item : cut) task.process(item, emit);
      stats.items_processed += cut.size();
      cut.swap(next);
    }
    // A few of the cut's items hold most of the traversal (cloth-ball on 16 threads, ranges of
    // the cut: the busiest thread worked 2.3x the mean), so a thread hands the older half of its
    // stack (the largest subtrees left, nearest the root) on to the pool every kHandOnItems
    // items, where an idle thread takes it.
    std::vector<std::vector<Item>> chunks;
    const std::size_t chunk = std::max<std::size_t>(1, cut.size() / (std::size_t(n) * 16));
    for (std::size_t b = 0; b < cut.size(); b += chunk)
      chunks.emplace_back(cut.begin() + static_cast<std::ptrdiff_t>(b), cut.begin() + static_cast<std::ptrdiff_t>(std::min(cut.size(), b + chunk)));
    parallel_for_each_handing_on(chunks, [&](std::vector<Item>& chunk_seeds, unsigned w, auto&& hand_on_to_pool) {
      traverse_seeds(
          w,
          [&](auto&& visit) {
            for (const Item& seed : chunk_seeds) visit(seed);
          },
          [&](std::vector<Item>& stack) {
            if (stack.size() < 2) return;
            const auto half = stack.begin() + static_cast<std::ptrdiff_t>(stack.size() / 2);
            hand_on_to_pool(std::vector<Item>(stack.begin(), half));
            stack.erase(stack.begin(), half);
            ++counts[w].handed_on;
          });
    });
  }
  for (const Count& c : counts) stats.items_processed += c.processed, stats.handed_on += c.handed_on;
  stats.results = workspace.results.size();
  stats.front = workspace.fronts.size();
  return stats;
}

// One list read as a ListsOf (for_each_in, size), without a copy.
template <class T>
struct OneList {
  const std::vector<T>& list;
  std::size_t size() const { return list.size(); }
  template <class Fn>
  void for_each_in(std::size_t begin, std::size_t end, Fn&& fn) const {
    for (std::size_t i = begin; i < end; ++i) fn(list[i]);
  }
};

}  // namespace detail

namespace cpu {

/// As traverse() with the WorkStealingScheduler, with the results and the front left where the
/// threads wrote them: `workspace.results` and `workspace.fronts` (each a ListsOf, the sequence of
/// the threads' lists), not copied into one list each. For a caller that reads them there (the
/// CPU pipeline: the front as its next step's seeds, the results as its feature pairs' input);
/// `seeds` may be such lists too. Returns the traversal's counts.
template <class Task>
TraversalStats traverse_in_lists(const Task& task, const ListsOf<typename Task::item_type>& seeds, bool record_front,
                                 WorkStealingScheduler scheduler, TraversalWorkspace<Task>& workspace) {
  static_assert(require_traversal_task<Task>::value, "");
  if (scheduler.threads)  // a limit of its own: run under it
    return cpu::ThreadLimit(scheduler.threads).run([&] { return detail::traverse_in_threads_lists(task, seeds, record_front, workspace); });
  return detail::traverse_in_threads_lists(task, seeds, record_front, workspace);
}

/// As traverse() with the WorkStealingScheduler, into `out` (its lists' memory reused), the
/// threads' lists kept in `workspace` for the next call.
template <class Task>
void traverse_into(const Task& task, const std::vector<typename Task::item_type>& seeds, bool record_front,
                   WorkStealingScheduler scheduler, TraversalResult<Task>& out, TraversalWorkspace<Task>& workspace) {
  static_assert(require_traversal_task<Task>::value, "");
  auto run = [&] {
    out.stats = detail::traverse_in_threads_lists(task, detail::OneList<typename Task::item_type>{seeds}, record_front, workspace);
    // The threads' lists, concatenated in thread order (copies in parallel), then kept.
    lwsccd::detail::concatenate_in_parallel(workspace.results.lists, out.results);
    lwsccd::detail::concatenate_in_parallel(workspace.fronts.lists, out.front);
  };
  if (scheduler.threads)
    cpu::ThreadLimit(scheduler.threads).run(run);
  else
    run();
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
