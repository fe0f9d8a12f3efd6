// The ray-casting task on the CPU engine against testing every triangle.
#include <catch2/catch.hpp>

#include "lwsccd/io/dataset.hpp"
#include "lwsccd/traversal/cpu_traverse.hpp"
#include "ray_fixtures.hpp"
#include "scene_fixtures.hpp"
#include "test_support.hpp"

using namespace lwsccd;

static_assert(require_traversal_task<RayCastTask>::value, "");
static_assert(require_traversal_task<RayWalkTask<>>::value, "");
static_assert(RayWalkTask<>::kMaxChildren == 16 && RayWalkTask<1>::kMaxChildren == 3, "a walk hands back its stack and two nodes");

namespace {

// Walks of `budget` nodes with a stack of StackSize through the CPU work-stealing engine; the
// items it processed go to `items`.
template <int StackSize>
std::vector<std::uint64_t> walked(const cpu::Bvh<Aabbf>& bvh, const TriangleMesh& mesh, const std::vector<Vec3f>& x,
                                  const std::vector<Ray>& rays, bool any_hit, int budget, std::size_t& items) {
  std::vector<std::uint64_t> best(rays.size(), kNoHit);
  RayWalkTask<StackSize> task;
  static_cast<RayCastTask&>(task) = RayCastTask{bvh.view(), mesh.faces().data(), x.data(), rays.data(), best.data(), any_hit};
  task.visit_budget = budget;
  std::vector<RayNode> seeds;
  for (index_t r = 0; r < static_cast<index_t>(rays.size()); ++r) seeds.push_back({r, 0});
  items = cpu::traverse(task, seeds, false, cpu::WorkStealingScheduler{2}).stats.items_processed;
  return best;
}

template <class Scheduler>
std::vector<std::uint64_t> traced(const cpu::Bvh<Aabbf>& bvh, const TriangleMesh& mesh, const std::vector<Vec3f>& x,
                                  const std::vector<Ray>& rays, bool any_hit, Scheduler s, bool stored_inverses = false) {
  std::vector<std::uint64_t> best(rays.size(), kNoHit);
  RayCastTask task{bvh.view(), mesh.faces().data(), x.data(), rays.data(), best.data(), any_hit};
  const std::vector<Vec3f> inverse = inverse_directions(rays);
  if (stored_inverses) task.inverse = inverse.data();
  std::vector<RayNode> seeds;
  for (index_t r = 0; r < static_cast<index_t>(rays.size()); ++r) seeds.push_back({r, 0});
  cpu::traverse(task, seeds, false, s);
  return best;
}

void check_mesh(const TriangleMesh& mesh, const std::vector<Vec3f>& x, int grid, int random_rays) {
  const cpu::Bvh<Aabbf> bvh(mesh, x, x);
  const auto rays = lwsccd_test::test_rays(x, grid, random_rays);
  const auto reference = lwsccd_test::brute_force_hits(rays, mesh.faces(), x);
  REQUIRE(traced(bvh, mesh, x, rays, false, cpu::SerialScheduler{}) == reference);
  REQUIRE(traced(bvh, mesh, x, rays, false, cpu::WorkStealingScheduler{3}) == reference);
  REQUIRE(traced(bvh, mesh, x, rays, false, cpu::WorkStealingScheduler{2}, true) == reference);  // stored inverses
  // Any hit: a ray is blocked exactly when it has a closest hit.
  const auto any = traced(bvh, mesh, x, rays, true, cpu::WorkStealingScheduler{2});
  std::size_t hits = 0;
  for (std::size_t r = 0; r < rays.size(); ++r) {
    REQUIRE((any[r] == kNoHit) == (reference[r] == kNoHit));
    hits += reference[r] != kNoHit;
  }
  CHECK(hits > rays.size() / 10);
  // Walks: whole rays, budgets that split them, a stack of one node that fills at once. Each
  // hands what it did not visit back, so all give the same hits; the items counted show that
  // the short budgets and the small stack did split rays.
  std::size_t whole = 0, budget_3 = 0, budget_16 = 0, tiny_stack = 0;
  REQUIRE(walked<6>(bvh, mesh, x, rays, false, 0, whole) == reference);
  REQUIRE(walked<6>(bvh, mesh, x, rays, false, 3, budget_3) == reference);
  REQUIRE(walked<6>(bvh, mesh, x, rays, false, 16, budget_16) == reference);
  REQUIRE(walked<1>(bvh, mesh, x, rays, false, 0, tiny_stack) == reference);
  CHECK(budget_3 > budget_16);
  CHECK(budget_16 > whole);
  CHECK(tiny_stack > whole);
  std::size_t unused = 0;
  const auto any_walked = walked<6>(bvh, mesh, x, rays, true, 5, unused);
  for (std::size_t r = 0; r < rays.size(); ++r) REQUIRE((any_walked[r] == kNoHit) == (reference[r] == kNoHit));
}

}  // namespace

TEST_CASE("ray casting through the traversal engine equals testing every triangle", "[ray]") {
  const auto m = lwsccd_test::folded_cloth(30, 1);
  std::vector<Vec3f> x(m.x0.size());
  for (std::size_t v = 0; v < x.size(); ++v) x[v] = m.x0[v].cast<float>();
  check_mesh(m.mesh, x, 24, 300);
  if (lwsccd_test::have_data()) {
    const Scene scene = load_scene(lwsccd_test::data_dir() + "/scenes/cloth-funnel");
    std::vector<Vec3f> y(scene.step.x0.size());
    for (std::size_t v = 0; v < y.size(); ++v) y[v] = scene.step.x0[v].cast<float>();
    check_mesh(*scene.step.mesh, y, 16, 200);
  } else {
    WARN("shared data not found: the real-scene part of this test was skipped");
  }
}
