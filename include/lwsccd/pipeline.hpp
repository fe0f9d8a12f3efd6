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

#include "lwsccd/bvh.hpp"
#include "lwsccd/bvtt.hpp"
#include "lwsccd/certified_ccd.hpp"
#include "lwsccd/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase.hpp"
#include "lwsccd/orphans.hpp"
#include "lwsccd/representative.hpp"
#include "lwsccd/traverse.hpp"

namespace lwsccd {

/// Run-time parameters of a pipeline.
struct PipelineParams {
  double min_separation = 0;     ///< report features closer than this (0: contact)
  double tolerance = 1e-6;       ///< time resolution of the TOI
  int max_iterations = 16384;    ///< narrow-phase work bound per pair (InclusionCcd)
  bool front_tracking = true;    ///< restart each traversal from the last front
  double rebuild_factor = 1.5;   ///< rebuild the BVH when its cost exceeds this times the cost at build
  double front_growth_limit = 1.5;  ///< restart from the root once the front grew this much
  std::size_t device_memory_budget = 0;  ///< GPU backend: device bytes the library may hold (0: no limit)
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
  require(front_growth_limit >= 1, "front_growth_limit", "must be >= 1");
}

namespace detail {
inline PipelineParams validated(PipelineParams params) {
  params.validate();
  return params;
}
inline std::shared_ptr<const TriangleMesh> checked_mesh(std::shared_ptr<const TriangleMesh> mesh, const char* who) {
  if (!mesh) throw InputError(who, "mesh", "is null");
  return mesh;
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
  bool rebuilt = false, restarted_from_root = false;
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
        tracker_(FrontPolicy{params.front_growth_limit}) {
    // Features that come within min_separation: their boxes, each grown by half of it, overlap.
    bvh_.set_leaf_margin(params_.min_separation / 2);
  }

  StepResult<T> step(const std::vector<Vec3d>& x0, const std::vector<Vec3d>& x1) {
    using clock = std::chrono::steady_clock;
    auto ms = [](clock::time_point a) { return std::chrono::duration<double, std::milli>(clock::now() - a).count(); };
    StepResult<T> r;
    const auto start = clock::now();
    auto t = clock::now();
    if (!built_) {
      bvh_.build(*mesh_, x0, x1);
      built_ = r.stats.rebuilt = true;
    } else {
      r.stats.rebuilt = bvh_.refit_or_rebuild(x0, x1, RebuildPolicy{params_.rebuild_factor});
    }
    if (!self_collides_.empty() && bvh_.generation() != node_body_generation_) {
      node_body_ = node_bodies(bvh_.view(), layout_.face_body);  // topology changed
      node_body_generation_ = bvh_.generation();
    }
    r.stats.refit_ms = ms(t);
    t = clock::now();
    const bool bodies = !self_collides_.empty();
    SelfCollisionTask<BV> task{bvh_.view(),
                               LeafFilter{bodies ? layout_.face_body.data() : nullptr, bodies ? self_collides_.data() : nullptr,
                                          mesh_->faces().data(), true, bodies ? node_body_.data() : nullptr}};
    const std::vector<NodePair> root{NodePair{0, 0}};
    const auto& seeds = params_.front_tracking ? tracker_.seeds(bvh_.generation()) : root;
    r.stats.restarted_from_root = !params_.front_tracking || tracker_.last_was_restart();
    auto traversal = cpu::traverse(task, seeds, params_.front_tracking, WorkStealingScheduler{});
    if (params_.front_tracking) tracker_.update(std::move(traversal.front));
    r.stats.traverse_ms = ms(t);
    r.stats.bvtt_nodes = traversal.stats.items_processed;
    r.stats.front_size = tracker_.size();
    r.stats.triangle_pairs = traversal.results.size();
    t = clock::now();
    const FeaturePairs features = emit_feature_pairs(representatives_, traversal.results,
                                                         feature_boxes(*mesh_, x0, x1, params_.min_separation / 2));
    r.stats.features_ms = ms(t);
    r.stats.feature_pairs_vf = features.vf.size();
    r.stats.feature_pairs_ee = features.ee.size();
    t = clock::now();
    CcdParams<T> ccd;
    ccd.min_separation = static_cast<T>(params_.min_separation);
    ccd.tolerance = static_cast<T>(params_.tolerance);
    ccd.max_iterations = params_.max_iterations;
    ccd.mode = params_.mode;
    r.contacts = test_feature_pairs<Method, T>(*mesh_, x0, x1, features, ccd);
    r.stats.narrow_vf = r.contacts.vf_counts;
    r.stats.narrow_ee = r.contacts.ee_counts;
    r.stats.narrow_ms = ms(t);
    r.stats.hits_vf = r.contacts.vf.size();
    r.stats.hits_ee = r.contacts.ee.size();
    r.stats.gave_up = r.contacts.gave_up;
    r.stats.total_ms = ms(start);
    return r;
  }

  const TriangleMesh& mesh() const { return *mesh_; }
  const BodyLayout& layout() const { return layout_; }
  const PipelineParams& params() const { return params_; }

 private:

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
};

}  // namespace cpu

}  // namespace lwsccd
