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

#include "lwsccd/traversal_task.hpp"

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

/// All cores: a deque per thread; a thread pops its newest item and, when out of work, steals
/// the oldest half of another thread's deque (the largest subtrees). Termination: a shared count
/// of items pushed but not yet processed reaches zero only when no thread holds or can create
/// work, because an item's children are counted before the item itself is retired.
struct WorkStealingScheduler {
  unsigned threads = 0;  ///< 0: std::thread::hardware_concurrency()
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

template <class Task>
TraversalResult<Task> traverse(const Task& task, const std::vector<typename Task::item_type>& seeds, bool record_front,
                               WorkStealingScheduler scheduler) {
  static_assert(require_traversal_task<Task>::value, "");
  using Item = typename Task::item_type;
  const unsigned n = scheduler.threads ? scheduler.threads : std::max(1u, std::thread::hardware_concurrency());
  struct Worker {
    std::mutex lock;
    std::deque<Item> deque;
    std::vector<typename Task::result_type> results;
    std::vector<Item> front;
    std::size_t processed = 0;
  };
  std::vector<Worker> workers(n);
  std::atomic<long long> pending{static_cast<long long>(seeds.size())};
  for (std::size_t i = 0; i < seeds.size(); ++i) workers[i % n].deque.push_back(seeds[i]);

  auto run = [&](unsigned self) {
    Worker& me = workers[self];
    std::minstd_rand rng(self + 1);
    std::vector<Item> children;
    detail::VectorEmitter<Task> emit{&children, &me.results, record_front ? &me.front : nullptr};
    while (true) {
      Item item;
      bool have = false;
      {
        std::lock_guard<std::mutex> guard(me.lock);
        if (!me.deque.empty()) {
          item = me.deque.back();
          me.deque.pop_back();
          have = true;
        }
      }
      if (!have && n > 1) {  // steal the oldest half of a random victim's deque
        const unsigned victim = (self + 1 + rng() % (n - 1)) % n;
        std::vector<Item> stolen;
        {
          std::lock_guard<std::mutex> guard(workers[victim].lock);
          const std::size_t take = (workers[victim].deque.size() + 1) / 2;
          for (std::size_t i = 0; i < take; ++i) {
            stolen.push_back(workers[victim].deque.front());
            workers[victim].deque.pop_front();
          }
        }
        if (!stolen.empty()) {
          std::lock_guard<std::mutex> guard(me.lock);
          for (const Item& x : stolen) me.deque.push_back(x);
          continue;
        }
      }
      if (!have) {
        if (pending.load(std::memory_order_acquire) == 0) return;
        std::this_thread::yield();
        continue;
      }
      children.clear();
      task.process(item, emit);
      ++me.processed;
      if (!children.empty()) {
        pending.fetch_add(static_cast<long long>(children.size()), std::memory_order_acq_rel);
        std::lock_guard<std::mutex> guard(me.lock);
        for (auto it = children.rbegin(); it != children.rend(); ++it) me.deque.push_back(*it);
      }
      pending.fetch_sub(1, std::memory_order_acq_rel);  // retired after its children were counted
    }
  };
  std::vector<std::thread> threads;
  for (unsigned t = 1; t < n; ++t) threads.emplace_back(run, t);
  run(0);
  for (auto& t : threads) t.join();

  TraversalResult<Task> out;
  for (Worker& w : workers) {
    out.results.insert(out.results.end(), w.results.begin(), w.results.end());
    out.front.insert(out.front.end(), w.front.begin(), w.front.end());
    out.stats.items_processed += w.processed;
  }
  out.stats.results = out.results.size();
  out.stats.front = out.front.size();
  return out;
}

}  // namespace cpu

}  // namespace lwsccd
