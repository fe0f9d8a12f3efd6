// lwsccd — hits in (first, second) order: their keys, a one-block sort for short lists, and the
// sizes (id bits, grown room) the host loops use.
// Part of narrow_phase_kernels.cuh: include <lwsccd/narrow_phase/narrow_phase.cuh>, not this file.
#pragma once

#include <cooperative_groups.h>
#include <cooperative_groups/reduce.h>
#include <cooperative_groups/scan.h>
#include <cstring>

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
// there by its key (the index in the unsorted list breaks ties, so the sort is stable). Five
// short launches where a radix sort of the 2 id_bits-bit keys took eight (a histogram, a scan and
// one pass per 8 bits), ~60-80 us at the end of a step's edge-edge list (H200 trace, cloth-ball).
// A rank costs a read of every hit of its bucket; buckets of a real step can be crowded (a
// feature of a coarse mesh touching many of a fine one: cloth-ball's edge-edge hits hold 189 in
// one bucket of two edges, 118 for one edge), and a bucket of 1024 costs a thread ~1024 reads of
// keys its warp mostly shares. A bucket with more than kBucketRankMax hits is counted in
// *overflow and not ranked: the caller then sorts by radix.
constexpr unsigned kBucketRankMax = 1024;

template <class T>
__global__ void bucket_count_kernel(const FeatureHit<T>* hits, std::size_t span, const unsigned long long* device_n, int shift,
                                    unsigned* bucket_count, unsigned long long* overflow) {
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= span || i >= *device_n) return;
  const unsigned b = static_cast<unsigned>(hits[i].first) >> shift;
  if (atomicAdd(bucket_count + b, 1u) == kBucketRankMax) atomicAdd(overflow, 1ull);  // (once a bucket)
}
// Each hit to a slot of its bucket's range: its key and its index. The counts return to zero
// (they are zero again for the next sort).
template <class T>
__global__ void bucket_place_kernel(const FeatureHit<T>* hits, std::size_t span, const unsigned long long* device_n, int shift,
                                    int id_bits, unsigned* bucket_count, const unsigned* bucket_start, unsigned long long* keys,
                                    unsigned* order) {
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
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
