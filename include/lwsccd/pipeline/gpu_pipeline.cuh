// lwsccd — the end-to-end CCD pipeline on the GPU: same API and same answers as
// cpu::CcdPipeline (cpu_pipeline.hpp; the types both share are in pipeline_types.hpp). Everything
// between the positions' upload and the hits' download stays on the device: refit (or rebuild),
// traversal from the front kept on the device, feature pairs produced once (representative
// triangles, culled by their boxes), the narrow phase. The feature pairs and the narrow phase run
// without a host round trip: their lengths stay on the device, and the host reads them once, after
// the narrow phase (stage times are events, read then too).
//
// Under a device-memory budget (PipelineParams::device_memory_budget), or with parts asked for
// (PipelineParams::part_pairs), a step runs in parts instead (detail/gpu_step_in_parts.cuh): the
// traversal runs from its seeds (the kept front, or a cut of the BVTT below the root) a part at a
// time, and each part's triangle pairs go through the feature pairs and the narrow phase in parts
// that fit; the hits gather on the device and are sorted once. Same answer, more synchronisations.
#pragma once

#include <algorithm>
#include <memory>
#include <utility>
#include <vector>

#include "lwsccd/bvh/bvh.cuh"
#include "lwsccd/core/cuda_handles.cuh"
#include "lwsccd/features/representative.cuh"
#include "lwsccd/narrow_phase/narrow_phase.cuh"
#include "lwsccd/pipeline/detail/bvtt_share.cuh"
#include "lwsccd/pipeline/pipeline_types.hpp"
#include "lwsccd/pipeline/stage_sequence.hpp"
#include "lwsccd/traversal/gpu_traverse.cuh"

namespace lwsccd::gpu {

template <class BV = Aabbf, class Scheduler = LazyStealScheduler, class Method = CertifiedCcd, class T = double>
class CcdPipeline {
 public:
  using Task = SelfCollisionTask<BV>;
  using scalar_type = T;  ///< the narrow phase's scalar (the contacts' TOIs)

  /// One self-colliding body. The topology is uploaded on `stream`, which the constructor
  /// synchronizes (so that a step on any stream finds it on the device).
  explicit CcdPipeline(std::shared_ptr<const TriangleMesh> mesh, PipelineParams params = {}, cudaStream_t stream = nullptr)
      : CcdPipeline(std::move(mesh), BodyLayout{}, params, stream) {}
  /// Several bodies (as cpu::CcdPipeline: a body that does not self-collide costs no traversal).
  CcdPipeline(std::shared_ptr<const TriangleMesh> mesh, BodyLayout layout, PipelineParams params = {},
              cudaStream_t stream = nullptr)
      : mesh_(lwsccd::detail::checked_mesh(std::move(mesh), "gpu::CcdPipeline")), layout_(std::move(layout)),
        params_(lwsccd::detail::validated(params)), features_(*mesh_, stream),
        emitter_(RepresentativeTriangles(*mesh_, layout_), stream) {
    // Features that come within min_separation: their boxes, each grown by half of it, overlap.
    bvh_.set_leaf_margin(params_.min_separation / 2);
    emitter_.set_box_margin(params_.min_separation / 2);
    narrow_.plan_for_fp64_ratio(params_.fp64_ratio);
    const std::vector<unsigned char> self_collides = lwsccd::detail::self_collision_flags(layout_);
    if (!self_collides.empty()) {
      face_body_.upload(layout_.face_body, stream);
      self_collides_.upload(self_collides, stream);
    }
    for (auto& e : mark_) e = CudaEvent(cudaEventDefault);
    side_ = CudaStream(cudaStreamNonBlocking);
    for (CudaEvent* e : {&side_fork_, &side_refit_, &side_join_}) *e = CudaEvent(cudaEventDisableTiming);
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
  }
  CcdPipeline(const CcdPipeline&) = delete;
  CcdPipeline& operator=(const CcdPipeline&) = delete;
  /// Movable: the moved-to pipeline keeps the moved-from one's device data, front and buffers, and
  /// steps on as it would have; the moved-from one may only be destroyed or assigned to.
  CcdPipeline(CcdPipeline&&) = default;
  CcdPipeline& operator=(CcdPipeline&&) = default;

  // Streams: every step takes the stream its work is ordered on (default: the default stream).
  // The step's work runs on `stream` (the narrow phase's two lists and the work beside the
  // traversal on streams of their own, forked from it and joined back), so positions written on
  // `stream` before the call are read in order, and nothing else of the program is waited for.
  // Each step synchronizes `stream`, not the device, once at its end (to read its counts), and
  // more often on a first step (to size its buffers) and in a step in parts (a part at a time);
  // growing a buffer (cudaMalloc / cudaFree) may synchronize the device, which a warm step does
  // not do.

  /// One step from host positions (validated, uploaded). Positions are double (Vec3d) or float
  /// (Vec3f): float input crosses as float and is widened on the device, exactly, so the answers
  /// are certified for the float positions as given.
  /// @note Synchronizes `stream`.
  StepResult<T> step(const std::vector<Vec3d>& x0, const std::vector<Vec3d>& x1, cudaStream_t stream = nullptr) {
    StepResult<T> r;
    step_from_host(Span<const Vec3d>(x0), Span<const Vec3d>(x1), r, stream);
    return r;
  }
  StepResult<T> step(const std::vector<Vec3f>& x0, const std::vector<Vec3f>& x1, cudaStream_t stream = nullptr) {
    StepResult<T> r;
    step_from_host(Span<const Vec3f>(x0), Span<const Vec3f>(x1), r, stream);
    return r;
  }

  /// As step, from any host arrays (a std::vector, a NumPy array's memory: they may change once
  /// the call returns), into `result`, whose contact lists' memory is reused: a loop that keeps
  /// one StepResult pays no page faults for its contacts (on a virtual machine's host, ~2 us a
  /// page: cloth-ball's 114 K contacts are 450 pages). Large arrays cross through the process's
  /// page-locked chunks (HostStaging), the contacts too.
  /// @note Synchronizes `stream`.
  void step_into(Span<const Vec3d> x0, Span<const Vec3d> x1, StepResult<T>& result, cudaStream_t stream = nullptr) {
    step_from_host(x0, x1, result, stream);
  }
  void step_into(Span<const Vec3f> x0, Span<const Vec3f> x1, StepResult<T>& result, cudaStream_t stream = nullptr) {
    step_from_host(x0, x1, result, stream);
  }

  /// One step from positions already in device memory (mesh().num_vertices() points each, e.g.
  /// a simulation's own arrays; double ones read in place, float ones read in place by the refit
  /// and widened on the device beside it for the later stages): no
  /// host round trip for them, and no copy of double ones (free to change once the call returns).
  /// They are read in `stream`'s order: a kernel that wrote them on `stream` needs no host
  /// synchronisation before the call. Throws InputError for host pointers.
  /// @note Synchronizes `stream`.
  StepResult<T> step_from_device(const Vec3d* device_x0, const Vec3d* device_x1, cudaStream_t stream = nullptr) {
    return from_device(device_x0, device_x1, stream);
  }
  StepResult<T> step_from_device(const Vec3f* device_x0, const Vec3f* device_x1, cudaStream_t stream = nullptr) {
    return from_device(device_x0, device_x1, stream);
  }

  /// As step_from_device, with the contacts left in device memory (sorted by pair, valid until the
  /// next step): nothing crosses to the host but the counters the step reads once. Work enqueued
  /// on `stream` after the call reads the contacts in order.
  /// @note Synchronizes `stream`.
  DeviceStepResult<T> step_on_device(const Vec3d* device_x0, const Vec3d* device_x1, cudaStream_t stream = nullptr) {
    return on_device(device_x0, device_x1, stream);
  }
  DeviceStepResult<T> step_on_device(const Vec3f* device_x0, const Vec3f* device_x1, cudaStream_t stream = nullptr) {
    return on_device(device_x0, device_x1, stream);
  }

  /// The next step traverses the BVTT from its root instead of from the last step's front. Same
  /// answer either way: the front is a cut of the BVTT whatever the positions. For a caller who
  /// knows the last front is far larger than the next step needs; on the shared scenes a front
  /// from unrelated positions was still faster than the root (docs/PIPELINE.md, fresh steps), so
  /// the pipeline never restarts on its own for that.
  void restart_from_root() { reset_next_ = true; }

  // ---- One share of a step split over devices (gpu::MultiGpuPipeline drives these) ----

  /// From now on this pipeline finds only share `index` of `count` of each step's contacts. From
  /// the root, its traversal starts from every count-th node pair of a cut of the BVTT made from
  /// the tree's topology alone (the same cut on every device holding the same tree), and it takes
  /// the same share of the orphans; later steps start from its own front. `count` pipelines over
  /// the same positions, each with its share, find each contact exactly once, provided they
  /// rebuild their trees in the same steps and restart from the root together (rebuild_due(),
  /// wants_restart(); the front's entries may move between them: kept_front()). Throws InputError
  /// for index >= count, and for a split step that would stream (a budget or part_pairs).
  void set_share(std::size_t index, std::size_t count) {
    if (count == 0 || index >= count)
      throw InputError("gpu::CcdPipeline::set_share", "index", std::to_string(index) + " is not below the count " + std::to_string(count));
    if (count > 1 && (params_.device_memory_budget || params_.part_pairs))
      throw InputError("gpu::CcdPipeline::set_share", "params",
                       "a step split over devices does not stream: device_memory_budget and part_pairs must be 0");
    share_index_ = index;
    share_count_ = count;
    reset_next_ = true;
  }
  std::size_t share_index() const { return share_index_; }
  std::size_t share_count() const { return share_count_; }
  /// After a step: the last refit found the tree decayed, so the next step rebuilds it.
  bool rebuild_due() const { return rebuild_due_; }
  /// The next step rebuilds the tree (and so restarts from the root).
  void rebuild_next() { rebuild_due_ = true; }
  /// After a step: the next one would start from the root (its front grew past the limit, or a
  /// restart was asked for).
  bool wants_restart() const { return reset_next_ || rebuild_due_ || !params_.front_tracking; }
  /// The next step's seeds, the front kept on the device (kept_front_size() node pairs, on the
  /// stream of the last step). A split step moves entries between devices through these: each
  /// entry is a part of the BVTT on its own.
  NodePair* kept_front() { return seeds_.data(); }
  std::size_t kept_front_size() const { return front_size_; }
  /// Keeps `n` entries of the front: fewer drops the last ones (moved elsewhere); more keeps the
  /// entries there and makes room after them for the caller to fill on `stream` (moved here).
  void resize_kept_front(std::size_t n, cudaStream_t stream) {
    if (n > front_size_ && n > seeds_.capacity_bytes() / sizeof(NodePair)) {
      DeviceBuffer<NodePair> bigger(n + n / 4);
      if (front_size_)
        LWSCCD_CUDA_CHECK(cudaMemcpyAsync(bigger.data(), seeds_.data(), front_size_ * sizeof(NodePair), cudaMemcpyDeviceToDevice, stream));
      seeds_ = std::move(bigger);
    }
    // The growth limit compares against the size at the restart: moved entries move that too.
    size_at_restart_ = n > front_size_ ? size_at_restart_ + (n - front_size_) : size_at_restart_ - std::min(size_at_restart_, front_size_ - n);
    front_size_ = n;
  }

  const TriangleMesh& mesh() const { return *mesh_; }
  const BodyLayout& layout() const { return layout_; }
  const PipelineParams& params() const { return params_; }

  /// Device bytes this pipeline holds now (every buffer's capacity; they are kept between steps).
  std::size_t device_bytes() const { return memory_use().total(); }
  /// Of those, what no split of a step can reduce: topology, positions, the BVH, the feature boxes.
  std::size_t resident_bytes() const { return memory_use().resident(); }
  /// The same bytes by what they are held for (StepStats::device_memory reports it after a step).
  DeviceMemoryUse memory_use() const {
    DeviceMemoryUse m;
    if (step_)
      m.mesh = step_->faces.capacity_bytes() + step_->x0.capacity_bytes() + step_->x1.capacity_bytes() + step_->float_input_bytes();
    m.mesh += face_body_.capacity_bytes() + node_body_.capacity_bytes() + body_changes_.capacity_bytes() +
              self_collides_.capacity_bytes();
    m.bvh = bvh_.device_bytes();
    m.feature_boxes = features_.faces.capacity_bytes() + features_.edges.capacity_bytes() + emitter_.device_bytes() - emitter_.list_bytes();
    m.candidates = traversal_.results_bytes() + met_.capacity_bytes();
    m.front = traversal_.front_bytes() + seeds_.capacity_bytes() + root_.capacity_bytes() + cut_.capacity_bytes() +
              next_front_.capacity_bytes();
    m.scheduler = traversal_.device_bytes() - traversal_.results_bytes() - traversal_.front_bytes();
    m.feature_pairs = emitter_.list_bytes();
    m.narrow_hits = narrow_.hit_bytes();
    m.narrow_work = narrow_.device_bytes() - narrow_.hit_bytes();
    m.other = scratch_.capacity_bytes() + gathered_[0].capacity_bytes() + gathered_[1].capacity_bytes() +
              gathered_sorter_.device_bytes() + share_cut_.device_bytes();
    return m;
  }
  /// The budget streamed steps keep to (PipelineParams::device_memory_budget; 0: no streaming).
  /// It may change between steps (e.g. as the application's own use of the device changes).
  void set_device_memory_budget(std::size_t bytes) { params_.device_memory_budget = bytes; }

 private:
  template <class Q>
  void step_from_host(Span<const Vec3<Q>> x0, Span<const Vec3<Q>> x1, StepResult<T>& result, cudaStream_t stream) {
    begin_step();
    const auto start = std::chrono::steady_clock::now();
    stream_ = stream;
    if (!step_) step_ = std::make_unique<DeviceStep<double>>(*mesh_, stream_);
    // Float input crosses as float and is then handled as float device positions are (the refit
    // reads it in place, the vertices' rounding for the narrow phase widens it): no kernel more
    // than a double step.
    if constexpr (std::is_same<Q, float>::value) step_->upload_to_widen_later(x0, x1, stream_);
    else step_->set_positions(x0, x1, stream_);
    run_step(result, start);
  }
  template <class Q>
  StepResult<T> from_device(const Vec3<Q>* device_x0, const Vec3<Q>* device_x1, cudaStream_t stream) {
    begin_step();
    const auto start = std::chrono::steady_clock::now();
    stream_ = stream;
    set_device_positions(device_x0, device_x1);
    StepResult<T> r;
    run_step(r, start);
    return r;
  }
  template <class Q>
  DeviceStepResult<T> on_device(const Vec3<Q>* device_x0, const Vec3<Q>* device_x1, cudaStream_t stream) {
    begin_step();
    const auto start = std::chrono::steady_clock::now();
    stream_ = stream;
    set_device_positions(device_x0, device_x1);
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
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream_));  // the hits' sort is done
    finish_stats(r.stats, r.contacts.num_vf, r.contacts.num_ee, start);
    return r;
  }

  // Positions in device memory, read where they are (the step ends before the call returns):
  // double ones throughout; float ones by the refit, and widened into the step's arrays for the
  // later stages beside it (start_side_work; before a build, or a step in parts, on the step's
  // stream). Why: the copies or conversions and their launches came before the step's first
  // kernel, ~20 us of a device-resident cloth-ball step.
  template <class Q>
  void set_device_positions(const Vec3<Q>* device_x0, const Vec3<Q>* device_x1) {
    if (!step_) step_ = std::make_unique<DeviceStep<double>>(*mesh_, stream_);
    if constexpr (std::is_same<Q, double>::value) step_->use_device_positions(device_x0, device_x1);
    else step_->widen_later(device_x0, device_x1);
  }

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

  // The stages, then the contacts into `r` (its lists' memory reused) through page-locked chunks.
  void run_step(StepResult<T>& r, std::chrono::steady_clock::time_point start) {
    r.stats = StepStats{};
    run_stages(r.stats);
    if (!streamed_) {
      narrow_.download_into(r.contacts, stream_);
    } else {
      const Outcome& o = gathered_outcome_;
      const bool pairs = params_.mode != CcdMode::earliest;
      for (int list = 0; list < 2; ++list) {
        std::vector<FeatureHit<T>>& hits = list == 0 ? r.contacts.vf : r.contacts.ee;
        hits.resize(pairs ? o.num_hits[list] : 0);
        HostStaging<>::to_host(hits.data(), gathered_[list].data(), hits.size() * sizeof(FeatureHit<T>), stream_);
      }
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream_));  // (also with no hits)
      r.contacts.earliest_toi = o.earliest;
      r.contacts.gave_up = o.gave_up;
      r.contacts.vf_counts = o.counts[0];
      r.contacts.ee_counts = o.counts[1];
    }
    finish_stats(r.stats, r.contacts.vf.size(), r.contacts.ee.size(), start);
  }

  // A step's counts of memory start here: its peak, its cudaMalloc calls.
  void begin_step() {
    reset_peak_memory();
    allocations_before_ = memory_stats().allocations;
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
    stats.device_memory = memory_use();
    stats.device_allocations = memory_stats().allocations - allocations_before_;
    stats.total_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  }

  CcdParams<T> ccd_params() const { return lwsccd::detail::ccd_params_of<T>(params_); }

  // Build on the first step, or where the last step's refit found the tree decayed; refit
  // otherwise. `wait` false enqueues the refit's kernel alone: its reads (positions' status, the
  // cost) are then due (start_side_work enqueues them), for collect_refit() with the step's other
  // counters; the rebuild the cost calls for comes a step later. Returns whether reads are due.
  bool refit_stage(StepStats& stats, bool wait);

  // The refit's reads, once the step's stream has been synchronized. Non-finite positions throw
  // InputError; the front this step recorded (over boxes that were not finite) is then dropped.
  void collect_refit();

  // The feature pairs of the traversal's candidates, their number read on the device. The first
  // step waits for their numbers (to size their buffers); later steps reuse the room earlier
  // ones needed and leave the numbers on the device.
  void enqueue_feature_pairs();

  // One step on its way through the stages (lwsccd::detail::run_stage_sequence): its statistics
  // and, in a step streamed in parts, where the parts have got to.
  struct StepInProgress {
    explicit StepInProgress(StepStats& s) : stats(s) {}
    StepStats& stats;
    bool in_parts = false;
    bool traversed = false, tested = false;  ///< a whole step's one traversal part and one narrow part
    // In parts: stage times are host time, each stage waiting for its work.
    std::chrono::steady_clock::time_point stage_start = std::chrono::steady_clock::now();
    bool planned = false;          ///< the budget checked, the seeds chosen (the first traversal part)
    std::size_t budget = 0;        ///< the budget, or kUnlimited
    CcdParams<T> ccd;
    bool restart = false;          ///< this step's traversal starts from the root
    bool expansion_due = false;    ///< the cut below the root is still to be made (the first traversal part)
    bool traversal_over = false;
    std::size_t front_room = 0;    ///< the bytes the kept fronts may take
    std::size_t next_front = 0;    ///< entries of the next step's front recorded so far (next_front_)
    const NodePair* seeds = nullptr;
    std::size_t num_seeds = 0, next_seed = 0, seeds_per_part = 0, max_seeds_per_part = 0;
    // The candidates the narrow-phase parts go through now: a traversal part's, the pairs the cut
    // met, or the orphans; the next one to test; this part's range; the part size.
    enum class Source { none, traversal, met, orphans };
    Source source = Source::none;
    Source last_source = Source::none;  ///< the leftovers (met, orphans) opened so far after the traversal
    const TrianglePair* candidates = nullptr;
    std::size_t num_candidates = 0, next_candidate = 0, part_first = 0, part_count = 0, part_size = 0;
  };

  // Every stage of a step on the device (lwsccd::detail::run_stage_sequence). A whole step makes
  // one host round trip at its end (the refit's reads, the traversal's, the feature pairs' and the
  // narrow phase's counters); its narrow phase's hits stay there (sorted on the step's stream
  // once collected). A step in parts (a memory budget, or part_pairs) waits for each part.
  void run_stages(StepStats& stats) {
    streamed_ = params_.device_memory_budget > 0 || params_.part_pairs > 0;
    if (streamed_ && share_count_ > 1)  // (a budget set after set_share)
      throw InputError("gpu::CcdPipeline", "device_memory_budget", "a share of a step split over devices does not stream");
    StepInProgress step(stats);
    step.in_parts = streamed_;
    if (side_open_) {  // a step that threw before its join: nothing may overtake its side work
      join_side_work();
      narrow_.drop_positions_ahead();
    }
    if (streamed_) step_->enqueue_widening(stream_);  // (parts read the positions on the step's stream)
    if (!streamed_) {
      LWSCCD_CUDA_CHECK(cudaEventRecord(mark_[0], stream_));
      LWSCCD_CUDA_CHECK(cudaEventRecord(side_fork_, stream_));  // the positions are in place
    }
    lwsccd::detail::run_stage_sequence(*this, step);
  }

  // A whole step's work that reads only the positions (float ones widened, the feature boxes
  // packed by face, the vertices rounded to float; from side_fork_ on) and the refit's reads (status, cost; after the
  // refit's kernel), enqueued once the refit's kernel is (after a build: once the traversal is),
  // on side_ beside the refit and the traversal; the feature pairs wait for them (join_side_work).
  // Why: on the step's stream they ran between the refit and the traversal and between the
  // traversal and the emission, ~60 us of cloth-ball's steady step with the gaps between those
  // short launches (docs/PIPELINE.md, "GPU: the work beside the traversal").
  void start_side_work(bool refit_reads) {
    if (refit_reads) LWSCCD_CUDA_CHECK(cudaEventRecord(side_refit_, stream_));
    LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(side_, side_fork_, 0));
    if (step_->widening_due()) {  // float positions: widened by the kernel that rounds the vertices
      const auto [f0, f1] = step_->take_widening();
      narrow_.enqueue_positions_widened(features_, f0, f1, step_->x0.data(), step_->x1.data(), side_);
      emitter_.enqueue_boxes(step_->x0_data(), step_->x1_data(), side_);
    } else {
      emitter_.enqueue_boxes(step_->x0_data(), step_->x1_data(), side_);
      narrow_.enqueue_positions(features_, step_->x0_data(), step_->x1_data(), side_);
    }
    if (refit_reads) {
      LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(side_, side_refit_, 0));
      bvh_.enqueue_refit_reads(side_);
    }
    side_open_ = boxes_current_ = true;
  }
  void join_side_work() {
    LWSCCD_CUDA_CHECK(cudaEventRecord(side_join_, side_));
    LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(stream_, side_join_, 0));
    side_open_ = false;
  }

  // The stages as the sequence asks for them. In a whole step each enqueues its work on the
  // stream, and stage_done marks its end with an event (mark_[k + 1]; mark_[0] is the step's
  // start); in parts each waits for its work (pipeline/detail/gpu_step_in_parts.cuh), and
  // stage_done adds up host time.
  void stage_refit(StepInProgress& step) {
    if (step.in_parts) return refit_part(step);
    refit_pending_ = refit_stage(step.stats, false);
    if (refit_pending_) start_side_work(true);
  }
  bool next_traversal_part(StepInProgress& step) {
    if (step.in_parts) return next_traversal_part_in_parts(step);
    const bool first = !step.traversed;
    step.traversed = true;
    return first;
  }
  void stage_traversal(StepInProgress& step) {
    if (step.in_parts) return traversal_part(step);
    restarted_ = traverse_step();
    // After a build the side work waits until the traversal is enqueued: its first allocations
    // then cost no idle time between the two.
    if (!side_open_) start_side_work(false);
  }
  bool next_narrow_part(StepInProgress& step) {
    if (step.in_parts) return next_narrow_part_in_parts(step);
    const bool first = step.traversed && !step.tested;  // after the one traversal part
    step.tested = step.traversed;
    return first;
  }
  void stage_feature_pairs(StepInProgress& step) {
    if (step.in_parts) return feature_pairs_part(step);
    enqueue_feature_pairs();
  }
  void stage_narrow_phase(StepInProgress& step) {
    if (step.in_parts) return narrow_phase_part(step);
    enqueue_narrow_phase();
  }
  void stage_done(lwsccd::detail::PipelineStage stage, StepInProgress& step) {
    if (!step.in_parts) {
      LWSCCD_CUDA_CHECK(cudaEventRecord(mark_[static_cast<int>(stage) + 1], stream_));
      return;
    }
    using clock = std::chrono::steady_clock;
    lwsccd::detail::add_stage_time(step.stats, stage,
                                   std::chrono::duration<double, std::milli>(clock::now() - step.stage_start).count());
    step.stage_start = clock::now();
  }
  // A whole step's one wait: where a count outgrew its buffer, the buffer is grown and what read
  // the short list runs again. A step in parts: its front kept, its gathered hits sorted.
  void complete_step(StepInProgress& step) {
    if (step.in_parts) return complete_step_in_parts(step);
    complete_whole_step(step);
  }
  void complete_whole_step(StepInProgress& step);  // pipeline/detail/gpu_whole_step.cuh
  friend void lwsccd::detail::run_stage_sequence<CcdPipeline, StepInProgress>(CcdPipeline&, StepInProgress&);
  friend void lwsccd::detail::run_narrow_parts<CcdPipeline, StepInProgress>(CcdPipeline&, StepInProgress&);
  void enqueue_narrow_phase() {
    narrow_.enqueue(features_, step_->x0_data(), step_->x1_data(), emitter_.vf_list(), emitter_.ee_list(), ccd_params(), stream_);
  }

  // LeafFilter::node_body for the current tree (after a build: topology only).
  void update_node_bodies();

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
  bool traverse_step();

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
  void keep_front(bool restart, StepStats& stats);

  // ---- A step in parts (a device-memory budget, or PipelineParams::part_pairs) ----
  // The stages' parts, defined in pipeline/detail/gpu_step_in_parts.cuh.

  static constexpr std::size_t kUnlimited = std::size_t(1) << 60;

  void refit_part(StepInProgress& step);
  void plan_parts(StepInProgress& step);
  void start_seed_parts(StepInProgress& step);
  bool next_traversal_part_in_parts(StepInProgress& step);
  void traversal_part(StepInProgress& step);
  void keep_part_front(StepInProgress& step);
  void open_candidates(StepInProgress& step, typename StepInProgress::Source source, const TrianglePair* candidates,
                       std::size_t n);
  bool next_narrow_part_in_parts(StepInProgress& step);
  void feature_pairs_part(StepInProgress& step);
  void narrow_phase_part(StepInProgress& step);
  void gather_hits();
  void complete_step_in_parts(StepInProgress& step);
  bool give_up_next_front();
  std::size_t held_beside_parts() const;

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
  std::size_t allocations_before_ = 0;  ///< memory_stats().allocations when this step began
  NarrowPhase<Method, T> narrow_;
  cudaStream_t stream_ = nullptr;  ///< the current (or last) step's stream, the caller's
  CudaEvent mark_[5];  ///< stage boundaries: refit, traversal, feature pairs, narrow phase
  CudaStream side_;    ///< a whole step's work beside the refit and the traversal (start_side_work)
  CudaEvent side_fork_, side_refit_, side_join_;
  bool side_open_ = false;  ///< side_ holds work the step's stream has not waited for yet
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
  // A share of a step split over devices (set_share):
  std::size_t share_index_ = 0, share_count_ = 1;
  detail::BvttShareCut share_cut_;         ///< the topology cut a restart deals out
};

}  // namespace lwsccd::gpu

#include "lwsccd/pipeline/detail/gpu_whole_step.cuh"
#include "lwsccd/pipeline/detail/gpu_step_in_parts.cuh"
