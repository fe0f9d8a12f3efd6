// The differential check of one fuzz scene: a pipeline's answer against the oracle composed by
// hand (brute-force feature pairs, culled by their boxes, through cpu::test_feature_pairs with the
// same method and precision). AABB pipelines must give it exactly (pairs, TOIs bit for bit,
// counts); OBB pipelines cull more triangle pairs, so their hits are a subset with the same TOIs,
// and each oracle hit they lack must come from a triangle pair whose OBBs are apart.
#pragma once

#include <catch2/catch.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "lwsccd/bvh/bvh.hpp"
#include "lwsccd/features/representative.hpp"
#include "lwsccd/narrow_phase/narrow_phase.hpp"
#include "lwsccd/pipeline/cpu_pipeline.hpp"
#include "contact_compare.hpp"
#include "fuzz_scenes.hpp"

namespace lwsccd_test {

/// Scenes and first seed of a fuzz run: LWSCCD_FUZZ_SCENES / LWSCCD_FUZZ_SEED, else the defaults.
// Seconds a fuzzing run spends in each kind of work (reported with its last line, so a slow run
// says whether the oracle, the pipelines' construction or their steps take the time).
struct FuzzTimes {
  double oracle = 0, construct = 0, step = 0, parts = 0;
};
inline FuzzTimes& fuzz_times() {
  static FuzzTimes t;
  return t;
}
// Runs f() and adds its wall time to `into`; returns what f returns.
template <class F>
auto fuzz_timed(double& into, F&& f) {
  const auto t0 = std::chrono::steady_clock::now();
  struct Add {
    double& into;
    std::chrono::steady_clock::time_point t0;
    ~Add() { into += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); }
  } add{into, t0};
  return f();
}

inline std::uint64_t fuzz_setting(const char* name, std::uint64_t fallback) {
  const char* text = std::getenv(name);
  return text && *text ? std::strtoull(text, nullptr, 10) : fallback;
}

/// Whether a scene also runs the pipelines in parts: every LWSCCD_FUZZ_PARTS_EVERY-th seed (default
/// 1: every scene). A step in parts of 1-17 candidate pairs is thousands of tiny parts, each with
/// its host synchronisation, so it costs ~5x all the whole pipelines of a scene: a long device run
/// thins it out to reach many scenes, and still covers the streamed path on a tenth of them.
inline bool fuzz_in_parts(std::uint64_t seed) {
  const std::uint64_t every = fuzz_setting("LWSCCD_FUZZ_PARTS_EVERY", 1);
  return every != 0 && seed % every == 0;
}

/// The mode a scene runs in: mostly contacts, sometimes earliest or set (from its seed).
inline lwsccd::CcdMode fuzz_mode(std::uint64_t seed) {
  const std::uint64_t r = (seed * 0xD1B54A32D192ED03ull) >> 61;
  return r == 0 ? lwsccd::CcdMode::earliest : r == 1 ? lwsccd::CcdMode::set : lwsccd::CcdMode::contacts;
}

/// The oracle: Method on the brute-force feature pairs, with the test of the faces' relative
/// motion where the pipelines apply it (contact: no minimum separation). It also checks that the
/// pairs that test leaves out change no answer: the same hits, TOIs and earliest TOI as Method
/// on the pairs of the boxes alone.
template <class Method, class T>
lwsccd::NarrowPhaseResult<T> fuzz_oracle(const FuzzScene& s, lwsccd::CcdMode mode) {
  using namespace lwsccd;
  const RepresentativeTriangles rep(*s.mesh, s.layout);
  const std::vector<Aabbf> boxes = feature_boxes(*s.mesh, s.x0, s.x1, s.min_separation / 2);
  const std::vector<FaceCorners> corners = face_corners(*s.mesh, s.x0, s.x1);
  const bool test_motion = !(s.min_separation > 0);
  CcdParams<T> params;
  params.min_separation = static_cast<T>(s.min_separation);
  params.mode = mode;
  auto run = [&](const FeaturePairs& pairs) {
    NarrowPhaseResult<T> r = cpu::test_feature_pairs<Method, T>(*s.mesh, s.x0, s.x1, pairs, params);
    std::sort(r.vf.begin(), r.vf.end());
    std::sort(r.ee.begin(), r.ee.end());
    return r;
  };
  NarrowPhaseResult<T> r = run(brute_force_feature_pairs(rep, boxes, test_motion ? &corners : nullptr));
  if (test_motion) {
    INFO("the faces' relative motion left out pairs that change the answer");
    const NarrowPhaseResult<T> boxes_only = run(brute_force_feature_pairs(rep, boxes));
    require_same_hits(r.vf, boxes_only.vf);
    require_same_hits(r.ee, boxes_only.ee);
    REQUIRE(r.earliest_toi == boxes_only.earliest_toi);
  }
  return r;
}

inline lwsccd::PipelineParams fuzz_params(const FuzzScene& s, lwsccd::CcdMode mode) {
  lwsccd::PipelineParams p;
  p.min_separation = s.min_separation;
  p.mode = mode;
  return p;
}

// The swept OBB of every face as the CPU BVH fits its leaves (same leaf margin as a pipeline's).
inline std::vector<lwsccd::Obbf> face_obbs(const FuzzScene& s) {
  lwsccd::cpu::Bvh<lwsccd::Obbf> bvh(*s.mesh, s.x0, s.x1);
  bvh.set_leaf_margin(s.min_separation / 2);
  bvh.refit(s.x0, s.x1);
  const lwsccd::BvhView<lwsccd::Obbf> view = bvh.view();
  std::vector<lwsccd::Obbf> boxes(static_cast<std::size_t>(view.num_leaves));
  for (lwsccd::index_t k = 0; k < view.num_leaves; ++k) boxes[view.leaf_primitive[k]] = view.bvs[view.leaf_node(k)];
  return boxes;
}

// An OBB pipeline culls triangle pairs whose swept OBBs are apart, so its hits are a subset of the
// oracle's with the same TOIs. Each oracle hit it lacks must be explained: the faces representing
// its two features (the triangle pair that would have produced it) have disjoint OBBs, which
// proves that no contact was lost. (Orphan pairs share a vertex: their OBBs always overlap.)
template <class T>
void require_obb_subset(const std::vector<lwsccd::FeatureHit<T>>& hits, const std::vector<lwsccd::FeatureHit<T>>& all,
                        const std::vector<lwsccd::Obbf>& obbs, bool vertex_face, const lwsccd::RepresentativeTriangles& rep,
                        const lwsccd::TriangleMesh& mesh) {
  using lwsccd::index_t;
  std::size_t j = 0;
  auto explain_missing = [&](const lwsccd::FeatureHit<T>& lost) {
    // Hits name features by feature id (vertices, then edges, then faces); owners take indices.
    const index_t nv = mesh.num_vertices(), ne = mesh.num_edges();
    const index_t a = vertex_face ? rep.vertex_owner(lost.first) : rep.edge_owner(lost.first - nv);
    const index_t b = vertex_face ? lost.second - nv - ne : rep.edge_owner(lost.second - nv);
    INFO("oracle hit (" << lost.first << ", " << lost.second << ") missing from the OBB pipeline; faces " << a << ", " << b);
    REQUIRE_FALSE(lwsccd::Obbf::overlap(obbs[a], obbs[b]));
  };
  for (const auto& h : hits) {
    while (j < all.size() && all[j] < h) explain_missing(all[j++]);
    REQUIRE(j < all.size());
    REQUIRE(all[j].first == h.first);
    REQUIRE(all[j].second == h.second);
    REQUIRE(std::memcmp(&all[j].toi, &h.toi, sizeof(T)) == 0);
    ++j;
  }
  while (j < all.size()) explain_missing(all[j++]);
}

/// One pipeline's answer against the oracle: AABB pipelines exactly (pairs, TOIs, counts), OBB
/// pipelines as require_obb_subset says.
template <class BV, class T>
void require_fuzz_agreement(const lwsccd::StepResult<T>& got, const lwsccd::NarrowPhaseResult<T>& oracle, const FuzzScene& s) {
  if (std::is_same<BV, lwsccd::Aabbf>::value) {
    require_same_contacts(got.contacts, oracle);
    require_same_counts(got.contacts.vf_counts, oracle.vf_counts);
    require_same_counts(got.contacts.ee_counts, oracle.ee_counts);
  } else {
    const lwsccd::RepresentativeTriangles rep(*s.mesh, s.layout);
    const std::vector<lwsccd::Obbf> obbs = face_obbs(s);
    require_obb_subset(got.contacts.vf, oracle.vf, obbs, true, rep, *s.mesh);
    require_obb_subset(got.contacts.ee, oracle.ee, obbs, false, rep, *s.mesh);
    REQUIRE(got.contacts.vf_counts.pairs <= oracle.vf_counts.pairs);
    REQUIRE(got.contacts.ee_counts.pairs <= oracle.ee_counts.pairs);
    REQUIRE(got.contacts.earliest_toi >= oracle.earliest_toi);
  }
}

/// A scene's step in parts: PipelineParams::part_pairs a few candidate triangle pairs (1-17, from
/// the scene's size), so that even small scenes split into many parts.
inline lwsccd::PipelineParams fuzz_part_params(const FuzzScene& s, lwsccd::CcdMode mode) {
  lwsccd::PipelineParams p = fuzz_params(s, mode);
  p.part_pairs = 1 + static_cast<std::size_t>(s.mesh->num_faces()) % 17;
  return p;
}

/// An AABB pipeline's step in parts against the oracle: the same pairs, TOIs bit for bit and
/// earliest TOI; the same counts in mode contacts and hits given up in modes contacts and set.
/// (Mode earliest counts per time window, and a part does not know the earlier parts' best time,
/// so it may search, and give up on, pairs a whole step drops as later: neither adds up to a whole
/// step's.)
template <class T>
void require_parts_agreement(const lwsccd::StepResult<T>& got, const lwsccd::NarrowPhaseResult<T>& oracle, lwsccd::CcdMode mode) {
  INFO("step in parts: " << got.stats.traversal_parts << " traversal parts, " << got.stats.narrow_parts << " narrow-phase parts");
  require_same_hits(got.contacts.vf, oracle.vf);
  require_same_hits(got.contacts.ee, oracle.ee);
  REQUIRE(got.contacts.earliest_toi == oracle.earliest_toi);
  if (mode != lwsccd::CcdMode::earliest) REQUIRE(got.contacts.gave_up == oracle.gave_up);
  if (mode == lwsccd::CcdMode::contacts) {
    require_same_counts(got.contacts.vf_counts, oracle.vf_counts);
    require_same_counts(got.contacts.ee_counts, oracle.ee_counts);
  }
}

/// The fuzz run: scenes LWSCCD_FUZZ_SEED .. + LWSCCD_FUZZ_SCENES (default 1 .. 40), each with its
/// mode, through check_scene(scene, mode) (which compares every configuration with the oracle).
/// Failures name the seed that reruns the scene alone; long runs print progress every 500 scenes.
template <class CheckScene>
void run_fuzz(const char* backend, const char* configurations, CheckScene&& check_scene) {
  const std::uint64_t first = fuzz_setting("LWSCCD_FUZZ_SEED", 1);
  const std::uint64_t scenes = fuzz_setting("LWSCCD_FUZZ_SCENES", 40);
  std::size_t triangles = 0;
  for (std::uint64_t seed = first; seed < first + scenes; ++seed) {
    const FuzzScene s = make_fuzz_scene(seed);
    const lwsccd::CcdMode mode = fuzz_mode(seed);
    INFO(s.what << ", mode " << static_cast<int>(mode) << " (rerun: LWSCCD_FUZZ_SEED=" << seed << " LWSCCD_FUZZ_SCENES=1)");
    check_scene(s, mode);
    triangles += static_cast<std::size_t>(s.mesh->num_faces());
    if ((seed - first + 1) % 500 == 0) {
      std::printf("fuzz (%s): %llu scenes done\n", backend, static_cast<unsigned long long>(seed - first + 1));
      std::fflush(stdout);
    }
  }
  const FuzzTimes& t = fuzz_times();
  std::printf("fuzz (%s): %llu scenes from seed %llu (%zu triangles), %s each: no disagreement"
              " (seconds: oracle %.1f, pipelines' construction %.1f, steps %.1f, steps in parts %.1f)\n",
              backend, static_cast<unsigned long long>(scenes), static_cast<unsigned long long>(first), triangles,
              configurations, t.oracle, t.construct, t.step, t.parts);
}

}  // namespace lwsccd_test
