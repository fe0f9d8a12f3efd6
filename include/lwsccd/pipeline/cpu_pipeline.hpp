// lwsccd — the end-to-end CCD pipeline, CPU backend, and the types both backends share.
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
#include "lwsccd/features/orphans.hpp"
#include "lwsccd/features/representative.hpp"
#include "lwsccd/narrow_phase/certified_ccd.hpp"
#include "lwsccd/narrow_phase/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.hpp"
#include "lwsccd/pipeline/stage_sequence.hpp"
#include "lwsccd/traversal/bvtt.hpp"
#include "lwsccd/traversal/cpu_traverse.hpp"

namespace lwsccd {

/// Run-time parameters of a pipeline.
struct PipelineParams {
  double min_separation = 0;     ///< report features closer than this (0: contact)
  double tolerance = 1e-6;       ///< time resolution of the TOI
  int max_iterations = 16384;    ///< narrow-phase work bound per pair (InclusionCcd)
  bool front_tracking = true;    ///< restart each traversal from the last front
  double rebuild_factor = 1.5;   ///< rebuild the BVH when its cost exceeds this times the cost at build
  /// Restart from the root once the front has grown this much since the last restart (>= 1, or
  /// 0: the backend's default, kCpuFrontGrowthLimit / kGpuFrontGrowthLimit).
  double front_growth_limit = 0;
  /// GPU backend: device bytes the pipeline may hold (0: no limit). Under a budget a step streams:
  /// its traversal, feature pairs and narrow phase run in parts that fit, with the same answer.
  std::size_t device_memory_budget = 0;
  /// Both backends: at most this many candidate triangle pairs go through the feature pairs and
  /// the narrow phase together, and the traversal runs from its seeds in parts of about as many
  /// candidates (0: no limit). A step in parts holds less memory at once; same answer.
  std::size_t part_pairs = 0;
  CcdMode mode = CcdMode::contacts;      ///< contacts, only the earliest TOI, or the colliding set (ccd_query.hpp)

  /// Throws InputError naming the first parameter out of range.
  void validate() const;
};

inline void PipelineParams::validate() const {
  auto require = [](bool ok, const char* name, const std::string& what) {
    if (!ok) throw InputError("PipelineParams", name, what);
  };
  require(min_separation >= 0 && std::isfinite(min_separation), "min_separation", "must be finite and >= 0");
  require(tolerance > 0 && tolerance < 1, "tolerance", "must be in (0, 1)");
  require(max_iterations >= 1, "max_iterations", "must be at least 1");
  require(rebuild_factor >= 1, "rebuild_factor", "must be >= 1 (1: rebuild every step)");
  require(front_growth_limit == 0 || front_growth_limit >= 1, "front_growth_limit",
          "must be >= 1, or 0 for the backend's default");
}

/// The CPU backend's front growth limit: a CPU pays as much for an item of a front as for one of a
/// traversal from the root, so a grown front soon costs more than a restart (horse-gallop on 2
/// cores, mean step: limit 1.5 -> 84 ms, 3 -> 104; docs/BENCHMARKS.md, fourteenth session).
inline constexpr double kCpuFrontGrowthLimit = 1.5;
/// The GPU backend's: a front goes through one flat launch, a thread per item, several times
/// cheaper per item than the lazy traversal from the root (H100, horse-gallop: 1.4 M front items
/// in 0.05-0.06 ms, 1.25 M node pairs from the root in 0.25-0.30), so a front may grow further
/// (mean step device-resident: limit 1.5 -> 0.56 ms with 11 restarts in 46 steps, 3 -> 0.50 with none).
inline constexpr double kGpuFrontGrowthLimit = 3;

namespace detail {
/// The growth limit a backend applies: the caller's, or the backend's default for 0.
inline double front_growth_limit_of(const PipelineParams& params, double backend_default) {
  return params.front_growth_limit > 0 ? params.front_growth_limit : backend_default;
}
}  // namespace detail

namespace detail {
inline PipelineParams validated(PipelineParams params) {
  params.validate();
  return params;
}
inline std::shared_ptr<const TriangleMesh> checked_mesh(std::shared_ptr<const TriangleMesh> mesh, const char* who) {
  if (!mesh) throw InputError(who, "mesh", "is null");
  return mesh;
}
// The narrow phase's parameters of a pipeline's.
template <class T>
CcdParams<T> ccd_params_of(const PipelineParams& params) {
  CcdParams<T> ccd;
  ccd.min_separation = static_cast<T>(params.min_separation);
  ccd.tolerance = static_cast<T>(params.tolerance);
  ccd.max_iterations = params.max_iterations;
  ccd.mode = params.mode;
  return ccd;
}
// BodyLayout::body_self_collides as bytes (device-friendly), empty when every body self-collides
// (then nothing is pruned by body).
inline std::vector<unsigned char> self_collision_flags(const BodyLayout& layout) {
  std::vector<unsigned char> flags(layout.body_self_collides.begin(), layout.body_self_collides.end());
  if (layout.face_body.empty() || std::all_of(flags.begin(), flags.end(), [](unsigned char f) { return f != 0; }))
    flags.clear();
  return flags;
}
}  // namespace detail

/// Knobs of a step run in parts (PipelineParams::part_pairs, and on the GPU under a device-memory
/// budget).
struct StreamingPolicy {
  /// A traversal from the root is first expanded breadth first into a cut of at least this many
  /// node pairs, which are then traversed a part at a time (both backends).
  static constexpr std::size_t kCutItems = std::size_t(1) << 15;
  // GPU, under a budget:
  /// Share of the room (budget less the resident data) that the kept fronts (the last step's and
  /// the one being recorded) may take; past it the next step starts from the root instead.
  static constexpr double kFrontShare = 0.35;
  /// Share of the room that one traversal part's outputs (candidate pairs, front) may take.
  static constexpr double kTraversalShare = 0.25;
  /// Share of the room that the scheduler's lists of one part's seeds (and of the items they first
  /// expand to) may take; it bounds the seeds of a part.
  static constexpr double kSeedListShare = 1.0 / 16;
  /// Device bytes a part may need per feature pair, counted as if every pair were a hit: its list
  /// entry, the narrow phase's work lists and a hit with its sort keys, each grown by a quarter.
  template <class T>
  static constexpr std::size_t bytes_per_feature_pair() {
    return (2 * sizeof(std::pair<index_t, index_t>) + 2 * sizeof(FeatureHit<T>) + 8 + 2 * sizeof(FeatureHit<T>) + 16) * 5 / 4;
  }
  /// Device bytes per candidate triangle pair of a part (its emission mask and block total).
  static constexpr std::size_t kBytesPerCandidate = 4;
  /// A part's next size is this share of what the last one's density of feature pairs would let
  /// fit (the density varies along the candidates; a part that overruns is counted again).
  static constexpr double kPartMargin = 0.8;
  /// Feature pairs per candidate triangle pair assumed before a step has counted any (the real
  /// scenes have 1.7-2.6; a wrong guess costs one counting pass).
  static constexpr double kPairsPerCandidateGuess = 3.0;
  /// A budget that leaves less than this for a part's feature pairs and narrow phase (beside the
  /// resident data, the traversal's lists and the hits so far) is refused with an error rather
  /// than run in parts of a few pairs.
  static constexpr std::size_t kLeastPartBytes = std::size_t(1) << 20;
};

/// What one step measured.
struct StepStats {
  double refit_ms = 0, traverse_ms = 0, features_ms = 0, narrow_ms = 0, total_ms = 0;
  std::size_t bvtt_nodes = 0, front_size = 0, triangle_pairs = 0, feature_pairs_vf = 0, feature_pairs_ee = 0;
  std::size_t hits_vf = 0, hits_ee = 0, gave_up = 0;
  std::size_t narrow_survivors = 0;      ///< GPU: pairs the narrow phase's first pass left for the full test
  std::size_t narrow_warp_searches = 0;  ///< GPU: of those, searched by a warp (still open after the thread's rounds)
  NarrowPhaseCounts narrow_vf, narrow_ee;  ///< certified hits / misses and fallbacks per list (CertifiedCcd)
  std::size_t peak_device_bytes = 0;
  /// GPU: stages enqueued again in this step because a list outgrew the room earlier steps gave
  /// it (the feature pairs' or the narrow phase's; nothing is lost, the step just costs more).
  std::size_t reruns = 0;
  /// A step in parts (PipelineParams::part_pairs, or a GPU budget): the traversal's parts and the
  /// narrow phase's parts (a part's candidates went through the feature pairs and the narrow
  /// phase together); 0: the step ran whole.
  std::size_t traversal_parts = 0, narrow_parts = 0;
  bool rebuilt = false, restarted_from_root = false;
  /// GPU: the front this step found outgrew its buffer (grown now). Its results are complete; the
  /// next step starts from this step's start instead (as valid a cut), with no rerun of this one.
  bool front_outgrown = false;
};

template <class T>
struct StepResult {
  NarrowPhaseResult<T> contacts;  ///< colliding VF and EE pairs with their TOI, earliest TOI
  StepStats stats;
};

/// A step's contacts left in device memory (gpu::CcdPipeline::step_on_device): the same pairs and
/// times as NarrowPhaseResult, sorted by pair, valid until the pipeline's next step.
template <class T>
struct DeviceContacts {
  const FeatureHit<T>* vf = nullptr;  ///< num_vf vertex-face hits (device memory)
  const FeatureHit<T>* ee = nullptr;  ///< num_ee edge-edge hits (device memory)
  std::size_t num_vf = 0, num_ee = 0;  ///< 0 in mode `earliest`
  T earliest_toi = T(1);
  std::size_t gave_up = 0;
  NarrowPhaseCounts vf_counts, ee_counts;
};

template <class T>
struct DeviceStepResult {
  DeviceContacts<T> contacts;
  StepStats stats;
};

namespace cpu {

/// The pipeline on the CPU backend (all cores).
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
        params_(detail::validated(params)), representatives_(*mesh_, layout_),
        tracker_(FrontPolicy{detail::front_growth_limit_of(params, kCpuFrontGrowthLimit)}) {
    // Features that come within min_separation: their boxes, each grown by half of it, overlap.
    bvh_.set_leaf_margin(params_.min_separation / 2);
  }

  StepResult<T> step(const std::vector<Vec3d>& x0, const std::vector<Vec3d>& x1) {
    StepResult<T> r;
    StepInProgress step{r, x0, x1};
    if (params_.part_pairs) {  // the traversal, feature pairs and narrow phase a part at a time
      stage_refit(step);
      stage_done(lwsccd::detail::PipelineStage::refit, step);
      const std::vector<NodePair>& seeds = step_seeds(r.stats);  // sets restarted_from_root, read next
      step_in_parts(traversal_task(), seeds, r.stats.restarted_from_root, x0, x1, r);
    } else {
      lwsccd::detail::run_stage_sequence(*this, step);
    }
    r.stats.total_ms = ms_since(step.start);
    return r;
  }

  const TriangleMesh& mesh() const { return *mesh_; }
  const BodyLayout& layout() const { return layout_; }
  const PipelineParams& params() const { return params_; }

 private:
  using Task = SelfCollisionTask<BV>;
  using clock = std::chrono::steady_clock;
  static double ms_since(clock::time_point t) { return std::chrono::duration<double, std::milli>(clock::now() - t).count(); }

  // One step on its way through the stages (lwsccd::detail::run_stage_sequence): its result, its
  // positions, and what each stage hands the next.
  struct StepInProgress {
    StepResult<T>& result;
    const std::vector<Vec3d>& x0;
    const std::vector<Vec3d>& x1;
    clock::time_point start = clock::now(), stage_start = start;
    std::vector<TrianglePair> candidates;
    FeaturePairs features;
  };
  friend void lwsccd::detail::run_stage_sequence<CcdPipeline, StepInProgress>(CcdPipeline&, StepInProgress&);

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
  // From the kept front (FrontTracker), or the root.
  void stage_traversal(StepInProgress& step) {
    StepStats& stats = step.result.stats;
    auto traversal = cpu::traverse(traversal_task(), step_seeds(stats), params_.front_tracking, WorkStealingScheduler{});
    if (params_.front_tracking) tracker_.update(std::move(traversal.front));
    stats.bvtt_nodes = traversal.stats.items_processed;
    stats.front_size = tracker_.size();
    stats.triangle_pairs = traversal.results.size();
    step.candidates = std::move(traversal.results);
  }
  void stage_feature_pairs(StepInProgress& step) {
    step.features = emit_feature_pairs(representatives_, step.candidates,
                                       feature_boxes(*mesh_, step.x0, step.x1, params_.min_separation / 2));
    step.result.stats.feature_pairs_vf = step.features.vf.size();
    step.result.stats.feature_pairs_ee = step.features.ee.size();
  }
  void stage_narrow_phase(StepInProgress& step) {
    StepResult<T>& r = step.result;
    r.contacts = test_feature_pairs<Method, T>(*mesh_, step.x0, step.x1, step.features, ccd_params());
    r.stats.narrow_vf = r.contacts.vf_counts;
    r.stats.narrow_ee = r.contacts.ee_counts;
  }
  // A stage's time, measured from the end of the one before.
  void stage_done(lwsccd::detail::PipelineStage stage, StepInProgress& step) {
    StepStats& stats = step.result.stats;
    double* times[lwsccd::detail::kPipelineStages] = {&stats.refit_ms, &stats.traverse_ms, &stats.features_ms, &stats.narrow_ms};
    *times[static_cast<int>(stage)] = ms_since(step.stage_start);
    step.stage_start = clock::now();
  }
  void complete_step(StepInProgress& step) {
    StepResult<T>& r = step.result;
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
  const std::vector<NodePair>& step_seeds(StepStats& stats) {
    const std::vector<NodePair>& seeds = params_.front_tracking ? tracker_.seeds(bvh_.generation()) : root_;
    stats.restarted_from_root = !params_.front_tracking || tracker_.last_was_restart();
    return seeds;
  }

  CcdParams<T> ccd_params() const { return detail::ccd_params_of<T>(params_); }

  // The step in parts (PipelineParams::part_pairs): a cut below the root when the traversal
  // restarts, traversed a part at a time; each part's candidates through the feature pairs and
  // the narrow phase in parts of at most part_pairs; the hits gathered and sorted as a whole
  // step's are. The same answer as the whole step.
  template <class Task>
  void step_in_parts(const Task& task, const std::vector<NodePair>& seeds, bool restart, const std::vector<Vec3d>& x0,
                     const std::vector<Vec3d>& x1, StepResult<T>& r) {
    using clock = std::chrono::steady_clock;
    auto ms = [](clock::time_point a) { return std::chrono::duration<double, std::milli>(clock::now() - a).count(); };
    const std::size_t cap = params_.part_pairs;
    const bool record = params_.front_tracking;
    auto t = clock::now();
    const std::vector<Aabbf> boxes = feature_boxes(*mesh_, x0, x1, params_.min_separation / 2);
    r.stats.features_ms += ms(t);
    const CcdParams<T> ccd = ccd_params();
    NarrowPhaseResult<T>& all = r.contacts;
    std::vector<NodePair> front;
    // Candidates in parts of at most `cap`, the orphans with the first when asked.
    auto test = [&](const TrianglePair* candidates, std::size_t n, bool orphans) {
      for (std::size_t first = 0; first < n || (orphans && first == 0); first += cap) {
        const std::size_t count = std::min(cap, n - first);
        auto t0 = clock::now();
        const FeaturePairs features = emit_feature_pairs(representatives_, candidates + first, count, boxes, orphans && first == 0);
        r.stats.features_ms += ms(t0);
        r.stats.feature_pairs_vf += features.vf.size();
        r.stats.feature_pairs_ee += features.ee.size();
        t0 = clock::now();
        add_narrow_phase_part(test_feature_pairs<Method, T>(*mesh_, x0, x1, features, ccd), all);
        r.stats.narrow_ms += ms(t0);
        ++r.stats.narrow_parts;
        if (n == 0) break;
      }
    };
    test(nullptr, 0, true);
    const std::vector<NodePair>* parts_of = &seeds;
    std::vector<NodePair> cut;
    if (restart) {
      t = clock::now();
      TraversalResult<Task> met = expand(task, seeds, StreamingPolicy::kCutItems, record, cut);
      r.stats.traverse_ms += ms(t);
      r.stats.bvtt_nodes += met.stats.items_processed;
      r.stats.triangle_pairs += met.results.size();
      front.insert(front.end(), met.front.begin(), met.front.end());
      test(met.results.data(), met.results.size(), false);
      parts_of = &cut;
    }
    // Traversal parts, halved while they yield more than `cap` candidates (down to one seed).
    const std::size_t num_seeds = parts_of->size();
    std::size_t part = std::max<std::size_t>(1, std::min(num_seeds, cap));
    for (std::size_t first = 0; first < num_seeds;) {
      const std::size_t n = std::min(part, num_seeds - first);
      t = clock::now();
      const std::vector<NodePair> part_seeds(parts_of->begin() + static_cast<std::ptrdiff_t>(first),
                                             parts_of->begin() + static_cast<std::ptrdiff_t>(first + n));
      TraversalResult<Task> traversal = cpu::traverse(task, part_seeds, record, WorkStealingScheduler{});
      r.stats.traverse_ms += ms(t);
      if (traversal.results.size() > cap && n > 1) {
        part = n / 2;
        ++r.stats.reruns;
        continue;
      }
      r.stats.bvtt_nodes += traversal.stats.items_processed;
      r.stats.triangle_pairs += traversal.results.size();
      front.insert(front.end(), traversal.front.begin(), traversal.front.end());
      test(traversal.results.data(), traversal.results.size(), false);
      ++r.stats.traversal_parts;
      first += n;
      if (traversal.results.size() * 4 < cap) part = std::min(num_seeds, 2 * part);
    }
    if (record) tracker_.update(std::move(front));
    r.stats.front_size = tracker_.size();
    sort_by_pair(all.vf);
    sort_by_pair(all.ee);
    r.stats.narrow_vf = all.vf_counts;
    r.stats.narrow_ee = all.ee_counts;
    r.stats.hits_vf = all.vf.size();
    r.stats.hits_ee = all.ee.size();
    r.stats.gave_up = all.gave_up;
  }

  std::shared_ptr<const TriangleMesh> mesh_;
  BodyLayout layout_;
  std::vector<unsigned char> self_collides_;  ///< empty: no body pruning
  std::vector<index_t> node_body_;
  std::uint64_t node_body_generation_ = ~std::uint64_t(0);
  PipelineParams params_;
  RepresentativeTriangles representatives_;
  Bvh<BV> bvh_;
  bool built_ = false;
  FrontTracker tracker_;
  const std::vector<NodePair> root_{NodePair{0, 0}};
};

}  // namespace cpu

}  // namespace lwsccd
