// The traversal engine's CPU backend with the BVTT tasks, against the brute-force oracle.
#include <catch2/catch.hpp>

#include <algorithm>

#include "lwsccd/traversal/bvtt.hpp"
#include "lwsccd/traversal/cpu_traverse.hpp"
#include "scene_fixtures.hpp"

using namespace lwsccd;
using lwsccd_test::MovingMesh;

// Compile-time contract: the library's tasks compose (the rejections are tests/compile_fail/).
static_assert(require_traversal_task<SelfCollisionTask<Aabbf>>::value, "");
static_assert(require_traversal_task<SelfCollisionTask<Obbd>>::value, "");
static_assert(require_traversal_task<InterCollisionTask<Aabbd>>::value, "");

namespace {

template <class Result>
std::vector<Result> sorted(std::vector<Result> v) {
  std::sort(v.begin(), v.end());
  return v;
}

template <class BV, class Scheduler>
std::vector<TrianglePair> self_pairs(const cpu::Bvh<BV>& bvh, const TriangleMesh& mesh, Scheduler s,
                                     const index_t* face_body = nullptr, const unsigned char* self = nullptr) {
  SelfCollisionTask<BV> task{bvh.view(), LeafFilter{face_body, self, mesh.faces().data(), false}};
  return sorted(cpu::traverse(task, {NodePair{0, 0}}, false, s).results);
}

}  // namespace

TEMPLATE_TEST_CASE("CPU self-collision traversal equals brute force (serial and work stealing)", "[traverse]", Aabbf,
                   Aabbd, Obbf) {
  using BV = TestType;
  for (const MovingMesh& m : {lwsccd_test::folded_cloth(24, 1), lwsccd_test::random_soup(1500, 2),
                              lwsccd_test::coincident_triangles(40), lwsccd_test::random_soup(1, 3),
                              lwsccd_test::random_soup(2, 4)}) {
    INFO("faces " << m.mesh.num_faces());
    const cpu::Bvh<BV> bvh(m.mesh, m.x0, m.x1);
    const auto reference = brute_force_pairs(m.mesh, swept_triangle_bvs<BV>(m.mesh, m.x0, m.x1));
    REQUIRE(self_pairs(bvh, m.mesh, cpu::SerialScheduler{}) == reference);
    REQUIRE(self_pairs(bvh, m.mesh, cpu::WorkStealingScheduler{4}) == reference);
    REQUIRE(self_pairs(bvh, m.mesh, cpu::WorkStealingScheduler{1}) == reference);
  }
}

TEST_CASE("CPU traversal: bodies that do not self-collide, and skipping adjacent pairs", "[traverse]") {
  const MovingMesh m = lwsccd_test::random_soup(900, 7);
  BodyLayout layout;
  for (index_t f = 0; f < m.mesh.num_faces(); ++f) layout.face_body.push_back(f % 3);
  layout.body_self_collides = {true, false, true};
  const unsigned char self[3] = {1, 0, 1};
  const cpu::Bvh<Aabbd> bvh(m.mesh, m.x0, m.x1);
  const auto reference = brute_force_pairs(m.mesh, swept_triangle_bvs<Aabbd>(m.mesh, m.x0, m.x1), layout);
  REQUIRE(self_pairs(bvh, m.mesh, cpu::WorkStealingScheduler{3}, layout.face_body.data(), self) == reference);
  // skip_adjacent drops exactly the adjacent pairs.
  const MovingMesh cloth = lwsccd_test::folded_cloth(16, 2);
  const cpu::Bvh<Aabbd> cloth_bvh(cloth.mesh, cloth.x0, cloth.x1);
  SelfCollisionTask<Aabbd> task{cloth_bvh.view(), LeafFilter{nullptr, nullptr, cloth.mesh.faces().data(), true}};
  const auto non_adjacent = sorted(cpu::traverse(task, {NodePair{0, 0}}).results);
  std::vector<TrianglePair> expected;
  for (const auto& p : brute_force_pairs(cloth.mesh, swept_triangle_bvs<Aabbd>(cloth.mesh, cloth.x0, cloth.x1)))
    if (!p.adjacent) expected.push_back(p);
  REQUIRE(non_adjacent == expected);
  REQUIRE_FALSE(expected.empty());
}

TEST_CASE("CPU traversal between two BVHs equals brute force across the meshes", "[traverse]") {
  const MovingMesh a = lwsccd_test::random_soup(700, 11), b = lwsccd_test::random_soup(500, 12);
  const cpu::Bvh<Obbf> ta(a.mesh, a.x0, a.x1), tb(b.mesh, b.x0, b.x1);
  InterCollisionTask<Obbf> task{ta.view(), tb.view()};
  const auto got = sorted(cpu::traverse(task, {NodePair{0, 0}}, false, cpu::WorkStealingScheduler{2}).results);
  const auto ba = swept_triangle_bvs<Obbf>(a.mesh, a.x0, a.x1), bb = swept_triangle_bvs<Obbf>(b.mesh, b.x0, b.x1);
  std::vector<TrianglePair> expected;
  for (index_t i = 0; i < a.mesh.num_faces(); ++i)
    for (index_t j = 0; j < b.mesh.num_faces(); ++j)
      if (Obbf::overlap(ba[i], bb[j])) expected.push_back({i, j, false});
  REQUIRE(got == expected);
  REQUIRE(expected.size() > 20);
}

TEST_CASE("front tracking: restarting from the front gives the fresh traversal's pairs, step after step", "[traverse][front]") {
  // A folded cloth over several steps: refit each step, traverse from last step's front.
  MovingMesh m = lwsccd_test::folded_cloth(20, 1);
  cpu::Bvh<Aabbf> bvh(m.mesh, m.x0, m.x1);
  SelfCollisionTask<Aabbf> task{bvh.view(), LeafFilter{nullptr, nullptr, m.mesh.faces().data(), false}};
  auto first = cpu::traverse(task, {NodePair{0, 0}}, true);
  std::vector<NodePair> front = first.front;
  REQUIRE(front.size() > 0);
  for (int step = 1; step <= 6; ++step) {
    const MovingMesh next = lwsccd_test::folded_cloth(20, 1 + step);  // same topology, new motion
    bvh.refit(next.x0, next.x1);
    task.bvh = bvh.view();
    const auto from_front = cpu::traverse(task, front, true, cpu::WorkStealingScheduler{2});
    const auto fresh = cpu::traverse(task, {NodePair{0, 0}}, true);
    INFO("step " << step);
    REQUIRE(sorted(from_front.results) == sorted(fresh.results));
    REQUIRE(sorted(fresh.results) == brute_force_pairs(m.mesh, swept_triangle_bvs<Aabbf>(m.mesh, next.x0, next.x1)));
    // Restarting visits fewer BVTT nodes than starting from the root.
    CHECK(from_front.stats.items_processed < fresh.stats.items_processed);
    front = from_front.front;
  }
}

TEST_CASE("CPU traversal from the root hands parts of a thread's stack on: same results, front and work as one thread", "[traverse]") {
  // Large enough that the threads' ranges of the cut below the root run past kHandOnItems.
  const MovingMesh m = lwsccd_test::folded_cloth(90, 5);
  const cpu::Bvh<Aabbf> bvh(m.mesh, m.x0, m.x1);
  SelfCollisionTask<Aabbf> task{bvh.view(), LeafFilter{nullptr, nullptr, m.mesh.faces().data(), false}};
  const auto serial = cpu::traverse(task, {NodePair{0, 0}}, true);
  auto front_order = [](const NodePair& x, const NodePair& y) { return x.a != y.a ? x.a < y.a : x.b < y.b; };
  auto sorted_front = [&](std::vector<NodePair> f) {
    std::sort(f.begin(), f.end(), front_order);
    return f;
  };
  for (unsigned threads : {2u, 3u, 4u}) {
    INFO("threads " << threads);
    const auto stolen = cpu::traverse(task, {NodePair{0, 0}}, true, cpu::WorkStealingScheduler{threads});
    CHECK(stolen.stats.handed_on > 0);
    REQUIRE(sorted(stolen.results) == sorted(serial.results));
    const auto a = sorted_front(stolen.front), b = sorted_front(serial.front);
    REQUIRE(a.size() == b.size());
    REQUIRE(std::equal(a.begin(), a.end(), b.begin(), [](const NodePair& x, const NodePair& y) { return x.a == y.a && x.b == y.b; }));
    CHECK(stolen.stats.items_processed == serial.stats.items_processed);
    // From a kept front (many seeds) nothing is handed on.
    CHECK(cpu::traverse(task, serial.front, true, cpu::WorkStealingScheduler{threads}).stats.handed_on == 0);
  }
  REQUIRE(serial.results.size() > 1000);
}

TEST_CASE("CPU traversal into the threads' lists: the results and front of one list, and a front kept in lists as seeds",
          "[traverse][front]") {
  MovingMesh m = lwsccd_test::folded_cloth(60, 2);
  cpu::Bvh<Aabbf> bvh(m.mesh, m.x0, m.x1);
  SelfCollisionTask<Aabbf> task{bvh.view(), LeafFilter{nullptr, nullptr, m.mesh.faces().data(), false}};
  auto key = [](const NodePair& p) { return std::make_pair(p.a, p.b); };
  auto keys = [&](const std::vector<NodePair>& f) {
    std::vector<std::pair<index_t, index_t>> k;
    for (const NodePair& p : f) k.push_back(key(p));
    std::sort(k.begin(), k.end());
    return k;
  };
  const auto serial = cpu::traverse(task, {NodePair{0, 0}}, true);
  cpu::TraversalWorkspace<SelfCollisionTask<Aabbf>> workspace;
  const cpu::ListsOf<NodePair> root{NodePair{0, 0}};
  const TraversalStats stats = cpu::traverse_in_lists(task, root, true, cpu::WorkStealingScheduler{3}, workspace);
  REQUIRE(workspace.results.lists.size() == 3);
  REQUIRE(sorted(workspace.results.joined()) == sorted(serial.results));
  REQUIRE(keys(workspace.fronts.joined()) == keys(serial.front));
  CHECK(stats.results == serial.results.size());
  CHECK(stats.front == serial.front.size());
  CHECK(stats.items_processed == serial.stats.items_processed);
  // The front kept in those lists seeds the next step's traversal, as BasicFrontTracker keeps it.
  BasicFrontTracker<cpu::ListsOf<NodePair>> tracker(FrontPolicy{1e9});  // (never restarts on growth)
  REQUIRE(tracker.seeds(bvh.generation()).size() == 1);  // the root first
  tracker.exchange(workspace.fronts);
  REQUIRE(tracker.size() == serial.front.size());
  for (int step = 1; step <= 3; ++step) {
    const MovingMesh next = lwsccd_test::folded_cloth(60, 2 + step);
    bvh.refit(next.x0, next.x1);
    task.bvh = bvh.view();
    INFO("step " << step);
    const auto& seeds = tracker.seeds(bvh.generation());
    REQUIRE_FALSE(tracker.last_was_restart());
    const auto from_root = cpu::traverse(task, {NodePair{0, 0}}, true);
    cpu::traverse_in_lists(task, seeds, true, cpu::WorkStealingScheduler{2}, workspace);
    REQUIRE(sorted(workspace.results.joined()) == sorted(from_root.results));
    // The same front as a traversal from the old front in one list.
    std::vector<NodePair> old_front = seeds.joined();
    const auto from_one_list = cpu::traverse(task, old_front, true);
    REQUIRE(keys(workspace.fronts.joined()) == keys(from_one_list.front));
    tracker.exchange(workspace.fronts);
  }
}
