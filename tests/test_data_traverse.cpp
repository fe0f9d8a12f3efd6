// The CPU traversal engine on the real scenes and on every step of horse-gallop with front
// tracking, against the sort-and-sweep / brute-force oracle.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cstdio>

#include "lwsccd/io/dataset.hpp"
#include "lwsccd/traversal/bvtt.hpp"
#include "lwsccd/traversal/cpu_traverse.hpp"
#include "test_support.hpp"

using namespace lwsccd;

namespace {
template <class V>
V sorted(V v) {
  std::sort(v.begin(), v.end());
  return v;
}
}  // namespace

TEMPLATE_TEST_CASE("CPU traversal equals the oracle on the real scenes", "[data][traverse]", Aabbf, Obbf) {
  using BV = TestType;
  // OBB: the O(n^2) brute-force oracle is affordable on cloth-funnel only.
  const std::vector<const char*> scenes = std::is_same<BV, Aabbf>::value
                                              ? std::vector<const char*>{"cloth-funnel", "armadillo-rollers", "cloth-ball"}
                                              : std::vector<const char*>{"cloth-funnel"};
  for (const char* name : scenes) {
    INFO(name);
    const Scene scene = load_scene(lwsccd_test::data_dir() + "/scenes/" + name);
    const TriangleMesh& mesh = *scene.step.mesh;
    const cpu::Bvh<BV> bvh(mesh, scene.step.x0, scene.step.x1);
    SelfCollisionTask<BV> task{bvh.view(), LeafFilter{nullptr, nullptr, mesh.faces().data(), false}};
    const auto got = cpu::traverse(task, {NodePair{0, 0}}, false, cpu::WorkStealingScheduler{});
    const auto leaf_bvs = swept_triangle_bvs<BV>(mesh, scene.step.x0, scene.step.x1);
    std::vector<TrianglePair> expected;
    if constexpr (std::is_same<BV, Aabbf>::value) {
      expected = sweep_and_prune_pairs(mesh, leaf_bvs);
    } else {
      expected = brute_force_pairs(mesh, leaf_bvs);
    }
    std::printf("%s (%s): %zu candidate triangle pairs, %zu BVTT nodes visited\n", name,
                std::is_same<BV, Aabbf>::value ? "AABB" : "OBB", expected.size(), got.stats.items_processed);
    REQUIRE(sorted(got.results) == expected);
  }
}

TEST_CASE("horse-gallop, all 47 steps: refit + front tracking equals a fresh traversal and the oracle", "[data][traverse][front]") {
  const Sequence horse = load_sequence(lwsccd_test::data_dir() + "/sequences/horse-gallop");
  const TriangleMesh& mesh = *horse.mesh();
  cpu::Bvh<Aabbf> bvh(mesh, horse.frame(0), horse.frame(1));
  SelfCollisionTask<Aabbf> task{bvh.view(), LeafFilter{nullptr, nullptr, mesh.faces().data(), false}};
  FrontTracker tracker;
  tracker.update(cpu::traverse(task, tracker.seeds(bvh.generation()), true).front);
  std::size_t tracked_nodes = 0, fresh_nodes = 0, restarts = 0;
  for (std::size_t s = 1; s < horse.num_steps(); ++s) {
    INFO("step " << s);
    bvh.refit(horse.frame(s), horse.frame(s + 1));
    task.bvh = bvh.view();
    const auto tracked = cpu::traverse(task, tracker.seeds(bvh.generation()), true, cpu::WorkStealingScheduler{});
    restarts += tracker.last_was_restart();
    tracker.update(tracked.front);
    const auto fresh = cpu::traverse(task, {NodePair{0, 0}}, false);
    const auto oracle = sweep_and_prune_pairs(mesh, swept_triangle_bvs<Aabbf>(mesh, horse.frame(s), horse.frame(s + 1)));
    REQUIRE(sorted(tracked.results) == oracle);
    REQUIRE(sorted(fresh.results) == oracle);
    tracked_nodes += tracked.stats.items_processed;
    fresh_nodes += fresh.stats.items_processed;
  }
  std::printf("horse-gallop: BVTT nodes visited over 46 refitted steps: %zu with front tracking (%zu restarts from "
              "the root), %zu always from the root\n",
              tracked_nodes, restarts, fresh_nodes);
}
