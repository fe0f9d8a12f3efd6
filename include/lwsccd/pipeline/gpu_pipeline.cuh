// lwsccd — the end-to-end CCD pipeline on the GPU: same API and same answers as
// cpu::CcdPipeline (cpu_pipeline.hpp). Everything between the positions' upload and the hits'
// download stays on the device: refit (or rebuild), traversal from the front kept on the device,
// feature pairs produced once (representative triangles, culled by their boxes), the narrow
// phase. The feature pairs and the narrow phase run without a host round trip: their lengths stay
// on the device, and the host reads them once, after the narrow phase (stage times are events,
// read then too).
//
// Under a device-memory budget (PipelineParams::device_memory_budget), or with parts asked for
// (PipelineParams::part_pairs), a step streams instead: the traversal runs from its seeds (the kept
// front, or a cut of the BVTT below the root) a part at a time, and each part's triangle pairs go
// through the feature pairs and the narrow phase in parts that fit; the hits gather on the device
// and are sorted once. Same answer, more synchronisations.
#pragma once

#include <cub/device/device_scan.cuh>

#include <algorithm>
#include <memory>
#include <utility>
#include <vector>

#include "lwsccd/bvh/bvh.cuh"
#include "lwsccd/features/representative.cuh"
#include "lwsccd/narrow_phase/narrow_phase.cuh"
#include "lwsccd/pipeline/cpu_pipeline.hpp"
#include "lwsccd/pipeline/stage_sequence.hpp"
#include "lwsccd/traversal/gpu_traverse.cuh"

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
    const Outcome o = outcome();
    const bool pairs = params_.mode != CcdMode::earliest;
    r.contacts.vf = o.hits[0];
    r.contacts.ee = o.hits[1];
    r.contacts.num_vf = pairs ? o.num_hits[0] : 0;
    r.contacts.num_ee = pairs ? o.num_hits[1] : 0;
    r.contacts.earliest_toi = o.earliest;
    r.contacts.gave_up = o.gave_up;
    r.contacts.vf_counts = o.counts[0];
    r.contacts.ee_counts = o.counts[1];
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(nullptr));  // the hits' sort is done
    finish_stats(r.stats, r.contacts.num_vf, r.contacts.num_ee, start);
    return r;
  }

  const TriangleMesh& mesh() const { return *mesh_; }
  const BodyLayout& layout() const { return layout_; }
  const PipelineParams& params() const { return params_; }

  /// Device bytes this pipeline holds now (every buffer's capacity; they are kept between steps).
  std::size_t device_bytes() const {
    return resident_bytes() + traversal_.device_bytes() + seeds_.capacity_bytes() + root_.capacity_bytes() +
           cut_.capacity_bytes() + next_front_.capacity_bytes() + scratch_.capacity_bytes() + emitter_.list_bytes() +
           narrow_.device_bytes() + gathered_[0].capacity_bytes() + gathered_[1].capacity_bytes() + gathered_sorter_.device_bytes() +
           met_.capacity_bytes();
  }
  /// Of those, what no split of a step can reduce: topology, positions, the BVH, the feature boxes.
  std::size_t resident_bytes() const {
    const std::size_t step = step_ ? step_->faces.capacity_bytes() + step_->x0.capacity_bytes() + step_->x1.capacity_bytes() : 0;
    return step + bvh_.device_bytes() + features_.faces.capacity_bytes() + features_.edges.capacity_bytes() +
           emitter_.device_bytes() - emitter_.list_bytes() + face_body_.capacity_bytes() + node_body_.capacity_bytes() +
           body_changes_.capacity_bytes() + self_collides_.capacity_bytes();
  }
  /// The budget streamed steps keep to (PipelineParams::device_memory_budget; 0: no streaming).
  /// It may change between steps (e.g. as the application's own use of the device changes).
  void set_device_memory_budget(std::size_t bytes) { params_.device_memory_budget = bytes; }

 private:
  // What the last step's narrow phase (or its parts, gathered) found, on the device.
  struct Outcome {
    const FeatureHit<T>* hits[2];
    std::size_t num_hits[2];
    T earliest;
    std::size_t gave_up, survivors, warp_searches;
    NarrowPhaseCounts counts[2];
  };
  Outcome outcome() const {
    if (streamed_) return gathered_outcome_;
    return {{narrow_.vf_hits(), narrow_.ee_hits()}, {narrow_.num_vf_hits(), narrow_.num_ee_hits()}, narrow_.earliest_toi(),
            narrow_.gave_up(), narrow_.survivors(), narrow_.warp_searches(), {narrow_.counts(0), narrow_.counts(1)}};
  }

  StepResult<T> run_step(std::chrono::steady_clock::time_point start) {
    StepResult<T> r;
    run_stages(r.stats);
    if (!streamed_) {
      r.contacts = narrow_.download();
    } else {
      const Outcome& o = gathered_outcome_;
      const bool pairs = params_.mode != CcdMode::earliest;
      r.contacts.vf = gathered_[0].download_prefix(pairs ? o.num_hits[0] : 0);
      r.contacts.ee = gathered_[1].download_prefix(pairs ? o.num_hits[1] : 0);
      r.contacts.earliest_toi = o.earliest;
      r.contacts.gave_up = o.gave_up;
      r.contacts.vf_counts = o.counts[0];
      r.contacts.ee_counts = o.counts[1];
    }
    finish_stats(r.stats, r.contacts.vf.size(), r.contacts.ee.size(), start);
    return r;
  }

  void finish_stats(StepStats& stats, std::size_t hits_vf, std::size_t hits_ee, std::chrono::steady_clock::time_point start) {
    const Outcome o = outcome();
    stats.hits_vf = hits_vf;
    stats.hits_ee = hits_ee;
    stats.gave_up = o.gave_up;
    stats.narrow_survivors = o.survivors;
    stats.narrow_warp_searches = o.warp_searches;
    stats.narrow_vf = o.counts[0];
    stats.narrow_ee = o.counts[1];
    stats.peak_device_bytes = memory_stats().peak;
    stats.total_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  }

  CcdParams<T> ccd_params() const { return lwsccd::detail::ccd_params_of<T>(params_); }

  // Build on the first step, or where the last step's refit found the tree decayed; refit
  // otherwise. `wait` false leaves the refit's reads (positions' status, the cost) on their way to
  // the host, for collect_refit() with the step's other counters: the rebuild the cost calls for
  // then comes a step later. Returns whether reads await collect_refit().
  bool refit_stage(StepStats& stats, bool wait) {
    bool pending = false;
    if (!built_ || rebuild_due_) {
      bvh_.build(*step_);
      built_ = stats.rebuilt = true;
      rebuild_due_ = false;
    } else if (wait) {
      stats.rebuilt = bvh_.refit_or_rebuild(*step_, RebuildPolicy{params_.rebuild_factor});
    } else {
      bvh_.refit_enqueue(*step_);
      pending = true;
    }
    if (face_body_.size() && bvh_.generation() != node_body_generation_) update_node_bodies();
    return pending;
  }

  // The refit's reads, once the step's stream has been synchronized. Non-finite positions throw
  // InputError; the front this step recorded (over boxes that were not finite) is then dropped.
  void collect_refit() {
    try {
      rebuild_due_ = bvh_.collect_refit(RebuildPolicy{params_.rebuild_factor});
    } catch (...) {
      front_size_ = 0;
      throw;
    }
  }

  // The feature pairs of the traversal's candidates, their number read on the device. The first
  // step waits for their numbers (to size their buffers); later steps reuse the room earlier
  // ones needed and leave the numbers on the device.
  void enqueue_feature_pairs() {
    using OrphanRange = typename FeatureEmitter<>::OrphanRange;
    emitter_.enqueue(step_->x0.data(), step_->x1.data(), traversal_.results(), traversal_.result_count(), nullptr,
                     OrphanRange{0, emitter_.num_orphans()}, false);
    if (!emitter_sized_) {
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(nullptr));
      if (!emitter_.collect()) LWSCCD_CUDA_CHECK(cudaStreamSynchronize(nullptr));
    }
    emitter_sized_ = true;
  }

  // Every stage of a step on the device (lwsccd::detail::run_stage_sequence), one host round trip
  // at its end (the refit's reads, the traversal's, the feature pairs' and the narrow phase's
  // counters); the narrow phase's hits stay there (sorted on the default stream once collected).
  void run_stages(StepStats& stats) {
    streamed_ = params_.device_memory_budget > 0 || params_.part_pairs > 0;
    if (streamed_) return run_streamed_stages(stats);
    LWSCCD_CUDA_CHECK(cudaEventRecord(mark_[0]));
    lwsccd::detail::run_stage_sequence(*this, stats);
  }

  // The stages as the sequence asks for them: each enqueues its work on the stream, and
  // stage_done marks its end with an event (mark_[k + 1]; mark_[0] is the step's start).
  void stage_refit(StepStats& stats) { refit_pending_ = refit_stage(stats, false); }
  void stage_traversal(StepStats&) { restarted_ = traverse_step(); }
  void stage_feature_pairs(StepStats&) { enqueue_feature_pairs(); }
  void stage_narrow_phase(StepStats&) {
    narrow_.enqueue(features_, step_->x0.data(), step_->x1.data(), emitter_.vf_list(), emitter_.ee_list(), ccd_params());
  }
  void stage_done(lwsccd::detail::PipelineStage stage, StepStats&) {
    LWSCCD_CUDA_CHECK(cudaEventRecord(mark_[static_cast<int>(stage) + 1]));
  }
  // The step's one wait. Where a count outgrew its buffer, the buffer is grown and what read the
  // short list runs again.
  void complete_step(StepStats& stats) {
    while (true) {
      LWSCCD_CUDA_CHECK(cudaEventSynchronize(mark_[4]));
      if (refit_pending_) collect_refit();
      refit_pending_ = false;
      if (!traversal_.collect()) {  // an output or a deque overflowed: the traversal again, waiting
        traverse<Scheduler>(traversal_task(), seeds_.data(), front_size_, traversal_, params_.front_tracking);
        enqueue_feature_pairs();
        ++stats.reruns;
      } else if (emitter_.collect() && narrow_.collect()) {
        break;
      } else {
        ++stats.reruns;
      }
      stage_narrow_phase(stats);
      stage_done(lwsccd::detail::PipelineStage::narrow_phase, stats);
    }
    keep_front(restarted_, stats);
    stats.refit_ms = elapsed(mark_[0], mark_[1]);
    stats.traverse_ms = elapsed(mark_[1], mark_[2]);
    stats.features_ms = elapsed(mark_[2], mark_[3]);
    stats.narrow_ms = elapsed(mark_[3], mark_[4]);
    stats.feature_pairs_vf = emitter_.num_vf();
    stats.feature_pairs_ee = emitter_.num_ee();
  }
  friend void lwsccd::detail::run_stage_sequence<CcdPipeline, StepStats>(CcdPipeline&, StepStats&);

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

  Task traversal_task() const {
    const bool bodies = face_body_.size() > 0;
    return Task{bvh_.view(), LeafFilter{bodies ? face_body_.data() : nullptr, bodies ? self_collides_.data() : nullptr,
                                        features_.faces.data(), true, bodies ? node_body_.data() : nullptr}};
  }

  // Traversal from the front kept on the device (FrontTracker's policy, without a host copy), or
  // from the root; from a front without a host round trip (its counts are read at the step's
  // end). Returns whether it started from the root.
  bool traverse_step() {
    const Task task = traversal_task();
    const bool restart = !params_.front_tracking || bvh_.generation() != generation_ || front_size_ == 0 || reset_next_;
    generation_ = bvh_.generation();
    if (restart) {
      root_.upload(std::vector<NodePair>{NodePair{0, 0}});
      traverse<Scheduler>(task, root_.data(), 1, traversal_, params_.front_tracking);
    } else {
      traverse_async<Scheduler>(task, seeds_.data(), front_size_, traversal_, true);
    }
    return restart;
  }

  // Whether the front has grown past the growth limit since the last restart (the next step
  // then starts from the root).
  bool front_past_growth_limit() const {
    const double limit = lwsccd::detail::front_growth_limit_of(params_, kGpuFrontGrowthLimit);
    return static_cast<double>(front_size_) > limit * static_cast<double>(size_at_restart_);
  }

  // After the traversal's counts are read: its front becomes the next step's seeds (the buffers
  // trade places; the one the seeds held takes the next front). A front that outgrew its buffer
  // is not kept: the seeds stay, a cut the next step starts from as well (a rerun of the
  // traversal for the front alone cost ~1 ms on horse-gallop, whose steps take ~0.45).
  void keep_front(bool restart, StepStats& stats) {
    stats.front_outgrown = !traversal_.front_complete();
    if (params_.front_tracking && !stats.front_outgrown) {
      front_size_ = traversal_.num_front();
      std::swap(seeds_, traversal_.front_);
      // Room for the next front to grow by a quarter (horse-gallop's grows by up to a fifth a
      // step): the spare buffer's whole capacity where that suffices, else half as much again.
      const std::size_t need = front_size_ + front_size_ / 4;
      const std::size_t capacity = traversal_.front_.capacity_bytes() / sizeof(NodePair);
      traversal_.front_.resize_discard(capacity >= need ? capacity : front_size_ + front_size_ / 2);
      if (restart) size_at_restart_ = front_size_;
      reset_next_ = front_past_growth_limit();
    }
    stats.restarted_from_root = restart;
    stats.bvtt_nodes = traversal_.stats().items_processed;
    stats.front_size = front_size_;
    stats.triangle_pairs = traversal_.num_results();
  }

  // ---- A step streamed under PipelineParams::device_memory_budget ----

  static constexpr std::size_t kUnlimited = std::size_t(1) << 60;

  // The stages in parts that fit the budget: traversal from the seeds a part at a time, each
  // part's candidates through the feature pairs and the narrow phase in parts, the hits gathered.
  void run_streamed_stages(StepStats& stats) {
    using clock = std::chrono::steady_clock;
    auto ms_since = [](clock::time_point t) { return std::chrono::duration<double, std::milli>(clock::now() - t).count(); };
    auto t = clock::now();
    refit_stage(stats, true);
    LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
    stats.refit_ms = ms_since(t);
    const std::size_t budget = params_.device_memory_budget ? params_.device_memory_budget : kUnlimited;
    const std::size_t resident = resident_bytes();
    // A budget that leaves less than a few MiB beside the resident data cannot make progress (the
    // narrow phase's and the scheduler's starting buffers alone take that).
    const std::size_t least = resident + (std::size_t(4) << 20);
    if (budget < least)
      throw InputError("gpu::CcdPipeline", "device_memory_budget",
                       std::to_string(budget) + " bytes is below what this mesh needs at least: " + std::to_string(least) +
                           " (positions, BVH and topology take " + std::to_string(resident) + ")");
    const std::size_t room = budget - resident;
    gathered_outcome_ = Outcome{{nullptr, nullptr}, {0, 0}, T(1), 0, 0, 0, {}};
    const CcdParams<T> ccd = ccd_params();
    boxes_current_ = false;  // the first part to emit feature pairs computes the step's feature boxes
    room_ = room;

    const Task task = traversal_task();
    const std::uint64_t generation = bvh_.generation();
    recording_front_ = params_.front_tracking && front_refused_generation_ != generation;
    const bool restart = !params_.front_tracking || generation != generation_ || front_size_ == 0 || reset_next_;
    generation_ = generation;
    const std::size_t front_room = static_cast<std::size_t>(StreamingPolicy::kFrontShare * static_cast<double>(room));
    std::size_t next_front = 0;
    // Keeps the part's front entries for the next step while they fit their share.
    auto keep_front = [&] {
      if (!recording_front_) return;
      const std::size_t n = traversal_.num_front();
      const std::size_t kept_seeds = restart ? 0 : seeds_.capacity_bytes();
      const std::size_t wanted = (next_front + n) * sizeof(NodePair) * 5 / 4;
      // The front is kept within its share and only where the budget has room for it now (it is
      // an optimisation: the parts' narrow phase does not leave room for it).
      const std::size_t grows = (next_front + n) * sizeof(NodePair) > next_front_.capacity_bytes() ? wanted : 0;
      if (kept_seeds + wanted > front_room || device_bytes() + grows > budget) {
        give_up_next_front();
        return;
      }
      next_front_.resize_keep(next_front + n, (next_front + n) * 5 / 4);
      if (n) LWSCCD_CUDA_CHECK(cudaMemcpyAsync(next_front_.data() + next_front, traversal_.front(), n * sizeof(NodePair),
                                              cudaMemcpyDeviceToDevice));
      next_front += n;
    };
    const NodePair* seeds = seeds_.data();
    std::size_t num_seeds = front_size_;
    if (restart) {
      seeds_ = DeviceBuffer<NodePair>();  // an old front is of no use from the root: its room goes to the parts
      // A cut below the root; what the expansion met on the way is a part of its own.
      t = clock::now();
      root_.upload(std::vector<NodePair>{NodePair{0, 0}});
      traversal_.set_output_limit(traversal_output_limit());
      num_seeds = expand(task, root_.data(), 1, StreamingPolicy::kCutItems, traversal_, recording_front_);
      if (!traversal_.complete())
        throw Error("gpu::CcdPipeline: the device memory budget of " + std::to_string(budget) +
                    " bytes cannot hold the first levels of the traversal; give it more");
      cut_.resize_discard(std::max<std::size_t>(num_seeds, 1));
      if (num_seeds)
        LWSCCD_CUDA_CHECK(cudaMemcpyAsync(cut_.data(), traversal_.expanded(), num_seeds * sizeof(NodePair), cudaMemcpyDeviceToDevice));
      seeds = cut_.data();
      stats.bvtt_nodes += traversal_.stats().items_processed;
      stats.traverse_ms += ms_since(t);
      keep_front();
      // What the expansion met is tested after the parts, once the scheduler's own lists hold
      // their room (the parts' narrow phase is sized around them).
      met_.resize_discard(std::max<std::size_t>(traversal_.num_results(), 1));
      met_size_ = traversal_.num_results();
      stats.triangle_pairs += met_size_;
      if (met_size_)
        LWSCCD_CUDA_CHECK(cudaMemcpyAsync(met_.data(), traversal_.results(), met_size_ * sizeof(TrianglePair),
                                          cudaMemcpyDeviceToDevice));
    }
    // A part's seeds take room in the scheduler's own lists too (a few entries each).
    const std::size_t max_part = std::max<std::size_t>(1, seed_list_bytes() / seed_bytes());
    std::size_t part = std::min(seeds_per_part_ ? seeds_per_part_ : num_seeds, max_part);
    if (params_.part_pairs) part = std::min(part, std::max<std::size_t>(1, params_.part_pairs));
    for (std::size_t first = 0; first < num_seeds;) {
      const std::size_t n = std::min(part, num_seeds - first);
      t = clock::now();
      traversal_.set_output_limit(traversal_output_limit());
      traverse<Scheduler>(task, seeds + first, n, traversal_, recording_front_);
      stats.traverse_ms += ms_since(t);
      const std::size_t cap = params_.part_pairs;
      if (traversal_.complete() && cap && traversal_.num_results() > cap && n > 1) {
        part = n / 2;  // more candidates than a part may have: fewer seeds
        ++stats.reruns;
        continue;
      }
      if (!traversal_.complete()) {
        if (n == 1)
          throw Error("gpu::CcdPipeline: the device memory budget of " + std::to_string(budget) +
                      " bytes cannot hold what one node pair of the traversal yields; give it more");
        part = n / 2;
        ++stats.reruns;
        continue;
      }
      stats.bvtt_nodes += traversal_.stats().items_processed;
      keep_front();
      test_traversal_output(ccd, stats);
      ++stats.traversal_parts;
      first += n;
      // Parts whose outputs took under a quarter of their room may double.
      const std::size_t used = traversal_.num_results() * sizeof(TrianglePair) + traversal_.num_front() * sizeof(NodePair);
      if (used * 4 < traversal_.output_limit() && (!cap || traversal_.num_results() * 4 < cap))
        part = std::min({num_seeds, 2 * part, max_part});
    }
    traversal_.set_output_limit(0);
    seeds_per_part_ = part;
    if (met_size_) test_candidates(met_.data(), met_size_, false, ccd, stats);
    met_size_ = 0;
    met_ = DeviceBuffer<TrianglePair>();  // tested: its room goes back to the orphans' parts
    // The orphans (pairs no candidate emits), in parts of their own.
    test_candidates(nullptr, 0, true, ccd, stats);
    // The front for the next step, when it was kept whole.
    if (recording_front_) {
      std::swap(seeds_, next_front_);
      front_size_ = next_front;
      if (restart) size_at_restart_ = front_size_;
      reset_next_ = front_past_growth_limit();
    } else {
      front_size_ = 0;
      seeds_ = DeviceBuffer<NodePair>();
    }
    next_front_ = DeviceBuffer<NodePair>();
    stats.restarted_from_root = restart;
    stats.front_size = front_size_;
    // The gathered hits in (first, second) order, as an unstreamed step gives them.
    t = clock::now();
    if (params_.mode != CcdMode::earliest)
      for (int k = 0; k < 2; ++k) gathered_sorter_.sort(gathered_[k], gathered_outcome_.num_hits[k], features_.num_features());
    for (int k = 0; k < 2; ++k) gathered_outcome_.hits[k] = gathered_[k].data();
    LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
    stats.narrow_ms += ms_since(t);
  }

  // The current traversal output's candidates through the feature pairs and the narrow phase.
  void test_traversal_output(const CcdParams<T>& ccd, StepStats& stats) {
    stats.triangle_pairs += traversal_.num_results();
    test_candidates(traversal_.results(), traversal_.num_results(), false, ccd, stats);
  }

  // Stops recording this step's front for the next one (which then starts from the root; this tree
  // keeps no front) and frees what it held. False when none was being recorded.
  bool give_up_next_front() {
    if (!recording_front_) return false;
    recording_front_ = false;
    front_refused_generation_ = bvh_.generation();
    next_front_ = DeviceBuffer<NodePair>();
    traversal_.front_ = DeviceBuffer<NodePair>();  // regrown to one entry by a traversal without a front
    return true;
  }

  // The bytes one traversal part's outputs may grow to under the budget.
  std::size_t traversal_output_limit() const {
    return static_cast<std::size_t>(StreamingPolicy::kTraversalShare * static_cast<double>(room_));
  }

  // Bytes the scheduler's lists may take for one traversal part's seeds, and per seed: the seed and
  // the items it first expands to.
  std::size_t seed_list_bytes() const {
    return static_cast<std::size_t>(StreamingPolicy::kSeedListShare * static_cast<double>(room_));
  }
  static constexpr std::size_t seed_bytes() { return sizeof(NodePair) * (1 + Task::kMaxChildren); }

  // Bytes a part's feature pairs and narrow phase may hold: the budget less everything else held
  // now, less what the traversal's outputs may still grow to in this step and a reserve for
  // gathering and sorting the hits so far (so nothing later passes the budget; a front is kept
  // only where it fits beside).
  std::size_t narrow_allowance() const {
    if (!params_.device_memory_budget) return kUnlimited;
    const std::size_t others = held_beside_parts();
    return params_.device_memory_budget > others ? params_.device_memory_budget - others : 0;
  }
  // What narrow_allowance() leaves out of the budget.
  std::size_t held_beside_parts() const {
    const std::size_t own = emitter_.list_bytes() + narrow_.device_bytes();
    const std::size_t outputs = traversal_.results_.capacity_bytes() + traversal_.front_.capacity_bytes();
    const std::size_t limit = traversal_output_limit();
    std::size_t later = limit > outputs ? limit - outputs : 0;
    // The scheduler's lists of a part's seeds (and of what they first expand to) may still grow.
    const std::size_t seed_lists = traversal_.work_.capacity_bytes() + traversal_.next_.capacity_bytes();
    if (seed_list_bytes() > seed_lists) later += seed_list_bytes() - seed_lists;
    const std::size_t gathered = gathered_outcome_.num_hits[0] + gathered_outcome_.num_hits[1];
    later += gathered * (2 * sizeof(FeatureHit<T>) + 24) * 5 / 4;  // keys, sorted copy, CUB's temporary
    return device_bytes() - own + later;
  }

  // Candidates [0, n), or (orphans) the orphan pairs, in parts whose feature pairs and narrow
  // phase fit narrow_allowance(). The first part of a step also computes the feature boxes.
  void test_candidates(const TrianglePair* candidates, std::size_t n, bool orphans, const CcdParams<T>& ccd, StepStats& stats) {
    using clock = std::chrono::steady_clock;
    auto ms_since = [](clock::time_point t) { return std::chrono::duration<double, std::milli>(clock::now() - t).count(); };
    using OrphanRange = typename FeatureEmitter<>::OrphanRange;
    if (orphans) n = emitter_.num_orphans();
    constexpr std::size_t bytes_per_pair = StreamingPolicy::bytes_per_feature_pair<T>();
    // Items (candidates or orphans) per part: the estimate the last part of this kind left, at
    // first a guess from their usual numbers of pairs; never above PipelineParams::part_pairs.
    const std::size_t cap = params_.part_pairs ? params_.part_pairs : kUnlimited;
    std::size_t& estimate = orphans ? orphans_per_part_ : candidates_per_part_;
    auto guess = [&] {
      const double per_item = StreamingPolicy::kBytesPerCandidate +
                              (orphans ? 1.0 : StreamingPolicy::kPairsPerCandidateGuess) * static_cast<double>(bytes_per_pair);
      return std::max<std::size_t>(
          1, static_cast<std::size_t>(std::min(1e18, StreamingPolicy::kPartMargin * static_cast<double>(narrow_allowance()) / per_item)));
    };
    std::size_t part = std::min(estimate ? estimate : guess(), cap);
    for (std::size_t first = 0; first < n || !boxes_current_;) {
      const std::size_t count = std::min(part, n - first);
      auto t = clock::now();
      if (orphans)
        emitter_.enqueue(step_->x0.data(), step_->x1.data(), static_cast<const TrianglePair*>(nullptr), 0, nullptr,
                         OrphanRange{first, count}, boxes_current_);
      else
        emitter_.enqueue(step_->x0.data(), step_->x1.data(), candidates + first, count, nullptr, OrphanRange{}, boxes_current_);
      boxes_current_ = true;  // the feature boxes are this step's from the first part on
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(nullptr));
      const auto counted = emitter_.counted();
      const std::size_t pairs = counted.first + counted.second;
      std::size_t allowed = narrow_allowance();
      const std::size_t need = pairs * bytes_per_pair + count * StreamingPolicy::kBytesPerCandidate;
      // Before refusing, the front being recorded for the next step goes: it is an optimisation,
      // and without this a step from a grown front could refuse a budget that earlier steps met.
      if (allowed < StreamingPolicy::kLeastPartBytes && need > allowed && give_up_next_front()) allowed = narrow_allowance();
      if (allowed < StreamingPolicy::kLeastPartBytes && need > allowed)
        throw Error("gpu::CcdPipeline: the device memory budget of " + std::to_string(params_.device_memory_budget) +
                    " bytes leaves " + std::to_string(allowed) + " for the feature pairs and the narrow phase (the mesh's data take " +
                    std::to_string(resident_bytes()) + ", the traversal " + std::to_string(traversal_.device_bytes()) +
                    "); give it at least " + std::to_string(held_beside_parts() + StreamingPolicy::kLeastPartBytes) + " bytes");
      // The items a part of this density may have (with a margin: density varies along the list).
      // Parts are sized from it both ways, so they neither overrun nor stay small.
      const std::size_t fits =
          need ? std::max<std::size_t>(1, static_cast<std::size_t>(StreamingPolicy::kPartMargin * static_cast<double>(count) *
                                                                   static_cast<double>(allowed) / static_cast<double>(need)))
               : part;
      if (count > 1 && need > allowed) {
        part = std::min(fits, count - 1);
        ++stats.reruns;
        stats.features_ms += ms_since(t);
        continue;
      }
      if (count) part = std::min(fits, cap);
      if (!emitter_.collect()) LWSCCD_CUDA_CHECK(cudaStreamSynchronize(nullptr));
      stats.feature_pairs_vf += emitter_.num_vf();
      stats.feature_pairs_ee += emitter_.num_ee();
      stats.features_ms += ms_since(t);
      first += count;
      if (count == 0) break;  // nothing to test (the feature boxes only)
      t = clock::now();
      narrow_.run(features_, step_->x0.data(), step_->x1.data(), emitter_.vf_list(), emitter_.ee_list(), ccd);
      gather_hits();
      stats.narrow_ms += ms_since(t);
      ++stats.narrow_parts;
    }
    if (n) estimate = part;
  }

  // Adds the narrow phase's last run to what the step's parts found.
  void gather_hits() {
    Outcome& o = gathered_outcome_;
    const bool pairs = params_.mode != CcdMode::earliest;
    const std::size_t found[2] = {narrow_.num_vf_hits(), narrow_.num_ee_hits()};
    const FeatureHit<T>* hits[2] = {narrow_.vf_hits(), narrow_.ee_hits()};
    for (int k = 0; k < 2 && pairs; ++k) {
      if (!found[k]) continue;
      gathered_[k].resize_keep(o.num_hits[k] + found[k], (o.num_hits[k] + found[k]) * 3 / 2);
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(gathered_[k].data() + o.num_hits[k], hits[k], found[k] * sizeof(FeatureHit<T>),
                                        cudaMemcpyDeviceToDevice));
      o.num_hits[k] += found[k];
    }
    o.earliest = std::min(o.earliest, narrow_.earliest_toi());
    o.gave_up += narrow_.gave_up();
    o.survivors += narrow_.survivors();
    o.warp_searches += narrow_.warp_searches();
    for (int k = 0; k < 2; ++k) add_counts(o.counts[k], narrow_.counts(k));
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
  bool rebuild_due_ = false;  ///< the last refit found the tree decayed: build before the next traversal
  TraversalOutput<Task> traversal_;
  DeviceBuffer<NodePair> seeds_, root_;
  std::size_t front_size_ = 0, size_at_restart_ = 0;
  std::uint64_t generation_ = ~std::uint64_t(0);
  bool reset_next_ = false;
  bool emitter_sized_ = false;  ///< the emitter's buffers have been sized by a step
  NarrowPhase<Method, T> narrow_;
  cudaEvent_t mark_[5];  ///< stage boundaries: refit, traversal, feature pairs, narrow phase
  // Streaming under a budget:
  bool streamed_ = false;                        ///< the last step was streamed
  bool refit_pending_ = false;                   ///< this step's refit reads await collect_refit()
  bool restarted_ = false;                       ///< this step's traversal started from the root
  DeviceBuffer<NodePair> cut_, next_front_;      ///< a cut below the root; the front being recorded
  DeviceBuffer<FeatureHit<T>> gathered_[2];      ///< the parts' hits (vertex-face, edge-edge)
  HitSorter<T> gathered_sorter_;
  Outcome gathered_outcome_{};
  std::size_t seeds_per_part_ = 0, candidates_per_part_ = 0, orphans_per_part_ = 0;  ///< part sizes that fitted last
  std::size_t room_ = 0;                   ///< this step's room beside the resident data
  bool boxes_current_ = false;             ///< the feature boxes are this step's
  DeviceBuffer<TrianglePair> met_;         ///< candidates the expansion below the root met
  std::size_t met_size_ = 0;
  std::uint64_t front_refused_generation_ = ~std::uint64_t(0);  ///< the tree on which a front did not fit
  bool recording_front_ = false;           ///< this streamed step records the front for the next one
};

}  // namespace lwsccd::gpu
