// lwsccd — what every GPU scheduler shares on the host: buffers sized on demand, the number of
// blocks resident at once, the counters read back, and a start expanded breadth first.
// Part of traverse_kernels.cuh: include <lwsccd/traverse.cuh>, not this file.
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

namespace lwsccd::gpu::detail {

template <class T>
void ensure(DeviceBuffer<T>& b, std::size_t n) {
  if (b.size() < n) b.resize_discard(n);
}

inline int resident_blocks(int blocks_per_sm) {
  int device = 0, sms = 0;
  LWSCCD_CUDA_CHECK(cudaGetDevice(&device));
  LWSCCD_CUDA_CHECK(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, device));
  return std::max(1, sms * blocks_per_sm);
}

// Blocks of `kernel` that are resident at once, at most blocks_per_sm per SM: persistent blocks
// beyond that would wait for a slot (registers or shared memory) and start only when others end.
// `cache` (one per kernel, per device id; 0: not asked yet) spares the query on later calls
// (a traversal from a small front takes tens of microseconds).
template <class Kernel, int kDevices>
int co_resident_blocks(Kernel kernel, int threads, int blocks_per_sm, std::atomic<int> (&cache)[kDevices]) {
  int device = 0;
  LWSCCD_CUDA_CHECK(cudaGetDevice(&device));
  int fit = device < kDevices ? cache[device].load(std::memory_order_relaxed) : 0;
  if (fit == 0) {
    LWSCCD_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&fit, kernel, threads, 0));
    if (fit < 1) throw Error("lwsccd: LazyStealScheduler: its kernel cannot run a block of " + std::to_string(threads) +
                             " threads on this GPU (registers or shared memory)");
    if (device < kDevices) cache[device].store(fit, std::memory_order_relaxed);
  }
  return resident_blocks(std::min(fit, blocks_per_sm));
}

// Enqueues the counters' copy into host_counters_ (pinned: the copy does not block).
template <class Task>
void enqueue_counter_read(TraversalStorage<Task>& out, cudaStream_t stream) {
  if (out.host_counters_.size() < static_cast<std::size_t>(kCounters))
    out.host_counters_ = PinnedBuffer<unsigned long long>(kCounters);
  LWSCCD_CUDA_CHECK(cudaMemcpyAsync(out.host_counters_.data(), out.counters_.data(), kCounters * sizeof(unsigned long long),
                                    cudaMemcpyDeviceToHost, stream));
}

// Reads the counters (one synchronisation). The reading stays in host_counters_, so that
// traverse() need not read again what the scheduler's last read saw.
template <class Task>
std::vector<unsigned long long> read_counters(TraversalStorage<Task>& out, cudaStream_t stream) {
  enqueue_counter_read(out, stream);
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
  ++out.counter_reads_;
  return std::vector<unsigned long long>(out.host_counters_.data(), out.host_counters_.data() + kCounters);
}

template <class Task>
Outputs<Task> outputs_of(TraversalStorage<Task>& out, bool record_front) {
  return {out.results_.data(), out.results_.size(), out.front_.data(), out.front_.size(), out.counters_.data(), record_front,
          out.halt_on_overflow_};
}

// How much an output that was full grows at once in a halting traversal (the final count is not
// known until the traversal ends: a few growths from the starting room reach any size).
inline constexpr std::size_t kOutputGrowth = 4;
// Up to this many entries an output half full grows along with a full one (absorb_overflow).
inline constexpr std::size_t kSmallOutputRoom = std::size_t(1) << 20;

// After a launch of a halting traversal whose counters `c` the host has read: where the outputs
// were full, each full one grows (keeping what it holds), the counts resume where the stored
// prefix ends, and the next launch takes up the items handed back. Returns false where the output
// limit forbids growing: the traversal stops there, incomplete, with what was stored.
template <class Task>
bool absorb_overflow(TraversalStorage<Task>& out, const std::vector<unsigned long long>& c, cudaStream_t stream) {
  if (c[kOverflow] == 0) return true;
  using Item = typename Task::item_type;
  using Result = typename Task::result_type;
  const unsigned long long stored = ~c[kOverflow];
  const std::size_t results = results_of(stored), front = front_of(stored);
  const std::size_t results_room = out.results_.size(), front_room = out.front_.size();
  // An output is full when the reservations after the stored prefix pass its room (c[kOutputs]
  // counts them all); only those grow.
  auto grown = [](std::size_t room, std::size_t reserved) {
    return reserved > room ? std::min(std::max(room * kOutputGrowth, reserved + reserved / 4), kMaxOutputRoom) : room;
  };
  const std::size_t reserved_results = results_of(c[kOutputs]), reserved_front = front_of(c[kOutputs]);
  check_output_counts(reserved_results, reserved_front);  // (never silently incomplete without a limit)
  std::size_t new_results = grown(results_room, reserved_results), new_front = grown(front_room, reserved_front);
  // An output still small and half full grows with the other: both fill as the traversal goes
  // deeper, and a relaunch (~0.05-0.08 ms on an H100) costs more than the room.
  auto along = [](std::size_t room, std::size_t stored, std::size_t grown_room) {
    return grown_room == room && room <= kSmallOutputRoom && 2 * stored >= room ? std::min(room * kOutputGrowth, kMaxOutputRoom)
                                                                               : grown_room;
  };
  if (new_results != results_room || new_front != front_room) {
    new_results = along(results_room, results, new_results);
    new_front = along(front_room, front, new_front);
  }
  auto bytes = [](std::size_t r, std::size_t f) { return r * sizeof(Result) + f * sizeof(Item); };
  if (out.output_limit_ && bytes(new_results, new_front) > out.output_limit_) {  // the least growth that lets it go on
    new_results = reserved_results > results_room ? std::min(reserved_results + reserved_results / 4, kMaxOutputRoom) : results_room;
    new_front = reserved_front > front_room ? std::min(reserved_front + reserved_front / 4, kMaxOutputRoom) : front_room;
  }
  if ((out.output_limit_ && bytes(new_results, new_front) > out.output_limit_) ||
      (new_results <= results_room && new_front <= front_room)) {  // (the second: nothing could grow)
    out.complete_ = false;
    out.num_results_ = results;
    out.num_front_ = front;
    return false;
  }
  out.results_.resize_discard(results);  // (no reallocation: only what is kept is copied below)
  out.results_.resize_keep(new_results, 0, stream);
  out.front_.resize_discard(front);
  out.front_.resize_keep(new_front, 0, stream);
  const unsigned long long resume[2] = {stored, 0};  // kOutputs, kOverflow
  LWSCCD_CUDA_CHECK(cudaMemcpyAsync(out.counters_.data() + kOutputs, resume, sizeof resume, cudaMemcpyHostToDevice, stream));
  ++out.stats_.relaunches;
  return true;
}

// Threads per block of the flat launches (a thread per item, no shared memory: the block size
// only sets the grid's granularity).
inline constexpr int kFlatLaunchThreads = 256;

// One breadth-first level in one launch, a thread per item: in[0, n) processed, their children
// left in out.work_ (`in` may be out.work_ itself); returns how many (one host synchronisation).
template <class Task>
std::size_t expand_level(const Task& task, const typename Task::item_type* in, std::size_t n, TraversalStorage<Task>& out,
                         bool record_front, cudaStream_t stream) {
  ensure(out.next_, n * Task::kMaxChildren);
  LWSCCD_CUDA_CHECK(cudaMemsetAsync(out.counters_.data() + kAppended, 0, sizeof(unsigned long long), stream));
  LWSCCD_CUDA_CHECK(cudaMemsetAsync(out.counters_.data() + kRequeued, 0, sizeof(unsigned long long), stream));
  expand_kernel<Task, kFlatLaunchThreads><<<static_cast<unsigned>((n + kFlatLaunchThreads - 1) / kFlatLaunchThreads),
                                             kFlatLaunchThreads, 0, stream>>>(
      task, in, n, out.next_.data(), n * Task::kMaxChildren, outputs_of(out, record_front));
  LWSCCD_CUDA_CHECK_LAUNCH();
  const auto c = read_counters(out, stream);
  out.stats_.items_processed += n - static_cast<std::size_t>(c[kRequeued]);
  std::swap(out.work_, out.next_);
  if (!absorb_overflow(out, c, stream)) return 0;  // stopped at the output limit (incomplete)
  return static_cast<std::size_t>(c[kAppended]);
}

// Breadth-first expansion of the seeds (copied to out.work_) until there are at least `target`
// items or none; returns their count (in out.work_).
template <class Task>
std::size_t expand_breadth_first(const Task& task, const typename Task::item_type* seeds, std::size_t num_seeds,
                                 std::size_t target, TraversalStorage<Task>& out, bool record_front, cudaStream_t stream) {
  using Item = typename Task::item_type;
  std::size_t n = num_seeds;
  const std::size_t stop_at = target / Task::kMaxChildren;
  // Small levels in one launch (a single block of kOneBlockThreads), up to a few items per thread.
  constexpr int kOneBlockThreads = 512;
  const std::size_t one_block_stop = std::min<std::size_t>(stop_at, 4 * kOneBlockThreads);
  const bool one_block = n > 0 && n < one_block_stop;
  const std::size_t room = one_block ? one_block_stop * Task::kMaxChildren : 0;
  ensure(out.work_, std::max<std::size_t>({num_seeds, room, 1}));
  if (num_seeds)
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(out.work_.data(), seeds, num_seeds * sizeof(Item), cudaMemcpyDeviceToDevice, stream));
  if (one_block) {
    ensure(out.next_, room);
    expand_small_levels_kernel<Task, kOneBlockThreads><<<1, kOneBlockThreads, 0, stream>>>(
        task, out.work_.data(), out.next_.data(), n, one_block_stop, room, outputs_of(out, record_front));
    LWSCCD_CUDA_CHECK_LAUNCH();
    const auto c = read_counters(out, stream);
    n = static_cast<std::size_t>(c[kAppended]);
    if (c[kLevels] % 2 == 1) std::swap(out.work_, out.next_);
    if (!absorb_overflow(out, c, stream)) return 0;  // stopped at the output limit (incomplete)
  }
  while (n > 0 && n < stop_at) n = expand_level(task, out.work_.data(), n, out, record_front, stream);
  return n;
}

}  // namespace lwsccd::gpu::detail
