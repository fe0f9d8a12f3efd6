// Ray casting with every GPU scheduler (no change to any of them): the same closest hits as
// testing every triangle, hit for hit.
#include <catch2/catch.hpp>

#include "lwsccd/bvh/bvh.cuh"
#include "lwsccd/io/dataset.hpp"
#include "lwsccd/traverse.cuh"
#include "ray_fixtures.hpp"
#include "scene_fixtures.hpp"
#include "test_support.hpp"

using namespace lwsccd;

namespace {

// Scheduler policies measured or tested beside the defaults (knobs overridden by name).
struct StaticDeepStack : gpu::StaticTaskList {
  static constexpr int kSharedStack = 4096;
};
struct BalancedDeepStack : gpu::GProximityBalancer {
  static constexpr int kSharedStack = 4096;
};

// The rays on the device, every ray's best hit at kNoHit, one seed {ray, root} per ray.
struct UploadedRays {
  gpu::DeviceBuffer<Ray> rays;
  gpu::DeviceBuffer<std::uint64_t> best;
  gpu::DeviceBuffer<RayNode> seeds;
  explicit UploadedRays(const std::vector<Ray>& host) {
    rays.upload(host);
    best.upload(std::vector<std::uint64_t>(host.size(), kNoHit));
    std::vector<RayNode> s;
    for (index_t r = 0; r < static_cast<index_t>(host.size()); ++r) s.push_back({r, 0});
    seeds.upload(s);
  }
};

template <class Scheduler>
std::vector<std::uint64_t> traced(const gpu::Bvh<Aabbf>& bvh, const gpu::DeviceBuffer<Face>& faces,
                                  const gpu::DeviceBuffer<Vec3f>& x, const std::vector<Ray>& rays, bool any_hit,
                                  bool stored_inverses = false) {
  UploadedRays d(rays);
  RayCastTask task{bvh.view(), faces.data(), x.data(), d.rays.data(), d.best.data(), any_hit};
  gpu::DeviceBuffer<Vec3f> inverse;
  if (stored_inverses) {
    inverse.upload(inverse_directions(rays));
    task.inverse = inverse.data();
  }
  gpu::TraversalOutput<RayCastTask> out;
  gpu::traverse<Scheduler>(task, d.seeds.data(), d.seeds.size(), out, false);
  return d.best.download();
}

// Walks of `budget` nodes (RayWalkTask, StackSize + 2 children per item: policies with room for them).
template <class Scheduler, int StackSize = 14>
std::vector<std::uint64_t> walked(const gpu::Bvh<Aabbf>& bvh, const gpu::DeviceBuffer<Face>& faces,
                                  const gpu::DeviceBuffer<Vec3f>& x, const std::vector<Ray>& rays, bool any_hit, int budget) {
  UploadedRays d(rays);
  RayWalkTask<StackSize> task;
  static_cast<RayCastTask&>(task) = RayCastTask{bvh.view(), faces.data(), x.data(), d.rays.data(), d.best.data(), any_hit};
  task.visit_budget = budget;
  gpu::TraversalOutput<RayWalkTask<StackSize>> out;
  gpu::traverse<Scheduler>(task, d.seeds.data(), d.seeds.size(), out, false);
  return d.best.download();
}

// Small pops and deques, no flat start: walks handed back are stolen and spilled often.
struct WalkLazyTight : gpu::LazyStealScheduler {
  static constexpr int kBlockThreads = 32;
  static constexpr int kSharedStack = 1024;
  static constexpr int kDequeCapacity = 512;
  static constexpr int kPopSize = 16;
  static constexpr int kPushThreshold = 512;
  static constexpr int kFlatStartPerBlock = 0;
};

void check_mesh(const TriangleMesh& mesh, const std::vector<Vec3d>& x0, int grid, int random_rays) {
  std::vector<Vec3f> x(x0.size());
  for (std::size_t v = 0; v < x.size(); ++v) x[v] = x0[v].cast<float>();
  gpu::DeviceStep<float> step(mesh, x0, x0);
  gpu::Bvh<Aabbf> bvh;
  bvh.build(step);
  gpu::DeviceBuffer<Face> faces;
  faces.upload(mesh.faces());
  gpu::DeviceBuffer<Vec3f> dx;
  dx.upload(x);
  const auto rays = lwsccd_test::test_rays(x, grid, random_rays);
  const auto reference = lwsccd_test::brute_force_hits(rays, mesh.faces(), x);
  REQUIRE(traced<gpu::StaticTaskList>(bvh, faces, dx, rays, false) == reference);
  REQUIRE(traced<gpu::GProximityBalancer>(bvh, faces, dx, rays, false) == reference);
  REQUIRE(traced<gpu::LazyStealScheduler>(bvh, faces, dx, rays, false) == reference);
  REQUIRE(traced<gpu::LazyStealScheduler>(bvh, faces, dx, rays, false, true) == reference);  // stored inverses
  const auto any = traced<gpu::LazyStealScheduler>(bvh, faces, dx, rays, true);
  for (std::size_t r = 0; r < rays.size(); ++r) REQUIRE((any[r] == kNoHit) == (reference[r] == kNoHit));
  // Walks (RayWalkTask): whole rays, budgets that split them, a one-node stack, each scheduler.
  for (const int budget : {0, 3, 32}) {
    INFO("visit budget " << budget);
    REQUIRE(walked<gpu::RayWalkLazySteal>(bvh, faces, dx, rays, false, budget) == reference);
    REQUIRE(walked<WalkLazyTight>(bvh, faces, dx, rays, false, budget) == reference);
    REQUIRE(walked<StaticDeepStack>(bvh, faces, dx, rays, false, budget) == reference);
    REQUIRE(walked<BalancedDeepStack>(bvh, faces, dx, rays, false, budget) == reference);
    REQUIRE(walked<gpu::LazyStealScheduler, 4>(bvh, faces, dx, rays, false, budget) == reference);  // 6 children: the default fits
  }
  REQUIRE(walked<gpu::LazyStealScheduler, 1>(bvh, faces, dx, rays, false, 0) == reference);
  const auto any_walked = walked<gpu::RayWalkLazySteal>(bvh, faces, dx, rays, true, 5);
  for (std::size_t r = 0; r < rays.size(); ++r) REQUIRE((any_walked[r] == kNoHit) == (reference[r] == kNoHit));
}

}  // namespace

TEST_CASE("GPU ray casting with every scheduler equals testing every triangle", "[gpu][ray]") {
  const auto m = lwsccd_test::folded_cloth(40, 2);
  check_mesh(m.mesh, m.x0, 32, 500);
  if (!lwsccd_test::have_data()) {
    WARN("SKIPPED (real scenes): shared data not found at " << lwsccd_test::data_dir());
    return;
  }
  for (const char* name : {"cloth-funnel", "cloth-ball"}) {
    INFO(name);
    const Scene scene = load_scene(lwsccd_test::data_dir() + "/scenes/" + name);
    check_mesh(*scene.step.mesh, scene.step.x0, 16, 150);
  }
}
