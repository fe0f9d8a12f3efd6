// lwsccd — feature pairs produced once on the GPU: representative triangles and feature-box
// culling (representative.hpp says what and why), with no sort.
//
// Three kernels and one small scan: the swept box of every feature; a count pass that runs the
// shared emission test (emission_mask, orphan_kept) over every candidate triangle pair and every
// orphan, stores each item's mask and sums each block's counts (vertex-face and edge-edge packed in
// one 64-bit word, so one scan gives both offsets); an inclusive scan of the block totals; a write
// pass that ranks the items within their block and decodes each mask at its offset. The output has exactly the size
// it needs and the order of the items (candidates, then vertex-face orphans, then edge-edge
// orphans), the order cpu emit_feature_pairs gives for the same candidate list.
#pragma once

#include <cub/block/block_reduce.cuh>
#include <cub/block/block_scan.cuh>
#include <cub/device/device_scan.cuh>

#include <utility>

#include "lwsccd/cuda_check.cuh"
#include "lwsccd/device_buffer.cuh"
#include "lwsccd/representative.hpp"

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

template <class P>
__global__ void feature_boxes_kernel(EmissionView m, const Vec3<P>* x0, const Vec3<P>* x1, index_t n, float margin,
                                     Aabbf* boxes) {
  const index_t id = static_cast<index_t>(blockIdx.x * blockDim.x + threadIdx.x);
  if (id >= n) return;
  boxes[id] = feature_box(m.faces, m.edges, m.num_vertices, m.num_edges, x0, x1, id, margin);
}

// Item i: candidate triangle pair i (i < n), then vertex-face orphan i - n, then edge-edge orphan.
// Its emission mask: emission_mask for a candidate; bit 0 (vertex-face) or bit 6 (edge-edge) for a
// kept orphan.
template <class Pair>
__device__ unsigned item_mask(const EmissionView& m, const TrianglePair* candidates, std::size_t n, const Pair* orphan_vf,
                              std::size_t num_orphan_vf, const Pair* orphan_ee, std::size_t i) {
  if (i < n) {
    const TrianglePair p = candidates[i];
    return p.adjacent ? 0u : emission_mask(m, p.a, p.b);
  }
  if (i < n + num_orphan_vf) {
    const Pair q = orphan_vf[i - n];
    return orphan_kept(m, q.first, q.second) ? 1u : 0u;
  }
  const Pair q = orphan_ee[i - n - num_orphan_vf];
  return orphan_kept(m, q.first, q.second) ? 1u << 6 : 0u;
}

__device__ inline unsigned long long mask_counts(unsigned mask) {
  return pack_counts(static_cast<unsigned>(__popc(mask & kEmissionVfBits)), static_cast<unsigned>(__popc(mask & kEmissionEeBits)));
}

// Counting pass: every item's mask, and each block's packed totals (the write pass scans within
// the block again, so only block totals need a device-wide scan).
template <int kBlock, class Pair>
__global__ void __launch_bounds__(kBlock)
    emission_count_kernel(EmissionView m, const TrianglePair* candidates, std::size_t n, const Pair* orphan_vf,
                          std::size_t num_orphan_vf, const Pair* orphan_ee, std::size_t items, unsigned short* masks,
                          unsigned long long* block_totals) {
  using Reduce = cub::BlockReduce<unsigned long long, kBlock>;
  __shared__ typename Reduce::TempStorage storage;
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * kBlock + threadIdx.x;
  unsigned mask = 0;
  if (i < items) {
    mask = item_mask(m, candidates, n, orphan_vf, num_orphan_vf, orphan_ee, i);
    masks[i] = static_cast<unsigned short>(mask);
  }
  const unsigned long long total = Reduce(storage).Sum(mask_counts(mask));
  if (threadIdx.x == 0) block_totals[blockIdx.x] = total;
}

// Writing pass: each item's offset = its block's (scanned totals) + its rank in the block; the
// pairs are decoded from the mask (no box is read again).
template <int kBlock, class Pair>
__global__ void __launch_bounds__(kBlock)
    emission_write_kernel(EmissionView m, const TrianglePair* candidates, std::size_t n, const Pair* orphan_vf,
                          std::size_t num_orphan_vf, const Pair* orphan_ee, std::size_t items, const unsigned short* masks,
                          const unsigned long long* block_inclusive, Pair* vf_out, Pair* ee_out) {
  using Scan = cub::BlockScan<unsigned long long, kBlock>;
  __shared__ typename Scan::TempStorage storage;
  const std::size_t i = static_cast<std::size_t>(blockIdx.x) * kBlock + threadIdx.x;
  const unsigned mask = i < items ? masks[i] : 0u;
  unsigned long long offset = 0;
  Scan(storage).ExclusiveSum(mask_counts(mask), offset);
  if (mask == 0) return;
  offset += blockIdx.x ? block_inclusive[blockIdx.x - 1] : 0ull;
  unsigned long long vf = offset >> 32, ee = offset & 0xffffffffull;
  // (std::pair's assignment is host-only before C++20: the fields are written one by one.)
  auto put = [](Pair* out, unsigned long long& at, index_t x, index_t y) {
    out[at].first = x;
    out[at++].second = y;
  };
  if (i < n) {
    const TrianglePair p = candidates[i];
    decode_emission(
        m, p.a, p.b, mask, [&](index_t x, index_t y) { put(vf_out, vf, x, y); }, [&](index_t x, index_t y) { put(ee_out, ee, x, y); });
  } else if (i < n + num_orphan_vf) {
    const Pair q = orphan_vf[i - n];
    put(vf_out, vf, q.first, q.second);
  } else {
    const Pair q = orphan_ee[i - n - num_orphan_vf];
    put(ee_out, ee, q.first, q.second);
  }
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
    boxes_.resize_discard(static_cast<std::size_t>(num_vertices_ + num_edges_ + num_faces_));
  }

  /// The feature pairs of `n` candidate triangle pairs (device memory; adjacent ones are skipped)
  /// for the positions x0, x1 (device, one per vertex). Synchronizes `stream` once, to size the
  /// outputs; the pairs stay on the device (vf(), ee()).
  template <class P>
  void run(const Vec3<P>* x0, const Vec3<P>* x1, const TrianglePair* candidates, std::size_t n, cudaStream_t stream = nullptr) {
    const index_t features = num_vertices_ + num_edges_ + num_faces_;
    const EmissionView m = view();
    detail::feature_boxes_kernel<<<static_cast<unsigned>((features + Policy::kBlock - 1) / Policy::kBlock), Policy::kBlock, 0,
                                   stream>>>(m, x0, x1, features, margin_, boxes_.data());
    LWSCCD_CUDA_CHECK_LAUNCH();
    const std::size_t items = n + orphan_vf_.size() + orphan_ee_.size();
    num_vf_ = num_ee_ = 0;
    if (items == 0) return;
    const std::size_t blocks = (items + Policy::kBlock - 1) / Policy::kBlock;
    masks_.resize_discard(items);
    block_totals_.resize_discard(blocks);
    detail::emission_count_kernel<Policy::kBlock><<<static_cast<unsigned>(blocks), Policy::kBlock, 0, stream>>>(
        m, candidates, n, orphan_vf_.data(), orphan_vf_.size(), orphan_ee_.data(), items, masks_.data(), block_totals_.data());
    LWSCCD_CUDA_CHECK_LAUNCH();
    std::size_t bytes = 0;
    LWSCCD_CUDA_CHECK(cub::DeviceScan::InclusiveSum(nullptr, bytes, block_totals_.data(), block_totals_.data(),
                                                    static_cast<std::int64_t>(blocks), stream));
    scratch_.resize_discard(std::max<std::size_t>(bytes, 1));
    LWSCCD_CUDA_CHECK(cub::DeviceScan::InclusiveSum(scratch_.data(), bytes, block_totals_.data(), block_totals_.data(),
                                                    static_cast<std::int64_t>(blocks), stream));
    unsigned long long total = 0;
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(&total, block_totals_.data() + blocks - 1, sizeof total, cudaMemcpyDeviceToHost, stream));
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
    num_vf_ = static_cast<std::size_t>(total >> 32);
    num_ee_ = static_cast<std::size_t>(total & 0xffffffffull);
    vf_.resize_discard(std::max<std::size_t>(num_vf_, 1));
    ee_.resize_discard(std::max<std::size_t>(num_ee_, 1));
    detail::emission_write_kernel<Policy::kBlock><<<static_cast<unsigned>(blocks), Policy::kBlock, 0, stream>>>(
        m, candidates, n, orphan_vf_.data(), orphan_vf_.size(), orphan_ee_.data(), items, masks_.data(), block_totals_.data(),
        vf_.data(), ee_.data());
    LWSCCD_CUDA_CHECK_LAUNCH();
  }

  /// Grows every feature box by `margin` from the next run on (as feature_boxes' margin).
  void set_box_margin(double margin) { margin_ = lwsccd::detail::checked_margin<Aabbf>(margin, "gpu::FeatureEmitter"); }

  const Pair* vf() const { return vf_.data(); }
  const Pair* ee() const { return ee_.data(); }
  std::size_t num_vf() const { return num_vf_; }
  std::size_t num_ee() const { return num_ee_; }
  /// The swept box of every feature id, from the last run.
  const Aabbf* boxes() const { return boxes_.data(); }

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
           orphan_vf_.capacity_bytes() + orphan_ee_.capacity_bytes() + boxes_.capacity_bytes() + masks_.capacity_bytes() +
           block_totals_.capacity_bytes() +
           scratch_.capacity_bytes() + vf_.capacity_bytes() + ee_.capacity_bytes();
  }

 private:
  EmissionView view() const {
    return {faces_.data(), face_edges_.data(), edges_.data(), represents_.data(), boxes_.data(), num_vertices_, num_edges_};
  }

  index_t num_vertices_, num_edges_, num_faces_;
  DeviceBuffer<Face> faces_;
  DeviceBuffer<Edge> edges_;
  DeviceBuffer<FaceEdgeIds> face_edges_;
  DeviceBuffer<unsigned char> represents_, scratch_;
  DeviceBuffer<Pair> orphan_vf_, orphan_ee_, vf_, ee_;
  DeviceBuffer<Aabbf> boxes_;
  DeviceBuffer<unsigned short> masks_;          ///< per item: its emission mask
  DeviceBuffer<unsigned long long> block_totals_;  ///< per block: packed counts, then their inclusive scan
  std::size_t num_vf_ = 0, num_ee_ = 0;
  float margin_ = 0;
};

}  // namespace lwsccd::gpu
