// lwsccd — gpu::CcdPipeline's whole step (no budget, no parts): the refit with its reads left on
// their way to the host, the nodes' bodies after a build, the traversal from the kept front or the
// root, the feature pairs enqueued, and the step's one wait, where what outgrew its buffer runs
// again and the front the traversal recorded becomes the next step's seeds.
//
// Member definitions of gpu::CcdPipeline (declared in pipeline/gpu_pipeline.cuh): include that
// header, not this file.
#pragma once

#include <cub/device/device_scan.cuh>

#include <algorithm>
#include <vector>

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

template <class BV, class Scheduler, class Method, class T>
bool CcdPipeline<BV, Scheduler, Method, T>::refit_stage(StepStats& stats, bool wait) {
  bool pending = false;
  if (!built_ || rebuild_due_) {
    step_->enqueue_widening(stream_);  // (the build reads the positions more than once)
    bvh_.build(*step_, stream_);
    built_ = stats.rebuilt = true;
    rebuild_due_ = false;
  } else if (wait) {
    stats.rebuilt = bvh_.refit_or_rebuild(*step_, RebuildPolicy{params_.rebuild_factor}, stream_);
  } else {
    bvh_.refit(*step_, stream_);  // (its reads: start_side_work)
    pending = true;
  }
  if (face_body_.size() && bvh_.generation() != node_body_generation_) update_node_bodies();
  return pending;
}

template <class BV, class Scheduler, class Method, class T>
void CcdPipeline<BV, Scheduler, Method, T>::collect_refit() {
  try {
    rebuild_due_ = bvh_.collect_refit(RebuildPolicy{params_.rebuild_factor}, stream_);
  } catch (...) {
    front_size_ = 0;
    throw;
  }
}

template <class BV, class Scheduler, class Method, class T>
void CcdPipeline<BV, Scheduler, Method, T>::enqueue_feature_pairs() {
  using OrphanRange = typename FeatureEmitter<>::OrphanRange;
  // A share of a split step tests its share of the orphans (all of them where there is one share).
  const std::size_t orphans = emitter_.num_orphans();
  const std::size_t first = orphans * share_index_ / share_count_, end = orphans * (share_index_ + 1) / share_count_;
  if (side_open_) join_side_work();  // (the feature boxes)
  emitter_.enqueue(step_->x0_data(), step_->x1_data(), traversal_.results(), traversal_.result_count(), stream_,
                   OrphanRange{first, end - first}, boxes_current_);
  if (!emitter_sized_) {
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream_));
    if (!emitter_.collect(stream_)) LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream_));
  }
  emitter_sized_ = true;
}

template <class BV, class Scheduler, class Method, class T>
void CcdPipeline<BV, Scheduler, Method, T>::complete_whole_step(StepInProgress& step) {
  StepStats& stats = step.stats;
  while (true) {
    LWSCCD_CUDA_CHECK(cudaEventSynchronize(mark_[4]));
    if (refit_pending_) collect_refit();
    refit_pending_ = false;
    if (!traversal_.collect()) {  // an output or a deque overflowed: the traversal again, waiting
      traverse<Scheduler>(traversal_task(), seeds_.data(), front_size_, traversal_, params_.front_tracking, stream_);
      enqueue_feature_pairs();
      ++stats.reruns;
    } else if (emitter_.collect(stream_) && narrow_.collect()) {
      break;
    } else {
      ++stats.reruns;
    }
    enqueue_narrow_phase();
    stage_done(lwsccd::detail::PipelineStage::narrow_phase, step);
  }
  keep_front(restarted_, stats);
  stats.refit_ms = elapsed(mark_[0], mark_[1]);
  stats.traverse_ms = elapsed(mark_[1], mark_[2]);
  stats.features_ms = elapsed(mark_[2], mark_[3]);
  stats.narrow_ms = elapsed(mark_[3], mark_[4]);
  stats.feature_pairs_vf = emitter_.num_vf();
  stats.feature_pairs_ee = emitter_.num_ee();
}

template <class BV, class Scheduler, class Method, class T>
void CcdPipeline<BV, Scheduler, Method, T>::update_node_bodies() {
  const BvhView<BV> view = bvh_.view();
  const index_t n = view.num_leaves;
  body_changes_.resize_discard(static_cast<std::size_t>(n));
  node_body_.resize_discard(static_cast<std::size_t>(view.num_nodes()));
  detail::body_change_kernel<<<static_cast<unsigned>((n + 255) / 256), 256, 0, stream_>>>(view.leaf_primitive, n,
                                                                                          face_body_.data(), body_changes_.data());
  LWSCCD_CUDA_CHECK_LAUNCH();
  std::size_t bytes = 0;
  LWSCCD_CUDA_CHECK(cub::DeviceScan::InclusiveSum(nullptr, bytes, body_changes_.data(), body_changes_.data(), n, stream_));
  scratch_.resize_discard(std::max({bytes, scratch_.size(), std::size_t(1)}));
  LWSCCD_CUDA_CHECK(
      cub::DeviceScan::InclusiveSum(scratch_.data(), bytes, body_changes_.data(), body_changes_.data(), n, stream_));
  detail::node_body_kernel<<<static_cast<unsigned>((view.num_nodes() + 255) / 256), 256, 0, stream_>>>(
      view, body_changes_.data(), face_body_.data(), node_body_.data());
  LWSCCD_CUDA_CHECK_LAUNCH();
  node_body_generation_ = bvh_.generation();
}

template <class BV, class Scheduler, class Method, class T>
bool CcdPipeline<BV, Scheduler, Method, T>::traverse_step() {
  const Task task = traversal_task();
  // A share of a split step restarts only when told (every share at once): an empty front is then
  // its share of the BVTT with nothing on it.
  const bool shared = share_count_ > 1;
  const bool restart =
      !params_.front_tracking || bvh_.generation() != generation_ || (front_size_ == 0 && !shared) || reset_next_;
  generation_ = bvh_.generation();
  if (restart && shared) {
    // Enough pairs per share that pairs of uneven work even out (cloth-ball: ~1.3 M node pairs from the root).
    const std::size_t n = share_cut_.make(bvh_.view(), task.filter, StreamingPolicy::kCutItems * share_count_, share_index_,
                                          share_count_, cut_, stream_);
    traverse<Scheduler>(task, cut_.data(), n, traversal_, params_.front_tracking, stream_);
  } else if (restart) {
    root_.upload(std::vector<NodePair>{NodePair{0, 0}}, stream_);
    traverse<Scheduler>(task, root_.data(), 1, traversal_, params_.front_tracking, stream_);
  } else {
    traverse_async<Scheduler>(task, seeds_.data(), front_size_, traversal_, true, stream_);
  }
  return restart;
}

template <class BV, class Scheduler, class Method, class T>
void CcdPipeline<BV, Scheduler, Method, T>::keep_front(bool restart, StepStats& stats) {
  stats.front_outgrown = !traversal_.front_complete();
  if (params_.front_tracking && !stats.front_outgrown) {
    front_size_ = traversal_.num_front();
    // Room for the next front to grow by a quarter (horse-gallop's grows by up to a fifth a
    // step): the spare buffer's whole capacity where that suffices, else half as much again.
    const std::size_t need = front_size_ + front_size_ / 4;
    const std::size_t capacity = seeds_.capacity_bytes() / sizeof(NodePair);
    traversal_.exchange_front(seeds_, capacity >= need ? capacity : front_size_ + front_size_ / 2);
    if (restart) size_at_restart_ = front_size_;
    reset_next_ = front_past_growth_limit();
  }
  stats.restarted_from_root = restart;
  stats.bvtt_nodes = traversal_.stats().items_processed;
  stats.traversal_relaunches = traversal_.stats().relaunches;
  stats.front_size = front_size_;
  stats.triangle_pairs = traversal_.num_results();
}

}  // namespace lwsccd::gpu
