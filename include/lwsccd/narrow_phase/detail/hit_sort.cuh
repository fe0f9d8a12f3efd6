// lwsccd — hits in (first, second) order: their keys, a one-block sort for short lists, and the
// sizes (id bits, grown room) the host loops use.
// Part of narrow_phase_kernels.cuh: include <lwsccd/narrow_phase/narrow_phase.cuh>, not this file.
#pragma once

#include <cub/block/block_load.cuh>
#include <cub/block/block_reduce.cuh>
#include <cub/block/block_scan.cuh>
#include <cub/block/block_store.cuh>

#include <cooperative_groups.h>
#include <cooperative_groups/reduce.h>
#include <cooperative_groups/scan.h>
#include <cstring>

#include "lwsccd/core/launch.cuh"
#include "lwsccd/narrow_phase/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.cuh"
#include "lwsccd/narrow_phase/detail/narrow_lists.cuh"

namespace lwsccd::gpu::detail {

// The sort key of a hit: (first, second) as one word, first shifted by `id_bits` (every id is
// below 2^id_bits, so the key's order is the pair's and it has 2 id_bits bits to sort).
template <class T>
__device__ inline unsigned long long hit_key(const FeatureHit<T>& hit, int id_bits) {
  assert(static_cast<unsigned long long>(static_cast<unsigned>(hit.first)) >> id_bits == 0 &&
         static_cast<unsigned long long>(static_cast<unsigned>(hit.second)) >> id_bits == 0 && "a feature id past the mesh's features");
  return (static_cast<unsigned long long>(static_cast<unsigned>(hit.first)) << id_bits) | static_cast<unsigned>(hit.second);
}

// The keys for the radix sort. With `device_n` (a sort enqueued before the host knows the count)
// only the first min(*device_n, n) slots hold hits: the others get the largest key and sort after
// them.
template <class T>
__global__ void hit_keys_kernel(const FeatureHit<T>* hits, std::size_t n, int id_bits, unsigned long long* keys,
                                const unsigned long long* device_n = nullptr) {
  lwsccd::detail::start_after_previous_grids();
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  if (device_n && i >= *device_n) {
    keys[i] = 2 * id_bits >= 64 ? ~0ull : (1ull << (2 * id_bits)) - 1;
    return;
  }
  keys[i] = hit_key(hits[i], id_bits);
}

// A sort of at most kThreads hits in one block, a thread per hit: its place is the number of
// keys below its own plus the equal ones before it (stable, as the radix sort). A step's few
// hits (horse-gallop: a handful) took a radix sort's ~14 us single-tile pass plus the key
// kernel; the block compares every pair of keys in shared memory instead. With `device_n`: the
// first min(*device_n, n) hits.
template <class T, int kThreads>
__global__ void __launch_bounds__(kThreads)
    small_hit_sort_kernel(const FeatureHit<T>* hits, int n, int id_bits, FeatureHit<T>* sorted,
                          const unsigned long long* device_n = nullptr) {
  __shared__ unsigned long long keys[kThreads];
  lwsccd::detail::start_after_previous_grids();
  if (device_n && *device_n < static_cast<unsigned long long>(n)) n = static_cast<int>(*device_n);
  const int i = static_cast<int>(threadIdx.x);
  FeatureHit<T> hit;
  unsigned long long key = 0;
  if (i < n) {
    hit = hits[i];
    key = hit_key(hit, id_bits);
    keys[i] = key;
  }
  __syncthreads();
  if (i >= n) return;
  int place = 0;
  for (int j = 0; j < n; ++j) {
    const unsigned long long other = keys[j];
    place += other < key || (other == key && j < i);
  }
  sorted[place] = hit;
}
constexpr int kSmallHitSort = 256;  ///< hits sorted by small_hit_sort_kernel (more: the radix sort)

// The sort ahead by buckets (HitSorter::sort_ahead): bucket b holds the hits whose first id lies
// in [b 2^shift, (b + 1) 2^shift), so the buckets' order is the first ids' order; the hits are
// counted per bucket, the counts scanned, each hit placed in its bucket's range, and then ranked
// there by its key (the index in the unsorted list breaks ties, so the sort is stable). Four
// short launches (each may overlap the end of the one before it: they start with
// start_after_previous_grids) where a radix sort of the 2 id_bits-bit keys took eight (a
// histogram, a scan and one pass per 8 bits), ~60-80 us at the end of a step's edge-edge list
// (H200 trace, cloth-ball).
// A rank costs a read of every hit of its bucket; buckets of a real step can be crowded (a
// feature of a coarse mesh touching many of a fine one: cloth-ball's edge-edge hits hold 189 in
// one bucket of two edges, 118 for one edge), and a bucket of 1024 costs a thread ~1024 reads of
// keys its warp mostly shares. A bucket with more than kBucketRankMax hits is counted in
// *overflow and not ranked: the caller then sorts by radix.
constexpr unsigned kBucketRankMax = 1024;

template <class T>
__global__ void bucket_count_kernel(const FeatureHit<T>* hits, std::size_t span, const unsigned long long* device_n, int shift,
                                    unsigned* bucket_count, unsigned long long* overflow) {
  lwsccd::detail::start_after_previous_grids();
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= span || i >= *device_n) return;
  const unsigned b = static_cast<unsigned>(hits[i].first) >> shift;
  if (atomicAdd(bucket_count + b, 1u) == kBucketRankMax) atomicAdd(overflow, 1ull);  // (once a bucket)
}

// The bucket counts' exclusive sum (bucket_start), in one launch where CUB's scan took two (its
// tile states' initialization, then the scan): a block per tile of kBucketScanTile counts, the
// tiles taken in order by a ticket (*tile_ticket, zero before; bucket_place_kernel returns it to
// zero), each tile's sum published (with this sort's `generation` in the high word: words of
// earlier sorts are stale, nothing is cleared) before its block adds up the sums of the tiles
// before it. Those tiles' blocks took their tickets earlier and publish without waiting, so the
// wait ends. A sort has a few hundred tiles at most (2^bucket_bits < 4 span).
constexpr int kBucketScanThreads = 256;
constexpr int kBucketScanItems = 16;
constexpr std::size_t kBucketScanTile = static_cast<std::size_t>(kBucketScanThreads) * kBucketScanItems;

template <int kThreads = kBucketScanThreads, int kItems = kBucketScanItems>
__global__ void __launch_bounds__(kThreads)
    bucket_scan_kernel(const unsigned* bucket_count, std::size_t n, unsigned* bucket_start, unsigned long long* tile_sums,
                       unsigned* tile_ticket, unsigned generation) {
  using Load = cub::BlockLoad<unsigned, kThreads, kItems, cub::BLOCK_LOAD_WARP_TRANSPOSE>;
  using Store = cub::BlockStore<unsigned, kThreads, kItems, cub::BLOCK_STORE_WARP_TRANSPOSE>;
  using Scan = cub::BlockScan<unsigned, kThreads>;
  using Reduce = cub::BlockReduce<unsigned, kThreads>;
  __shared__ union {
    typename Load::TempStorage load;
    typename Store::TempStorage store;
    typename Scan::TempStorage scan;
    typename Reduce::TempStorage reduce;
  } temp;
  __shared__ unsigned tile_shared, before_shared;
  lwsccd::detail::start_after_previous_grids();
  if (threadIdx.x == 0) tile_shared = atomicAdd(tile_ticket, 1u);
  __syncthreads();
  const unsigned tile = tile_shared;
  const std::size_t from = static_cast<std::size_t>(tile) * kThreads * kItems;
  if (from >= n) return;  // (no more tiles than blocks: never taken)
  const int valid = static_cast<int>(n - from < static_cast<std::size_t>(kThreads * kItems) ? n - from : kThreads * kItems);
  unsigned counts[kItems];
  Load(temp.load).Load(bucket_count + from, counts, valid, 0u);
  unsigned mine = 0;
  for (int k = 0; k < kItems; ++k) mine += counts[k];
  __syncthreads();
  unsigned before_mine = 0, tile_sum = 0;
  Scan(temp.scan).ExclusiveSum(mine, before_mine, tile_sum);
  if (threadIdx.x == 0) atomicExch(tile_sums + tile, (static_cast<unsigned long long>(generation) << 32) | tile_sum);
  unsigned before = 0;
  for (unsigned j = threadIdx.x; j < tile; j += kThreads) {
    unsigned long long word;
    do {
      word = *static_cast<volatile unsigned long long*>(tile_sums + j);
    } while (static_cast<unsigned>(word >> 32) != generation);
    before += static_cast<unsigned>(word);
  }
  __syncthreads();
  before = Reduce(temp.reduce).Sum(before);
  if (threadIdx.x == 0) before_shared = before;
  __syncthreads();
  unsigned start = before_shared + before_mine;
  for (int k = 0; k < kItems; ++k) {
    const unsigned c = counts[k];
    counts[k] = start;
    start += c;
  }
  Store(temp.store).Store(bucket_start + from, counts, valid);
}

// Each hit to a slot of its bucket's range: its key and its index. The counts return to zero
// (they are zero again for the next sort), and so does the scan's ticket.
template <class T>
__global__ void bucket_place_kernel(const FeatureHit<T>* hits, std::size_t span, const unsigned long long* device_n, int shift,
                                    int id_bits, unsigned* bucket_count, const unsigned* bucket_start, unsigned long long* keys,
                                    unsigned* order, unsigned* tile_ticket) {
  lwsccd::detail::start_after_previous_grids();
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i == 0) *tile_ticket = 0;
  if (i >= span || i >= *device_n) return;
  const FeatureHit<T> h = hits[i];
  const unsigned b = static_cast<unsigned>(h.first) >> shift;
  const unsigned at = bucket_start[b] + atomicSub(bucket_count + b, 1u) - 1u;
  keys[at] = hit_key(h, id_bits);
  order[at] = static_cast<unsigned>(i);
}
// A thread per placed hit: its rank among its bucket's hits is its place after the bucket's start.
template <class T>
__global__ void bucket_rank_kernel(const FeatureHit<T>* hits, std::size_t span, const unsigned long long* device_n, int shift,
                                   int id_bits, const unsigned* bucket_start, const unsigned long long* __restrict__ keys,
                                   const unsigned* __restrict__ order, FeatureHit<T>* sorted) {
  lwsccd::detail::start_after_previous_grids();
  const std::size_t p = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (p >= span || p >= *device_n) return;
  const unsigned long long key = keys[p];
  const unsigned index = order[p];
  const unsigned b = static_cast<unsigned>(key >> id_bits) >> shift;
  const unsigned from = bucket_start[b], to = bucket_start[b + 1];
  if (to - from > kBucketRankMax) return;  // (counted: the caller sorts by radix)
  // Branch-free and unrolled, so that a crowded bucket's loads are in flight together (one after
  // the other, each waited for, a bucket of 189 took its threads ~18 us: cloth-ball, H200 trace).
  unsigned rank = 0;
#pragma unroll 8
  for (unsigned j = from; j < to; ++j) {
    const unsigned long long other = keys[j];
    rank += static_cast<unsigned>(other < key) | (static_cast<unsigned>(other == key) & static_cast<unsigned>(order[j] < index));
  }
  sorted[from + rank] = hits[index];
}

// Bits of the largest feature id below `id_limit` (at least 1, at most 32).
inline int id_bits_below(std::size_t id_limit) {
  int bits = 1;
  while (bits < 32 && (std::size_t(1) << bits) < id_limit) ++bits;
  return bits;
}

// Room for a list that needed `needed`: a quarter more, so that a list that grows a little from
// step to step does not repeat runs.
inline std::size_t grown_room(unsigned long long needed) {
  const std::size_t n = static_cast<std::size_t>(needed);
  return n + n / 4 + 1024;
}

}  // namespace lwsccd::gpu::detail
