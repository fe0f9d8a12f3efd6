// lwsccd — kernels and definitions for bvh.cuh.
#pragma once

#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_reduce.cuh>
#include <cuda/atomic>
#include <thrust/iterator/counting_iterator.h>
#include <thrust/iterator/transform_iterator.h>

#include <algorithm>
#include <cassert>

#include "lwsccd/bvh/bvh.cuh"
#include "lwsccd/bvh/detail/lbvh.hpp"
#include "lwsccd/core/error.hpp"
#include "lwsccd/geometry/morton.hpp"

namespace lwsccd::gpu {

namespace detail {

constexpr int kBvhBlock = 256;
// The refit's block: 512 leaves, whose nodes within count their arrivals in shared memory (more of
// the climb's levels than at 256; bottom_up_kernel).
constexpr int kRefitBlock = 512;

inline unsigned blocks_for(index_t n) { return static_cast<unsigned>((n + kBvhBlock - 1) / kBvhBlock); }

inline std::size_t align_up(std::size_t bytes) { return (bytes + 255) / 256 * 256; }

template <class P>
__global__ void swept_centers_kernel(const Face* faces, index_t n, const Vec3<P>* x0, const Vec3<P>* x1, Vec3<P>* centers,
                                     int* status) {
  const index_t i = static_cast<index_t>(blockIdx.x * blockDim.x + threadIdx.x);
  if (i >= n) return;
  const Face f = faces[i];
  bool finite = true;
  for (int k = 0; k < 3; ++k) finite = finite && is_finite(x0[f.v[k]]) && is_finite(x1[f.v[k]]);
  if (!finite) status[0] = 1;  // benign race: every writer writes 1
  centers[i] = lwsccd::detail::leaf_center(f, x0, x1);
}

template <class P>
struct PointBox {
  LWSCCD_HD Aabb<P> operator()(const Vec3<P>& p) const { return {p, p}; }
};

template <class P>
struct MergeBoxes {
  LWSCCD_HD Aabb<P> operator()(const Aabb<P>& a, const Aabb<P>& b) const {
    Aabb<P> r = a;
    r.expand(b);
    return r;
  }
};

template <class P>
__global__ void morton_kernel(const Vec3<P>* centers, index_t n, const Aabb<P>* scene, std::uint64_t* codes, index_t* ids) {
  const index_t i = static_cast<index_t>(blockIdx.x * blockDim.x + threadIdx.x);
  if (i >= n) return;
  codes[i] = morton63(centers[i], *scene);
  ids[i] = i;
}

template <class Index>  // a template so that the header defines it in every translation unit
__global__ void radix_tree_kernel(const std::uint64_t* codes, Index n, Index* left, Index* right, Index* parent,
                                  LeafRange* ranges) {
  const Index i = static_cast<Index>(blockIdx.x * blockDim.x + threadIdx.x);
  if (i >= 2 * n - 1) return;
  if (i == 0) parent[0] = -1;
  if (i >= n - 1) {
    ranges[i] = {i - (n - 1), i - (n - 1)};
    return;
  }
  const lwsccd::detail::RadixNode node = lwsccd::detail::radix_tree_node(codes, n, i);
  left[i] = node.left;
  right[i] = node.right;
  ranges[i] = {node.first, node.last};
  parent[node.left] = i;
  parent[node.right] = i;
}

// One thread per leaf: fits the leaf, then climbs; the second child to arrive at a node fits it.
// The acq_rel arrival counter orders the first child's BV store before the second's loads. A node
// whose leaves are all the block's (its leaf range within the block's; a radix tree's internal node
// i has i at one end of its range, so i lies in the block's range too) counts its arrivals in
// shared memory at block scope; the others count in `arrivals` at device scope, where the second
// arriver resets the counter, so the counters are all zero again when the kernel ends and a refit
// needs no memset. The climb keeps its own child's BV in registers and loads only the sibling's,
// and each level's links and range (never written by a refit) are loaded before its arrival.
// Why: the climb is a chain of dependent memory round trips, ~30-40 levels deep on cloth-ball, and
// a device-scope arrival with its release costs several of them; in shared memory, about one.
// Positions stored as Q are converted to P as they are loaded (float to double exactly: the same
// leaves as from widened arrays).
template <class BV, class P, class Q, int kBlock>
__global__ void __launch_bounds__(kBlock)
    bottom_up_kernel(const Face* faces, const index_t* leaf_primitive, index_t n, const Vec3<Q>* x0, const Vec3<Q>* x1,
                     const index_t* left, const index_t* right, const index_t* parent, const LeafRange* ranges, BV* bvs,
                     int* arrivals, int* status, typename bv_traits<BV>::scalar_type margin) {
  __shared__ int block_arrivals[kBlock];
  block_arrivals[threadIdx.x] = 0;
  __syncthreads();
  const index_t block_first = static_cast<index_t>(blockIdx.x) * kBlock;
  const index_t block_last = block_first + kBlock - 1;
  const index_t k = block_first + static_cast<index_t>(threadIdx.x);
  if (k >= n) return;
  const Face f = faces[leaf_primitive[k]];
  const Vec3<P> pts[6] = {x0[f.v[0]].template cast<P>(), x0[f.v[1]].template cast<P>(), x0[f.v[2]].template cast<P>(),
                          x1[f.v[0]].template cast<P>(), x1[f.v[1]].template cast<P>(), x1[f.v[2]].template cast<P>()};
  BV bv;
  Vec3<P> center;
  lwsccd::detail::leaf_volume_of_points(pts, bv, center, margin);
  // Each vertex checked, not the box: the box's min and max pass over a NaN coordinate.
  bool finite = is_finite(center);
  for (int v = 0; v < 6; ++v) finite = finite && is_finite(pts[v]);
  if (!finite) status[0] = 1;  // benign race: every writer writes 1
  index_t node = n - 1 + k;
  bvs[node] = bv;
  for (index_t p = parent[node]; p != -1;) {
    const index_t l = left[p], r = right[p], next = parent[p];
    const LeafRange range = ranges[p];
    if (range.first >= block_first && range.last <= block_last) {
      assert((p == range.first || p == range.last) && "bottom_up_kernel: an internal node at neither end of its leaf range");
      cuda::atomic_ref<int, cuda::thread_scope_block> arrived(block_arrivals[p - block_first]);
      if (arrived.fetch_add(1, cuda::memory_order_acq_rel) == 0) return;
    } else {
      cuda::atomic_ref<int, cuda::thread_scope_device> arrived(arrivals[p]);
      if (arrived.fetch_add(1, cuda::memory_order_acq_rel) == 0) return;
      arrived.store(0, cuda::memory_order_relaxed);  // both children are done with this node
    }
    // Always merge(left, right): the same operation order as the CPU backend.
    bv = l == node ? bv_traits<BV>::merge(bv, bvs[r]) : bv_traits<BV>::merge(bvs[l], bv);
    bvs[p] = bv;
    node = p;
    p = next;
  }
}

template <class BV>
struct InternalSurfaceArea {
  const BV* bvs;
  LWSCCD_HD double operator()(index_t i) const { return static_cast<double>(bv_traits<BV>::surface_area(bvs[i])); }
};

}  // namespace detail

namespace detail {

// Points converted from Q to P (widened exactly, or rounded to nearest as the host's cast does).
template <class Q, class P>
__global__ void convert_points_kernel(const Vec3<Q>* in, Vec3<P>* out, std::size_t n) {
  for (std::size_t i = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x; i < n;
       i += static_cast<std::size_t>(gridDim.x) * blockDim.x)
    out[i] = in[i].template cast<P>();
}

template <class Q, class P>
void convert_points(const Vec3<Q>* in, Vec3<P>* out, std::size_t n, cudaStream_t stream) {
  if (n == 0) return;
  const unsigned blocks = static_cast<unsigned>(std::min<std::size_t>((n + 255) / 256, 4096));
  convert_points_kernel<Q, P><<<blocks, 256, 0, stream>>>(in, out, n);
  LWSCCD_CUDA_CHECK_LAUNCH();
}

template <class Q>
constexpr void require_position_type() {
  static_assert(std::is_same<Q, float>::value || std::is_same<Q, double>::value,
                "lwsccd: positions are given as float or double points (Vec3f, Vec3d)");
}

// Throws InputError (naming `where`) unless d0 and d1 point to device or managed memory.
inline void require_device_pointers(const void* d0, const void* d1, const char* where) {
  for (const void* d : {d0, d1}) {
    const char* name = d == d0 ? "x0" : "x1";
    cudaPointerAttributes attributes{};
    LWSCCD_CUDA_CHECK(cudaPointerGetAttributes(&attributes, d));
    if (d == nullptr || (attributes.type != cudaMemoryTypeDevice && attributes.type != cudaMemoryTypeManaged))
      throw InputError(where, name, "is not a pointer to device memory");
  }
}

}  // namespace detail

template <class P>
template <class Q>
DeviceStep<P>::DeviceStep(const TriangleMesh& mesh, const std::vector<Vec3<Q>>& h0, const std::vector<Vec3<Q>>& h1,
                          cudaStream_t stream)
    : num_vertices(mesh.num_vertices()) {
  faces.upload(mesh.faces(), stream);
  set_positions(h0, h1, stream);
}

template <class P>
DeviceStep<P>::DeviceStep(const TriangleMesh& mesh, cudaStream_t stream) : num_vertices(mesh.num_vertices()) {
  faces.upload(mesh.faces(), stream);
  x0.resize_discard(static_cast<std::size_t>(num_vertices));
  x1.resize_discard(static_cast<std::size_t>(num_vertices));
}

template <class P>
void DeviceStep<P>::use_device_positions(const Vec3<P>* d0, const Vec3<P>* d1) {
  detail::require_device_pointers(d0, d1, "gpu::DeviceStep::use_device_positions");
  float_source_[0] = float_source_[1] = nullptr;
  in_place_[0] = d0;
  in_place_[1] = d1;
}

template <class P>
void DeviceStep<P>::widen_later(const Vec3<float>* d0, const Vec3<float>* d1) {
  static_assert(std::is_same<P, double>::value, "lwsccd: gpu::DeviceStep::widen_later widens float positions to double");
  detail::require_device_pointers(d0, d1, "gpu::DeviceStep::widen_later");
  in_place_[0] = in_place_[1] = nullptr;
  const auto n = static_cast<std::size_t>(num_vertices);
  x0.resize_discard(n);
  x1.resize_discard(n);
  float_source_[0] = d0;
  float_source_[1] = d1;
}

template <class P>
void DeviceStep<P>::require_sizes(std::size_t n0, std::size_t n1) const {
  for (int k = 0; k < 2; ++k) {
    const std::size_t n = k == 0 ? n0 : n1;
    if (n != static_cast<std::size_t>(num_vertices))
      throw InputError("gpu::DeviceStep", k == 0 ? "x0" : "x1",
                       "has " + std::to_string(n) + " positions, the mesh has " + std::to_string(num_vertices) + " vertices");
  }
}

template <class P>
void DeviceStep<P>::upload_to_widen_later(Span<const Vec3<float>> h0, Span<const Vec3<float>> h1, cudaStream_t stream) {
  static_assert(std::is_same<P, double>::value, "lwsccd: gpu::DeviceStep::upload_to_widen_later widens float positions to double");
  require_sizes(h0.size(), h1.size());
  // Both arrays in one buffer: the second upload need not wait for a conversion of the first.
  const auto n = static_cast<std::size_t>(num_vertices);
  wide_.resize_discard(2 * n);
  HostStaging<>::to_device(wide_.data(), h0.data(), n * sizeof(Vec3<float>), stream);
  HostStaging<>::to_device(wide_.data() + n, h1.data(), n * sizeof(Vec3<float>), stream);
  widen_later(wide_.data(), wide_.data() + n);
}

template <class P>
void DeviceStep<P>::enqueue_widening(cudaStream_t stream) {
  if (!widening_due()) return;
  const auto n = static_cast<std::size_t>(num_vertices);
  detail::convert_points(float_source_[0], x0.data(), n, stream);
  detail::convert_points(float_source_[1], x1.data(), n, stream);
  float_source_[0] = float_source_[1] = nullptr;
}

template <class P>
template <class Q>
void DeviceStep<P>::set_positions_from_device(const Vec3<Q>* d0, const Vec3<Q>* d1, cudaStream_t stream) {
  detail::require_position_type<Q>();
  detail::require_device_pointers(d0, d1, "gpu::DeviceStep::set_positions_from_device");
  in_place_[0] = in_place_[1] = nullptr;
  float_source_[0] = float_source_[1] = nullptr;
  const auto n = static_cast<std::size_t>(num_vertices);
  x0.resize_discard(n);
  x1.resize_discard(n);
  if constexpr (std::is_same<P, Q>::value) {
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(x0.data(), d0, n * sizeof(Vec3<P>), cudaMemcpyDeviceToDevice, stream));
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(x1.data(), d1, n * sizeof(Vec3<P>), cudaMemcpyDeviceToDevice, stream));
  } else {
    detail::convert_points(d0, x0.data(), n, stream);
    detail::convert_points(d1, x1.data(), n, stream);
  }
}

template <class P>
template <class Q>
void DeviceStep<P>::set_positions(Span<const Vec3<Q>> h0, Span<const Vec3<Q>> h1, cudaStream_t stream) {
  detail::require_position_type<Q>();
  require_sizes(h0.size(), h1.size());
  in_place_[0] = in_place_[1] = nullptr;
  float_source_[0] = float_source_[1] = nullptr;
  const auto n = static_cast<std::size_t>(num_vertices);
  if constexpr (std::is_same<P, Q>::value) {
    // Small arrays go as they are (the driver takes pageable memory at once); large ones through
    // page-locked chunks, copied there on several threads (HostStaging).
    x0.resize_discard(n);
    x1.resize_discard(n);
    HostStaging<>::to_device(x0.data(), h0.data(), n * sizeof(Vec3<P>), stream);
    HostStaging<>::to_device(x1.data(), h1.data(), n * sizeof(Vec3<P>), stream);
  } else if constexpr (std::is_same<P, double>::value) {
    // Float input: half the bytes cross, widened on the device (exact), here and now.
    upload_to_widen_later(h0, h1, stream);
    enqueue_widening(stream);
  } else {
    // Staged through a host array of P; the copy must finish before the staging is reused.
    for (int which = 0; which < 2; ++which) {
      const Span<const Vec3<Q>>& h = which == 0 ? h0 : h1;
      staging_.resize(h.size());
      for (std::size_t v = 0; v < h.size(); ++v) staging_[v] = h[v].template cast<P>();
      (which == 0 ? x0 : x1).upload(staging_, stream);
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
    }
  }
}

template <class BV>
template <class P>
void Bvh<BV>::build(const DeviceStep<P>& step, cudaStream_t stream) {
  const auto n = static_cast<index_t>(step.faces.size());
  if (n == 0) throw InputError("gpu::Bvh::build", "", "mesh has no faces");
  num_leaves_ = n;
  const std::size_t nodes = static_cast<std::size_t>(2 * n - 1);
  const std::size_t internal = static_cast<std::size_t>(std::max<index_t>(n - 1, 1));
  bvs_.resize_discard(nodes);
  left_.resize_discard(internal);
  right_.resize_discard(internal);
  parent_.resize_discard(nodes);
  ranges_.resize_discard(nodes);
  leaf_primitive_.resize_discard(static_cast<std::size_t>(n));
  primitive_scratch_.resize_discard(static_cast<std::size_t>(n));
  codes_.resize_discard(static_cast<std::size_t>(n));
  codes_sorted_.resize_discard(static_cast<std::size_t>(n));
  arrivals_.resize_discard(internal);
  status_.resize_discard(1);
  cost_.resize_discard(1);

  // Scratch: centres | scene box | CUB temporary storage (the largest of the three passes).
  const auto point_boxes = thrust::make_transform_iterator(static_cast<const Vec3<P>*>(nullptr), detail::PointBox<P>{});
  std::size_t reduce_bytes = 0, sort_bytes = 0, sum_bytes = 0;
  LWSCCD_CUDA_CHECK(cub::DeviceReduce::Reduce(nullptr, reduce_bytes, point_boxes, static_cast<Aabb<P>*>(nullptr), n,
                                              detail::MergeBoxes<P>{}, Aabb<P>::empty(), stream));
  LWSCCD_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, sort_bytes, codes_.data(), codes_sorted_.data(),
                                                    primitive_scratch_.data(), leaf_primitive_.data(), n, 0, 63, stream));
  const auto areas = thrust::make_transform_iterator(thrust::counting_iterator<index_t>(0),
                                                     detail::InternalSurfaceArea<BV>{bvs_.data()});
  LWSCCD_CUDA_CHECK(cub::DeviceReduce::Sum(nullptr, sum_bytes, areas, cost_.data(), n, stream));
  const std::size_t centers_bytes = detail::align_up(sizeof(Vec3<P>) * static_cast<std::size_t>(n));
  const std::size_t scene_bytes = detail::align_up(sizeof(Aabb<P>));
  const std::size_t temp_bytes = std::max({reduce_bytes, sort_bytes, sum_bytes, std::size_t(1)});
  scratch_.resize_discard(centers_bytes + scene_bytes + temp_bytes);
  auto* centers = reinterpret_cast<Vec3<P>*>(scratch_.data());
  auto* scene = reinterpret_cast<Aabb<P>*>(scratch_.data() + centers_bytes);
  temp_offset_ = centers_bytes + scene_bytes;
  void* temp = scratch_.data() + temp_offset_;

  LWSCCD_CUDA_CHECK(cudaMemsetAsync(status_.data(), 0, sizeof(int), stream));
  detail::swept_centers_kernel<<<detail::blocks_for(n), detail::kBvhBlock, 0, stream>>>(
      step.faces.data(), n, step.x0_data(), step.x1_data(), centers, status_.data());
  LWSCCD_CUDA_CHECK_LAUNCH();
  std::size_t bytes = temp_bytes;
  LWSCCD_CUDA_CHECK(cub::DeviceReduce::Reduce(temp, bytes, thrust::make_transform_iterator(
                                                                  static_cast<const Vec3<P>*>(centers), detail::PointBox<P>{}),
                                              scene, n, detail::MergeBoxes<P>{}, Aabb<P>::empty(), stream));
  detail::morton_kernel<<<detail::blocks_for(n), detail::kBvhBlock, 0, stream>>>(centers, n, scene, codes_.data(),
                                                                                  primitive_scratch_.data());
  LWSCCD_CUDA_CHECK_LAUNCH();
  bytes = temp_bytes;
  // Stable LSD radix sort: equal codes keep triangle order, as on the CPU backend.
  LWSCCD_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(temp, bytes, codes_.data(), codes_sorted_.data(),
                                                    primitive_scratch_.data(), leaf_primitive_.data(), n, 0, 63, stream));
  detail::radix_tree_kernel<<<detail::blocks_for(2 * n - 1), detail::kBvhBlock, 0, stream>>>(
      codes_sorted_.data(), n, left_.data(), right_.data(), parent_.data(), ranges_.data());
  LWSCCD_CUDA_CHECK_LAUNCH();
  // Zero once here; each bottom-up pass leaves the counters at zero again.
  LWSCCD_CUDA_CHECK(cudaMemsetAsync(arrivals_.data(), 0, sizeof(int) * internal, stream));
  refit(step, stream);
  LWSCCD_CUDA_CHECK(cudaMemcpyAsync(&readback().status, status_.data(), sizeof(int), cudaMemcpyDeviceToHost, stream));
  enqueue_cost(stream);
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
  throw_if_flagged(readback().status, stream);
  cost_at_build_ = cost_from_readback();
  ++generation_;
}

template <class BV>
template <class P>
void Bvh<BV>::refit(const DeviceStep<P>& step, cudaStream_t stream) {
  if (num_leaves_ == 0) throw Error("gpu::Bvh::refit: the BVH has not been built");
  if (static_cast<index_t>(step.faces.size()) != num_leaves_)
    throw InputError("gpu::Bvh::refit", "", "the step has " + std::to_string(step.faces.size()) +
                                                " faces, the BVH was built over " + std::to_string(num_leaves_));
  const index_t n = num_leaves_;
  constexpr int kBlock = detail::kRefitBlock;
  const auto blocks = static_cast<unsigned>((n + kBlock - 1) / kBlock);
  if constexpr (std::is_same<P, double>::value) {
    if (step.widening_due()) {  // float positions read where they are (DeviceStep::widen_later)
      detail::bottom_up_kernel<BV, P, float, kBlock><<<blocks, kBlock, 0, stream>>>(
          step.faces.data(), leaf_primitive_.data(), n, step.float_source(0), step.float_source(1), left_.data(),
          right_.data(), parent_.data(), ranges_.data(), bvs_.data(), arrivals_.data(), status_.data(), leaf_margin_);
      LWSCCD_CUDA_CHECK_LAUNCH();
      return;
    }
  }
  detail::bottom_up_kernel<BV, P, P, kBlock><<<blocks, kBlock, 0, stream>>>(
      step.faces.data(), leaf_primitive_.data(), n, step.x0_data(), step.x1_data(), left_.data(), right_.data(),
      parent_.data(), ranges_.data(), bvs_.data(), arrivals_.data(), status_.data(), leaf_margin_);
  LWSCCD_CUDA_CHECK_LAUNCH();
}

template <class BV>
template <class P>
bool Bvh<BV>::refit_or_rebuild(const DeviceStep<P>& step, const RebuildPolicy& policy, cudaStream_t stream) {
  // One synchronisation for both reads (status flag, then the cost), into pinned memory.
  refit_enqueue(step, stream);
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
  if (!collect_refit(policy, stream)) return false;
  build(step, stream);
  return true;
}

template <class BV>
template <class P>
void Bvh<BV>::refit_enqueue(const DeviceStep<P>& step, cudaStream_t stream) {
  refit(step, stream);
  enqueue_refit_reads(stream);
}

template <class BV>
void Bvh<BV>::enqueue_refit_reads(cudaStream_t stream) {
  LWSCCD_CUDA_CHECK(cudaMemcpyAsync(&readback().status, status_.data(), sizeof(int), cudaMemcpyDeviceToHost, stream));
  enqueue_cost(stream);
}

template <class BV>
bool Bvh<BV>::collect_refit(const RebuildPolicy& policy, cudaStream_t stream) {
  throw_if_flagged(readback().status, stream);
  return policy.should_rebuild(cost_from_readback(), cost_at_build_);
}

template <class BV>
void Bvh<BV>::enqueue_cost(cudaStream_t stream) const {
  readback().cost = 0;
  if (num_leaves_ < 2) return;
  const auto areas = thrust::make_transform_iterator(thrust::counting_iterator<index_t>(0),
                                                     detail::InternalSurfaceArea<BV>{bvs_.data()});
  std::size_t bytes = 0;
  LWSCCD_CUDA_CHECK(cub::DeviceReduce::Sum(nullptr, bytes, areas, cost_.data(), num_leaves_ - 1, stream));
  // The scratch's temporary part was sized for this pass at build time.
  LWSCCD_CUDA_CHECK(cub::DeviceReduce::Sum(const_cast<unsigned char*>(scratch_.data()) + temp_offset_, bytes, areas,
                                           cost_.data(), num_leaves_ - 1, stream));
  LWSCCD_CUDA_CHECK(cudaMemcpyAsync(&readback().cost, cost_.data(), sizeof(double), cudaMemcpyDeviceToHost, stream));
  LWSCCD_CUDA_CHECK(cudaMemcpyAsync(&readback().root, bvs_.data(), sizeof(BV), cudaMemcpyDeviceToHost, stream));
}

template <class BV>
double Bvh<BV>::cost_from_readback() const {
  if (num_leaves_ < 2) return 0.0;
  const double root_area = static_cast<double>(bv_traits<BV>::surface_area(readback().root));
  return root_area > 0 ? readback().cost / root_area : 0.0;
}

template <class BV>
double Bvh<BV>::sah_cost(cudaStream_t stream) const {
  enqueue_cost(stream);
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
  return cost_from_readback();
}

template <class BV>
void Bvh<BV>::throw_if_flagged(int flag, cudaStream_t stream) {
  if (flag) {
    LWSCCD_CUDA_CHECK(cudaMemsetAsync(status_.data(), 0, sizeof(int), stream));
    throw InputError("gpu::Bvh", "positions", "a vertex coordinate is NaN or infinite");
  }
}

template <class BV>
void Bvh<BV>::check_status(cudaStream_t stream) {
  LWSCCD_CUDA_CHECK(cudaMemcpyAsync(&readback().status, status_.data(), sizeof(int), cudaMemcpyDeviceToHost, stream));
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
  throw_if_flagged(readback().status, stream);
}

template <class BV>
BvhNodes<BV> Bvh<BV>::download(cudaStream_t stream) const {
  BvhNodes<BV> t;
  t.num_leaves = num_leaves_;
  t.bvs = bvs_.download(stream);
  if (num_leaves_ > 1) {  // a one-leaf tree has no internal nodes (the arrays hold a placeholder)
    t.left = left_.download(stream);
    t.right = right_.download(stream);
  }
  t.parent = parent_.download(stream);
  t.ranges = ranges_.download(stream);
  t.leaf_primitive = leaf_primitive_.download(stream);
  t.leaf_codes = codes_sorted_.download(stream);
  return t;
}

template <class BV>
std::size_t Bvh<BV>::device_bytes() const {
  return bvs_.capacity_bytes() + left_.capacity_bytes() + right_.capacity_bytes() + parent_.capacity_bytes() +
         leaf_primitive_.capacity_bytes() + primitive_scratch_.capacity_bytes() + ranges_.capacity_bytes() +
         codes_.capacity_bytes() + codes_sorted_.capacity_bytes() + arrivals_.capacity_bytes() +
         status_.capacity_bytes() + scratch_.capacity_bytes() + cost_.capacity_bytes();
}

}  // namespace lwsccd::gpu
