// The CPU pipeline against its stages composed by hand from the oracles.
#include <catch2/catch.hpp>

#include <type_traits>

#include <algorithm>
#include <cstdio>
#include <string>

#include "lwsccd/pipeline/cpu_pipeline.hpp"
#include "lwsccd/simulation/scenes.hpp"
#include "lwsccd/simulation/simulation.hpp"
#include "contact_compare.hpp"
#include "scene_fixtures.hpp"

using namespace lwsccd;

TEST_CASE("CPU pipeline: refit + front tracking + culling + narrow phase equal the oracles, step after step", "[pipeline]") {
  const auto first = lwsccd_test::folded_cloth(30, 1);
  auto mesh = std::make_shared<const TriangleMesh>(first.mesh);
  cpu::CcdPipeline<Aabbf> pipeline(mesh);
  const RepresentativeTriangles rep(*mesh);
  for (int s = 0; s < 4; ++s) {
    INFO("step " << s);
    const auto m = lwsccd_test::folded_cloth(30, 1 + s);
    const auto r = pipeline.step(m.x0, m.x1);
    std::vector<TrianglePair> non_adjacent;
    for (const auto& p : brute_force_pairs(*mesh, swept_triangle_bvs<Aabbf>(*mesh, m.x0, m.x1)))
      if (!p.adjacent) non_adjacent.push_back(p);
    // The feature pairs are the brute-force feature oracle's (with the test of the faces' relative
    // motion, as the pipeline emits them), each tested once.
    const std::vector<FaceCorners> corners = face_corners(*mesh, m.x0, m.x1);
    const FeaturePairs features = brute_force_feature_pairs(rep, feature_boxes(*mesh, m.x0, m.x1), &corners);
    const auto expected = cpu::test_feature_pairs<CertifiedCcd, double>(*mesh, m.x0, m.x1, features);
    REQUIRE(r.stats.triangle_pairs == non_adjacent.size());
    REQUIRE(r.stats.feature_pairs_vf == features.vf.size());
    REQUIRE(r.stats.feature_pairs_ee == features.ee.size());
    REQUIRE(r.contacts.vf.size() == expected.vf.size());
    REQUIRE(r.contacts.ee.size() == expected.ee.size());
    for (std::size_t i = 0; i < expected.vf.size(); ++i) REQUIRE(r.contacts.vf[i].toi == expected.vf[i].toi);
    REQUIRE(r.contacts.earliest_toi == expected.earliest_toi);
    CHECK(r.stats.hits_vf + r.stats.hits_ee > 0);
    CHECK(r.stats.restarted_from_root == (s == 0));
  }
}

TEST_CASE("CPU pipeline: restart_from_root makes the next step traverse from the root, with the same answer",
          "[pipeline][fresh]") {
  const auto first = lwsccd_test::folded_cloth(24, 1);
  auto mesh = std::make_shared<const TriangleMesh>(first.mesh);
  cpu::CcdPipeline<Aabbf> pipeline(mesh), tracked(mesh);
  const auto a = lwsccd_test::folded_cloth(24, 2), b = lwsccd_test::folded_cloth(24, 6);
  pipeline.step(a.x0, a.x1);
  tracked.step(a.x0, a.x1);
  pipeline.restart_from_root();
  const auto from_root = pipeline.step(b.x0, b.x1);
  const auto from_front = tracked.step(b.x0, b.x1);
  CHECK(from_root.stats.restarted_from_root);
  CHECK_FALSE(from_front.stats.restarted_from_root);
  REQUIRE(from_root.stats.hits_vf + from_root.stats.hits_ee > 0);
  lwsccd_test::require_same_contacts(from_root.contacts, from_front.contacts);
  CHECK(from_root.stats.triangle_pairs == from_front.stats.triangle_pairs);
  // The front the restart recorded serves the next step.
  const auto next = pipeline.step(b.x0, b.x1);
  CHECK_FALSE(next.stats.restarted_from_root);
  lwsccd_test::require_same_contacts(next.contacts, from_root.contacts);
}

namespace {

// The oracle for a scene with bodies: the brute-force feature pairs under the layout (a feature's
// body is its representing face's), the narrow phase.
NarrowPhaseResult<double> oracle_contacts(const MultiBodyStep& scene) {
  const TriangleMesh& mesh = *scene.step.mesh;
  const RepresentativeTriangles rep(mesh, scene.layout);
  const FeaturePairs features = sweep_feature_pairs(rep, feature_boxes(mesh, scene.step.x0, scene.step.x1));
  return cpu::test_feature_pairs<CertifiedCcd, double>(mesh, scene.step.x0, scene.step.x1, features);
}

}  // namespace

TEST_CASE("CPU pipeline with bodies: a rigid ball costs no self traversal and no contacts are lost", "[pipeline][bodies]") {
  const MultiBodyStep scene = make_cloth_ball_scene(3000);
  REQUIRE(scene.layout.body_self_collides == std::vector<bool>{true, false});
  cpu::CcdPipeline<Aabbf> with_bodies(scene.step.mesh, scene.layout);
  cpu::CcdPipeline<Aabbf> one_body(scene.step.mesh);
  const auto r = with_bodies.step(scene.step.x0, scene.step.x1);
  const auto all = one_body.step(scene.step.x0, scene.step.x1);
  const auto expected = oracle_contacts(scene);
  lwsccd_test::require_same_contacts(r.contacts, expected);
  // Cloth-cloth and cloth-ball contacts exist; the ball's subtrees are pruned whole.
  CHECK(r.stats.hits_vf + r.stats.hits_ee > 0);
  CHECK(r.stats.bvtt_nodes < all.stats.bvtt_nodes);
  CHECK(r.stats.triangle_pairs < all.stats.triangle_pairs);
  // Every contact of the layout's pipeline is also one of the single-body pipeline's.
  for (const auto& h : r.contacts.vf) CHECK(std::binary_search(all.contacts.vf.begin(), all.contacts.vf.end(), h));
  std::printf("built-in cloth-ball, %d faces: BVTT nodes %zu with bodies vs %zu as one body; triangle pairs %zu vs %zu\n",
              scene.step.mesh->num_faces(), r.stats.bvtt_nodes, all.stats.bvtt_nodes, r.stats.triangle_pairs,
              all.stats.triangle_pairs);
  // A second step from the front (same positions): same answer.
  const auto again = with_bodies.step(scene.step.x0, scene.step.x1);
  CHECK_FALSE(again.stats.restarted_from_root);
  CHECK(again.contacts.vf.size() == r.contacts.vf.size());
  CHECK(again.contacts.ee.size() == r.contacts.ee.size());
}

TEST_CASE("node_bodies: one body per subtree, mixed where bodies meet", "[pipeline][bodies]") {
  const MultiBodyStep scene = make_cloth_ball_scene(800);
  cpu::Bvh<Aabbf> bvh;
  bvh.build(*scene.step.mesh, scene.step.x0, scene.step.x1);
  const auto view = bvh.view();
  const std::vector<index_t> bodies = node_bodies(view, scene.layout.face_body);
  std::size_t uniform = 0;
  for (index_t node = 0; node < view.num_nodes(); ++node) {
    // The brute-force answer from the node's leaves.
    index_t expected = scene.layout.face_body[view.leaf_primitive[view.ranges[node].first]];
    for (index_t k = view.ranges[node].first; k <= view.ranges[node].last; ++k)
      if (scene.layout.face_body[view.leaf_primitive[k]] != expected) expected = kMixedBodies;
    REQUIRE(bodies[node] == expected);
    uniform += expected != kMixedBodies;
  }
  CHECK(bodies[0] == kMixedBodies);
  CHECK(uniform > static_cast<std::size_t>(view.num_leaves));  // leaves and some internal nodes
}

TEST_CASE("orphans_for_layout drops only pairs inside a body that does not self-collide", "[pipeline][bodies]") {
  const MultiBodyStep scene = make_cloth_ball_scene(1500);
  const TriangleMesh& mesh = *scene.step.mesh;
  const OrphanSets all = find_orphan_sets(mesh);
  const OrphanSets kept = orphans_for_layout(mesh, all, scene.layout);
  // The cloth self-collides: its orphans (all there are: the closed ball has none) stay.
  REQUIRE(all.vf.size() + all.ee.size() > 0);
  CHECK(kept.vf.size() == all.vf.size());
  CHECK(kept.ee.size() == all.ee.size());
  // A rigid cloth over a self-colliding ball: the cloth's orphans go.
  BodyLayout swapped = scene.layout;
  swapped.body_self_collides = {false, true};
  CHECK(orphans_for_layout(mesh, all, swapped).vf.size() + orphans_for_layout(mesh, all, swapped).ee.size() == 0);
  const std::vector<index_t> ball_faces_only(mesh.num_faces(), 1);  // all faces in the rigid ball's body
  BodyLayout all_rigid{ball_faces_only, {true, false}};
  CHECK(orphans_for_layout(mesh, all, all_rigid).vf.empty());
  CHECK(orphans_for_layout(mesh, all, all_rigid).ee.empty());
  BodyLayout everyone = scene.layout;
  everyone.body_self_collides = {true, true};
  CHECK(orphans_for_layout(mesh, all, everyone).vf.size() == all.vf.size());
  CHECK(orphans_for_layout(mesh, all, everyone).ee.size() == all.ee.size());
  BodyLayout wrong = scene.layout;
  wrong.face_body.pop_back();
  CHECK_THROWS_AS(orphans_for_layout(mesh, all, wrong), InputError);
}

TEST_CASE("CPU pipeline rejects bad parameters, layouts and positions with a clear error", "[pipeline]") {
  const auto m = lwsccd_test::folded_cloth(8, 1);
  auto mesh = std::make_shared<const TriangleMesh>(m.mesh);
  auto with = [](auto change) {
    PipelineParams p;
    change(p);
    return p;
  };
  CHECK_THROWS_AS(cpu::CcdPipeline<>(mesh, with([](PipelineParams& p) { p.tolerance = 0; })), InputError);
  CHECK_THROWS_AS(cpu::CcdPipeline<>(mesh, with([](PipelineParams& p) { p.min_separation = -1; })), InputError);
  CHECK_THROWS_AS(cpu::CcdPipeline<>(mesh, with([](PipelineParams& p) { p.max_iterations = 0; })), InputError);
  CHECK_THROWS_AS(cpu::CcdPipeline<>(mesh, with([](PipelineParams& p) { p.rebuild_factor = 0.5; })), InputError);
  CHECK_THROWS_AS(cpu::CcdPipeline<>(mesh, with([](PipelineParams& p) { p.front_growth_limit = 0.5; })), InputError);
  CHECK_THROWS_AS(cpu::CcdPipeline<>(mesh, with([](PipelineParams& p) { p.front_growth_limit = -1; })), InputError);
  CHECK_NOTHROW(cpu::CcdPipeline<>(mesh, with([](PipelineParams& p) { p.front_growth_limit = 0; })));  // the backend's default
  CHECK_THROWS_AS(cpu::CcdPipeline<>(mesh, with([](PipelineParams& p) { p.fp64_ratio = -1; })), InputError);
  CHECK_THROWS_AS(cpu::CcdPipeline<>(nullptr), InputError);
  BodyLayout short_layout;
  short_layout.face_body = {0};
  CHECK_THROWS_AS(cpu::CcdPipeline<>(mesh, short_layout), InputError);
  try {
    cpu::CcdPipeline<>(mesh, with([](PipelineParams& p) { p.tolerance = 2; }));
  } catch (const InputError& e) {
    CHECK(std::string(e.what()).find("tolerance") != std::string::npos);
  }
  cpu::CcdPipeline<> pipeline(mesh);
  std::vector<Vec3d> too_few(m.x0.begin(), m.x0.end() - 1);
  CHECK_THROWS_AS(pipeline.step(too_few, m.x1), InputError);
}

TEST_CASE("CPU pipeline with a minimum separation: pairs closer than it are found though their boxes are apart",
          "[pipeline][separation]") {
  // Two separate triangles in parallel planes 0.004 apart, still: no contact, but closer than 0.01.
  const std::vector<Vec3d> x = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.1, 0.1, 0.004}, {1.1, 0.1, 0.004}, {0.1, 1.1, 0.004}};
  auto mesh = std::make_shared<const TriangleMesh>(6, std::vector<Face>{{{0, 1, 2}}, {{3, 4, 5}}});
  PipelineParams near, contact;
  near.min_separation = 0.01;
  const auto r = cpu::CcdPipeline<Aabbf>(mesh, near).step(x, x);
  CHECK(r.stats.triangle_pairs == 1);
  CHECK(r.stats.hits_vf + r.stats.hits_ee > 0);
  const auto r0 = cpu::CcdPipeline<Aabbf>(mesh, contact).step(x, x);
  CHECK(r0.stats.triangle_pairs == 0);
  CHECK(r0.stats.hits_vf + r0.stats.hits_ee == 0);
  PipelineParams far;
  far.min_separation = 0.002;
  const auto r2 = cpu::CcdPipeline<Obbf>(mesh, far).step(x, x);
  CHECK(r2.stats.hits_vf + r2.stats.hits_ee == 0);
  const auto r3 = cpu::CcdPipeline<Obbf>(mesh, near).step(x, x);
  CHECK(r3.stats.hits_vf + r3.stats.hits_ee == r.stats.hits_vf + r.stats.hits_ee);
  cpu::Bvh<Aabbf> bvh;
  CHECK_THROWS_AS(bvh.set_leaf_margin(-1), InputError);
  CHECK_THROWS_AS(feature_boxes(*mesh, x, x, -0.5), InputError);
}

TEST_CASE("CPU pipeline in parts (part_pairs): a cut below the root, traversal and narrow phase a part at a time, the "
          "whole step's answer",
          "[pipeline][parts]") {
  lwsccd::ClothBallSimulation simulation(12000);
  simulation.advance(30);
  std::vector<lwsccd::Step> steps;
  for (int s = 0; s < 4; ++s) steps.push_back(simulation.next_step());
  for (const lwsccd::CcdMode mode : {lwsccd::CcdMode::contacts, lwsccd::CcdMode::earliest, lwsccd::CcdMode::set}) {
    lwsccd::PipelineParams whole_params;
    whole_params.mode = mode;
    lwsccd::PipelineParams part_params = whole_params;
    part_params.part_pairs = 500;
    lwsccd::cpu::CcdPipeline<> whole(simulation.mesh(), simulation.layout(), whole_params);
    lwsccd::cpu::CcdPipeline<> parts(simulation.mesh(), simulation.layout(), part_params);
    for (std::size_t i = 0; i < steps.size(); ++i) {
      INFO("mode " << static_cast<int>(mode) << ", step " << i);
      const auto w = whole.step(steps[i].x0, steps[i].x1);
      const auto p = parts.step(steps[i].x0, steps[i].x1);
      lwsccd_test::require_same_contacts(p.contacts, w.contacts);
      REQUIRE(p.contacts.earliest_toi == w.contacts.earliest_toi);
      REQUIRE(p.stats.triangle_pairs == w.stats.triangle_pairs);
      REQUIRE(p.stats.feature_pairs_vf == w.stats.feature_pairs_vf);
      REQUIRE(p.stats.feature_pairs_ee == w.stats.feature_pairs_ee);
      REQUIRE(p.stats.front_size == w.stats.front_size);  // the same front kept, found in parts
      REQUIRE(p.stats.restarted_from_root == w.stats.restarted_from_root);
      if (mode == lwsccd::CcdMode::contacts) {
        lwsccd_test::require_same_counts(p.contacts.vf_counts, w.contacts.vf_counts);
        lwsccd_test::require_same_counts(p.contacts.ee_counts, w.contacts.ee_counts);
        CHECK(w.stats.hits_vf + w.stats.hits_ee > 0);
      }
      // Split for real: more parts than the candidates could fill at 500 each, none with more.
      REQUIRE(p.stats.narrow_parts > w.stats.triangle_pairs / 500);
      REQUIRE(p.stats.traversal_parts > 1);
      CHECK(w.stats.narrow_parts == 0);
      // Each stage's time is counted once: the parts' add up to no more than the step's.
      for (const auto* s : {&w.stats, &p.stats}) {
        CHECK(s->traverse_ms > 0);
        CHECK(s->narrow_ms > 0);
        CHECK(s->refit_ms + s->traverse_ms + s->features_ms + s->narrow_ms <= s->total_ms);
      }
    }
  }
}

TEST_CASE("cpu::expand: a cut of the traversal whose parts give the whole traversal", "[traverse][parts]") {
  const auto m = lwsccd_test::folded_cloth(40, 2);
  lwsccd::cpu::Bvh<lwsccd::Aabbf> bvh;
  bvh.build(m.mesh, m.x0, m.x1);
  const lwsccd::SelfCollisionTask<lwsccd::Aabbf> task{bvh.view(), lwsccd::LeafFilter{nullptr, nullptr, m.mesh.faces().data(), true}};
  const std::vector<lwsccd::NodePair> root{lwsccd::NodePair{0, 0}};
  auto whole = lwsccd::cpu::traverse(task, root, true);
  std::sort(whole.results.begin(), whole.results.end());
  for (const std::size_t target : {std::size_t(1), std::size_t(10), std::size_t(1000)}) {
    std::vector<lwsccd::NodePair> cut;
    auto met = lwsccd::cpu::expand(task, root, target, true, cut);
    CHECK((cut.size() >= target || cut.empty()));
    std::vector<lwsccd::TrianglePair> results = met.results;
    std::size_t front = met.front.size();
    for (std::size_t first = 0; first < cut.size(); first += 3) {
      const std::vector<lwsccd::NodePair> part(cut.begin() + first, cut.begin() + std::min(cut.size(), first + 3));
      const auto r = lwsccd::cpu::traverse(task, part, true);
      results.insert(results.end(), r.results.begin(), r.results.end());
      front += r.front.size();
    }
    std::sort(results.begin(), results.end());
    REQUIRE(results == whole.results);
    REQUIRE(front == whole.front.size());
  }
}

namespace {

// A backend that records the calls run_stage_sequence makes: `traversal_parts` traversal parts,
// each followed by `narrow_per_part` narrow-phase parts, then `leftover_parts` narrow-phase parts
// that no traversal part holds.
struct RecordingBackend {
  int traversal_parts = 1, narrow_per_part = 1, leftover_parts = 0;
  int traversals_done = 0, narrow_left = 0;
  bool traversal_over = false;
  std::string calls;

  bool next_traversal_part(std::string&) {
    calls += "?T ";
    traversal_over = traversals_done == traversal_parts;
    if (traversal_over) narrow_left = leftover_parts;
    return !traversal_over;
  }
  bool next_narrow_part(std::string&) {
    calls += "?N ";
    if (narrow_left == 0) return false;
    --narrow_left;
    return true;
  }
  void stage_refit(std::string&) { calls += "refit "; }
  void stage_traversal(std::string&) {
    calls += "traversal ";
    ++traversals_done;
    narrow_left = narrow_per_part;
  }
  void stage_feature_pairs(std::string&) { calls += "features "; }
  void stage_narrow_phase(std::string&) { calls += "narrow "; }
  void stage_done(detail::PipelineStage stage, std::string&) { calls += "done" + std::to_string(static_cast<int>(stage)) + " "; }
  void complete_step(std::string&) { calls += "complete"; }
};

}  // namespace

TEST_CASE("run_stage_sequence: a whole step is one part of each kind; a step in parts interleaves them, leftovers last",
          "[pipeline][parts]") {
  std::string unused;
  RecordingBackend whole;
  detail::run_stage_sequence(whole, unused);
  CHECK(whole.calls ==
        "refit done0 ?T traversal done1 ?N features done2 narrow done3 ?N ?T ?N complete");

  RecordingBackend parts;
  parts.traversal_parts = 2;
  parts.narrow_per_part = 2;
  parts.leftover_parts = 1;
  detail::run_stage_sequence(parts, unused);
  const std::string narrow = "features done2 narrow done3 ";
  const std::string part = "?T traversal done1 ?N " + narrow + "?N " + narrow + "?N ";
  CHECK(parts.calls == "refit done0 " + part + part + "?T ?N " + narrow + "?N complete");

  // A traversal part without candidates: no narrow-phase part, the next traversal part follows.
  RecordingBackend empty;
  empty.traversal_parts = 2;
  empty.narrow_per_part = 0;
  detail::run_stage_sequence(empty, unused);
  CHECK(empty.calls == "refit done0 ?T traversal done1 ?N ?T traversal done1 ?N ?T ?N complete");
}

TEST_CASE("CPU pipeline: any thread count gives the same steps, bit for bit (PipelineParams::threads)", "[pipeline][threads]") {
  lwsccd::ClothBallSimulation simulation(12000);
  simulation.advance(30);
  std::vector<lwsccd::Step> steps;
  for (int s = 0; s < 3; ++s) steps.push_back(simulation.next_step());
  auto with_threads = [&](unsigned n) {
    lwsccd::PipelineParams params;
    params.threads = n;
    params.rebuild_factor = 1;  // a rebuild every step: the parallel build as well as the refit
    return lwsccd::cpu::CcdPipeline<>(simulation.mesh(), simulation.layout(), params);
  };
  auto one = with_threads(1), two = with_threads(2), five = with_threads(5);
  for (std::size_t i = 0; i < steps.size(); ++i) {
    INFO("step " << i);
    const auto a = one.step(steps[i].x0, steps[i].x1);
    REQUIRE(a.stats.hits_vf + a.stats.hits_ee > 0);
    for (auto* other : {&two, &five}) {
      const auto b = other->step(steps[i].x0, steps[i].x1);
      lwsccd_test::require_same_contacts(b.contacts, a.contacts);
      REQUIRE(b.contacts.earliest_toi == a.contacts.earliest_toi);
      REQUIRE(b.stats.triangle_pairs == a.stats.triangle_pairs);
      REQUIRE(b.stats.bvtt_nodes == a.stats.bvtt_nodes);
      REQUIRE(b.stats.front_size == a.stats.front_size);
      REQUIRE(b.stats.feature_pairs_vf == a.stats.feature_pairs_vf);
      REQUIRE(b.stats.feature_pairs_ee == a.stats.feature_pairs_ee);
      lwsccd_test::require_same_counts(b.contacts.vf_counts, a.contacts.vf_counts);
      lwsccd_test::require_same_counts(b.contacts.ee_counts, a.contacts.ee_counts);
    }
  }
}

static_assert(std::is_move_constructible_v<lwsccd::cpu::CcdPipeline<>> && std::is_move_assignable_v<lwsccd::cpu::CcdPipeline<>>,
              "cpu::CcdPipeline: movable");

TEST_CASE("CPU pipeline moved and assigned mid-sequence steps on as the pipeline it was, under its own thread limit",
          "[pipeline][threads]") {
  const auto first = lwsccd_test::folded_cloth(30, 1);
  auto mesh = std::make_shared<const TriangleMesh>(first.mesh);
  PipelineParams two_threads;
  two_threads.threads = 2;
  cpu::CcdPipeline<> unmoved(mesh), moving(mesh, two_threads);
  for (int s = 0; s < 5; ++s) {
    INFO("step " << s);
    const auto m = lwsccd_test::folded_cloth(30, 1 + s);
    if (s == 2) {
      cpu::CcdPipeline<> constructed(std::move(moving));
      moving = cpu::CcdPipeline<>(mesh);  // assigned over: a fresh pipeline for a moment
      moving = std::move(constructed);    // and the stepped one back, its front with it
      CHECK(moving.params().threads == 2);
    }
    const auto g = moving.step(m.x0, m.x1);
    const auto u = unmoved.step(m.x0, m.x1);
    lwsccd_test::require_same_contacts(g.contacts, u.contacts);
    CHECK(g.stats.restarted_from_root == u.stats.restarted_from_root);
    CHECK(g.stats.bvtt_nodes == u.stats.bvtt_nodes);
  }
}

TEST_CASE("cpu::ThreadLimit: the work inside run() gets the limit; the BVH it builds is the one of all cores",
          "[pipeline][threads]") {
  const auto m = lwsccd_test::folded_cloth(24, 1);
  const cpu::ThreadLimit three(3), every_core;
  CHECK(three.threads() == 3);
  CHECK(three.effective_threads() == 3);
  CHECK(every_core.effective_threads() >= 1);
  CHECK(three.run([] { return detail::worker_count(); }) == 3u);
  CHECK(cpu::ThreadLimit(1).run([] { return detail::worker_count(); }) == 1u);
  // Exceptions pass through run().
  CHECK_THROWS_AS(three.run([]() -> int { throw InputError("here", "x", "thrown inside"); }), InputError);
  const auto serial = cpu::ThreadLimit(1).run([&] { return cpu::Bvh<Aabbf>(m.mesh, m.x0, m.x1); });
  const cpu::Bvh<Aabbf> parallel(m.mesh, m.x0, m.x1);
  REQUIRE(serial.nodes().leaf_primitive == parallel.nodes().leaf_primitive);
  REQUIRE(serial.nodes().parent == parallel.nodes().parent);
  REQUIRE(serial.cost_at_build() == parallel.cost_at_build());
  for (std::size_t i = 0; i < parallel.nodes().bvs.size(); ++i) {
    REQUIRE(serial.nodes().bvs[i].lo == parallel.nodes().bvs[i].lo);
    REQUIRE(serial.nodes().bvs[i].hi == parallel.nodes().bvs[i].hi);
  }
}

TEST_CASE("reserve_large and push_back_large: lists past the huge-page size keep every element as they grow",
          "[pipeline][threads]") {
  // Large enough that the buffers take the huge-page path (kHugePageListBytes), several times.
  const std::size_t n = 5 * detail::kHugePageListBytes / sizeof(std::pair<index_t, index_t>);
  std::vector<std::pair<index_t, index_t>> grown;
  for (std::size_t i = 0; i < n; ++i) detail::push_back_large(grown, {static_cast<index_t>(i), static_cast<index_t>(n - i)});
  REQUIRE(grown.size() == n);
  CHECK(grown.capacity() * sizeof(grown[0]) >= detail::kHugePageListBytes);
  bool intact = true;
  for (std::size_t i = 0; i < n; ++i) intact = intact && grown[i].first == index_t(i) && grown[i].second == index_t(n - i);
  CHECK(intact);
  // reserve_large keeps the elements too, and never shrinks.
  const auto* before = grown.data();
  detail::reserve_large(grown, n / 2);
  CHECK(grown.data() == before);
  detail::reserve_large(grown, 3 * n);
  CHECK(grown.capacity() >= 3 * n);
  CHECK(grown.size() == n);
  CHECK(grown[n - 1].first == index_t(n - 1));
  // The copies that gather threads' lists into one go through it.
  std::vector<std::vector<std::pair<index_t, index_t>>> lists(3, grown);
  std::vector<std::pair<index_t, index_t>> all;
  detail::concatenate_in_parallel(lists, all);
  REQUIRE(all.size() == 3 * n);
  CHECK(all[2 * n + 7] == grown[7]);
}
