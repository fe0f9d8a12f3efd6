// lwsccd — the traversal engine's CPU backend: runs any traversal task (traversal_task.hpp) to
// completion, serially or on all cores with work stealing. It is the oracle the GPU schedulers
// (traverse.cuh) are compared with, and the default where there is no GPU.
#pragma once

#include <algorithm>
#include <atomic>
#include <deque>
#include <mutex>
#include <random>
#include <thread>
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
  void push_item(const typename Task::item_type& x) { items->push_back(x); }
  void push_result(const typename Task::result_type& r) { results->push_back(r); }
  void push_front(const typename Task::item_type& x) {
    if (front) front->push_back(x);
  }
};

}  // namespace detail

namespace cpu {

/// One thread, one explicit stack (depth first).
struct SerialScheduler {};

/// All cores: each thread works depth first on a private stack and shares the older half of it
/// through its deque whenever that deque is empty; a thread out of work takes its deque's newest
/// items (a batch), else the next batch of the seeds, else steals the oldest half of another's
/// deque (the largest subtrees). Termination: a shared count of the unclaimed seeds, the items in
/// the deques and those taken from either but not settled reaches zero only when no thread holds
/// or can create work (a thread settles only with an empty private stack, and counts items before
/// it shares them). No lock or shared counter per item.
struct WorkStealingScheduler {
  unsigned threads = 0;  ///< 0: the threads the caller may use (cpu::ThreadLimit; default every core)
};

/// The memory a work-stealing traversal keeps for the next one: its workers' lists. A caller that
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
/// workers' lists kept in `workspace` for the next call.
template <class Task>
void traverse_into(const Task& task, const std::vector<typename Task::item_type>& seeds, bool record_front,
                   WorkStealingScheduler scheduler, TraversalResult<Task>& out, TraversalWorkspace<Task>& workspace) {
  static_assert(require_traversal_task<Task>::value, "");
  using Item = typename Task::item_type;
  const unsigned n = scheduler.threads ? scheduler.threads : lwsccd::detail::worker_count();
  struct Worker {
    std::mutex lock;
    std::deque<Item> deque;                     ///< shared: the owner takes its newest, thieves the oldest half
    std::atomic<std::size_t> shared_size{0};    ///< deque.size(), readable without the lock
    std::vector<typename Task::result_type> results;
    std::vector<Item> front;
    std::size_t processed = 0;
  };
  std::vector<Worker> workers(n);
  workspace.results.resize(n);
  workspace.fronts.resize(n);
  for (unsigned w = 0; w < n; ++w) {  // the lists of the last call, emptied (their memory kept)
    workers[w].results.swap(workspace.results[w]);
    workers[w].front.swap(workspace.fronts[w]);
    workers[w].results.clear();
    workers[w].front.clear();
  }
  // The unclaimed seeds, plus the items in the deques, plus, per worker, the items it took from
  // either and has not settled; a worker settles (subtracts what it took) only once its private
  // stack is empty, and adds items before it shares them, so this is 0 only when no item is left.
  std::atomic<long long> pending{static_cast<long long>(seeds.size())};
  std::atomic<std::size_t> next_seed{0};  // seeds are claimed in batches (a front seeds millions)
  // A worker runs a private stack (no lock, no shared counter per item) and shares the older half
  // of it, in one batch, whenever its own deque has been emptied (by itself or by thieves).
  constexpr std::size_t kShareAbove = 8;
  constexpr std::size_t kTakeBatch = 64;  // items a worker moves from its own deque, or the seeds, at once

  auto run = [&](unsigned self) {
    Worker& me = workers[self];
    std::minstd_rand rng(self + 1);
    std::vector<Item> children, local;
    long long taken = 0;  // items this worker took from the seeds or the deques and has not settled
    detail::VectorEmitter<Task> emit{&children, &me.results, record_front ? &me.front : nullptr};
    while (true) {
      if (local.empty()) {
        if (taken) pending.fetch_sub(taken, std::memory_order_acq_rel), taken = 0;
        {
          std::lock_guard<std::mutex> guard(me.lock);
          if (!me.deque.empty()) {  // its newest items, a batch at a time
            const std::size_t take = std::min(me.deque.size(), kTakeBatch);
            local.insert(local.end(), me.deque.end() - static_cast<std::ptrdiff_t>(take), me.deque.end());
            me.deque.erase(me.deque.end() - static_cast<std::ptrdiff_t>(take), me.deque.end());
            me.shared_size.store(me.deque.size(), std::memory_order_relaxed);
          }
        }
        if (local.empty() && next_seed.load(std::memory_order_relaxed) < seeds.size()) {
          const std::size_t first = next_seed.fetch_add(kTakeBatch, std::memory_order_relaxed);
          // Reversed onto the stack, so the batch's first seed is processed first.
          for (std::size_t i = std::min(seeds.size(), first + kTakeBatch); i > first && i <= seeds.size(); --i)
            local.push_back(seeds[i - 1]);
        }
        if (local.empty() && n > 1) {  // steal the oldest half of a random victim's deque
          Worker& victim = workers[(self + 1 + rng() % (n - 1)) % n];
          if (victim.shared_size.load(std::memory_order_relaxed) > 0) {
            std::lock_guard<std::mutex> guard(victim.lock);
            const std::size_t take = (victim.deque.size() + 1) / 2;
            for (std::size_t i = 0; i < take; ++i) {
              local.push_back(victim.deque.front());
              victim.deque.pop_front();
            }
            victim.shared_size.store(victim.deque.size(), std::memory_order_relaxed);
          }
        }
        if (local.empty()) {
          if (pending.load(std::memory_order_acquire) == 0) return;
          std::this_thread::yield();
          continue;
        }
        taken = static_cast<long long>(local.size());
      }
      const Item item = local.back();
      local.pop_back();
      children.clear();
      task.process(item, emit);
      ++me.processed;
      for (auto it = children.rbegin(); it != children.rend(); ++it) local.push_back(*it);
      if (n > 1 && local.size() >= kShareAbove && me.shared_size.load(std::memory_order_relaxed) == 0) {
        const std::size_t share = local.size() / 2;  // the oldest: the largest subtrees
        pending.fetch_add(static_cast<long long>(share), std::memory_order_acq_rel);  // counted before seen
        {
          std::lock_guard<std::mutex> guard(me.lock);
          for (std::size_t i = 0; i < share; ++i) me.deque.push_back(local[i]);
          me.shared_size.store(me.deque.size(), std::memory_order_relaxed);
        }
        local.erase(local.begin(), local.begin() + static_cast<std::ptrdiff_t>(share));
      }
    }
  };
  lwsccd::detail::for_each_worker([&](unsigned self, unsigned) { run(self); }, n);

  // The workers' lists, concatenated in worker order (copies in parallel), then kept.
  out.stats = {};
  for (unsigned w = 0; w < n; ++w) {
    workspace.results[w].swap(workers[w].results);
    workspace.fronts[w].swap(workers[w].front);
    out.stats.items_processed += workers[w].processed;
  }
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
