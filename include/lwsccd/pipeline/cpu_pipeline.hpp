// lwsccd — the end-to-end CCD pipeline, CPU backend (the types both backends share are in
// pipeline_types.hpp).
//
// One object per mesh topology: set up once (BVH, representative triangles and their orphans),
// then step(x0, x1) per time step: refit (or rebuild when the tree decayed), BVTT self-collision
// traversal from the kept front, the feature pairs that the non-adjacent candidate triangle pairs
// represent plus the orphans, each produced once and kept when their feature boxes overlap
// (representative.hpp), and the narrow phase. gpu::CcdPipeline (pipeline.cuh) is the same on the GPU.
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "lwsccd/bvh/bvh.hpp"
#include "lwsccd/core/parallel.hpp"
#include "lwsccd/features/orphans.hpp"
#include "lwsccd/features/representative.hpp"
#include "lwsccd/narrow_phase/certified_ccd.hpp"
#include "lwsccd/narrow_phase/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.hpp"
#include "lwsccd/pipeline/pipeline_types.hpp"
#include "lwsccd/pipeline/stage_sequence.hpp"
#include "lwsccd/traversal/bvtt.hpp"
#include "lwsccd/traversal/cpu_traverse.hpp"

namespace lwsccd {

namespace cpu {

/// The pipeline on the CPU backend: every core, or PipelineParams::threads (on oneTBB where the
/// build has it: core/parallel.hpp).
template <class BV = Aabbf, class Method = CertifiedCcd, class T = double>
class CcdPipeline {
 public:
  /// One self-colliding body.
  explicit CcdPipeline(std::shared_ptr<const TriangleMesh> mesh, PipelineParams params = {})
      : CcdPipeline(std::move(mesh), BodyLayout{}, params) {}
  /// Several bodies: pairs inside a body that does not self-collide are never looked at (its
  /// subtrees are pruned whole in the traversal, its orphan pairs dropped).
  CcdPipeline(std::shared_ptr<const TriangleMesh> mesh, BodyLayout layout, PipelineParams params = {})
      : mesh_(detail::checked_mesh(std::move(mesh), "cpu::CcdPipeline")), layout_(std::move(layout)), self_collides_(detail::self_collision_flags(layout_)),
        params_(detail::validated(params)), threads_(params_.threads),
        representatives_(threads_.run([&] { return RepresentativeTriangles(*mesh_, layout_); })),  // (on the pipeline's threads)
        tracker_(FrontPolicy{detail::front_growth_limit_of(params, kCpuFrontGrowthLimit)}) {
    // Features that come within min_separation: their boxes, each grown by half of it, overlap.
    bvh_.set_leaf_margin(params_.min_separation / 2);
  }

  /// One step: the vertices move from x0 to x1 (mesh().num_vertices() points each).
  StepResult<T> step(const std::vector<Vec3d>& x0, const std::vector<Vec3d>& x1) {
    StepResult<T> r;
    StepInProgress step{r, x0, x1};
    // The lists' memory of the last step, reused (fresh pages cost page faults, which serialise threads).
    step.candidates.swap(candidates_);
    step.features.vf.swap(features_.vf);
    step.features.ee.swap(features_.ee);
    threads_.run([&] { lwsccd::detail::run_stage_sequence(*this, step); });
    candidates_.swap(step.candidates);
    features_.vf.swap(step.features.vf);
    features_.ee.swap(step.features.ee);
    r.stats.total_ms = ms_since(step.start);
    return r;
  }
  /// The same from float positions, widened first (exactly: the answers are certified for the
  /// float positions as given, and equal the GPU backend's for them).
  StepResult<T> step(const std::vector<Vec3f>& x0, const std::vector<Vec3f>& x1) {
    auto widen = [](const std::vector<Vec3f>& from, std::vector<Vec3d>& to) {
      to.resize(from.size());
      for (std::size_t v = 0; v < from.size(); ++v) to[v] = from[v].template cast<double>();
    };
    widen(x0, wide0_);
    widen(x1, wide1_);
    return step(wide0_, wide1_);
  }

  /// The next step traverses the BVTT from its root instead of from the last step's front (as
  /// gpu::CcdPipeline::restart_from_root; same answer either way).
  void restart_from_root() { tracker_.restart_next(); }

  const TriangleMesh& mesh() const { return *mesh_; }
  const BodyLayout& layout() const { return layout_; }
  const PipelineParams& params() const { return params_; }

 private:
  using Task = SelfCollisionTask<BV>;
  using clock = std::chrono::steady_clock;
  static double ms_since(clock::time_point t) { return std::chrono::duration<double, std::milli>(clock::now() - t).count(); }

  // One step on its way through the stages (lwsccd::detail::run_stage_sequence): its result, its
  // positions, what each stage hands the next and, in a step in parts (PipelineParams::
  // part_pairs), where the parts have got to.
  struct StepInProgress {
    StepInProgress(StepResult<T>& r, const std::vector<Vec3d>& from, const std::vector<Vec3d>& to) : result(r), x0(from), x1(to) {}
    StepResult<T>& result;
    const std::vector<Vec3d>& x0;
    const std::vector<Vec3d>& x1;
    clock::time_point start = clock::now(), stage_start = start;
    bool in_parts = false;
    std::size_t cap = 0;  ///< candidates (and seeds) per part; a whole step: no limit
    // Traversal parts: the step's seeds (in parts after a restart, the cut below the root once the
    // expansion made it), the next seed to traverse and how many a part takes.
    const ListsOf<NodePair>* seeds = nullptr;
    ListsOf<NodePair> cut;
    bool seeds_chosen = false, expansion_due = false, traversal_over = false;
    std::size_t next_seed = 0, seeds_per_part = 0;
    std::vector<NodePair> front;  ///< in parts: the front the parts recorded, kept at the end
    // Narrow-phase parts: the current traversal part's candidates (a whole step: where the
    // traversal's threads wrote them, `candidate_lists`), the next one to test, this part's range
    // and whether the orphans' pairs (those no candidate emits) go with it.
    std::vector<TrianglePair> candidates;
    const ListsOf<TrianglePair>* candidate_lists = nullptr;
    std::size_t num_candidates = 0;
    std::size_t next_candidate = 0, part_first = 0, part_count = 0;
    bool orphans_due = true, orphans_in_part = false;
    std::vector<Aabbf> boxes;  ///< the step's feature boxes (computed by the first feature pairs)
    std::vector<FaceCorners> corners;  ///< with them, for the test of the faces' motion (contact only)
    bool boxes_ready = false;
    FeaturePairs features;
  };
  friend void lwsccd::detail::run_stage_sequence<CcdPipeline, StepInProgress>(CcdPipeline&, StepInProgress&);
  friend void lwsccd::detail::run_narrow_parts<CcdPipeline, StepInProgress>(CcdPipeline&, StepInProgress&);

  // Build on the first step, refit (or rebuild where the tree decayed) after it.
  void stage_refit(StepInProgress& step) {
    StepStats& stats = step.result.stats;
    if (!built_) {
      bvh_.build(*mesh_, step.x0, step.x1);
      built_ = stats.rebuilt = true;
    } else {
      stats.rebuilt = bvh_.refit_or_rebuild(step.x0, step.x1, RebuildPolicy{params_.rebuild_factor});
    }
    if (!self_collides_.empty() && bvh_.generation() != node_body_generation_) {
      node_body_ = node_bodies(bvh_.view(), layout_.face_body);  // topology changed
      node_body_generation_ = bvh_.generation();
    }
  }

  // A whole step: one traversal part, from the step's seeds. In parts: when the traversal restarts
  // from the root, first a cut below it (the expansion, a part of its own), then the seeds (the
  // kept front, or the cut) a part at a time.
  bool next_traversal_part(StepInProgress& step) {
    if (!step.seeds_chosen) {
      step.seeds_chosen = true;
      step.in_parts = params_.part_pairs > 0;
      step.cap = step.in_parts ? params_.part_pairs : ~std::size_t(0);
      step.seeds = &step_seeds(step.result.stats);  // sets restarted_from_root
      step.expansion_due = step.in_parts && step.result.stats.restarted_from_root;
      step.seeds_per_part = std::max<std::size_t>(1, std::min(step.seeds->size(), step.cap));
      if (!step.in_parts) return true;
    } else if (!step.in_parts) {
      return false;
    }
    step.traversal_over = !step.expansion_due && step.next_seed >= step.seeds->size();
    return !step.traversal_over;
  }

  // From the kept front (FrontTracker), or the root; in parts, the next part of the seeds, halved
  // while it yields more than `cap` candidates (down to one seed), or the expansion below the root.
  void stage_traversal(StepInProgress& step) {
    StepStats& stats = step.result.stats;
    const Task task = traversal_task();
    const bool record = params_.front_tracking;
    TraversalResult<Task>& traversal = traversal_;
    if (!step.in_parts) {
      // The results and front stay in the threads' lists (copying them into one list each would
      // cost a first step the page faults of 87 MB on cloth-ball): the front is kept as they are,
      // the feature pairs read the results there.
      const TraversalStats t = cpu::traverse_in_lists(task, *step.seeds, record, WorkStealingScheduler{}, traversal_workspace_);
      if (record) tracker_.exchange(traversal_workspace_.fronts);  // (the seeds, read no more, become the next front's memory)
      stats.front_size = tracker_.size();
      stats.bvtt_nodes += t.items_processed;
      stats.triangle_pairs += t.results;
      step.candidate_lists = &traversal_workspace_.results;
      step.num_candidates = t.results;
      step.next_candidate = 0;
      return;
    }
    if (step.expansion_due) {
      std::vector<NodePair> cut;
      traversal = expand(task, step.seeds->joined(), StreamingPolicy::kCutItems, record, cut);
      step.cut.lists.assign(1, std::move(cut));
      step.expansion_due = false;
      step.seeds = &step.cut;
      step.seeds_per_part = std::max<std::size_t>(1, std::min(step.cut.size(), step.cap));
    } else {
      const std::size_t num_seeds = step.seeds->size();
      std::size_t n = 0;
      while (true) {
        n = std::min(step.seeds_per_part, num_seeds - step.next_seed);
        std::vector<NodePair> part_seeds;
        part_seeds.reserve(n);
        step.seeds->for_each_in(step.next_seed, step.next_seed + n, [&](const NodePair& seed) { part_seeds.push_back(seed); });
        cpu::traverse_into(task, part_seeds, record, WorkStealingScheduler{}, traversal, traversal_workspace_);
        if (traversal.results.size() <= step.cap || n == 1) break;
        step.seeds_per_part = n / 2;
        ++stats.reruns;
      }
      ++stats.traversal_parts;
      step.next_seed += n;
      if (traversal.results.size() * 4 < step.cap) step.seeds_per_part = std::min(num_seeds, 2 * step.seeds_per_part);
    }
    step.front.insert(step.front.end(), traversal.front.begin(), traversal.front.end());
    stats.bvtt_nodes += traversal.stats.items_processed;
    stats.triangle_pairs += traversal.results.size();
    step.candidates.swap(traversal.results);  // (the last part's memory goes to the next traversal)
    step.next_candidate = 0;
  }

  // A whole step: one part, every candidate and the orphans. In parts: the candidates at most
  // `cap` at a time, then, once the traversal is over, the orphans in a part of their own.
  bool next_narrow_part(StepInProgress& step) {
    if (!step.in_parts) {  // the one part: every candidate, with the orphans
      if (!step.orphans_due) return false;
      step.orphans_due = false;
      step.orphans_in_part = true;
      step.part_first = 0;
      step.part_count = step.num_candidates;
      return true;
    }
    const bool candidates_left = step.next_candidate < step.candidates.size();
    step.orphans_in_part = !candidates_left && step.traversal_over && step.orphans_due;
    if (!candidates_left && !step.orphans_in_part) return false;
    step.part_first = step.next_candidate;
    step.part_count = std::min(step.cap, step.candidates.size() - step.next_candidate);
    step.next_candidate += step.part_count;
    if (step.orphans_in_part) step.orphans_due = false;
    return true;
  }
  void stage_feature_pairs(StepInProgress& step) {
    // Candidates whose faces are apart by their relative motion give no pairs (faces_apart, as the
    // GPU's emission): a test of contact, so not with a minimum separation.
    const bool test_motion = !(params_.min_separation > 0);
    if (!step.boxes_ready) {
      step.boxes = feature_boxes(*mesh_, step.x0, step.x1, params_.min_separation / 2);
      if (test_motion) step.corners = face_corners(*mesh_, step.x0, step.x1);
    }
    step.boxes_ready = true;
    const std::vector<FaceCorners>* corners = test_motion ? &step.corners : nullptr;
    StepStats& stats = step.result.stats;
    if (step.in_parts) {
      emit_feature_pairs_into(representatives_, step.candidates.data() + step.part_first, step.part_count, step.boxes,
                              step.orphans_in_part, step.features, feature_parts_, corners);
      stats.feature_pairs_vf += step.features.vf.size();
      stats.feature_pairs_ee += step.features.ee.size();
      return;
    }
    // A whole step's pairs stay in the lists the threads filled: the narrow phase reads them there.
    emit_feature_pairs_into(representatives_, step.candidate_lists->lists, step.boxes, step.orphans_in_part, feature_parts_,
                            corners);
    stats.feature_pairs_vf += feature_parts_.vf_size();
    stats.feature_pairs_ee += feature_parts_.ee_size();
  }
  void stage_narrow_phase(StepInProgress& step) {
    StepResult<T>& r = step.result;
    if (!step.in_parts) {
      r.contacts = test_feature_pairs<Method, T>(*mesh_, step.x0, step.x1, feature_parts_, ccd_params());
      return;
    }
    NarrowPhaseResult<T> found = test_feature_pairs<Method, T>(*mesh_, step.x0, step.x1, step.features, ccd_params());
    add_narrow_phase_part(found, r.contacts);  // sorted once every part is in (complete_step)
    ++r.stats.narrow_parts;
  }
  // A stage's time, measured from the end of the one before (a step in parts adds up its parts').
  void stage_done(lwsccd::detail::PipelineStage stage, StepInProgress& step) {
    lwsccd::detail::add_stage_time(step.result.stats, stage, ms_since(step.stage_start));
    step.stage_start = clock::now();
  }
  void complete_step(StepInProgress& step) {
    StepResult<T>& r = step.result;
    if (step.in_parts) {  // the parts' front kept, their hits in the order a whole step gives them
      if (params_.front_tracking) {
        ListsOf<NodePair> front;
        front.lists.push_back(std::move(step.front));
        tracker_.update(std::move(front));
      }
      r.stats.front_size = tracker_.size();
      sort_by_pair(r.contacts.vf);
      sort_by_pair(r.contacts.ee);
    }
    r.stats.narrow_vf = r.contacts.vf_counts;
    r.stats.narrow_ee = r.contacts.ee_counts;
    r.stats.hits_vf = r.contacts.vf.size();
    r.stats.hits_ee = r.contacts.ee.size();
    r.stats.gave_up = r.contacts.gave_up;
  }

  Task traversal_task() const {
    const bool bodies = !self_collides_.empty();
    return Task{bvh_.view(), LeafFilter{bodies ? layout_.face_body.data() : nullptr, bodies ? self_collides_.data() : nullptr,
                                        mesh_->faces().data(), true, bodies ? node_body_.data() : nullptr}};
  }
  // The step's seeds: the tracked front, or the root (also when front tracking is off).
  const ListsOf<NodePair>& step_seeds(StepStats& stats) {
    const ListsOf<NodePair>& seeds = params_.front_tracking ? tracker_.seeds(bvh_.generation()) : root_;
    stats.restarted_from_root = !params_.front_tracking || tracker_.last_was_restart();
    return seeds;
  }

  CcdParams<T> ccd_params() const { return detail::ccd_params_of<T>(params_); }

  std::shared_ptr<const TriangleMesh> mesh_;
  BodyLayout layout_;
  std::vector<unsigned char> self_collides_;  ///< empty: no body pruning
  std::vector<index_t> node_body_;
  std::uint64_t node_body_generation_ = ~std::uint64_t(0);
  PipelineParams params_;
  ThreadLimit threads_;
  RepresentativeTriangles representatives_;
  Bvh<BV> bvh_;
  bool built_ = false;
  BasicFrontTracker<ListsOf<NodePair>> tracker_;  ///< the front in the lists the traversal's threads wrote
  ListsOf<NodePair> root_{NodePair{0, 0}};  // the root alone (never changed; not const: pipelines are assignable)
  std::vector<Vec3d> wide0_, wide1_;  ///< float input, widened (kept: the next step reuses the room)
  // Memory kept from step to step (a warm step allocates no large list): the traversal's threads'
  // lists (a whole step's candidates and front, read there), a step in parts' traversal result and
  // candidates, the feature pairs and their per-thread lists.
  TraversalResult<Task> traversal_;
  TraversalWorkspace<Task> traversal_workspace_;
  std::vector<TrianglePair> candidates_;
  FeaturePairs features_;          ///< a step in parts: a part's feature pairs in one list
  FeaturePairParts feature_parts_;  ///< the threads' lists of feature pairs (a whole step's pairs)
};

}  // namespace cpu

}  // namespace lwsccd
