// lwsccd — feature pairs produced once on the GPU: representative triangles and feature-box
// culling (representative.hpp says what and why), with no sort.
//
// Three kernels and one small scan: the swept boxes, packed face by face (a face's box, then the
// boxes of the vertices and edges it represents, as the CPU's pack_emission lays them out); a
// count pass that runs the shared emission test (the masks of emission_mask, orphan_kept) over
// every candidate triangle pair and every orphan, stores each item's mask and sums each block's
// counts (vertex-face and edge-edge packed in one 64-bit word, so one scan gives both offsets); an
// inclusive scan of the block totals; a write pass that ranks the items within their block and
// decodes each mask at its offset, into buffers sized by earlier runs (enqueue() leaves the totals
// on the device for the narrow phase; collect() grows a buffer that was short and writes again).
// The pairs come in the order of the items (candidates, then vertex-face orphans, then edge-edge
// orphans), the order cpu emit_feature_pairs gives for the same candidate list.
#pragma once

#include <cub/block/block_reduce.cuh>
#include <cub/block/block_scan.cuh>
#include <cub/device/device_scan.cuh>

#include <cstring>
#include <tuple>
#include <utility>
#include <vector>

#include "lwsccd/core/cuda_check.cuh"
#include "lwsccd/core/device_buffer.cuh"
#include "lwsccd/features/representative.hpp"

namespace lwsccd::gpu {

/// Knobs of the GPU emission.
struct EmissionPolicy {
  static constexpr int kBlock = 256;  ///< threads per block, a thread per item (feature, triangle pair or orphan)
};

namespace detail {

// The two counts of an item packed in one word: vertex-face in the high half, edge-edge in the low
// half (a step's totals stay far below 2^32, so the scan never carries between the halves).
LWSCCD_HD inline unsigned long long pack_counts(unsigned vf, unsigned ee) {
  return (static_cast<unsigned long long>(vf) << 32) | ee;
}

// The swept boxes packed face by face, each 32 bytes (two 16-byte loads, one sector): per face its
// box with, in the fourth words, where its features' boxes start and its represents bits; per
// represented vertex or edge, in the face's order (vertices by corner, then edges), its box. A
// candidate pair then reads two face records and its faces' few feature boxes, which lie
// together, instead of a box per feature id through the faces' vertex and edge ids (cloth-ball,
// H200: the count pass was bound by its L1 requests, 24-byte boxes read a float at a time).
struct PackedBoxes {
  float4* faces = nullptr;     ///< two per face: (lo, first), (hi, represents)
  float4* features = nullptr;  ///< two per represented vertex or edge: (lo, -), (hi, -)
  /// Five per face (three sectors): its FaceCorners and two unused words, or null: the faces'
  /// motion not tested.
  float4* corners = nullptr;
  static constexpr int kCornerWords = 5;
  static_assert(sizeof(FaceCorners) == 18 * sizeof(float), "lwsccd: FaceCorners is 18 floats");

  __device__ void put_corners(index_t f, const FaceCorners& c) const {
    float v[4 * kCornerWords] = {};
    memcpy(v, &c, sizeof c);
    float4* at = corners + kCornerWords * static_cast<std::size_t>(f);
#pragma unroll
    for (int k = 0; k < kCornerWords; ++k) at[k] = make_float4(v[4 * k], v[4 * k + 1], v[4 * k + 2], v[4 * k + 3]);
  }
  __device__ FaceCorners corners_of(index_t f) const {
    float v[4 * kCornerWords];
    const float4* at = corners + kCornerWords * static_cast<std::size_t>(f);
#pragma unroll
    for (int k = 0; k < kCornerWords; ++k) {
      const float4 w = __ldg(at + k);
      v[4 * k] = w.x, v[4 * k + 1] = w.y, v[4 * k + 2] = w.z, v[4 * k + 3] = w.w;
    }
    FaceCorners c;
    memcpy(&c, v, sizeof c);
    return c;
  }

  __device__ static void put(float4* at, const Aabbf& box, unsigned a, unsigned b) {
    at[0] = make_float4(box.lo.x, box.lo.y, box.lo.z, __uint_as_float(a));
    at[1] = make_float4(box.hi.x, box.hi.y, box.hi.z, __uint_as_float(b));
  }
  __device__ static Aabbf get(const float4* at, unsigned& a, unsigned& b) {
    const float4 lo = __ldg(at), hi = __ldg(at + 1);
    a = __float_as_uint(lo.w);
    b = __float_as_uint(hi.w);
    return {{lo.x, lo.y, lo.z}, {hi.x, hi.y, hi.z}};
  }
  __device__ Aabbf feature(unsigned slot) const {
    unsigned unused_a, unused_b;
    return get(features + 2 * static_cast<std::size_t>(slot), unused_a, unused_b);
  }
  __device__ Aabbf face(index_t f) const {
    unsigned unused_a, unused_b;
    return get(faces + 2 * static_cast<std::size_t>(f), unused_a, unused_b);
  }
};

// A thread per face: its box and its represented features' boxes, each feature_box of its id (the
// same values as the CPU's boxes), at the face's slots; its corners when the faces' motion is tested.
template <class P>
__global__ void packed_boxes_kernel(EmissionView m, const Vec3<P>* x0, const Vec3<P>* x1, index_t num_faces, float margin,
                                    const unsigned* face_first, PackedBoxes packed) {
  const index_t f = static_cast<index_t>(blockIdx.x * blockDim.x + threadIdx.x);
  if (f >= num_faces) return;
  const unsigned r = m.represents[f];
  unsigned slot = face_first[f];
  PackedBoxes::put(packed.faces + 2 * static_cast<std::size_t>(f),
                   feature_box(m.faces, m.edges, m.num_vertices, m.num_edges, x0, x1, m.face_feature(f), margin), slot, r);
  const Face t = m.faces[f];
  if (packed.corners) packed.put_corners(f, face_corners(t, x0, x1));
  const FaceEdgeIds e = m.face_edges[f];
#pragma unroll
  for (int k = 0; k < 3; ++k)
    if ((r >> k) & 1u)
      PackedBoxes::put(packed.features + 2 * static_cast<std::size_t>(slot++),
                       feature_box(m.faces, m.edges, m.num_vertices, m.num_edges, x0, x1, t.v[k], margin), 0u, 0u);
#pragma unroll
  for (int k = 0; k < 3; ++k)
    if ((r >> (3 + k)) & 1u)
      PackedBoxes::put(packed.features + 2 * static_cast<std::size_t>(slot++),
                       feature_box(m.faces, m.edges, m.num_vertices, m.num_edges, x0, x1, m.edge_feature(e.e[k]), margin), 0u, 0u);
}

// emission_mask of the candidate (a, b) over the packed boxes: the same bits (a feature's bit by
// its corner or edge index, its box at the next of its face's slots).
__device__ inline unsigned packed_emission_mask(const PackedBoxes& packed, index_t a, index_t b) {
  unsigned slot_a, ra, slot_b, rb;
  const Aabbf box_a = PackedBoxes::get(packed.faces + 2 * static_cast<std::size_t>(a), slot_a, ra);
  const Aabbf box_b = PackedBoxes::get(packed.faces + 2 * static_cast<std::size_t>(b), slot_b, rb);
  if (ra == 0 && rb == 0) return 0;
  unsigned mask = 0;
#pragma unroll
  for (int k = 0; k < 3; ++k)
    if ((ra >> k) & 1u && packed.feature(slot_a++).overlaps(box_b)) mask |= 1u << k;
#pragma unroll
  for (int k = 0; k < 3; ++k)
    if ((rb >> k) & 1u && packed.feature(slot_b++).overlaps(box_a)) mask |= 1u << (3 + k);
  if ((ra >> 3) == 0 || (rb >> 3) == 0) return mask;
  Aabbf edges_b[3];  // (constant indices once unrolled: registers)
#pragma unroll
  for (int y = 0; y < 3; ++y)
    if ((rb >> (3 + y)) & 1u) edges_b[y] = packed.feature(slot_b++);
#pragma unroll
  for (int x = 0; x < 3; ++x) {
    if (!((ra >> (3 + x)) & 1u)) continue;
    const Aabbf box_x = packed.feature(slot_a++);
#pragma unroll
    for (int y = 0; y < 3; ++y)
      if ((rb >> (3 + y)) & 1u && box_x.overlaps(edges_b[y])) mask |= 1u << (6 + 3 * x + y);
  }
  return mask;
}

// Orphan k of the items past the candidates: vertex-face orphan k, then the edge-edge ones.
template <class Pair>
__device__ inline Pair orphan_item(const Pair* orphan_vf, std::size_t num_orphan_vf, const Pair* orphan_ee, std::size_t k) {
  return k < num_orphan_vf ? orphan_vf[k] : orphan_ee[k - num_orphan_vf];
}

// Item i: candidate triangle pair i (i < n), then vertex-face orphan i - n, then edge-edge orphan.
// Its emission mask: emission_mask for a candidate (with corners, none for faces apart by
// faces_apart, tested first; else the boxes' mask);
// bit 0 (vertex-face) or bit 6 (edge-edge) for a kept orphan (orphan_kept: the two features'
// packed boxes overlap; `feature_slot` gives a vertex's or an edge's slot, every feature of an
// orphan having a representing face).
template <class Pair>
__device__ unsigned item_mask(const EmissionView& m, const PackedBoxes& packed, const unsigned* feature_slot,
                              const TrianglePair* candidates, std::size_t n, const Pair* orphan_vf, std::size_t num_orphan_vf,
                              const Pair* orphan_ee, std::size_t i) {
  if (i < n) {
    const TrianglePair p = candidates[i];
    if (p.adjacent) return 0u;
    // The faces first: three sectors a face read at once, which spare the pairs apart the boxes'
    // two dependent reads (the mask is the same either way; H200, boxes first: cloth-ball's
    // feature-pairs stage 0.28 -> 0.32 ms, armadillo-rollers' 0.17 -> 0.20).
    if (packed.corners && faces_apart(packed.corners_of(p.a), packed.corners_of(p.b))) return 0u;
    return packed_emission_mask(packed, p.a, p.b);
  }
  const index_t faces_from = m.num_vertices + m.num_edges;
  auto box_of = [&](index_t id) {
    if (id >= faces_from) return packed.face(id - faces_from);
    const unsigned slot = feature_slot[id];
    assert(slot != ~0u && "an orphan's feature without a representing face");
    return packed.feature(slot);
  };
  const Pair q = orphan_item(orphan_vf, num_orphan_vf, orphan_ee, i - n);
  if (!box_of(q.first).overlaps(box_of(q.second))) return 0u;
  return i < n + num_orphan_vf ? 1u : 1u << 6;
}

__device__ inline unsigned long long mask_counts(unsigned mask) {
  return pack_counts(static_cast<unsigned>(__popc(mask & kEmissionVfBits)), static_cast<unsigned>(__popc(mask & kEmissionEeBits)));
}

// Counting pass: every item's mask, and each block's packed totals (the write pass scans within
// the block again, so only block totals need a device-wide scan).
template <int kBlock, class Pair>
__global__ void __launch_bounds__(kBlock)
    emission_count_kernel(EmissionView m, PackedBoxes packed, const unsigned* feature_slot, const TrianglePair* candidates,
                          DeviceCount candidate_count, const Pair* orphan_vf, std::size_t num_orphan_vf, const Pair* orphan_ee,
                          std::size_t num_orphan_ee, unsigned short* masks, unsigned long long* block_totals) {
  using Reduce = cub::BlockReduce<unsigned long long, kBlock>;
  __shared__ typename Reduce::TempStorage storage;
  const std::size_t n = candidate_count.get(), items = n + num_orphan_vf + num_orphan_ee;
  if (static_cast<std::size_t>(blockIdx.x) * kBlock >= items) {  // (a launch sized for the room, past the device's count)
    if (threadIdx.x == 0) block_totals[blockIdx.x] = 0;
    return;
  }
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * kBlock + threadIdx.x;
  unsigned mask = 0;
  if (i < items) {
    mask = item_mask(m, packed, feature_slot, candidates, n, orphan_vf, num_orphan_vf, orphan_ee, i);
    masks[i] = static_cast<unsigned short>(mask);
  }
  const unsigned long long total = Reduce(storage).Sum(mask_counts(mask));
  if (threadIdx.x == 0) block_totals[blockIdx.x] = total;
}

// The position of the set bit of rank k (0: the lowest) of a 16-bit mask with more than k set:
// three halvings by popcount and a last pair (__fns took ~40 instructions here).
__device__ inline int nth_set_bit16(unsigned mask, unsigned k) {
  int at = 0;
  unsigned c = static_cast<unsigned>(__popc(mask & 0xffu));
  if (k >= c) k -= c, mask >>= 8, at += 8;
  c = static_cast<unsigned>(__popc(mask & 0xfu));
  if (k >= c) k -= c, mask >>= 4, at += 4;
  c = static_cast<unsigned>(__popc(mask & 0x3u));
  if (k >= c) k -= c, mask >>= 2, at += 2;
  return at + (k >= (mask & 1u) ? 1 : 0);
}

// Writing pass: each item's offsets = its block's (scanned totals) + its rank in the block. A
// warp writes its items' pairs together: lane j of a round takes the warp's j-th vertex-face (then
// edge-edge) pair, finds the item it belongs to among the warp's 32 (a search over their offsets
// in shared memory) and decodes that one bit of its mask (emission_pair; no box is read again).
// The pairs land where a thread per item would put them, but in full, coalesced rounds: a thread
// per item wrote up to 15 pairs while most of its warp's lanes had fewer or none (cloth-ball,
// H100: 13 of 32 lanes active, 122 us for 6.85 M pairs).
template <int kBlock, class Pair>
__global__ void __launch_bounds__(kBlock)
    emission_write_kernel(EmissionView m, const TrianglePair* candidates, DeviceCount candidate_count, const Pair* orphan_vf,
                          std::size_t num_orphan_vf, const Pair* orphan_ee, std::size_t num_orphan_ee, const unsigned short* masks,
                          const unsigned long long* block_inclusive, Pair* vf_out, std::size_t vf_room, Pair* ee_out,
                          std::size_t ee_room) {
  static_assert(kBlock % 32 == 0, "lwsccd: the emission's blocks are whole warps");
  using Scan = cub::BlockScan<unsigned long long, kBlock>;
  __shared__ typename Scan::TempStorage storage;
  constexpr int kWarps = kBlock / 32;
  constexpr unsigned kOrphan = 1u << 16;  // (above the mask's 15 bits) the item is an orphan: its pair is (a, b)
  __shared__ unsigned item_mask[kWarps][32], vf_before[kWarps][32], ee_before[kWarps][32];
  __shared__ index_t item_a[kWarps][32], item_b[kWarps][32];
  const std::size_t n = candidate_count.get(), items = n + num_orphan_vf + num_orphan_ee;
  if (static_cast<std::size_t>(blockIdx.x) * kBlock >= items) return;  // (past the device's count: nothing to write)
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * kBlock + threadIdx.x;
  const unsigned mask = i < items ? masks[i] : 0u;
  unsigned long long offset = 0;
  Scan(storage).ExclusiveSum(mask_counts(mask), offset);
  offset += blockIdx.x ? block_inclusive[blockIdx.x - 1] : 0ull;
  const int lane = static_cast<int>(threadIdx.x % 32), warp = static_cast<int>(threadIdx.x / 32);
  // The warp's pairs are consecutive in each list from its first lane's offsets.
  const unsigned long long warp_offset = __shfl_sync(0xffffffffu, offset, 0);
  const unsigned vf_start = static_cast<unsigned>(offset >> 32) - static_cast<unsigned>(warp_offset >> 32);
  const unsigned ee_start = static_cast<unsigned>(offset & 0xffffffffull) - static_cast<unsigned>(warp_offset & 0xffffffffull);
  index_t a = 0, b = 0;
  if (mask != 0) {
    if (i < n) {
      const TrianglePair p = candidates[i];
      a = p.a, b = p.b;
    } else {
      const Pair q = orphan_item(orphan_vf, num_orphan_vf, orphan_ee, i - n);
      a = q.first, b = q.second;
    }
  }
  item_mask[warp][lane] = mask | (i >= n ? kOrphan : 0u);
  vf_before[warp][lane] = vf_start;
  ee_before[warp][lane] = ee_start;
  item_a[warp][lane] = a;
  item_b[warp][lane] = b;
  __syncwarp();
  const unsigned vf_total = __shfl_sync(0xffffffffu, vf_start + static_cast<unsigned>(__popc(mask & kEmissionVfBits)), 31);
  const unsigned ee_total = __shfl_sync(0xffffffffu, ee_start + static_cast<unsigned>(__popc(mask & kEmissionEeBits)), 31);
  // Pair j of one list: its item is the last lane whose pairs start at or before j (offsets do
  // not decrease; a lane with none shares the next one's start and is passed over).
  auto write_pairs = [&](const unsigned (&before)[32], unsigned total, unsigned bits, unsigned long long list_start, Pair* out,
                         std::size_t room) {
    for (unsigned j = static_cast<unsigned>(lane); j < total; j += 32) {
      int owner = 0;
#pragma unroll
      for (int step = 16; step > 0; step /= 2)
        if (before[owner + step] <= j) owner += step;
      const unsigned owner_mask = item_mask[warp][owner];
      const index_t x = item_a[warp][owner], y = item_b[warp][owner];
      const unsigned long long at = list_start + j;
      if (at >= room) continue;  // (the host sees the totals and writes again with more room)
      // (std::pair's assignment is host-only before C++20: the fields are written one by one.)
      if (owner_mask & kOrphan) {
        out[at].first = x;
        out[at].second = y;
      } else {
        const int bit = nth_set_bit16(owner_mask & bits, j - before[owner]);
        const EmittedPair p = emission_pair(m, x, y, bit);
        out[at].first = p.first;
        out[at].second = p.second;
      }
    }
  };
  write_pairs(vf_before[warp], vf_total, kEmissionVfBits, warp_offset >> 32, vf_out, vf_room);
  write_pairs(ee_before[warp], ee_total, kEmissionEeBits, warp_offset & 0xffffffffull, ee_out, ee_room);
}

}  // namespace detail

/// Produces a step's feature pairs on the device from candidate triangle pairs (the traversal's
/// output): each pair once, kept when its feature boxes overlap, plus the kept orphans. Owns the
/// topology arrays (uploaded once) and its outputs and scratch (reused; they only grow).
template <class Policy = EmissionPolicy>
class FeatureEmitter {
 public:
  using Pair = std::pair<index_t, index_t>;

  /// Uploads the representing faces and the orphans of `rep` (which may be dropped afterwards).
  explicit FeatureEmitter(const RepresentativeTriangles& rep, cudaStream_t stream = nullptr)
      : num_vertices_(rep.mesh().num_vertices()), num_edges_(rep.mesh().num_edges()), num_faces_(rep.mesh().num_faces()) {
    faces_.upload(rep.mesh().faces(), stream);
    edges_.upload(rep.mesh().edges(), stream);
    face_edges_.upload(rep.face_edges(), stream);
    represents_.upload(rep.represents(), stream);
    orphan_vf_.upload(rep.orphans().vf, stream);
    orphan_ee_.upload(rep.orphans().ee, stream);
    // Each face's first slot of the packed boxes (the represented vertices and edges before it),
    // and each vertex's and edge's slot (~0u: a vertex of no face), in detail::packed_boxes_kernel's order.
    std::vector<unsigned> first(static_cast<std::size_t>(num_faces_));
    std::vector<unsigned> slot_of(static_cast<std::size_t>(num_vertices_ + num_edges_), ~0u);
    unsigned slots = 0;
    for (std::size_t f = 0; f < first.size(); ++f) {
      first[f] = slots;
      const unsigned r = rep.represents()[f];
      for (int k = 0; k < 3; ++k)
        if ((r >> k) & 1u) slot_of[static_cast<std::size_t>(rep.mesh().faces()[f].v[k])] = slots++;
      for (int k = 0; k < 3; ++k)
        if ((r >> (3 + k)) & 1u) slot_of[static_cast<std::size_t>(num_vertices_ + rep.face_edges()[f].e[k])] = slots++;
    }
    face_first_.upload(first, stream);
    feature_slot_.upload(slot_of, stream);
    packed_faces_.resize_discard(2 * static_cast<std::size_t>(std::max<index_t>(num_faces_, 1)));
    packed_features_.resize_discard(2 * static_cast<std::size_t>(std::max(slots, 1u)));
  }

  /// The feature pairs of `n` candidate triangle pairs (device memory; adjacent ones are skipped)
  /// for the positions x0, x1 (device, one per vertex), and waits for them: the pairs stay on the
  /// device (vf(), ee()), their numbers are known on the host.
  template <class P>
  void run(const Vec3<P>* x0, const Vec3<P>* x1, const TrianglePair* candidates, std::size_t n, cudaStream_t stream = nullptr) {
    enqueue(x0, x1, candidates, n, stream);
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
    if (!collect(stream)) LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
  }

  /// As run() without waiting: the pairs go to buffers sized by earlier runs and their numbers stay
  /// on the device (vf_list(), ee_list() give them to the narrow phase); call collect() after
  /// `stream` has been synchronized. The candidates must stay valid until then. `with_orphans`
  /// false leaves the orphans out (a step split into parts lists them a range at a time, below).
  /// `boxes_current` true skips recomputing the feature boxes (they are those of an earlier
  /// enqueue with the same positions).
  template <class P>
  void enqueue(const Vec3<P>* x0, const Vec3<P>* x1, const TrianglePair* candidates, std::size_t n, cudaStream_t stream = nullptr,
               bool with_orphans = true, bool boxes_current = false) {
    enqueue(x0, x1, candidates, n, stream, with_orphans ? OrphanRange{0, num_orphans()} : OrphanRange{}, boxes_current);
  }

  /// A range of the orphans, numbered vertex-face first, then edge-edge: [first, first + count)
  /// of [0, num_orphans()).
  struct OrphanRange {
    std::size_t first = 0, count = 0;
  };
  std::size_t num_orphans() const { return orphan_vf_.size() + orphan_ee_.size(); }

  /// As enqueue() above with a range of the orphans (a step split into parts lists them a range
  /// at a time). Throws lwsccd::Error for a range past num_orphans().
  template <class P>
  void enqueue(const Vec3<P>* x0, const Vec3<P>* x1, const TrianglePair* candidates, std::size_t n, cudaStream_t stream,
               OrphanRange orphans, bool boxes_current) {
    enqueue(x0, x1, candidates, DeviceCount::known(n), stream, orphans, boxes_current);
  }

  /// As enqueue() above with the candidates' number on the device (e.g. TraversalOutput::
  /// result_count() after traverse_async(): no host round trip between the stages). The launches
  /// are sized for `count.room` candidates; those past the device's count do nothing.
  template <class P>
  void enqueue(const Vec3<P>* x0, const Vec3<P>* x1, const TrianglePair* candidates, DeviceCount count, cudaStream_t stream,
               OrphanRange orphans, bool boxes_current) {
    const std::size_t n = count.room;
    if (orphans.first > num_orphans() || orphans.count > num_orphans() - orphans.first)
      throw Error("gpu::FeatureEmitter::enqueue: orphan range [" + std::to_string(orphans.first) + ", " +
                  std::to_string(orphans.first + orphans.count) + ") is past the " + std::to_string(num_orphans()) +
                  " orphans");
    const EmissionView m = view();
    const bool test_motion = face_motion_test();
    if (test_motion && !corners_current_) boxes_current = false;  // (the test was off when the boxes were computed)
    if (!boxes_current) enqueue_boxes(x0, x1, stream);
    else if (!test_motion) corners_current_ = false;
    const detail::PackedBoxes packed = packed_boxes();
    candidates_ = candidates;
    candidate_count_ = count;
    // The range split at the boundary between the two orphan lists.
    const std::size_t vf_total = orphan_vf_.size(), end = orphans.first + orphans.count;
    orphan_vf_first_ = std::min(orphans.first, vf_total);
    num_orphan_vf_ = std::min(end, vf_total) - orphan_vf_first_;
    orphan_ee_first_ = std::max(orphans.first, vf_total) - vf_total;
    num_orphan_ee_ = std::max(end, vf_total) - vf_total - orphan_ee_first_;
    const std::size_t items = n + num_orphan_vf_ + num_orphan_ee_;
    blocks_ = (items + Policy::kBlock - 1) / Policy::kBlock;
    vf_.resize_discard(std::max<std::size_t>(vf_room_, 1));
    ee_.resize_discard(std::max<std::size_t>(ee_room_, 1));
    if (items == 0) {
      LWSCCD_CUDA_CHECK(cudaMemsetAsync(total_.data(), 0, sizeof(unsigned long long), stream));
    } else {
      masks_.resize_discard(items);
      block_totals_.resize_discard(blocks_);
      detail::emission_count_kernel<Policy::kBlock><<<static_cast<unsigned>(blocks_), Policy::kBlock, 0, stream>>>(
          m, packed, feature_slot_.data(), candidates, count, orphan_vf_.data() + orphan_vf_first_, num_orphan_vf_,
          orphan_ee_.data() + orphan_ee_first_, num_orphan_ee_, masks_.data(), block_totals_.data());
      LWSCCD_CUDA_CHECK_LAUNCH();
      std::size_t bytes = 0;
      LWSCCD_CUDA_CHECK(cub::DeviceScan::InclusiveSum(nullptr, bytes, block_totals_.data(), block_totals_.data(),
                                                      static_cast<std::int64_t>(blocks_), stream));
      scratch_.resize_discard(std::max<std::size_t>(bytes, 1));
      LWSCCD_CUDA_CHECK(cub::DeviceScan::InclusiveSum(scratch_.data(), bytes, block_totals_.data(), block_totals_.data(),
                                                      static_cast<std::int64_t>(blocks_), stream));
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(total_.data(), block_totals_.data() + blocks_ - 1, sizeof(unsigned long long),
                                        cudaMemcpyDeviceToDevice, stream));
      write(stream);
    }
    host_total_.ensure(1);
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(host_total_.data(), total_.data(), sizeof(unsigned long long), cudaMemcpyDeviceToHost, stream));
  }

  /// The feature boxes (and the faces' corners) of positions x0, x1, packed by face: what
  /// enqueue computes first. Enqueued on its own (e.g. on a second stream while the traversal
  /// runs: it reads the positions only), an enqueue on the same positions that passes
  /// `boxes_current` true then skips it; that enqueue's stream must wait for this one's work.
  template <class P>
  void enqueue_boxes(const Vec3<P>* x0, const Vec3<P>* x1, cudaStream_t stream = nullptr) {
    const bool test_motion = face_motion_test();
    if (test_motion)
      corners_.resize_discard(detail::PackedBoxes::kCornerWords * static_cast<std::size_t>(std::max<index_t>(num_faces_, 1)));
    corners_current_ = test_motion;
    if (num_faces_ == 0) return;
    detail::packed_boxes_kernel<<<static_cast<unsigned>((num_faces_ + Policy::kBlock - 1) / Policy::kBlock), Policy::kBlock, 0,
                                  stream>>>(view(), x0, x1, num_faces_, margin_, face_first_.data(), packed_boxes());
    LWSCCD_CUDA_CHECK_LAUNCH();
  }

  /// After `stream` (the last enqueue's) has been synchronized: reads the numbers of pairs. Returns
  /// false when a list outgrew its buffer: the buffer is grown and the pairs written again on
  /// `stream` (what read the short lists must run again); true when the lists were complete.
  bool collect(cudaStream_t stream = nullptr) {
    std::tie(num_vf_, num_ee_) = counted();
    if (num_vf_ <= vf_room_ && num_ee_ <= ee_room_) return true;
    // A quarter more room than needed, so that lists that grow a little do not repeat the writing.
    vf_room_ = std::max(vf_room_, num_vf_ + num_vf_ / 4);
    ee_room_ = std::max(ee_room_, num_ee_ + num_ee_ / 4);
    vf_.resize_discard(std::max<std::size_t>(vf_room_, 1));
    ee_.resize_discard(std::max<std::size_t>(ee_room_, 1));
    write(stream);
    return false;
  }

  /// After `stream` (the last enqueue's) has been synchronized: the numbers of vertex-face and
  /// edge-edge pairs that enqueue counted, whether or not they fitted (collect() not needed).
  std::pair<std::size_t, std::size_t> counted() const {
    const unsigned long long total = host_total_[0];
    return {static_cast<std::size_t>(total >> 32), static_cast<std::size_t>(total & 0xffffffffull)};
  }
  /// Bytes of the lists and the per-candidate scratch (what grows with a step's candidates).
  std::size_t list_bytes() const {
    return vf_.capacity_bytes() + ee_.capacity_bytes() + masks_.capacity_bytes() + block_totals_.capacity_bytes() +
           scratch_.capacity_bytes();
  }

  /// The lists for the narrow phase, their lengths read on the device (valid after enqueue()).
  PairList vf_list() const { return {vf_.data(), DeviceCount{total_.data(), DeviceCount::Part::high, vf_room_}}; }
  PairList ee_list() const { return {ee_.data(), DeviceCount{total_.data(), DeviceCount::Part::low, ee_room_}}; }


  /// Grows every feature box by `margin` from the next run on (as feature_boxes' margin).
  void set_box_margin(double margin) { margin_ = lwsccd::detail::checked_margin<Aabbf>(margin, "gpu::FeatureEmitter"); }

  /// Whether a candidate pair whose faces are apart by their relative motion (faces_apart) gives
  /// no pairs, from the next run on (default on; emit_feature_pairs with face_corners gives the
  /// same lists). A box margin (a minimum separation) turns the test off: it speaks of contact.
  void set_face_motion_test(bool on) { face_motion_ = on; }
  bool face_motion_test() const { return face_motion_ && !(margin_ > 0); }

  const Pair* vf() const { return vf_.data(); }
  const Pair* ee() const { return ee_.data(); }
  /// The numbers of pairs of the last collected run.
  std::size_t num_vf() const { return num_vf_; }
  std::size_t num_ee() const { return num_ee_; }

  /// The last run's pairs on the host, in emission order.
  FeaturePairs download(cudaStream_t stream = nullptr) const {
    FeaturePairs out;
    out.vf.resize(num_vf_);
    out.ee.resize(num_ee_);
    if (num_vf_) LWSCCD_CUDA_CHECK(cudaMemcpyAsync(out.vf.data(), vf_.data(), num_vf_ * sizeof(Pair), cudaMemcpyDeviceToHost, stream));
    if (num_ee_) LWSCCD_CUDA_CHECK(cudaMemcpyAsync(out.ee.data(), ee_.data(), num_ee_ * sizeof(Pair), cudaMemcpyDeviceToHost, stream));
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
    return out;
  }

  std::size_t device_bytes() const {
    return faces_.capacity_bytes() + edges_.capacity_bytes() + face_edges_.capacity_bytes() + represents_.capacity_bytes() +
           orphan_vf_.capacity_bytes() + orphan_ee_.capacity_bytes() + face_first_.capacity_bytes() + feature_slot_.capacity_bytes() +
           packed_faces_.capacity_bytes() + packed_features_.capacity_bytes() + corners_.capacity_bytes() + masks_.capacity_bytes() +
           block_totals_.capacity_bytes() + total_.capacity_bytes() +
           scratch_.capacity_bytes() + vf_.capacity_bytes() + ee_.capacity_bytes();
  }

 private:
  detail::PackedBoxes packed_boxes() {
    return {packed_faces_.data(), packed_features_.data(), face_motion_test() ? corners_.data() : nullptr};
  }

  // The writing pass of the last enqueue (the masks and the block totals are still there).
  void write(cudaStream_t stream) {
    const std::size_t items = candidate_count_.room + num_orphan_vf_ + num_orphan_ee_;
    if (items == 0) return;
    detail::emission_write_kernel<Policy::kBlock><<<static_cast<unsigned>(blocks_), Policy::kBlock, 0, stream>>>(
        view(), candidates_, candidate_count_, orphan_vf_.data() + orphan_vf_first_, num_orphan_vf_,
        orphan_ee_.data() + orphan_ee_first_, num_orphan_ee_, masks_.data(),
        block_totals_.data(), vf_.data(), vf_room_, ee_.data(), ee_room_);
    LWSCCD_CUDA_CHECK_LAUNCH();
  }

  EmissionView view() const {
    // (No per-id boxes on the device: the count pass reads the packed ones.)
    return {faces_.data(), face_edges_.data(), edges_.data(), represents_.data(), nullptr, num_vertices_, num_edges_};
  }

  index_t num_vertices_, num_edges_, num_faces_;
  DeviceBuffer<Face> faces_;
  DeviceBuffer<Edge> edges_;
  DeviceBuffer<FaceEdgeIds> face_edges_;
  DeviceBuffer<unsigned char> represents_, scratch_;
  DeviceBuffer<Pair> orphan_vf_, orphan_ee_, vf_, ee_;
  DeviceBuffer<unsigned> face_first_;             ///< per face: its first slot in packed_features_
  DeviceBuffer<unsigned> feature_slot_;           ///< per vertex and edge id: its slot (~0u: none)
  DeviceBuffer<float4> packed_faces_, packed_features_;  ///< detail::PackedBoxes, from the last run's positions
  DeviceBuffer<float4> corners_;                         ///< detail::PackedBoxes::corners (while the test is on)
  bool face_motion_ = true, corners_current_ = false;
  DeviceBuffer<unsigned short> masks_;          ///< per item: its emission mask
  DeviceBuffer<unsigned long long> block_totals_;  ///< per block: packed counts, then their inclusive scan
  DeviceBuffer<unsigned long long> total_{1};     ///< the last run's packed totals (read by the narrow phase)
  PinnedBuffer<unsigned long long> host_total_;  // allocated on first use
  const TrianglePair* candidates_ = nullptr;
  DeviceCount candidate_count_;  ///< the last enqueue's (room: the bound its launches were sized for)
  std::size_t blocks_ = 0;
  std::size_t num_orphan_vf_ = 0, num_orphan_ee_ = 0;      ///< orphans the last enqueue listed
  std::size_t orphan_vf_first_ = 0, orphan_ee_first_ = 0;  ///< and where they start in each list
  std::size_t vf_room_ = 0, ee_room_ = 0;         ///< room of vf_, ee_ (grown by collect())
  std::size_t num_vf_ = 0, num_ee_ = 0;
  float margin_ = 0;
};

}  // namespace lwsccd::gpu
