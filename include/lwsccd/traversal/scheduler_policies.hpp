// lwsccd — the GPU traversal's scheduler policies (card: named, composable policies; used by
// gpu::traverse in <lwsccd/traverse.cuh>). Plain C++: a policy can be declared, derived and
// checked without CUDA.
#pragma once

#include <type_traits>

namespace lwsccd::gpu {

// Scheduler policies (CUB's habit): a struct of named static constexpr knobs and a kind tag.
// Use one as it is, or derive from it and override knobs by name:
//
//   struct SmallBlocks : lwsccd::gpu::LazyStealScheduler {
//     static constexpr int kBlockThreads = 128;
//     static constexpr int kBlocksPerSm = 8;
//   };
//   lwsccd::gpu::traverse<SmallBlocks>(task, seeds, num_seeds, out, record_front, stream);
//
// Knobs derived from others (LazyStealScheduler's kShareWhenHungry) are recomputed from the
// policy as it is at the end. traverse() dispatches on the kind tag and refuses a policy that
// names none (static_assert). The measurements behind the defaults are in docs/TRAVERSAL.md.

/// Kind tags: which scheduler runs a policy (`using scheduler_kind = ...`).
struct static_task_list_kind {};
struct gproximity_kind {};
struct lazy_steal_kind {};

/// Static split of a BVTT cut over the blocks, no balancing.
struct StaticTaskList {
  using scheduler_kind = static_task_list_kind;
  static constexpr int kBlockThreads = 128;
  static constexpr int kSharedStack = 1024;   ///< items per block in shared memory
  static constexpr int kGlobalStack = 16384;  ///< items per block in global memory (spill)
  static constexpr int kItemsPerBlock = 256;  ///< size of the initial cut per block
  static constexpr int kBlocksPerSm = 2;
};

/// gProximity-style balancing: traverse until too many blocks idle, then rebalance.
struct GProximityBalancer {
  using scheduler_kind = gproximity_kind;
  static constexpr int kBlockThreads = 128;
  static constexpr int kSharedStack = 1024;
  static constexpr int kGlobalStack = 16384;
  static constexpr int kIdlePercent = 50;  ///< stop the traversal kernel when this share of blocks idles
  static constexpr int kBlocksPerSm = 2;
};

/// Lazy work stealing (dissertation Algorithms 3.7-3.13): persistent blocks, a shared-memory
/// stack per block, a deque per block in global memory that the owner fills and drains in
/// batches, and, when a block runs dry, a lazy steal: it reads every deque's size at once and
/// takes half of the fullest one's oldest items. The defaults are the fastest shape measured for
/// BVTT traversals on an H100 (docs/TRAVERSAL.md, "Tuning").
struct LazyStealScheduler {
  using scheduler_kind = lazy_steal_kind;
  /// Threads per persistent block (512: smaller blocks left the SMs' latency unhidden).
  static constexpr int kBlockThreads = 512;
  /// Items per block in shared memory: at least kPushThreshold plus one round of children.
  static constexpr int kSharedStack = 4096;
  static constexpr int kDequeCapacity = 8192;  ///< items per block deque (global memory)
  static constexpr int kPopSize = 512;         ///< items moved from a deque into shared memory at once
  static constexpr int kPushThreshold = 1024;  ///< shared stack size above which a batch goes to the deque
  static constexpr int kBlocksPerSm = 2;       ///< persistent blocks per SM (occupancy hides memory latency)
  /// A start from few seeds (the root) is first expanded breadth first to about this many items
  /// per block; stealing spreads the rest.
  static constexpr int kSeedsPerBlock = 8;
  /// A block that found nothing to steal sleeps from 256 ns, doubling up to this (ns) before it
  /// looks again.
  static constexpr int kMaxBackoffNs = 256;
  /// A thief tries its victim's lock this many times (64 ns apart) before it looks again (0: it
  /// waits for the lock): no convoy of thieves at the end of a traversal.
  static constexpr int kStealLockAttempts = 16;
  /// A thief picks its victim at random among the deques within a factor of two of the fullest
  /// (false: the fullest), so that thieves that saw the same fullest deque do not all contend.
  static constexpr bool kRandomVictim = true;
  /// Compile the kernel to fit kBlocksPerSm blocks per SM (__launch_bounds__; registers capped).
  /// Either way a launch has only as many blocks as can be resident at once.
  static constexpr bool kFitBlocksPerSm = true;
  /// A start of at least this many items per block (a front kept from the last step) is first
  /// processed by one flat launch, a thread per item (0: never): most front items end at once.
  static constexpr int kFlatStartPerBlock = 512;
  /// A block holding more than this many items moves the older half to its empty deque when some
  /// block is looking for work (0: never; negative: half of kPushThreshold, recomputed for a
  /// derived policy that changes kPushThreshold).
  static constexpr int kShareWhenHungry = -1;
};

/// LazyStealScheduler with room for 16 children per thread and round (RayWalkTask<>'s items):
/// the fastest shape for ray walks on an H100 (docs/RAYTRACING.md).
struct RayWalkLazySteal : LazyStealScheduler {
  static constexpr int kBlockThreads = 128;
  static constexpr int kPushThreshold = 2048;
  static constexpr int kBlocksPerSm = 6;
};

namespace detail {
/// LazyStealScheduler's kShareWhenHungry as the kernel uses it (a negative knob: half of the
/// policy's kPushThreshold).
template <class Policy>
constexpr int share_when_hungry() {
  return Policy::kShareWhenHungry < 0 ? Policy::kPushThreshold / 2 : Policy::kShareWhenHungry;
}

template <class S, class = void>
struct has_scheduler_kind : std::false_type {};
template <class S>
struct has_scheduler_kind<S, std::void_t<typename S::scheduler_kind>> : std::true_type {};
template <class S, class = void>
struct has_block_threads : std::false_type {};
template <class S>
struct has_block_threads<S, std::void_t<decltype(S::kBlockThreads)>> : std::true_type {};

template <class S, bool = has_scheduler_kind<S>::value>
struct known_scheduler_kind : std::false_type {};
template <class S>
struct known_scheduler_kind<S, true>
    : std::bool_constant<std::is_same<typename S::scheduler_kind, static_task_list_kind>::value ||
                         std::is_same<typename S::scheduler_kind, gproximity_kind>::value ||
                         std::is_same<typename S::scheduler_kind, lazy_steal_kind>::value> {};

template <class S>
constexpr bool block_threads_valid() {
  if constexpr (has_block_threads<S>::value) return S::kBlockThreads > 0 && S::kBlockThreads % 32 == 0 && S::kBlockThreads <= 1024;
  else return true;
}

/// What traverse() asks of a scheduler policy, each with its own message (ArborX's habit).
template <class S>
struct require_scheduler_policy {
  static_assert(has_scheduler_kind<S>::value,
                "lwsccd: a scheduler policy needs a kind tag: using scheduler_kind = lwsccd::gpu::lazy_steal_kind (or "
                "static_task_list_kind, gproximity_kind); derive it from LazyStealScheduler, StaticTaskList or "
                "GProximityBalancer and override knobs by name");
  static_assert(!has_scheduler_kind<S>::value || known_scheduler_kind<S>::value,
                "lwsccd: a scheduler policy's scheduler_kind must be lazy_steal_kind, static_task_list_kind or "
                "gproximity_kind");
  static_assert(has_block_threads<S>::value, "lwsccd: a scheduler policy needs static constexpr int kBlockThreads");
  static_assert(block_threads_valid<S>(), "lwsccd: a scheduler policy's kBlockThreads must be a multiple of 32, at most 1024");
  static constexpr bool value = true;
};
}  // namespace detail

}  // namespace lwsccd::gpu
