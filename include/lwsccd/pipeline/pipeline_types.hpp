// lwsccd — what both pipelines (cpu::CcdPipeline, gpu::CcdPipeline) share: the run-time
// parameters of a pipeline, the knobs of a step run in parts, and what a step returns (its
// contacts and its statistics).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "lwsccd/core/error.hpp"
#include "lwsccd/features/oracle.hpp"
#include "lwsccd/geometry/mesh.hpp"
#include "lwsccd/narrow_phase/ccd_query.hpp"
#include "lwsccd/narrow_phase/narrow_phase.hpp"
#include "lwsccd/pipeline/stage_sequence.hpp"

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
  /// CPU backend: at most this many threads (0: every core; cpu::ThreadLimit). The GPU backend's
  /// host side is one thread and ignores it.
  unsigned threads = 0;
  /// GPU backend: plan the narrow phase as for a GPU whose FP32 runs this many times faster than
  /// its FP64 (0: the device's own ratio). Above 2 the searches in double (those the thread kernel
  /// hands on, and a short deferred list's) run a thread each rather than a warp each
  /// (NarrowPhasePolicy::kHandedWarpsMaxFp64Ratio);
  /// the answers are the same for every value. For measuring on one GPU the path another takes
  /// (e.g. 64, an RTX- or L40-class GPU, counted on an H100: bench/fp_instructions.py). From
  /// kFloatPairLeavesMinFp64Ratio (8) on, contacts' leaves are proved in pairs of floats first
  /// (CcdParams::leaves_in_float_pairs), on either backend: the CPU follows the plan, so that its
  /// counts of where pairs were decided are the GPU's (the answers are the same either way).
  int fp64_ratio = 0;

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
  require(fp64_ratio >= 0, "fp64_ratio", "must be >= 0 (0: the device's own)");
}

/// The CPU backend's front growth limit: a CPU pays as much for an item of a front as for one of a
/// traversal from the root, so a grown front soon costs more than a restart (horse-gallop on 2
/// cores, mean step: limit 1.5 -> 84 ms, 3 -> 104; docs/PIPELINE.md).
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
  // (The GPU backend also does so on a GPU of such a ratio, planned or not; the answers are the same.)
  ccd.leaves_in_float_pairs = params.fp64_ratio >= kFloatPairLeavesMinFp64Ratio;
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

/// GPU: the device memory a pipeline holds, by what it holds it for (bytes of every buffer's
/// capacity; buffers are kept between steps, so this is also what the next step starts with).
/// The first three are the resident data no split of a step reduces (CcdPipeline::resident_bytes()).
struct DeviceMemoryUse {
  std::size_t mesh = 0;           ///< topology, the step's positions, the bodies' tags
  std::size_t bvh = 0;            ///< the tree: nodes, boxes, build scratch
  std::size_t feature_boxes = 0;  ///< the edges' and faces' boxes and the feature tables the emission reads
  std::size_t candidates = 0;     ///< the traversal's results: candidate triangle pairs
  std::size_t front = 0;          ///< the front being recorded, the seeds (last front), the root's cut
  std::size_t scheduler = 0;      ///< the traversal scheduler's own lists (deques, work lists)
  std::size_t feature_pairs = 0;  ///< the emitted vertex-face and edge-edge pairs, their masks and scratch
  std::size_t narrow_hits = 0;    ///< the narrow phase's hits and their sorting
  std::size_t narrow_work = 0;    ///< the narrow phase's work lists (survivors, deferred, intervals, ...)
  std::size_t other = 0;          ///< a step in parts' gathered hits, scratch, a share's cut
  std::size_t resident() const { return mesh + bvh + feature_boxes; }
  std::size_t total() const {
    return mesh + bvh + feature_boxes + candidates + front + scheduler + feature_pairs + narrow_hits + narrow_work + other;
  }
};

/// Calls f(name, bytes) for each part of `m` in the order above (the names reports print).
template <class F>
void for_each_part(const DeviceMemoryUse& m, F&& f) {
  f("mesh", m.mesh);
  f("bvh", m.bvh);
  f("feature_boxes", m.feature_boxes);
  f("candidates", m.candidates);
  f("front", m.front);
  f("scheduler", m.scheduler);
  f("feature_pairs", m.feature_pairs);
  f("narrow_hits", m.narrow_hits);
  f("narrow_work", m.narrow_work);
  f("other", m.other);
}

/// What one step measured.
struct StepStats {
  double refit_ms = 0, traverse_ms = 0, features_ms = 0, narrow_ms = 0, total_ms = 0;
  std::size_t bvtt_nodes = 0, front_size = 0, triangle_pairs = 0, feature_pairs_vf = 0, feature_pairs_ee = 0;
  std::size_t hits_vf = 0, hits_ee = 0, gave_up = 0;
  std::size_t narrow_survivors = 0;      ///< GPU: pairs the narrow phase's first pass left for the full test
  std::size_t narrow_warp_searches = 0;  ///< GPU: of those, searched by a warp (still open after the thread's rounds)
  NarrowPhaseCounts narrow_vf, narrow_ee;  ///< certified hits / misses and fallbacks per list (CertifiedCcd)
  std::size_t peak_device_bytes = 0;
  /// gpu::CcdPipeline: what the pipeline holds on its device after the step, by purpose (its total
  /// is device_bytes(); the peak above adds the step's passing scratch). Empty from the CPU
  /// backend and from MultiGpuPipeline (its device_stats() give each GPU's bytes in peak_device_bytes).
  DeviceMemoryUse device_memory;
  /// GPU: stages enqueued again in this step because a list outgrew the room earlier steps gave
  /// it (the feature pairs' or the narrow phase's; nothing is lost, the step just costs more).
  std::size_t reruns = 0;
  /// gpu::CcdPipeline: cudaMalloc calls the process's lwsccd objects made during the step (a first
  /// step on new memory makes a few; a steady one none: its buffers and the cache's blocks serve
  /// it). 0 from the CPU backend and from MultiGpuPipeline.
  std::size_t device_allocations = 0;
  /// GPU: launches of this step's traversal after its first (blocks handed items back: a full
  /// deque, or outputs that filled up and grew; a first step from the root has a few).
  std::size_t traversal_relaunches = 0;
  /// A step in parts (PipelineParams::part_pairs, or a GPU budget): the traversal's parts and the
  /// narrow phase's parts (a part's candidates went through the feature pairs and the narrow
  /// phase together); 0: the step ran whole.
  std::size_t traversal_parts = 0, narrow_parts = 0;
  bool rebuilt = false, restarted_from_root = false;
  /// GPU: the front this step found outgrew its buffer (grown now). Its results are complete; the
  /// next step starts from this step's start instead (as valid a cut), with no rerun of this one.
  bool front_outgrown = false;
};

namespace detail {
/// Adds `ms` to the time `stats` keeps for `stage` (a step in parts adds up its parts'; both
/// backends' stage_done).
inline void add_stage_time(StepStats& stats, PipelineStage stage, double ms) {
  double* times[kPipelineStages] = {&stats.refit_ms, &stats.traverse_ms, &stats.features_ms, &stats.narrow_ms};
  *times[static_cast<int>(stage)] += ms;
}
}  // namespace detail

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

}  // namespace lwsccd
