// lwsccd — gpu::CcdPipeline's step in parts: the stages of lwsccd::detail::run_stage_sequence
// when a step streams (a device-memory budget, or PipelineParams::part_pairs). The traversal runs
// from its seeds (the kept front, or a cut of the BVTT below the root) a part at a time; each
// part's candidates go through the feature pairs and the narrow phase in parts that fit; the pairs
// the cut met and the orphans follow the traversal; the hits gather on the device and are sorted
// once. Same answer as a whole step, a synchronisation per part.
//
// Member definitions of gpu::CcdPipeline (declared in pipeline/gpu_pipeline.cuh): include that
// header, not this file.
#pragma once

#include <algorithm>
#include <chrono>
#include <string>
#include <utility>
#include <vector>

namespace lwsccd::gpu {

// The refit, waited for (its reads are needed before the parts are sized).
template <class BV, class Scheduler, class Method, class T>
void CcdPipeline<BV, Scheduler, Method, T>::refit_part(StepInProgress& step) {
  refit_stage(step.stats, true);
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream_));
}

// The budget checked against what the step holds after its refit, the hits so far cleared, and
// the seeds chosen: the kept front, or (a restart) the root, cut below first.
template <class BV, class Scheduler, class Method, class T>
void CcdPipeline<BV, Scheduler, Method, T>::plan_parts(StepInProgress& step) {
  step.planned = true;
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
  step.budget = budget;
  gathered_outcome_ = Outcome{{nullptr, nullptr}, {0, 0}, T(1), 0, 0, 0, {}};
  step.ccd = ccd_params();
  boxes_current_ = false;  // the first part to emit feature pairs computes the step's feature boxes
  room_ = room;

  const std::uint64_t generation = bvh_.generation();
  recording_front_ = params_.front_tracking && front_refused_generation_ != generation;
  step.restart = !params_.front_tracking || generation != generation_ || front_size_ == 0 || reset_next_;
  generation_ = generation;
  step.front_room = static_cast<std::size_t>(StreamingPolicy::kFrontShare * static_cast<double>(room));
  step.next_front = 0;
  step.seeds = seeds_.data();
  step.num_seeds = front_size_;
  step.expansion_due = step.restart;
  if (step.restart) {
    seeds_ = DeviceBuffer<NodePair>();  // an old front is of no use from the root: its room goes to the parts
  } else {
    start_seed_parts(step);
  }
}

// The size of the seeds' first part: what the last step's parts ended with, within what the
// scheduler's lists may take for them (a part's seeds take a few entries each there) and
// PipelineParams::part_pairs.
template <class BV, class Scheduler, class Method, class T>
void CcdPipeline<BV, Scheduler, Method, T>::start_seed_parts(StepInProgress& step) {
  step.max_seeds_per_part = std::max<std::size_t>(1, seed_list_bytes() / seed_bytes());
  step.seeds_per_part = std::min(seeds_per_part_ ? seeds_per_part_ : step.num_seeds, step.max_seeds_per_part);
  if (params_.part_pairs) step.seeds_per_part = std::min(step.seeds_per_part, std::max<std::size_t>(1, params_.part_pairs));
}

// First the cut below the root (a restart), then the seeds a part at a time.
template <class BV, class Scheduler, class Method, class T>
bool CcdPipeline<BV, Scheduler, Method, T>::next_traversal_part_in_parts(StepInProgress& step) {
  if (!step.planned) plan_parts(step);
  if (step.expansion_due || step.next_seed < step.num_seeds) return true;
  if (!step.traversal_over) {
    traversal_.set_output_limit(0);
    seeds_per_part_ = step.seeds_per_part;
    step.traversal_over = true;
  }
  return false;
}

// The cut below the root (what the expansion met is tested after the parts, once the scheduler's
// own lists hold their room: the parts' narrow phase is sized around them), or the next part of
// the seeds, halved while it yields more than a part may have.
template <class BV, class Scheduler, class Method, class T>
void CcdPipeline<BV, Scheduler, Method, T>::traversal_part(StepInProgress& step) {
  StepStats& stats = step.stats;
  const Task task = traversal_task();
  const std::size_t budget = step.budget;
  if (step.expansion_due) {
    step.expansion_due = false;
    root_.upload(std::vector<NodePair>{NodePair{0, 0}}, stream_);
    traversal_.set_output_limit(traversal_output_limit());
    step.num_seeds = expand(task, root_.data(), 1, StreamingPolicy::kCutItems, traversal_, recording_front_, stream_);
    if (!traversal_.complete())
      throw Error("gpu::CcdPipeline: the device memory budget of " + std::to_string(budget) +
                  " bytes cannot hold the first levels of the traversal; give it more");
    cut_.resize_discard(std::max<std::size_t>(step.num_seeds, 1));
    if (step.num_seeds)
      LWSCCD_CUDA_CHECK(
          cudaMemcpyAsync(cut_.data(), traversal_.expanded(), step.num_seeds * sizeof(NodePair), cudaMemcpyDeviceToDevice, stream_));
    step.seeds = cut_.data();
    stats.bvtt_nodes += traversal_.stats().items_processed;
    stats.traversal_relaunches += traversal_.stats().relaunches;
    keep_part_front(step);
    met_.resize_discard(std::max<std::size_t>(traversal_.num_results(), 1));
    met_size_ = traversal_.num_results();
    stats.triangle_pairs += met_size_;
    if (met_size_)
      LWSCCD_CUDA_CHECK(
          cudaMemcpyAsync(met_.data(), traversal_.results(), met_size_ * sizeof(TrianglePair), cudaMemcpyDeviceToDevice, stream_));
    start_seed_parts(step);
    return;
  }
  const std::size_t cap = params_.part_pairs;
  std::size_t n = 0;
  while (true) {
    n = std::min(step.seeds_per_part, step.num_seeds - step.next_seed);
    traversal_.set_output_limit(traversal_output_limit());
    traverse<Scheduler>(task, step.seeds + step.next_seed, n, traversal_, recording_front_, stream_);
    if (traversal_.complete() && cap && traversal_.num_results() > cap && n > 1) {
      step.seeds_per_part = n / 2;  // more candidates than a part may have: fewer seeds
      ++stats.reruns;
      continue;
    }
    if (!traversal_.complete()) {
      if (n == 1)
        throw Error("gpu::CcdPipeline: the device memory budget of " + std::to_string(budget) +
                    " bytes cannot hold what one node pair of the traversal yields; give it more");
      step.seeds_per_part = n / 2;
      ++stats.reruns;
      continue;
    }
    break;
  }
  stats.bvtt_nodes += traversal_.stats().items_processed;
  stats.traversal_relaunches += traversal_.stats().relaunches;
  keep_part_front(step);
  ++stats.traversal_parts;
  step.next_seed += n;
  // Parts whose outputs took under a quarter of their room may double.
  const std::size_t used = traversal_.num_results() * sizeof(TrianglePair) + traversal_.num_front() * sizeof(NodePair);
  if (used * 4 < traversal_.output_limit() && (!cap || traversal_.num_results() * 4 < cap))
    step.seeds_per_part = std::min({step.num_seeds, 2 * step.seeds_per_part, step.max_seeds_per_part});
  stats.triangle_pairs += traversal_.num_results();
  open_candidates(step, StepInProgress::Source::traversal, traversal_.results(), traversal_.num_results());
}

// Keeps the traversal part's front entries for the next step while they fit their share and the
// budget has room for them now (the front is an optimisation: the parts' narrow phase does not
// leave room for it).
template <class BV, class Scheduler, class Method, class T>
void CcdPipeline<BV, Scheduler, Method, T>::keep_part_front(StepInProgress& step) {
  if (!recording_front_) return;
  const std::size_t n = traversal_.num_front();
  const std::size_t kept_seeds = step.restart ? 0 : seeds_.capacity_bytes();
  const std::size_t wanted = (step.next_front + n) * sizeof(NodePair) * 5 / 4;
  const std::size_t grows = (step.next_front + n) * sizeof(NodePair) > next_front_.capacity_bytes() ? wanted : 0;
  if (kept_seeds + wanted > step.front_room || device_bytes() + grows > step.budget) {
    give_up_next_front();
    return;
  }
  next_front_.resize_keep(step.next_front + n, (step.next_front + n) * 5 / 4, stream_);
  if (n)
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(next_front_.data() + step.next_front, traversal_.front(), n * sizeof(NodePair),
                                      cudaMemcpyDeviceToDevice, stream_));
  step.next_front += n;
}

// Candidates [0, n) (or, for the orphans, the orphan pairs) for the narrow-phase parts, in parts
// of the estimate the last candidates of this kind left, at first a guess from their usual
// numbers of pairs; never above PipelineParams::part_pairs.
template <class BV, class Scheduler, class Method, class T>
void CcdPipeline<BV, Scheduler, Method, T>::open_candidates(StepInProgress& step, typename StepInProgress::Source source,
                                                            const TrianglePair* candidates, std::size_t n) {
  const bool orphans = source == StepInProgress::Source::orphans;
  step.source = source;
  step.candidates = candidates;
  step.num_candidates = orphans ? emitter_.num_orphans() : n;
  step.next_candidate = 0;
  constexpr std::size_t bytes_per_pair = StreamingPolicy::bytes_per_feature_pair<T>();
  const std::size_t estimate = orphans ? orphans_per_part_ : candidates_per_part_;
  auto guess = [&] {
    const double per_item = StreamingPolicy::kBytesPerCandidate +
                            (orphans ? 1.0 : StreamingPolicy::kPairsPerCandidateGuess) * static_cast<double>(bytes_per_pair);
    return std::max<std::size_t>(
        1, static_cast<std::size_t>(std::min(1e18, StreamingPolicy::kPartMargin * static_cast<double>(narrow_allowance()) / per_item)));
  };
  step.part_size = std::min(estimate ? estimate : guess(), params_.part_pairs ? params_.part_pairs : kUnlimited);
}

// The next part of the open candidates (the first part of a step also computes the feature boxes,
// with no candidates if need be); once they are through, after the traversal, the pairs the cut
// met, then the orphans.
template <class BV, class Scheduler, class Method, class T>
bool CcdPipeline<BV, Scheduler, Method, T>::next_narrow_part_in_parts(StepInProgress& step) {
  using Source = typename StepInProgress::Source;
  while (true) {
    if (step.source != Source::none) {
      if (step.next_candidate < step.num_candidates || !boxes_current_) return true;
      // Through: the part size these candidates ended with is the next ones' estimate.
      if (step.num_candidates) (step.source == Source::orphans ? orphans_per_part_ : candidates_per_part_) = step.part_size;
      if (step.source == Source::met) {
        met_size_ = 0;
        met_ = DeviceBuffer<TrianglePair>();  // tested: its room goes back to the orphans' parts
      }
      step.source = Source::none;
    }
    if (!step.traversal_over) return false;
    if (step.last_source == Source::none) {  // the pairs the cut below the root met
      step.last_source = Source::met;
      if (met_size_) {
        open_candidates(step, Source::met, met_.data(), met_size_);
      } else {
        met_size_ = 0;
        met_ = DeviceBuffer<TrianglePair>();
      }
    } else if (step.last_source == Source::met) {  // the orphans (pairs no candidate emits)
      step.last_source = Source::orphans;
      open_candidates(step, Source::orphans, nullptr, 0);
    } else {
      return false;
    }
  }
}

// The part's feature pairs, counted first: a part whose pairs and narrow phase would not fit
// narrow_allowance() is counted again smaller.
template <class BV, class Scheduler, class Method, class T>
void CcdPipeline<BV, Scheduler, Method, T>::feature_pairs_part(StepInProgress& step) {
  using OrphanRange = typename FeatureEmitter<>::OrphanRange;
  StepStats& stats = step.stats;
  const bool orphans = step.source == StepInProgress::Source::orphans;
  const std::size_t cap = params_.part_pairs ? params_.part_pairs : kUnlimited;
  constexpr std::size_t bytes_per_pair = StreamingPolicy::bytes_per_feature_pair<T>();
  while (true) {
    const std::size_t first = step.next_candidate;
    const std::size_t count = std::min(step.part_size, step.num_candidates - first);
    if (orphans)
      emitter_.enqueue(step_->x0_data(), step_->x1_data(), static_cast<const TrianglePair*>(nullptr), 0, stream_,
                       OrphanRange{first, count}, boxes_current_);
    else
      emitter_.enqueue(step_->x0_data(), step_->x1_data(), step.candidates + first, count, stream_, OrphanRange{}, boxes_current_);
    boxes_current_ = true;  // the feature boxes are this step's from the first part on
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream_));
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
             : step.part_size;
    if (count > 1 && need > allowed) {
      step.part_size = std::min(fits, count - 1);
      ++stats.reruns;
      continue;
    }
    if (count) step.part_size = std::min(fits, cap);
    if (!emitter_.collect(stream_)) LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream_));
    stats.feature_pairs_vf += emitter_.num_vf();
    stats.feature_pairs_ee += emitter_.num_ee();
    step.part_first = first;
    step.part_count = count;
    step.next_candidate = first + count;
    return;
  }
}

// The part's narrow phase, its hits added to the step's (none for a part that only computed the
// feature boxes).
template <class BV, class Scheduler, class Method, class T>
void CcdPipeline<BV, Scheduler, Method, T>::narrow_phase_part(StepInProgress& step) {
  if (step.part_count == 0) return;
  narrow_.run(features_, step_->x0_data(), step_->x1_data(), emitter_.vf_list(), emitter_.ee_list(), step.ccd, stream_);
  gather_hits();
  ++step.stats.narrow_parts;
}

// Adds the narrow phase's last run to what the step's parts found.
template <class BV, class Scheduler, class Method, class T>
void CcdPipeline<BV, Scheduler, Method, T>::gather_hits() {
  Outcome& o = gathered_outcome_;
  const bool pairs = params_.mode != CcdMode::earliest;
  const std::size_t found[2] = {narrow_.num_vf_hits(), narrow_.num_ee_hits()};
  const FeatureHit<T>* hits[2] = {narrow_.vf_hits(), narrow_.ee_hits()};
  for (int k = 0; k < 2 && pairs; ++k) {
    if (!found[k]) continue;
    gathered_[k].resize_keep(o.num_hits[k] + found[k], (o.num_hits[k] + found[k]) * 3 / 2, stream_);
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(gathered_[k].data() + o.num_hits[k], hits[k], found[k] * sizeof(FeatureHit<T>),
                                      cudaMemcpyDeviceToDevice, stream_));
    o.num_hits[k] += found[k];
  }
  o.earliest = std::min(o.earliest, narrow_.earliest_toi());
  o.gave_up += narrow_.gave_up();
  o.survivors += narrow_.survivors();
  o.warp_searches += narrow_.warp_searches();
  for (int k = 0; k < 2; ++k) add_counts(o.counts[k], narrow_.counts(k));
}

// The front for the next step (when it was kept whole), and the gathered hits in (first, second)
// order, as a whole step gives them.
template <class BV, class Scheduler, class Method, class T>
void CcdPipeline<BV, Scheduler, Method, T>::complete_step_in_parts(StepInProgress& step) {
  StepStats& stats = step.stats;
  if (recording_front_) {
    std::swap(seeds_, next_front_);
    front_size_ = step.next_front;
    if (step.restart) size_at_restart_ = front_size_;
    reset_next_ = front_past_growth_limit();
  } else {
    front_size_ = 0;
    seeds_ = DeviceBuffer<NodePair>();
  }
  next_front_ = DeviceBuffer<NodePair>();
  stats.restarted_from_root = step.restart;
  stats.front_size = front_size_;
  using clock = std::chrono::steady_clock;
  const auto t = clock::now();
  if (params_.mode != CcdMode::earliest)
    for (int k = 0; k < 2; ++k) gathered_sorter_.sort(gathered_[k], gathered_outcome_.num_hits[k], features_.num_features(), stream_);
  for (int k = 0; k < 2; ++k) gathered_outcome_.hits[k] = gathered_[k].data();
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream_));
  // The lazy scheduler's lists grow with the items its blocks hand back, which vary from run to
  // run: where they took the step past its budget, they go (the next traversal makes them again).
  if (params_.device_memory_budget && device_bytes() > params_.device_memory_budget) traversal_.release_scratch();
  stats.narrow_ms += std::chrono::duration<double, std::milli>(clock::now() - t).count();
}

// Stops recording this step's front for the next one (which then starts from the root; this tree
// keeps no front) and frees what it held. False when none was being recorded.
template <class BV, class Scheduler, class Method, class T>
bool CcdPipeline<BV, Scheduler, Method, T>::give_up_next_front() {
  if (!recording_front_) return false;
  recording_front_ = false;
  front_refused_generation_ = bvh_.generation();
  next_front_ = DeviceBuffer<NodePair>();
  traversal_.release_front();  // regrown to one entry by a traversal without a front
  return true;
}

// What narrow_allowance() leaves out of the budget: everything held now but the parts' own lists,
// what the traversal's outputs and the scheduler's lists of a part's seeds may still grow to in
// this step, and a reserve for gathering and sorting the hits so far.
template <class BV, class Scheduler, class Method, class T>
std::size_t CcdPipeline<BV, Scheduler, Method, T>::held_beside_parts() const {
  const std::size_t own = emitter_.list_bytes() + narrow_.device_bytes();
  const std::size_t outputs = traversal_.output_bytes();
  const std::size_t limit = traversal_output_limit();
  std::size_t later = limit > outputs ? limit - outputs : 0;
  // The scheduler's lists of a part's seeds (and of what they first expand to) may still grow.
  const std::size_t seed_lists = traversal_.seed_list_bytes();
  if (seed_list_bytes() > seed_lists) later += seed_list_bytes() - seed_lists;
  const std::size_t gathered = gathered_outcome_.num_hits[0] + gathered_outcome_.num_hits[1];
  later += gathered * (2 * sizeof(FeatureHit<T>) + 24) * 5 / 4;  // keys, sorted copy, CUB's temporary
  return device_bytes() - own + later;
}

}  // namespace lwsccd::gpu
