// lwsccd — the CPU backend's threads: a thread limit a caller chooses (cpu::ThreadLimit) and the
// parallel loops every CPU stage runs on (lwsccd::detail below).
//
// With oneTBB (the build defines LWSCCD_WITH_TBB=1 where CMake finds it; Debian libtbb-dev) the
// loops run on TBB's persistent pool with work stealing: no thread is created per call, and a
// ThreadLimit is a tbb::task_arena. Without it they start std::threads per call (correct, the
// same answers, slower on many cores and for short calls).
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <thread>
#include <utility>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

#ifndef LWSCCD_WITH_TBB
#define LWSCCD_WITH_TBB 0
#endif

#if LWSCCD_WITH_TBB
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_for_each.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_arena.h>
#endif

namespace lwsccd {

namespace detail {
// Without TBB: the thread limit of the calling thread (0: every core), set by ThreadLimit::run.
inline unsigned& fallback_thread_limit() {
  static thread_local unsigned limit = 0;
  return limit;
}
}  // namespace detail

namespace cpu {

/// True when the CPU backend runs on oneTBB (else on std::threads started per call).
inline constexpr bool kUsesTbb = LWSCCD_WITH_TBB != 0;

/// At most `threads` threads (0: every core) for the CPU backend's work run inside run(): the
/// pipeline, or any free function of the CPU backend (traverse, emit_feature_pairs,
/// test_feature_pairs...). Outside of one, the CPU backend uses every core. Copyable; a copy has
/// the same limit.
class ThreadLimit {
 public:
  explicit ThreadLimit(unsigned threads = 0)
      : threads_(threads)
#if LWSCCD_WITH_TBB
        ,
        arena_(threads ? static_cast<int>(threads) : tbb::task_arena::automatic)
#endif
  {
  }
  ThreadLimit(const ThreadLimit&) = default;
  /// Takes `other`'s limit (a pipeline assigned to another keeps working under the new one).
  ThreadLimit& operator=(const ThreadLimit& other) {
    if (this == &other) return *this;
    threads_ = other.threads_;
#if LWSCCD_WITH_TBB
    arena_.terminate();
    arena_.initialize(threads_ ? static_cast<int>(threads_) : tbb::task_arena::automatic);
#endif
    return *this;
  }
  /// The limit as given (0: every core).
  unsigned threads() const { return threads_; }
  /// The threads work inside run() gets: the limit, or the machine's hardware threads.
  unsigned effective_threads() const { return threads_ ? threads_ : std::max(1u, std::thread::hardware_concurrency()); }

  /// Runs fn() under the limit and returns its result; exceptions pass through.
  template <class Fn>
  decltype(auto) run(Fn&& fn) const {
#if LWSCCD_WITH_TBB
    return arena_.execute(std::forward<Fn>(fn));
#else
    struct Restore {
      unsigned saved = detail::fallback_thread_limit();
      ~Restore() { detail::fallback_thread_limit() = saved; }
    } restore;
    detail::fallback_thread_limit() = threads_;
    return std::forward<Fn>(fn)();
#endif
  }

 private:
  unsigned threads_ = 0;
#if LWSCCD_WITH_TBB
  mutable tbb::task_arena arena_;  // (execute() is not const; the arena's state is not the limit's)
#endif
};

}  // namespace cpu

namespace detail {

/// The threads the calling context may use (inside a ThreadLimit's run(): its limit).
inline unsigned worker_count() {
#if LWSCCD_WITH_TBB
  return static_cast<unsigned>(std::max(1, tbb::this_task_arena::max_concurrency()));
#else
  const unsigned limit = fallback_thread_limit();
  return limit ? limit : std::max(1u, std::thread::hardware_concurrency());
#endif
}

/// Runs body(worker, workers) once for each worker in [0, workers), concurrently where threads are
/// free, and waits: for work that keeps per-worker state (a work-stealing loop, private output
/// lists). `workers` = worker_count() unless given.
template <class Body>
void for_each_worker(Body body, unsigned workers = 0) {
  const unsigned n = workers ? workers : worker_count();
  if (n == 1) {
    body(0u, 1u);
    return;
  }
#if LWSCCD_WITH_TBB
  tbb::parallel_for(tbb::blocked_range<unsigned>(0, n, 1),
                    [&](const tbb::blocked_range<unsigned>& r) {
                      for (unsigned w = r.begin(); w != r.end(); ++w) body(w, n);
                    },
                    tbb::simple_partitioner());
#else
  std::vector<std::thread> threads;
  threads.reserve(n - 1);
  for (unsigned w = 1; w < n; ++w) threads.emplace_back([&body, w, n] { body(w, n); });
  body(0u, n);
  for (auto& t : threads) t.join();
#endif
}

/// Runs body(begin, end, worker) over [0, n) in ranges of about `grain` items, taken by threads as
/// they free up (load balance for uneven items), and waits. `worker` in [0, worker_count()) names
/// the thread running the range (no two ranges run at once with the same worker), for
/// per-thread output lists.
template <class Body>
void parallel_ranges_by_worker(std::size_t n, std::size_t grain, Body body) {
  if (n == 0) return;
  grain = std::max<std::size_t>(1, grain);
#if LWSCCD_WITH_TBB
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain), [&](const tbb::blocked_range<std::size_t>& r) {
    body(r.begin(), r.end(), static_cast<unsigned>(tbb::this_task_arena::current_thread_index()));
  });
#else
  std::atomic<std::size_t> next{0};
  for_each_worker([&](unsigned w, unsigned) {
    for (std::size_t begin = next.fetch_add(grain); begin < n; begin = next.fetch_add(grain))
      body(begin, std::min(n, begin + grain), w);
  });
#endif
}

/// As parallel_ranges_by_worker, with body(begin, end); a list no longer than `grain` runs on the
/// calling thread.
template <class Body>
void parallel_ranges(std::size_t n, std::size_t grain, Body body) {
  if (n <= std::max<std::size_t>(1, grain)) {
    if (n) body(std::size_t(0), n);
    return;
  }
  parallel_ranges_by_worker(n, grain, [&](std::size_t begin, std::size_t end, unsigned) { body(begin, end); });
}

/// Runs body(work, worker, hand_on) on each element of `work` in parallel and waits, where the
/// body may call hand_on(W&&) with more work, which any thread may take (oneTBB's feeder; without
/// oneTBB the same thread takes it after its element). For work whose size is not known up front
/// (a subtree of a traversal): a thread holding much of it hands part on instead of leaving the
/// others idle. `worker` as in parallel_ranges_by_worker (no two bodies at once with the same one).
template <class W, class Body>
void parallel_for_each_handing_on(std::vector<W>& work, Body body) {
  if (work.empty()) return;
#if LWSCCD_WITH_TBB
  tbb::parallel_for_each(work.begin(), work.end(), [&](W& w, tbb::feeder<W>& feeder) {
    body(w, static_cast<unsigned>(tbb::this_task_arena::current_thread_index()), [&feeder](W&& more) { feeder.add(std::move(more)); });
  });
#else
  parallel_ranges_by_worker(work.size(), 1, [&](std::size_t begin, std::size_t end, unsigned worker) {
    std::vector<W> later;
    auto hand_on = [&later](W&& more) { later.push_back(std::move(more)); };
    for (std::size_t i = begin; i < end; ++i) body(work[i], worker, hand_on);
    while (!later.empty()) {
      W next = std::move(later.back());
      later.pop_back();
      body(next, worker, hand_on);
    }
  });
#endif
}

/// A grain that gives each worker several ranges of [0, n) (load balance) but none shorter than
/// `at_least` items (overhead).
inline std::size_t grain_for(std::size_t n, std::size_t at_least = 1024) {
  return std::max(at_least, n / (std::size_t(worker_count()) * 16 + 1));
}

/// Splits [0, n) into `parts` contiguous ranges (part k: [n k / parts, n (k + 1) / parts)) and runs
/// body(begin, end, k) on each in parallel: for outputs gathered in input order (one list per part).
template <class Body>
void parallel_parts(std::size_t n, std::size_t parts, Body body) {
  parallel_ranges(parts, 1, [&](std::size_t first, std::size_t last) {
    for (std::size_t k = first; k < last; ++k) body(n * k / parts, n * (k + 1) / parts, k);
  });
}

/// Asks the kernel to back the whole 2 MiB pages inside [data, data + bytes) with transparent huge
/// pages (Linux's MADV_HUGEPAGE; where the kernel gives them only on request, as
/// /sys/kernel/mm/transparent_hugepage/enabled = madvise; elsewhere nothing). Only advice: memory
/// not yet touched then faults in 2 MiB at a time. Why: a first step's lists are new memory, and
/// threads touching it 4 KiB at a time spend much of the step in page faults (docs/PIPELINE.md,
/// "The CPU narrow phase without denormal products").
inline void advise_huge_pages(const void* data, std::size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  constexpr std::uintptr_t kHuge = std::uintptr_t(2) << 20;
  const std::uintptr_t at = reinterpret_cast<std::uintptr_t>(data);
  const std::uintptr_t begin = (at + kHuge - 1) & ~(kHuge - 1), end = (at + bytes) & ~(kHuge - 1);
  if (end > begin) (void)madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);  // (advice: a refusal is no error)
#else
  (void)data;
  (void)bytes;
#endif
}

/// Has the kernel back [data, data + bytes) with pages now, the range shared among the threads
/// (Linux's MADV_POPULATE_WRITE, kernel 5.14 on; elsewhere nothing: pages fault in as they are
/// touched). Why: a list about to be filled by a parallel copy is first value-initialised by one
/// thread (std::vector::resize), which would take every page fault of new memory alone (cloth-ball,
/// 16 cores: a first step's two traversal lists, 87 MB, 34 ms against 21 populated first).
inline void populate_in_parallel(void* data, std::size_t bytes) {
#if defined(__linux__) && defined(MADV_POPULATE_WRITE)
  constexpr std::uintptr_t kPage = 4096, kChunk = std::uintptr_t(2) << 20;
  const std::uintptr_t begin = reinterpret_cast<std::uintptr_t>(data) & ~(kPage - 1);
  const std::uintptr_t end = reinterpret_cast<std::uintptr_t>(data) + bytes;
  if (end <= begin) return;
  const std::size_t chunks = static_cast<std::size_t>((end - begin + kChunk - 1) / kChunk);
  parallel_ranges(chunks, 1, [&](std::size_t first, std::size_t last) {
    const std::uintptr_t from = begin + first * kChunk, to = std::min<std::uintptr_t>(end, begin + last * kChunk);
    (void)madvise(reinterpret_cast<void*>(from), to - from, MADV_POPULATE_WRITE);  // (advice: a refusal is no error)
  });
#else
  (void)data;
  (void)bytes;
#endif
}

/// Below this many bytes a list grows as std::vector grows it.
inline constexpr std::size_t kHugePageListBytes = std::size_t(4) << 20;

/// Room for n elements in v, at least twice v's size as std::vector grows (a list whose length
/// creeps up from step to step is not moved every step), where a new buffer of at least
/// kHugePageListBytes gets huge pages asked for before anything touches it (the elements are then
/// moved in).
/// With `populate` (a caller outside any parallel loop, about to fill the list in parallel), the
/// new buffer's first n elements' pages are also made present by all threads
/// (populate_in_parallel).
template <class T>
void reserve_large(std::vector<T>& v, std::size_t n, bool populate = false) {
  if (n <= v.capacity()) return;
  const std::size_t needed = n;
  n = std::max(n, 2 * v.size());
  if (n * sizeof(T) < kHugePageListBytes) {
    v.reserve(n);
    return;
  }
  std::vector<T> larger;
  larger.reserve(n);  // allocated, not touched
  advise_huge_pages(larger.data(), n * sizeof(T));
  if (populate) populate_in_parallel(larger.data(), needed * sizeof(T));
  larger.insert(larger.end(), std::make_move_iterator(v.begin()), std::make_move_iterator(v.end()));
  v.swap(larger);
}

/// v.push_back(x), growing as std::vector does (doubling) through reserve_large.
template <class T>
void push_back_large(std::vector<T>& v, const T& x) {
  if (v.size() == v.capacity()) reserve_large(v, v.capacity() ? 2 * v.capacity() : 16);
  v.push_back(x);
}

/// Appends the lists to `out[from..]` in their order, copying in parallel: `out` ends with
/// from + their total size elements. Elements `out` already held are overwritten, not
/// value-initialised first (a serial pass over memory that a reused `out` does not pay).
template <class T>
void copy_in_parallel(const std::vector<std::vector<T>>& lists, std::vector<T>& out, std::size_t from) {
  std::vector<std::size_t> at(lists.size() + 1, from);
  for (std::size_t k = 0; k < lists.size(); ++k) at[k + 1] = at[k] + lists[k].size();
  reserve_large(out, at.back(), true);
  out.resize(at.back());
  parallel_ranges(lists.size(), 1, [&](std::size_t first, std::size_t last) {
    for (std::size_t k = first; k < last; ++k) std::copy(lists[k].begin(), lists[k].end(), out.begin() + static_cast<std::ptrdiff_t>(at[k]));
  });
}
/// Appends the lists to `out`, in their order (copy_in_parallel).
template <class T>
void append_in_parallel(const std::vector<std::vector<T>>& lists, std::vector<T>& out) {
  copy_in_parallel(lists, out, out.size());
}
/// `out` becomes the lists' concatenation (copy_in_parallel: its memory and elements reused).
template <class T>
void concatenate_in_parallel(const std::vector<std::vector<T>>& lists, std::vector<T>& out) {
  copy_in_parallel(lists, out, 0);
}

/// fn(element) for the elements [begin, end) of the lists' concatenation, in order, read where
/// they lie.
template <class T, class Fn>
void for_each_in_lists(const std::vector<std::vector<T>>& lists, std::size_t begin, std::size_t end, Fn&& fn) {
  std::size_t at = 0;  // the concatenation's index of the current list's first element
  for (const auto& list : lists) {
    if (begin >= end) return;
    const std::size_t list_end = at + list.size();
    for (; begin < end && begin < list_end; ++begin) fn(list[begin - at]);
    at = list_end;
  }
}

/// Element i of the concatenation of several lists, read where they lie, in constant time: for
/// loops that index a sequence (splitting it into runs, keeping indices of what is left for
/// later) over lists that threads filled. The lists must outlive it and keep their sizes.
template <class T>
class ConcatenatedLists {
 public:
  ConcatenatedLists() = default;
  explicit ConcatenatedLists(std::vector<const std::vector<T>*> lists) : lists_(std::move(lists)) {
    starts_.assign(lists_.size() + 1, 0);
    for (std::size_t k = 0; k < lists_.size(); ++k) starts_[k + 1] = starts_[k] + lists_[k]->size();
    // Per block of kBlock indices, the list holding its first element (empty lists skipped).
    first_list_.resize((size() + kBlock - 1) / kBlock);
    std::size_t list = 0;
    for (std::size_t b = 0; b < first_list_.size(); ++b) {
      while (b * kBlock >= starts_[list + 1]) ++list;
      first_list_[b] = list;
    }
  }
  std::size_t size() const { return starts_.empty() ? 0 : starts_.back(); }
  const T& operator[](std::size_t i) const {
    std::size_t list = first_list_[i / kBlock];
    while (i >= starts_[list + 1]) ++list;
    return (*lists_[list])[i - starts_[list]];
  }

 private:
  static constexpr std::size_t kBlock = 1024;
  std::vector<const std::vector<T>*> lists_;
  std::vector<std::size_t> starts_;  ///< the concatenation's index of each list's first element, and the size
  std::vector<std::size_t> first_list_;
};

/// std::sort on all cores (a total order gives the same result as std::sort).
template <class It, class Less>
void parallel_sort(It first, It last, Less less) {
#if LWSCCD_WITH_TBB
  tbb::parallel_sort(first, last, less);
#else
  std::sort(first, last, less);
#endif
}
template <class It>
void parallel_sort(It first, It last) {
  parallel_sort(first, last, std::less<>());
}

}  // namespace detail

}  // namespace lwsccd
