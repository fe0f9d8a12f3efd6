// lwsccd — the end-to-end CCD pipeline on the GPU: same API and same answers as
// cpu::CcdPipeline (pipeline.hpp). Everything between the positions' upload and the hits'
// download stays on the device: refit (or rebuild), traversal from the front kept on the device,
// feature pairs produced once (representative triangles, culled by their boxes), the narrow
// phase. The feature pairs and the narrow phase run without a host round trip: their lengths stay
// on the device, and the host reads them once, after the narrow phase (stage times are events,
// read then too).
#pragma once

#include <cub/device/device_scan.cuh>

#include <memory>

#include "lwsccd/bvh.cuh"
#include "lwsccd/narrow_phase.cuh"
#include "lwsccd/pipeline.hpp"
#include "lwsccd/representative.cuh"
#include "lwsccd/traverse.cuh"

namespace lwsccd::gpu {

namespace detail {

// Body changes between consecutive sorted leaves (the node_bodies prefix, before the scan).
template <class Index>
__global__ void body_change_kernel(const Index* leaf_primitive, Index n, const Index* face_body, Index* changes) {
  const Index k = static_cast<Index>(blockIdx.x * blockDim.x + threadIdx.x);
  if (k >= n) return;
  changes[k] = k > 0 && face_body[leaf_primitive[k]] != face_body[leaf_primitive[k - 1]];
}

template <class BV>
__global__ void node_body_kernel(BvhView<BV> bvh, const index_t* changes, const index_t* face_body, index_t* node_body) {
  const index_t node = static_cast<index_t>(blockIdx.x * blockDim.x + threadIdx.x);
  if (node >= bvh.num_nodes()) return;
  node_body[node] = lwsccd::detail::node_body_of(bvh.ranges[node], changes, bvh.leaf_primitive, face_body);
}

}  // namespace detail

template <class BV = Aabbf, class Scheduler = LazyStealScheduler<>, class Method = CertifiedCcd, class T = double>
class CcdPipeline {
 public:
  using Task = SelfCollisionTask<BV>;

  /// One self-colliding body.
  explicit CcdPipeline(std::shared_ptr<const TriangleMesh> mesh, PipelineParams params = {})
      : CcdPipeline(std::move(mesh), BodyLayout{}, params) {}
  /// Several bodies (as cpu::CcdPipeline: a body that does not self-collide costs no traversal).
  CcdPipeline(std::shared_ptr<const TriangleMesh> mesh, BodyLayout layout, PipelineParams params = {})
      : mesh_(lwsccd::detail::checked_mesh(std::move(mesh), "gpu::CcdPipeline")), layout_(std::move(layout)),
        params_(lwsccd::detail::validated(params)), features_(*mesh_), emitter_(RepresentativeTriangles(*mesh_, layout_)) {
    if (params_.device_memory_budget) set_memory_budget(params_.device_memory_budget);
    // Features that come within min_separation: their boxes, each grown by half of it, overlap.
    bvh_.set_leaf_margin(params_.min_separation / 2);
    emitter_.set_box_margin(params_.min_separation / 2);
    const std::vector<unsigned char> self_collides = lwsccd::detail::self_collision_flags(layout_);
    if (!self_collides.empty()) {
      face_body_.upload(layout_.face_body);
      self_collides_.upload(self_collides);
    }
    for (auto& e : mark_) LWSCCD_CUDA_CHECK(cudaEventCreate(&e));
  }
  ~CcdPipeline() {
    for (auto& e : mark_) cudaEventDestroy(e);
  }
  CcdPipeline(const CcdPipeline&) = delete;
  CcdPipeline& operator=(const CcdPipeline&) = delete;

  /// One step from host positions (validated, uploaded).
  StepResult<T> step(const std::vector<Vec3d>& x0, const std::vector<Vec3d>& x1) {
    reset_peak_memory();
    const auto start = std::chrono::steady_clock::now();
    if (!step_) step_ = std::make_unique<DeviceStep<double>>(*mesh_, x0, x1);
    else step_->set_positions(x0, x1);
    return run_step(start);
  }

  /// One step from positions already in device memory (mesh().num_vertices() points each, e.g.
  /// a simulation's own arrays): no host round trip. Throws InputError for host pointers.
  StepResult<T> step_from_device(const Vec3d* device_x0, const Vec3d* device_x1) {
    reset_peak_memory();
    const auto start = std::chrono::steady_clock::now();
    if (!step_) step_ = std::make_unique<DeviceStep<double>>(*mesh_);
    step_->set_positions_from_device(device_x0, device_x1);
    return run_step(start);
  }

  /// As step_from_device, with the contacts left in device memory (sorted by pair, valid until the
  /// next step): nothing crosses to the host but the counters the step reads once.
  DeviceStepResult<T> step_on_device(const Vec3d* device_x0, const Vec3d* device_x1) {
    reset_peak_memory();
    const auto start = std::chrono::steady_clock::now();
    if (!step_) step_ = std::make_unique<DeviceStep<double>>(*mesh_);
    step_->set_positions_from_device(device_x0, device_x1);
    DeviceStepResult<T> r;
    run_stages(r.stats);
    const bool pairs = params_.mode != CcdMode::earliest;
    r.contacts.vf = narrow_.vf_hits();
    r.contacts.ee = narrow_.ee_hits();
    r.contacts.num_vf = pairs ? narrow_.num_vf_hits() : 0;
    r.contacts.num_ee = pairs ? narrow_.num_ee_hits() : 0;
    r.contacts.earliest_toi = narrow_.earliest_toi();
    r.contacts.gave_up = narrow_.gave_up();
    r.contacts.vf_counts = narrow_.counts(0);
    r.contacts.ee_counts = narrow_.counts(1);
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(nullptr));  // the hits' sort is done
    finish_stats(r.stats, r.contacts.num_vf, r.contacts.num_ee, r.contacts.gave_up, start);
    return r;
  }

  const TriangleMesh& mesh() const { return *mesh_; }
  const BodyLayout& layout() const { return layout_; }
  const PipelineParams& params() const { return params_; }

 private:
  StepResult<T> run_step(std::chrono::steady_clock::time_point start) {
    StepResult<T> r;
    run_stages(r.stats);
    r.contacts = narrow_.download();
    finish_stats(r.stats, r.contacts.vf.size(), r.contacts.ee.size(), r.contacts.gave_up, start);
    return r;
  }

  void finish_stats(StepStats& stats, std::size_t hits_vf, std::size_t hits_ee, std::size_t gave_up,
                    std::chrono::steady_clock::time_point start) {
    stats.hits_vf = hits_vf;
    stats.hits_ee = hits_ee;
    stats.gave_up = gave_up;
    stats.narrow_survivors = narrow_.survivors();
    stats.narrow_warp_searches = narrow_.warp_searches();
    stats.narrow_vf = narrow_.counts(0);
    stats.narrow_ee = narrow_.counts(1);
    stats.peak_device_bytes = memory_stats().peak;
    stats.total_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  }

  // Every stage of a step on the device; the narrow phase's hits stay there (sorted on the
  // default stream once collected).
  void run_stages(StepStats& stats) {
    LWSCCD_CUDA_CHECK(cudaEventRecord(mark_[0]));
    if (!built_) {
      bvh_.build(*step_);
      built_ = stats.rebuilt = true;
    } else {
      stats.rebuilt = bvh_.refit_or_rebuild(*step_, RebuildPolicy{params_.rebuild_factor});
    }
    if (face_body_.size() && bvh_.generation() != node_body_generation_) update_node_bodies();
    LWSCCD_CUDA_CHECK(cudaEventRecord(mark_[1]));
    traverse_step(stats);
    LWSCCD_CUDA_CHECK(cudaEventRecord(mark_[2]));
    // The feature pairs: the first step waits for their numbers (to size their buffers); later
    // steps reuse the room earlier ones needed and leave the numbers on the device.
    if (!emitter_sized_) emitter_.run(step_->x0.data(), step_->x1.data(), traversal_.results(), traversal_.num_results());
    else emitter_.enqueue(step_->x0.data(), step_->x1.data(), traversal_.results(), traversal_.num_results());
    emitter_sized_ = true;
    LWSCCD_CUDA_CHECK(cudaEventRecord(mark_[3]));
    CcdParams<T> ccd;
    ccd.min_separation = static_cast<T>(params_.min_separation);
    ccd.tolerance = static_cast<T>(params_.tolerance);
    ccd.max_iterations = params_.max_iterations;
    ccd.mode = params_.mode;
    // One host round trip for both stages: their counters, read once the narrow phase is done;
    // a list that outgrew its buffer has it grown, and what read it runs again.
    while (true) {
      narrow_.enqueue(features_, step_->x0.data(), step_->x1.data(), emitter_.vf_list(), emitter_.ee_list(), ccd);
      LWSCCD_CUDA_CHECK(cudaEventRecord(mark_[4]));
      LWSCCD_CUDA_CHECK(cudaEventSynchronize(mark_[4]));
      if (emitter_.collect() && narrow_.collect()) break;
      ++stats.reruns;
    }
    stats.refit_ms = elapsed(mark_[0], mark_[1]);
    stats.traverse_ms = elapsed(mark_[1], mark_[2]);
    stats.features_ms = elapsed(mark_[2], mark_[3]);
    stats.narrow_ms = elapsed(mark_[3], mark_[4]);
    stats.feature_pairs_vf = emitter_.num_vf();
    stats.feature_pairs_ee = emitter_.num_ee();
  }

  // LeafFilter::node_body for the current tree (after a build: topology only).
  void update_node_bodies() {
    const BvhView<BV> view = bvh_.view();
    const index_t n = view.num_leaves;
    body_changes_.resize_discard(static_cast<std::size_t>(n));
    node_body_.resize_discard(static_cast<std::size_t>(view.num_nodes()));
    detail::body_change_kernel<<<static_cast<unsigned>((n + 255) / 256), 256>>>(view.leaf_primitive, n, face_body_.data(),
                                                                                 body_changes_.data());
    LWSCCD_CUDA_CHECK_LAUNCH();
    std::size_t bytes = 0;
    LWSCCD_CUDA_CHECK(cub::DeviceScan::InclusiveSum(nullptr, bytes, body_changes_.data(), body_changes_.data(), n));
    scratch_.resize_discard(std::max({bytes, scratch_.size(), std::size_t(1)}));
    LWSCCD_CUDA_CHECK(cub::DeviceScan::InclusiveSum(scratch_.data(), bytes, body_changes_.data(), body_changes_.data(), n));
    detail::node_body_kernel<<<static_cast<unsigned>((view.num_nodes() + 255) / 256), 256>>>(
        view, body_changes_.data(), face_body_.data(), node_body_.data());
    LWSCCD_CUDA_CHECK_LAUNCH();
    node_body_generation_ = bvh_.generation();
  }

  // Milliseconds between two recorded events (both complete).
  static double elapsed(cudaEvent_t from, cudaEvent_t to) {
    float t = 0;
    LWSCCD_CUDA_CHECK(cudaEventElapsedTime(&t, from, to));
    return t;
  }

  // Traversal from the front kept on the device (FrontTracker's policy, without a host copy).
  void traverse_step(StepStats& stats) {
    const bool bodies = face_body_.size() > 0;
    const Task task{bvh_.view(), LeafFilter{bodies ? face_body_.data() : nullptr, bodies ? self_collides_.data() : nullptr,
                                            features_.faces.data(), true, bodies ? node_body_.data() : nullptr}};
    const bool restart = !params_.front_tracking || bvh_.generation() != generation_ || front_size_ == 0 || reset_next_;
    generation_ = bvh_.generation();
    if (restart) {
      root_.upload(std::vector<NodePair>{NodePair{0, 0}});
      traverse<Scheduler>(task, root_.data(), 1, traversal_, params_.front_tracking);
    } else {
      traverse<Scheduler>(task, seeds_.data(), front_size_, traversal_, true);
    }
    if (params_.front_tracking) {
      front_size_ = traversal_.num_front();
      seeds_.resize_discard(std::max<std::size_t>(front_size_, 1));
      if (front_size_)
        LWSCCD_CUDA_CHECK(cudaMemcpyAsync(seeds_.data(), traversal_.front(), front_size_ * sizeof(NodePair),
                                          cudaMemcpyDeviceToDevice));
      if (restart) size_at_restart_ = front_size_;
      reset_next_ = static_cast<double>(front_size_) > params_.front_growth_limit * static_cast<double>(size_at_restart_);
    }
    stats.restarted_from_root = restart;
    stats.bvtt_nodes = traversal_.stats().items_processed;
    stats.front_size = front_size_;
    stats.triangle_pairs = traversal_.num_results();
  }

  std::shared_ptr<const TriangleMesh> mesh_;
  BodyLayout layout_;
  PipelineParams params_;
  DeviceMeshFeatures features_;
  FeatureEmitter<> emitter_;
  DeviceBuffer<index_t> face_body_, node_body_, body_changes_;  ///< empty: no body pruning
  DeviceBuffer<unsigned char> self_collides_;
  std::uint64_t node_body_generation_ = ~std::uint64_t(0);
  DeviceBuffer<unsigned char> scratch_;
  std::unique_ptr<DeviceStep<double>> step_;
  Bvh<BV> bvh_;
  bool built_ = false;
  TraversalOutput<Task> traversal_;
  DeviceBuffer<NodePair> seeds_, root_;
  std::size_t front_size_ = 0, size_at_restart_ = 0;
  std::uint64_t generation_ = ~std::uint64_t(0);
  bool reset_next_ = false;
  bool emitter_sized_ = false;  ///< the emitter's buffers have been sized by a step
  NarrowPhase<Method, T> narrow_;
  cudaEvent_t mark_[5];  ///< stage boundaries: refit, traversal, feature pairs, narrow phase
};

}  // namespace lwsccd::gpu
