// lwsccd — the end-to-end CCD pipeline, CPU backend, and the types both backends share.
//
// One object per mesh topology: set up once (BVH, orphan sets), then step(x0, x1) per time step:
// refit (or rebuild when the tree decayed), BVTT self-collision traversal from the kept front,
// feature pairs of the non-adjacent candidate triangle pairs plus the orphan pairs, and the
// narrow phase. gpu::CcdPipeline (pipeline.cuh) is the same on the GPU.
#pragma once

#include <algorithm>
#include <chrono>
#include <memory>
#include <vector>

#include "lwsccd/bvh.hpp"
#include "lwsccd/bvtt.hpp"
#include "lwsccd/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase.hpp"
#include "lwsccd/orphans.hpp"
#include "lwsccd/traverse.hpp"

namespace lwsccd {

/// Run-time parameters of a pipeline.
struct PipelineParams {
  double min_separation = 0;     ///< report features closer than this (0: contact)
  double tolerance = 1e-6;       ///< time resolution of the TOI
  int max_iterations = 16384;    ///< narrow-phase work bound per pair (InclusionCcd)
  bool front_tracking = true;    ///< restart each traversal from the last front
  double rebuild_factor = 1.5;   ///< rebuild the BVH when its cost exceeds this times the cost at build
  double front_growth_limit = 1.5;
};

/// What one step measured.
struct StepStats {
  double refit_ms = 0, traverse_ms = 0, features_ms = 0, narrow_ms = 0, total_ms = 0;
  std::size_t bvtt_nodes = 0, front_size = 0, triangle_pairs = 0, feature_pairs_vf = 0, feature_pairs_ee = 0;
  std::size_t hits_vf = 0, hits_ee = 0, gave_up = 0;
  std::size_t peak_device_bytes = 0;
  bool rebuilt = false, restarted_from_root = false;
};

template <class T>
struct StepResult {
  NarrowPhaseResult<T> contacts;  ///< colliding VF and EE pairs with their TOI, earliest TOI
  StepStats stats;
};

namespace cpu {

/// The pipeline on the CPU backend (all cores).
template <class BV = Aabbf, class Method = Filtered<InclusionCcd>, class T = double>
class CcdPipeline {
 public:
  explicit CcdPipeline(std::shared_ptr<const TriangleMesh> mesh, PipelineParams params = {})
      : mesh_(std::move(mesh)), params_(params), orphans_(find_orphan_sets(*mesh_)),
        tracker_(FrontPolicy{params.front_growth_limit}) {}

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
    r.stats.refit_ms = ms(t);
    t = clock::now();
    SelfCollisionTask<BV> task{bvh_.view(), LeafFilter{nullptr, nullptr, mesh_->faces().data(), true}};
    const std::vector<NodePair> root{NodePair{0, 0}};
    const auto& seeds = params_.front_tracking ? tracker_.seeds(bvh_.generation()) : root;
    r.stats.restarted_from_root = !params_.front_tracking || tracker_.last_was_restart();
    auto traversal = cpu::traverse(task, seeds, params_.front_tracking, WorkStealingScheduler{});
    if (params_.front_tracking) tracker_.update(std::move(traversal.front));
    std::sort(traversal.results.begin(), traversal.results.end());
    r.stats.traverse_ms = ms(t);
    r.stats.bvtt_nodes = traversal.stats.items_processed;
    r.stats.front_size = tracker_.size();
    r.stats.triangle_pairs = traversal.results.size();
    t = clock::now();
    const FeaturePairs features = culled_feature_pairs(*mesh_, traversal.results, orphans_);
    r.stats.features_ms = ms(t);
    r.stats.feature_pairs_vf = features.vf.size();
    r.stats.feature_pairs_ee = features.ee.size();
    t = clock::now();
    CcdParams<T> ccd;
    ccd.min_separation = static_cast<T>(params_.min_separation);
    ccd.tolerance = static_cast<T>(params_.tolerance);
    ccd.max_iterations = params_.max_iterations;
    r.contacts = test_feature_pairs<Method, T>(*mesh_, x0, x1, features, ccd);
    r.stats.narrow_ms = ms(t);
    r.stats.hits_vf = r.contacts.vf.size();
    r.stats.hits_ee = r.contacts.ee.size();
    r.stats.gave_up = r.contacts.gave_up;
    r.stats.total_ms = ms(start);
    return r;
  }

 private:
  std::shared_ptr<const TriangleMesh> mesh_;
  PipelineParams params_;
  OrphanSets orphans_;
  Bvh<BV> bvh_;
  bool built_ = false;
  FrontTracker tracker_;
};

}  // namespace cpu

}  // namespace lwsccd
