// lwsccd — the LBVH on the GPU: build and refit in kernels, no host round trip in refit.
//
// Produces the same tree as cpu::Bvh for the same input (see bvh.hpp): identical leaf order,
// children, parents and leaf ranges; AABB node values bit for bit; OBB values within rounding
// (the device contracts multiply-adds).
#pragma once

#include <cuda_runtime.h>

#include <cstdint>
#include <type_traits>
#include <utility>
#include <vector>

#include "lwsccd/bvh/bvh.hpp"
#include "lwsccd/core/device_buffer.cuh"
#include "lwsccd/core/error.hpp"
#include "lwsccd/core/host_staging.cuh"
#include "lwsccd/core/span.hpp"

namespace lwsccd::gpu {

/// A step's topology and positions in device memory (P = float or double). Positions are taken
/// in either type (Q) and converted to P: float to double exactly (so a step is certified for
/// float input as given), double to float rounded to nearest.
template <class P>
struct DeviceStep {
  static_assert(std::is_same<P, float>::value || std::is_same<P, double>::value,
                "lwsccd: gpu::DeviceStep holds float or double positions");
  index_t num_vertices = 0;
  DeviceBuffer<Face> faces;
  DeviceBuffer<Vec3<P>> x0, x1;

  DeviceStep() = default;
  /// Uploads (and converts to P) a host step; positions are validated on the host first.
  template <class Q>
  DeviceStep(const TriangleMesh& mesh, const std::vector<Vec3<Q>>& h0, const std::vector<Vec3<Q>>& h1,
             cudaStream_t stream = nullptr);
  /// Topology only; positions follow through set_positions or set_positions_from_device.
  explicit DeviceStep(const TriangleMesh& mesh, cudaStream_t stream = nullptr);
  /// Replaces the positions (same topology), e.g. for the next step of a sequence. Float input
  /// to double positions crosses as float (half the bytes) and is widened on the device.
  template <class Q>
  void set_positions(const std::vector<Vec3<Q>>& h0, const std::vector<Vec3<Q>>& h1, cudaStream_t stream = nullptr) {
    set_positions(Span<const Vec3<Q>>(h0), Span<const Vec3<Q>>(h1), stream);
  }
  /// The same from any host arrays (e.g. a NumPy array's memory); they may change once it returns.
  template <class Q>
  void set_positions(Span<const Vec3<Q>> h0, Span<const Vec3<Q>> h1, cudaStream_t stream = nullptr);
  /// Replaces the positions from device memory (num_vertices points each; copied, or converted
  /// by a kernel, so the caller's arrays may change afterwards). Throws InputError unless both
  /// point to device (or managed) memory. Non-finite values are reported by the next BVH build or
  /// refit.
  template <class Q>
  void set_positions_from_device(const Vec3<Q>* d0, const Vec3<Q>* d1, cudaStream_t stream = nullptr);
  /// Reads positions already in device memory where they are, without a copy (P points, as the
  /// step holds them): the work enqueued from now on reads d0, d1 instead of x0, x1, so they must
  /// stay valid and unchanged until that work has run. set_positions and set_positions_from_device
  /// return to the step's own arrays. Throws InputError unless both point to device (or managed)
  /// memory.
  void use_device_positions(const Vec3<P>* d0, const Vec3<P>* d1);
  /// Float positions in device memory for a double step, widened later: Bvh::refit reads d0, d1
  /// where they are (each point widened as it is loaded, exactly), and enqueue_widening fills x0,
  /// x1 from them on the stream the caller chooses, e.g. beside the refit; until then widening_due()
  /// and x0_data() must not be read. d0, d1 must stay valid and unchanged until the widening has run.
  /// Why: widening both arrays before the refit delayed a float step's first kernel. Throws
  /// InputError unless both point to device (or managed) memory.
  void widen_later(const Vec3<float>* d0, const Vec3<float>* d1);
  /// Float host positions for a double step: uploaded as float (half the bytes) into the step's
  /// own device array and left to widen later, as widen_later leaves device ones (the refit reads
  /// them in place; enqueue_widening or take_widening fills x0, x1). Validated as set_positions;
  /// the host arrays may change once it returns. The array stays in use until the widening has run.
  void upload_to_widen_later(Span<const Vec3<float>> h0, Span<const Vec3<float>> h1, cudaStream_t stream = nullptr);
  /// Device bytes of the float input's array (set_positions' and upload_to_widen_later's).
  std::size_t float_input_bytes() const { return wide_.capacity_bytes(); }
  /// Enqueues the widening widen_later left due (nothing otherwise) on `stream`.
  void enqueue_widening(cudaStream_t stream);
  /// Hands the widening widen_later left due to the caller, who fills x0, x1 from the returned
  /// arrays itself (e.g. in a kernel that reads them for more); nothing is due afterwards.
  std::pair<const Vec3<float>*, const Vec3<float>*> take_widening() {
    const std::pair<const Vec3<float>*, const Vec3<float>*> sources{float_source_[0], float_source_[1]};
    float_source_[0] = float_source_[1] = nullptr;
    return sources;
  }
  bool widening_due() const { return float_source_[0] != nullptr; }
  /// widen_later's arrays (k = 0: x0, 1: x1) while their widening is due, else null.
  const Vec3<float>* float_source(int k) const { return float_source_[k]; }
  /// Where the step's work reads the positions: x0 and x1, or the arrays of use_device_positions.
  const Vec3<P>* x0_data() const { return assume_widened(in_place_[0] ? in_place_[0] : x0.data()); }
  const Vec3<P>* x1_data() const { return assume_widened(in_place_[1] ? in_place_[1] : x1.data()); }

 private:
  const Vec3<P>* assume_widened(const Vec3<P>* p) const {
    if (widening_due()) throw Error("gpu::DeviceStep: positions read before the widening widen_later left due was enqueued");
    return p;
  }
  const Vec3<P>* in_place_[2] = {nullptr, nullptr};  ///< use_device_positions' arrays, or null: x0, x1
  const Vec3<float>* float_source_[2] = {nullptr, nullptr};  ///< widen_later's arrays while due
  std::vector<Vec3<P>> staging_;   // double input rounded to float on the host (half the bytes to copy)
  DeviceBuffer<Vec3<float>> wide_;  // float input for double positions, widened on the device
  void require_sizes(std::size_t n0, std::size_t n1) const;
};

template <class BV>
class Bvh {
 public:
  static_assert(require_bounding_volume<BV>::value, "");

  Bvh() = default;
  Bvh(const Bvh&) = delete;
  Bvh& operator=(const Bvh&) = delete;
  Bvh(Bvh&&) = default;
  Bvh& operator=(Bvh&&) = default;

  /// Builds over the device step. Synchronizes once at the end to report NaN/inf positions
  /// (InputError) and launch failures (CudaError).
  template <class P>
  void build(const DeviceStep<P>& step, cudaStream_t stream = nullptr);
  /// Refits for the step's current positions: one kernel, asynchronous. Non-finite
  /// positions are flagged on the device and reported by the next check_status().
  template <class P>
  void refit(const DeviceStep<P>& step, cudaStream_t stream = nullptr);
  /// refit, then rebuild if the policy says the tree decayed (synchronizes to read the cost).
  template <class P>
  bool refit_or_rebuild(const DeviceStep<P>& step, const RebuildPolicy& policy = {}, cudaStream_t stream = nullptr);

  /// refit_or_rebuild without waiting: refits and enqueues the reads of the status flag and the
  /// cost into pinned memory; collect_refit() reports them once `stream` has been synchronized.
  /// The rebuild the cost calls for then comes a step later (gpu::CcdPipeline rebuilds before its
  /// next traversal): a refitted tree is as exact as a rebuilt one, only slower to traverse.
  template <class P>
  void refit_enqueue(const DeviceStep<P>& step, cudaStream_t stream = nullptr);
  /// refit_enqueue's reads alone (the status flag, the cost's reduction and its copies into pinned
  /// memory), for a refit() enqueued on another stream: `stream` must wait for that refit (an
  /// event recorded after it), so that the reads leave the refit's stream free for the traversal,
  /// which needs only the boxes. collect_refit() reports them once `stream` has been synchronized.
  void enqueue_refit_reads(cudaStream_t stream = nullptr);
  /// After refit_enqueue() and a synchronisation of its stream: throws InputError if the
  /// positions were non-finite; otherwise returns whether `policy` says the tree decayed.
  bool collect_refit(const RebuildPolicy& policy = {}, cudaStream_t stream = nullptr);

  /// Sum of internal surface areas over the root's, computed on the device (synchronizes).
  double sah_cost(cudaStream_t stream = nullptr) const;
  /// Synchronizes and throws InputError if positions seen since the last check were non-finite.
  void check_status(cudaStream_t stream = nullptr);

  /// As cpu::Bvh::set_leaf_margin: every leaf grown by `margin` from the next build or refit on.
  void set_leaf_margin(double margin) {
    leaf_margin_ = lwsccd::detail::checked_margin<BV>(margin, "gpu::Bvh::set_leaf_margin");
  }
  double leaf_margin() const { return leaf_margin_; }

  BvhView<BV> view() const {
    return {num_leaves_, bvs_.data(), left_.data(), right_.data(), parent_.data(), ranges_.data(), leaf_primitive_.data()};
  }
  /// Copies every array to the host (synchronizes).
  BvhNodes<BV> download(cudaStream_t stream = nullptr) const;
  index_t num_leaves() const { return num_leaves_; }
  std::uint64_t generation() const { return generation_; }
  double cost_at_build() const { return cost_at_build_; }
  /// Device bytes held by this BVH (nodes, codes, scratch).
  std::size_t device_bytes() const;

 private:
  index_t num_leaves_ = 0;
  std::uint64_t generation_ = 0;
  double cost_at_build_ = 0;
  typename bv_traits<BV>::scalar_type leaf_margin_ = 0;
  DeviceBuffer<BV> bvs_;
  DeviceBuffer<index_t> left_, right_, parent_, leaf_primitive_, primitive_scratch_;
  DeviceBuffer<LeafRange> ranges_;
  DeviceBuffer<std::uint64_t> codes_, codes_sorted_;
  DeviceBuffer<int> arrivals_;  ///< per internal node, for the bottom-up pass; zero between passes
  DeviceBuffer<int> status_;    ///< [0]: non-finite position seen
  DeviceBuffer<unsigned char> scratch_;  ///< centres | scene box | CUB temporary storage
  std::size_t temp_offset_ = 0;          ///< where the CUB part of scratch_ starts
  mutable DeviceBuffer<double> cost_;
  /// Pinned target of the small reads (cost, root box, status flag): copies that do not block.
  struct Readback {
    double cost;
    BV root;
    int status;
  };
  mutable PinnedBuffer<Readback> readback_;  // allocated on first use
  Readback& readback() const {
    readback_.ensure(1);
    return readback_[0];
  }
  // Enqueues the cost's reduction and the copies of cost and root box into readback_.
  void enqueue_cost(cudaStream_t stream) const;
  double cost_from_readback() const;
  void throw_if_flagged(int flag, cudaStream_t stream);
};

}  // namespace lwsccd::gpu

#include "lwsccd/bvh/detail/bvh_kernels.cuh"
