// lwsccd — the traversal task contract, checked at compile time.
//
// A task says what one work item is and how one item is processed:
//
//   struct MyTask {
//     using item_type = ...;    // trivially copyable work item
//     using result_type = ...;  // trivially copyable result
//     static constexpr int kMaxChildren = ...;  // most items one process() call pushes
//     static constexpr int kMaxResults = ...;   // most results one process() call pushes
//     template <class Out>
//     LWSCCD_HD void process(const item_type& item, Out& out) const;
//   };
//
// where `out` offers push_item(item_type), push_result(result_type) and push_front(item_type)
// (an item where the traversal stopped, kept to restart from next time; at most once per call).
// The bounds let the GPU schedulers collect a block's outputs in registers and append them with
// one atomic per block and round. A scheduler runs any
// task to completion, on the CPU (cpu_traverse.hpp) or the GPU (traverse.cuh).
#pragma once

#include <type_traits>
#include <utility>

#include "lwsccd/core/config.hpp"

namespace lwsccd {

namespace detail {

template <class Task>
struct ProbeEmitter {
  LWSCCD_HD void push_item(const typename Task::item_type&) {}
  LWSCCD_HD void push_result(const typename Task::result_type&) {}
  LWSCCD_HD void push_front(const typename Task::item_type&) {}
};

template <class T, class = void>
struct has_item_type : std::false_type {};
template <class T>
struct has_item_type<T, std::void_t<typename T::item_type>> : std::true_type {};

template <class T, class = void>
struct has_result_type : std::false_type {};
template <class T>
struct has_result_type<T, std::void_t<typename T::result_type>> : std::true_type {};

template <class T, class = void>
struct has_max_children : std::false_type {};
template <class T>
struct has_max_children<T, std::void_t<decltype(T::kMaxChildren)>> : std::true_type {};

template <class T, class = void>
struct has_max_results : std::false_type {};
template <class T>
struct has_max_results<T, std::void_t<decltype(T::kMaxResults)>> : std::true_type {};

template <class T, class = void>
struct has_process : std::false_type {};
template <class T>
struct has_process<T, std::void_t<decltype(std::declval<const T&>().process(
                          std::declval<const typename T::item_type&>(), std::declval<ProbeEmitter<T>&>()))>>
    : std::true_type {};

template <class T, bool = has_item_type<T>::value && has_result_type<T>::value>
struct process_ok : std::false_type {};
template <class T>
struct process_ok<T, true> : has_process<T> {};

template <class T, bool = has_item_type<T>::value>
struct item_copyable : std::false_type {};
template <class T>
struct item_copyable<T, true> : std::is_trivially_copyable<typename T::item_type> {};

}  // namespace detail

/// Checks the task contract with a message that names what is missing.
template <class Task>
struct require_traversal_task {
  static_assert(detail::has_item_type<Task>::value, "lwsccd: a traversal task needs a nested type item_type (its work item)");
  static_assert(detail::has_result_type<Task>::value, "lwsccd: a traversal task needs a nested type result_type");
  static_assert(detail::has_max_children<Task>::value,
                "lwsccd: a traversal task needs static constexpr int kMaxChildren (the most items one process() pushes)");
  static_assert(detail::has_max_results<Task>::value,
                "lwsccd: a traversal task needs static constexpr int kMaxResults (the most results one process() pushes)");
  static_assert(detail::item_copyable<Task>::value, "lwsccd: a traversal task's item_type must be trivially copyable");
  static_assert(detail::process_ok<Task>::value,
                "lwsccd: a traversal task needs a const member template process(const item_type&, Out&) "
                "(Out offers push_item, push_result, push_front)");
  static constexpr bool value = true;
};

/// Counters every scheduler reports.
struct TraversalStats {
  std::size_t items_processed = 0;  ///< BVTT nodes visited, for a collision task
  std::size_t results = 0;
  std::size_t front = 0;
  std::size_t relaunches = 0;  ///< GPU: restarts after an output grew
  /// GPU, lazy stealing: items of the start processed by one flat launch before the persistent
  /// blocks (LazyStealScheduler::kFlatStartPerBlock; 0: the blocks shared the whole start)
  std::size_t flat_start_items = 0;
  /// CPU, work stealing from a cut below the root: parts of a thread's stack handed on to the pool
  std::size_t handed_on = 0;
};

}  // namespace lwsccd
