// GPU schedulers x BVs x tasks against the CPU traversal engine, pair for pair.
#include <catch2/catch.hpp>

#include <algorithm>
#include <stdexcept>
#include <type_traits>

#include "lwsccd/bvh/bvh.cuh"
#include "lwsccd/io/dataset.hpp"
#include "lwsccd/traversal/bvtt.hpp"
#include "lwsccd/traversal/cpu_traverse.hpp"
#include "lwsccd/traversal/independent_traversal.cuh"
#include "lwsccd/traverse.cuh"
#include "scene_fixtures.hpp"
#include "test_support.hpp"

using namespace lwsccd;
using lwsccd_test::MovingMesh;

namespace {

// Scheduler policies measured or tested beside the defaults (knobs overridden by name).
struct NoFitLazy : gpu::LazyStealScheduler {
  static constexpr bool kFitBlocksPerSm = false;
};

// Tiny capacities: spills, hand-backs and relaunches on every run.
struct TinyStatic : gpu::StaticTaskList {
  static constexpr int kBlockThreads = 32;
  static constexpr int kSharedStack = 192;
  static constexpr int kGlobalStack = 64;
  static constexpr int kItemsPerBlock = 8;
};
struct TinyBalanced : gpu::GProximityBalancer {
  static constexpr int kBlockThreads = 32;
  static constexpr int kSharedStack = 192;
  static constexpr int kGlobalStack = 64;
  static constexpr int kIdlePercent = 30;
};
struct TinyLazy : gpu::LazyStealScheduler {
  static constexpr int kBlockThreads = 32;
  static constexpr int kSharedStack = 192;
  static constexpr int kDequeCapacity = 64;
  static constexpr int kPopSize = 32;
  static constexpr int kPushThreshold = 64;
};
// A flat first launch for any start of at least one item per block (the default asks 512).
struct FlatLazy : gpu::LazyStealScheduler {
  static constexpr int kFlatStartPerBlock = 1;
};
struct TinyFlatLazy : TinyLazy {
  static constexpr int kFlatStartPerBlock = 1;
};
// Sharing on demand (kShareWhenHungry; the defaults share above half of kPushThreshold): eagerly
// in the default's shape and with tiny deques that overflow, and never (0: sharing off).
struct NeverHungryLazy : gpu::LazyStealScheduler {
  static constexpr int kShareWhenHungry = 0;
};
struct TinyNeverHungryLazy : TinyLazy {
  static constexpr int kShareWhenHungry = 0;
};
struct HungryLazy : gpu::LazyStealScheduler {
  static constexpr int kShareWhenHungry = 128;
};
struct TinyHungryLazy : TinyLazy {
  static constexpr int kShareWhenHungry = 8;
};

template <class V>
V sorted(V v) {
  std::sort(v.begin(), v.end());
  return v;
}

// Node pairs (a front) as sorted (a, b) pairs, to compare as sets.
std::vector<std::pair<index_t, index_t>> as_pairs(const std::vector<NodePair>& items) {
  std::vector<std::pair<index_t, index_t>> pairs;
  for (const NodePair& p : items) pairs.emplace_back(p.a, p.b);
  std::sort(pairs.begin(), pairs.end());
  return pairs;
}

// A folded cloth on the device - positions, a BVH over them, the faces - and its self-collision
// task (adjacent triangle pairs skipped unless `keep_adjacent`), as several cases set it up.
template <class BV>
struct DeviceFoldedCloth {
  DeviceFoldedCloth(int n, int folds) : cloth(lwsccd_test::folded_cloth(n, folds)), step(cloth.mesh, cloth.x0, cloth.x1) {
    bvh.build(step);
    faces.upload(cloth.mesh.faces());
  }
  SelfCollisionTask<BV> task(bool keep_adjacent = false) const {
    return {bvh.view(), LeafFilter{nullptr, nullptr, faces.data(), keep_adjacent}};
  }
  MovingMesh cloth;
  gpu::DeviceStep<double> step;
  gpu::Bvh<BV> bvh;
  gpu::DeviceBuffer<Face> faces;
};

template <class Scheduler, class Task>
std::vector<TrianglePair> gpu_pairs(const Task& task, const std::vector<NodePair>& seeds, gpu::TraversalOutput<Task>& out,
                                    bool record_front = false) {
  gpu::DeviceBuffer<NodePair> d_seeds;
  d_seeds.upload(seeds);
  gpu::traverse<Scheduler>(task, d_seeds.data(), seeds.size(), out, record_front);
  return sorted(out.download_results());
}

template <class BV, class Scheduler>
void self_matches_cpu(const MovingMesh& m, bool tiny_outputs) {
  gpu::DeviceStep<double> step(m.mesh, m.x0, m.x1);
  gpu::Bvh<BV> gbvh;
  gbvh.build(step);
  gpu::DeviceBuffer<Face> faces;
  faces.upload(m.mesh.faces());
  SelfCollisionTask<BV> gtask{gbvh.view(), LeafFilter{nullptr, nullptr, faces.data(), false}};
  const cpu::Bvh<BV> cbvh(m.mesh, m.x0, m.x1);
  SelfCollisionTask<BV> ctask{cbvh.view(), LeafFilter{nullptr, nullptr, m.mesh.faces().data(), false}};
  const auto expected = sorted(cpu::traverse(ctask, {NodePair{0, 0}}).results);
  gpu::TraversalOutput<SelfCollisionTask<BV>> out;
  if (tiny_outputs) gpu::detail::storage_of(out).results_.resize_discard(1);  // forces growth and a rerun
  REQUIRE(gpu_pairs<Scheduler>(gtask, {NodePair{0, 0}}, out) == expected);
  // Karras's independent traversal (the baseline) finds the same pairs.
  gpu::TraversalOutput<SelfCollisionTask<BV>> independent;
  if (tiny_outputs) gpu::detail::storage_of(independent).results_.resize_discard(1);
  gpu::independent_self_traversal(gtask, independent);
  REQUIRE(sorted(independent.download_results()) == expected);
  if (tiny_outputs && !expected.empty()) CHECK(out.stats().relaunches > 0);
  CHECK(out.stats().items_processed > 0);
}

// Every GPU scheduler and Karras's traversal, from the root, against an oracle pair list.
template <class BV>
void every_scheduler_matches(const TriangleMesh& mesh, const std::vector<Vec3d>& x0, const std::vector<Vec3d>& x1,
                             const std::vector<TrianglePair>& oracle, const char* name) {
  gpu::DeviceStep<double> step(mesh, x0, x1);
  gpu::Bvh<BV> bvh;
  bvh.build(step);
  gpu::DeviceBuffer<Face> faces;
  faces.upload(mesh.faces());
  SelfCollisionTask<BV> task{bvh.view(), LeafFilter{nullptr, nullptr, faces.data(), false}};
  gpu::TraversalOutput<SelfCollisionTask<BV>> out;
  REQUIRE(gpu_pairs<gpu::StaticTaskList>(task, {NodePair{0, 0}}, out) == oracle);
  REQUIRE(gpu_pairs<gpu::GProximityBalancer>(task, {NodePair{0, 0}}, out) == oracle);
  REQUIRE(gpu_pairs<gpu::LazyStealScheduler>(task, {NodePair{0, 0}}, out) == oracle);
  gpu::independent_self_traversal(task, out);
  REQUIRE(sorted(out.download_results()) == oracle);
  std::printf("%s: %zu pairs, %zu BVTT nodes (Karras)\n", name, oracle.size(), out.stats().items_processed);
}

}  // namespace

TEMPLATE_TEST_CASE("GPU schedulers equal the CPU engine on self collision", "[gpu][traverse]", Aabbf, Obbf) {
  using BV = TestType;
  for (const MovingMesh& m : {lwsccd_test::folded_cloth(40, 1), lwsccd_test::random_soup(4000, 2),
                              lwsccd_test::coincident_triangles(50), lwsccd_test::random_soup(1, 3),
                              lwsccd_test::random_soup(2, 4)}) {
    INFO("faces " << m.mesh.num_faces());
    self_matches_cpu<BV, gpu::StaticTaskList>(m, false);
    self_matches_cpu<BV, gpu::GProximityBalancer>(m, false);
    self_matches_cpu<BV, TinyStatic>(m, true);
    self_matches_cpu<BV, TinyBalanced>(m, true);
    self_matches_cpu<BV, gpu::LazyStealScheduler>(m, false);
    self_matches_cpu<BV, TinyLazy>(m, true);
    self_matches_cpu<BV, HungryLazy>(m, false);
    self_matches_cpu<BV, TinyHungryLazy>(m, true);
    self_matches_cpu<BV, NeverHungryLazy>(m, false);
    self_matches_cpu<BV, TinyNeverHungryLazy>(m, true);
  }
}

// A traversal whose outputs fill up part way keeps what they hold: the blocks that find no room
// hand their items back unprocessed, the host grows the outputs and relaunches with those items.
// The same results and front as with room enough, and the same items processed (none twice).
template <class Scheduler, class Task>
void fills_up_and_goes_on(const Task& task, const std::vector<NodePair>& seeds, const std::vector<TrianglePair>& results,
                          const std::vector<std::pair<index_t, index_t>>& front, std::size_t processed) {
  gpu::TraversalOutput<Task> out;
  gpu::detail::storage_of(out).results_.resize_discard(7);
  gpu::detail::storage_of(out).front_.resize_discard(5);
  REQUIRE(gpu_pairs<Scheduler>(task, seeds, out, true) == results);
  CHECK(as_pairs(out.download_front()) == front);
  CHECK(out.complete());
  CHECK(out.stats().relaunches > 0);
  CHECK(out.stats().items_processed == processed);
  // Only the front short of room, then only the results.
  gpu::detail::storage_of(out).front_ = gpu::DeviceBuffer<NodePair>(3);
  REQUIRE(gpu_pairs<Scheduler>(task, seeds, out, true) == results);
  CHECK(as_pairs(out.download_front()) == front);
  gpu::detail::storage_of(out).results_ = gpu::DeviceBuffer<TrianglePair>(2);
  REQUIRE(gpu_pairs<Scheduler>(task, seeds, out, true) == results);
  CHECK(as_pairs(out.download_front()) == front);
  CHECK(out.stats().items_processed == processed);
}

TEST_CASE("GPU traversals whose outputs fill up keep what they hold and go on from there", "[gpu][traverse][front]") {
  const DeviceFoldedCloth<Aabbf> cloth(40, 2);
  using Task = SelfCollisionTask<Aabbf>;
  const Task task = cloth.task();
  gpu::TraversalOutput<Task> roomy;
  const std::vector<NodePair> root{NodePair{0, 0}};
  const auto results = gpu_pairs<gpu::LazyStealScheduler>(task, root, roomy, true);
  const auto front_items = roomy.download_front();
  const auto front = as_pairs(front_items);
  const std::size_t processed = roomy.stats().items_processed;
  REQUIRE(results.size() > 100);
  REQUIRE(front.size() > 100);
  fills_up_and_goes_on<gpu::StaticTaskList>(task, root, results, front, processed);
  fills_up_and_goes_on<gpu::GProximityBalancer>(task, root, results, front, processed);
  fills_up_and_goes_on<gpu::LazyStealScheduler>(task, root, results, front, processed);
  fills_up_and_goes_on<TinyStatic>(task, root, results, front, processed);
  fills_up_and_goes_on<TinyBalanced>(task, root, results, front, processed);
  fills_up_and_goes_on<TinyLazy>(task, root, results, front, processed);
  // From a front (the flat start: the items it cannot finish go to the next launch unprocessed).
  const auto from_front = gpu_pairs<gpu::LazyStealScheduler>(task, front_items, roomy, true);
  const auto next_front = as_pairs(roomy.download_front());
  const std::size_t from_front_processed = roomy.stats().items_processed;
  fills_up_and_goes_on<FlatLazy>(task, front_items, from_front, next_front, from_front_processed);
  fills_up_and_goes_on<TinyFlatLazy>(task, front_items, from_front, next_front, from_front_processed);
  // The cut of gpu::expand: what it met on the way is kept across the growths as well.
  gpu::DeviceBuffer<NodePair> d_root;
  d_root.upload(root);
  gpu::TraversalOutput<Task> cut_out;
  gpu::detail::storage_of(cut_out).results_.resize_discard(1);
  gpu::detail::storage_of(cut_out).front_.resize_discard(1);
  const std::size_t n = gpu::expand(task, d_root.data(), 1, 2000, cut_out, true);
  REQUIRE(cut_out.complete());
  std::vector<TrianglePair> met = cut_out.download_results();
  std::vector<NodePair> met_front = cut_out.download_front();
  gpu::DeviceBuffer<NodePair> cut(std::max<std::size_t>(n, 1));
  if (n) LWSCCD_CUDA_CHECK(cudaMemcpy(cut.data(), cut_out.expanded(), n * sizeof(NodePair), cudaMemcpyDeviceToDevice));
  gpu::traverse<gpu::LazyStealScheduler>(task, cut.data(), n, cut_out, true);
  const auto rest = cut_out.download_results();
  const auto rest_front = cut_out.download_front();
  met.insert(met.end(), rest.begin(), rest.end());
  met_front.insert(met_front.end(), rest_front.begin(), rest_front.end());
  CHECK(sorted(met) == results);
  CHECK(as_pairs(met_front) == front);
}

TEST_CASE("device memory budget: exceeding it is a clear error, not a crash", "[gpu][traverse]") {
  const DeviceFoldedCloth<Aabbf> cloth(60, 1);
  const SelfCollisionTask<Aabbf> task = cloth.task();
  const std::size_t previous = gpu::memory_budget();
  gpu::set_memory_budget(gpu::memory_stats().in_use + 4096);  // almost nothing more
  gpu::TraversalOutput<SelfCollisionTask<Aabbf>> out;
  gpu::DeviceBuffer<NodePair> root;
  CHECK_THROWS_WITH(root.upload(std::vector<NodePair>(1000, NodePair{0, 0})), Catch::Contains("memory budget exceeded"));
  gpu::set_memory_budget(gpu::memory_stats().in_use + (1 << 20));  // enough for the seeds only
  root.upload(std::vector<NodePair>{NodePair{0, 0}});
  CHECK_THROWS_WITH(gpu::traverse<gpu::LazyStealScheduler>(task, root.data(), 1, out, true),
                    Catch::Contains("memory budget exceeded"));
  gpu::set_memory_budget(previous);
  // With the budget lifted the same objects work.
  gpu::traverse<gpu::LazyStealScheduler>(task, root.data(), 1, out, true);
  CHECK(out.num_results() > 0);
}

TEST_CASE("GPU traversal split into parts: a cut below the root, traversed a part at a time, gives the whole traversal",
          "[gpu][traverse][streaming]") {
  const DeviceFoldedCloth<Aabbf> cloth(80, 2);
  using Task = SelfCollisionTask<Aabbf>;
  const Task task = cloth.task(true);
  gpu::DeviceBuffer<NodePair> root;
  root.upload(std::vector<NodePair>{NodePair{0, 0}});
  gpu::TraversalOutput<Task> whole;
  gpu::traverse<gpu::LazyStealScheduler>(task, root.data(), 1, whole, true);
  std::vector<TrianglePair> expected_results = whole.download_results();
  const auto expected_front = as_pairs(whole.download_front());
  std::sort(expected_results.begin(), expected_results.end());
  REQUIRE(!expected_results.empty());
  for (const std::size_t target : {std::size_t(1), std::size_t(64), std::size_t(5000)}) {
    INFO("cut of at least " << target);
    gpu::TraversalOutput<Task> out;
    const std::size_t n = gpu::expand(task, root.data(), 1, target, out, true);
    CHECK((n >= target || n == 0));
    std::vector<TrianglePair> results = out.download_results();
    std::vector<NodePair> front = out.download_front();
    gpu::DeviceBuffer<NodePair> cut;
    cut.upload(std::vector<NodePair>(n));
    LWSCCD_CUDA_CHECK(cudaMemcpy(cut.data(), out.expanded(), n * sizeof(NodePair), cudaMemcpyDeviceToDevice));
    const std::size_t part = std::max<std::size_t>(1, n / 7);
    for (std::size_t first = 0; first < n; first += part) {
      gpu::traverse<gpu::StaticTaskList>(task, cut.data() + first, std::min(part, n - first), out, true);
      REQUIRE(out.complete());
      const auto r = out.download_results();
      const auto f = out.download_front();
      results.insert(results.end(), r.begin(), r.end());
      front.insert(front.end(), f.begin(), f.end());
    }
    std::sort(results.begin(), results.end());
    REQUIRE(results == expected_results);
    REQUIRE(as_pairs(front) == expected_front);
  }
  // An output limit below what the traversal yields: it stops, says so, and grows nothing.
  gpu::TraversalOutput<Task> limited;
  limited.set_output_limit(1024);
  gpu::traverse<gpu::LazyStealScheduler>(task, root.data(), 1, limited, true);
  CHECK_FALSE(limited.complete());
  limited.set_output_limit(0);
  gpu::traverse<gpu::LazyStealScheduler>(task, root.data(), 1, limited, true);
  CHECK(limited.complete());
  CHECK(limited.num_results() == expected_results.size());
}

TEST_CASE("GPU schedulers: inter-object task and restarting from a front", "[gpu][traverse][front]") {
  const MovingMesh a = lwsccd_test::random_soup(3000, 21), b = lwsccd_test::random_soup(2000, 22);
  gpu::DeviceStep<double> sa(a.mesh, a.x0, a.x1), sb(b.mesh, b.x0, b.x1);
  gpu::Bvh<Aabbf> ta, tb;
  ta.build(sa);
  tb.build(sb);
  const cpu::Bvh<Aabbf> ca(a.mesh, a.x0, a.x1), cb(b.mesh, b.x0, b.x1);
  const auto expected = sorted(cpu::traverse(InterCollisionTask<Aabbf>{ca.view(), cb.view()}, {NodePair{0, 0}}).results);
  gpu::TraversalOutput<InterCollisionTask<Aabbf>> out;
  REQUIRE(gpu_pairs<gpu::StaticTaskList>(InterCollisionTask<Aabbf>{ta.view(), tb.view()}, {NodePair{0, 0}}, out) == expected);
  REQUIRE(gpu_pairs<TinyBalanced>(InterCollisionTask<Aabbf>{ta.view(), tb.view()}, {NodePair{0, 0}}, out) == expected);
  REQUIRE(gpu_pairs<gpu::LazyStealScheduler>(InterCollisionTask<Aabbf>{ta.view(), tb.view()}, {NodePair{0, 0}}, out) == expected);
  REQUIRE(expected.size() > 10);

  // Front: record on the GPU, refit, restart from it; equals a fresh CPU traversal.
  const MovingMesh m0 = lwsccd_test::folded_cloth(40, 1), m1 = lwsccd_test::folded_cloth(40, 2);
  gpu::DeviceStep<double> step(m0.mesh, m0.x0, m0.x1);
  gpu::Bvh<Aabbf> bvh;
  bvh.build(step);
  gpu::DeviceBuffer<Face> faces;
  faces.upload(m0.mesh.faces());
  SelfCollisionTask<Aabbf> task{bvh.view(), LeafFilter{nullptr, nullptr, faces.data(), false}};
  gpu::TraversalOutput<SelfCollisionTask<Aabbf>> self_out;
  gpu_pairs<gpu::GProximityBalancer>(task, {NodePair{0, 0}}, self_out, true);
  const auto front = self_out.download_front();
  REQUIRE(front.size() > 0);
  step.set_positions(m1.x0, m1.x1);
  bvh.refit(step);
  cpu::Bvh<Aabbf> cbvh(m0.mesh, m0.x0, m0.x1);
  cbvh.refit(m1.x0, m1.x1);
  SelfCollisionTask<Aabbf> ctask{cbvh.view(), LeafFilter{nullptr, nullptr, m0.mesh.faces().data(), false}};
  const auto fresh = sorted(cpu::traverse(ctask, {NodePair{0, 0}}).results);
  REQUIRE(gpu_pairs<gpu::StaticTaskList>(task, front, self_out, true) == fresh);
  const auto next_front = as_pairs(self_out.download_front());
  REQUIRE(gpu_pairs<TinyStatic>(task, front, self_out, true) == fresh);
  REQUIRE(gpu_pairs<TinyLazy>(task, front, self_out, true) == fresh);
  // Every block of the lazy scheduler reports its activity; a block leaves only after a search
  // for work found nothing anywhere, so each counts at least one failed steal.
  const auto activity = self_out.download_block_activity();
  unsigned long long busy = 0;
  for (const gpu::BlockActivity& a : activity) {
    busy += a.busy_cycles;
    CHECK(a.failed_steals >= 1);
  }
  CHECK(busy > 0);
  // The flat start (one launch over the whole front, the blocks sharing only its children): same
  // pairs and the same next front, with the default capacities and with tiny ones.
  REQUIRE(gpu_pairs<FlatLazy>(task, front, self_out, true) == fresh);
  CHECK(self_out.stats().flat_start_items == front.size());
  CHECK(as_pairs(self_out.download_front()) == next_front);
  REQUIRE(gpu_pairs<TinyFlatLazy>(task, front, self_out, true) == fresh);
  CHECK(self_out.stats().flat_start_items == front.size());
  CHECK(as_pairs(self_out.download_front()) == next_front);
  // From the root (one item) there is no flat start.
  gpu_pairs<FlatLazy>(task, {NodePair{0, 0}}, self_out, true);
  CHECK(self_out.stats().flat_start_items == 0);
}

namespace {
__global__ void read_device_count(gpu::DeviceCount count, std::size_t* value) { *value = count.get(); }

// What a later stage on the stream reads as the number of results.
template <class Task>
std::size_t device_result_count(const gpu::TraversalOutput<Task>& out) {
  gpu::DeviceBuffer<std::size_t> value(1);
  read_device_count<<<1, 1>>>(out.result_count(), value.data());
  LWSCCD_CUDA_CHECK_LAUNCH();
  return value.download()[0];
}
}  // namespace

TEST_CASE("GPU lazy stealing from a front without a host round trip: traverse_async, then collect", "[gpu][traverse][front]") {
  const MovingMesh m1 = lwsccd_test::folded_cloth(40, 2);
  DeviceFoldedCloth<Aabbf> cloth(40, 1);
  const SelfCollisionTask<Aabbf> task = cloth.task();
  gpu::TraversalOutput<SelfCollisionTask<Aabbf>> out;
  gpu_pairs<gpu::LazyStealScheduler>(task, {NodePair{0, 0}}, out, true);
  const std::vector<NodePair> front = out.download_front();
  REQUIRE(front.size() > 0);
  cloth.step.set_positions(m1.x0, m1.x1);
  cloth.bvh.refit(cloth.step);
  const auto fresh = gpu_pairs<gpu::LazyStealScheduler>(task, front, out, true);
  const auto next_front = as_pairs(out.download_front());
  const std::size_t processed = out.stats().items_processed;
  REQUIRE(fresh.size() > 10);
  gpu::DeviceBuffer<NodePair> seeds;
  seeds.upload(front);
  // Enqueues, reads the count a later stage would, collects; traverse() again where it asks.
  auto run_async = [&](auto scheduler, bool& complete, std::size_t& on_device) {
    using Scheduler = decltype(scheduler);
    gpu::traverse_async<Scheduler>(task, seeds.data(), front.size(), out, true);
    on_device = device_result_count(out);  // synchronizes
    complete = out.collect();
    if (!complete) gpu::traverse<Scheduler>(task, seeds.data(), front.size(), out, true);
    return sorted(out.download_results());
  };
  bool complete = false;
  std::size_t on_device = 0;
  REQUIRE(run_async(FlatLazy{}, complete, on_device) == fresh);
  CHECK(complete);
  CHECK(on_device == fresh.size());
  CHECK(out.num_results() == fresh.size());
  CHECK(as_pairs(out.download_front()) == next_front);
  CHECK(out.stats().flat_start_items == front.size());
  CHECK(out.stats().items_processed == processed);
  // Tiny deques: blocks hand items back, which only the host relaunches; collect() says so.
  REQUIRE(run_async(TinyFlatLazy{}, complete, on_device) == fresh);
  CHECK(as_pairs(out.download_front()) == next_front);
  // Outputs too small: the device's count stops at their room, collect() grows them and asks for
  // traverse(), which then fits them without growing again.
  gpu::detail::storage_of(out).results_.resize_discard(3);
  gpu::detail::storage_of(out).front_.resize_discard(5);
  REQUIRE(run_async(FlatLazy{}, complete, on_device) == fresh);
  CHECK_FALSE(complete);
  CHECK(on_device == 3);
  CHECK(out.stats().relaunches == 0);
  CHECK(out.front_complete());
  CHECK(as_pairs(out.download_front()) == next_front);
  // Only the front too small: the results are complete (no traverse() asked for), the front is
  // not (none kept), and its output is grown so that the next traversal's fits.
  REQUIRE(next_front.size() > 5);
  gpu::detail::storage_of(out).front_.resize_discard(5);
  gpu::traverse_async<FlatLazy>(task, seeds.data(), front.size(), out, true);
  CHECK(device_result_count(out) == fresh.size());
  CHECK(out.collect());
  CHECK_FALSE(out.front_complete());
  CHECK(out.num_front() == 0);
  CHECK(sorted(out.download_results()) == fresh);
  CHECK(gpu::detail::storage_of(out).front_.size() >= next_front.size());
  REQUIRE(run_async(FlatLazy{}, complete, on_device) == fresh);
  CHECK(complete);
  CHECK(out.front_complete());
  CHECK(as_pairs(out.download_front()) == next_front);
  // Lists too short for the flat start's children: the device counts what had no room, collect()
  // asks for traverse(), which grows them until a pass fits; the same with tiny deques, whose
  // hand-backs overflow too, and with traverse() alone.
  REQUIRE(processed > front.size() + 1);  // the flat start leaves children
  gpu::detail::storage_of(out).list_room_ = 1;
  REQUIRE(run_async(FlatLazy{}, complete, on_device) == fresh);
  CHECK_FALSE(complete);
  CHECK(gpu::detail::storage_of(out).list_room_ > 1);
  CHECK(as_pairs(out.download_front()) == next_front);
  gpu::detail::storage_of(out).list_room_ = 1;
  REQUIRE(run_async(TinyFlatLazy{}, complete, on_device) == fresh);
  CHECK(as_pairs(out.download_front()) == next_front);
  gpu::detail::storage_of(out).list_room_ = 1;
  REQUIRE(gpu_pairs<TinyFlatLazy>(task, front, out, true) == fresh);
  CHECK(out.stats().relaunches > 0);
  CHECK(as_pairs(out.download_front()) == next_front);
  const auto from_root = gpu_pairs<gpu::LazyStealScheduler>(task, {NodePair{0, 0}}, out, true);
  gpu::detail::storage_of(out).list_room_ = 1;  // from the root: tiny deques hand items back into a list of one
  REQUIRE(gpu_pairs<TinyLazy>(task, {NodePair{0, 0}}, out, true) == from_root);
  // A start the flat launch does not take (the root) runs as traverse() does: nothing to collect.
  gpu::DeviceBuffer<NodePair> root;
  root.upload(std::vector<NodePair>{NodePair{0, 0}});
  gpu::traverse_async<FlatLazy>(task, root.data(), 1, out, true);
  CHECK(out.collect());
  CHECK(out.stats().flat_start_items == 0);
  CHECK(device_result_count(out) == out.num_results());
}

TEST_CASE("GPU lazy stealing: a start the flat launch ends reports no lazy launch", "[gpu][traverse][front]") {
  const DeviceFoldedCloth<Aabbf> cloth(40, 1);
  const SelfCollisionTask<Aabbf> task = cloth.task();
  gpu::TraversalOutput<SelfCollisionTask<Aabbf>> out;
  out.record_timeline(64);
  const auto from_root = gpu_pairs<FlatLazy>(task, {NodePair{0, 0}}, out, true);
  REQUIRE(out.launched_blocks() > 0);
  REQUIRE(out.download_block_activity().size() == static_cast<std::size_t>(out.launched_blocks()));
  REQUIRE(out.download_timeline().size() == static_cast<std::size_t>(out.launched_blocks()));
  // The same positions from the front: every item ends in the flat launch (leaf pairs, boxes
  // apart), so no lazy launch follows - and the activity and timeline of the root's launch, which
  // a benchmark would otherwise read as this traversal's, are not reported.
  const std::vector<NodePair> front = out.download_front();
  REQUIRE(front.size() >= static_cast<std::size_t>(out.launched_blocks()));
  REQUIRE(gpu_pairs<FlatLazy>(task, front, out, true) == from_root);
  CHECK(out.stats().flat_start_items == front.size());
  CHECK(out.stats().items_processed == front.size());
  CHECK(out.launched_blocks() == 0);
  CHECK(out.download_block_activity().empty());
  CHECK(out.download_timeline().empty());
  // Another scheduler on the same output reports none either.
  REQUIRE(gpu_pairs<gpu::LazyStealScheduler>(task, {NodePair{0, 0}}, out, true) == from_root);
  REQUIRE(out.launched_blocks() > 0);
  REQUIRE(gpu_pairs<gpu::StaticTaskList>(task, {NodePair{0, 0}}, out, true) == from_root);
  CHECK(out.launched_blocks() == 0);
  CHECK(out.download_block_activity().empty());
}

TEST_CASE("GPU lazy stealing: a recorded timeline changes no result and agrees with the activity counters", "[gpu][traverse]") {
  const DeviceFoldedCloth<Aabbf> cloth(40, 3);
  const SelfCollisionTask<Aabbf> task = cloth.task();
  gpu::TraversalOutput<SelfCollisionTask<Aabbf>> out;
  // Small batches and deques: many phases per block, steals, and a relaunch or two.
  const auto plain = gpu_pairs<TinyLazy>(task, {NodePair{0, 0}}, out);
  REQUIRE(out.download_timeline().empty());  // not recorded unless asked
  CHECK_THROWS_AS(out.record_timeline(-1), std::invalid_argument);
  out.record_timeline(1 << 14);
  // The log is of the last launch (a relaunch can be short), and steals depend on timing: a few
  // runs, each checked in full, until one of them stole.
  std::size_t steals = 0;
  for (int run = 0; run < 8 && steals == 0; ++run) {
    REQUIRE(gpu_pairs<TinyLazy>(task, {NodePair{0, 0}}, out) == plain);
    const auto timeline = out.download_timeline();
    const auto activity = out.download_block_activity();
    REQUIRE(timeline.size() == activity.size());
    std::size_t events = 0, items = 0;
    for (std::size_t b = 0; b < timeline.size(); ++b) {
      const auto& e = timeline[b].events;
      REQUIRE(timeline[b].recorded == e.size());  // all fit
      REQUIRE(e.size() >= 2);
      // Every block starts by looking for work and ends when none is left anywhere; a phase of
      // work follows each search that found some, and time never goes back.
      CHECK(e.front().phase == gpu::BlockPhase::seek);
      CHECK(e.back().phase == gpu::BlockPhase::done);
      std::size_t block_steals = 0;
      for (std::size_t k = 0; k < e.size(); ++k) {
        if (k > 0) CHECK(e[k].time_ns >= e[k - 1].time_ns);
        const bool found = e[k].phase == gpu::BlockPhase::own || e[k].phase == gpu::BlockPhase::steal;
        if (found) {
          CHECK(e[k].items > 0);
          CHECK(e[k - 1].phase == gpu::BlockPhase::seek);
          items += e[k].items;
        }
        block_steals += e[k].phase == gpu::BlockPhase::steal;
      }
      CHECK(block_steals == activity[b].steals);
      steals += block_steals;
      events += e.size();
    }
    std::printf("  timeline: %zu blocks, %zu events, %zu steals, %zu items taken from deques\n", timeline.size(), events, steals,
                items);
  }
  CHECK(steals > 0);
  // The room per block bounds what is kept, not what is counted.
  out.record_timeline(2);
  REQUIRE(gpu_pairs<TinyLazy>(task, {NodePair{0, 0}}, out) == plain);
  std::size_t over = 0;
  for (const auto& t : out.download_timeline()) {
    CHECK(t.events.size() <= 2);
    over += t.recorded > t.events.size();
  }
  CHECK(over > 0);
}

// The lazy kernel's blocks are persistent: a block that could not be resident beside the others
// (registers, shared memory) would start only once they had finished - as half of them did for
// OBB tasks (113 registers, one 512-thread block per SM of two launched) without that rule. The
// launch must hold only co-resident blocks: every block starts before any block is done.
TEMPLATE_TEST_CASE("GPU lazy stealing launches only blocks that are resident at once", "[gpu][traverse]", Aabbf, Obbf) {
  const DeviceFoldedCloth<TestType> cloth(40, 3);
  const SelfCollisionTask<TestType> task = cloth.task();
  const MovingMesh& m = cloth.cloth;
  cpu::Bvh<TestType> cbvh(m.mesh, m.x0, m.x1);
  const SelfCollisionTask<TestType> ctask{cbvh.view(), LeafFilter{nullptr, nullptr, m.mesh.faces().data(), false}};
  const auto expected = sorted(cpu::traverse(ctask, {NodePair{0, 0}}).results);
  int device = 0, sms = 0;
  REQUIRE(cudaGetDevice(&device) == cudaSuccess);
  REQUIRE(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, device) == cudaSuccess);
  auto require_co_resident = [&](auto scheduler, const char* name, bool fits_all) {
    using Scheduler = decltype(scheduler);
    INFO(name);
    gpu::TraversalOutput<SelfCollisionTask<TestType>> out;
    out.record_timeline(1 << 12);
    REQUIRE(gpu_pairs<Scheduler>(task, {NodePair{0, 0}}, out) == expected);
    const int blocks = out.launched_blocks();
    REQUIRE(blocks >= sms);
    REQUIRE(blocks <= sms * Scheduler::kBlocksPerSm);
    if (fits_all) REQUIRE(blocks == sms * Scheduler::kBlocksPerSm);
    const auto timeline = out.download_timeline();
    REQUIRE(timeline.size() == static_cast<std::size_t>(blocks));
    REQUIRE(out.download_block_activity().size() == static_cast<std::size_t>(blocks));
    unsigned long long last_start = 0, first_end = ~0ull;
    for (const auto& t : timeline) {
      REQUIRE(t.events.size() >= 2);
      REQUIRE(t.events.back().phase == gpu::BlockPhase::done);
      last_start = std::max(last_start, t.events.front().time_ns);
      first_end = std::min(first_end, t.events.back().time_ns);
    }
    std::printf("  lazy %s (%s): %d blocks on %d SMs; last block started %.1f us before the first ended\n", name,
                std::is_same<TestType, Obbf>::value ? "OBB" : "AABB", blocks, sms, (static_cast<double>(first_end) - static_cast<double>(last_start)) / 1e3);
    CHECK(last_start <= first_end);
  };
  // The defaults are compiled to fit their two blocks per SM: all of them are launched.
  require_co_resident(gpu::LazyStealScheduler{}, "defaults", true);
  // Left to the compiler's register choice (OBB: 113): fewer blocks, all resident.
  require_co_resident(NoFitLazy{}, "no fit", false);
}

TEST_CASE("GPU schedulers on the real scenes and every horse-gallop step with front tracking", "[gpu][traverse][data]") {
  if (!lwsccd_test::have_data()) {
    WARN("SKIPPED: shared data not found at " << lwsccd_test::data_dir());
    return;
  }
  for (const char* name : {"cloth-funnel", "armadillo-rollers", "cloth-ball"}) {
    INFO(name);
    const Scene scene = load_scene(lwsccd_test::data_dir() + "/scenes/" + name);
    const TriangleMesh& mesh = *scene.step.mesh;
    every_scheduler_matches<Aabbf>(mesh, scene.step.x0, scene.step.x1,
                                   sweep_and_prune_pairs(mesh, swept_triangle_bvs<Aabbf>(mesh, scene.step.x0, scene.step.x1)),
                                   name);
  }
  {  // OBB on cloth-funnel (the O(n^2) OBB oracle is affordable there)
    const Scene scene = load_scene(lwsccd_test::data_dir() + "/scenes/cloth-funnel");
    const TriangleMesh& mesh = *scene.step.mesh;
    every_scheduler_matches<Obbf>(mesh, scene.step.x0, scene.step.x1,
                                  brute_force_pairs(mesh, swept_triangle_bvs<Obbf>(mesh, scene.step.x0, scene.step.x1)),
                                  "cloth-funnel (OBB)");
  }
  const Sequence horse = load_sequence(lwsccd_test::data_dir() + "/sequences/horse-gallop");
  const TriangleMesh& mesh = *horse.mesh();
  {  // OBB over every horse step, each scheduler in turn, against the CPU engine (work stealing)
    gpu::DeviceStep<float> step(mesh, horse.frame(0), horse.frame(1));
    gpu::Bvh<Obbf> bvh;
    bvh.build(step);
    std::vector<Vec3f> f0(mesh.num_vertices()), f1(f0.size());
    auto to_float = [&](std::size_t s) {
      for (std::size_t v = 0; v < f0.size(); ++v) f0[v] = horse.frame(s)[v].cast<float>(), f1[v] = horse.frame(s + 1)[v].cast<float>();
    };
    to_float(0);
    cpu::Bvh<Obbf> cbvh(mesh, f0, f1);
    gpu::DeviceBuffer<Face> faces;
    faces.upload(mesh.faces());
    SelfCollisionTask<Obbf> task{bvh.view(), LeafFilter{nullptr, nullptr, faces.data(), false}};
    SelfCollisionTask<Obbf> ctask{cbvh.view(), LeafFilter{nullptr, nullptr, mesh.faces().data(), false}};
    gpu::TraversalOutput<SelfCollisionTask<Obbf>> out;
    gpu::detail::storage_of(out).front_.resize_discard(1);  // a one-entry front output: grows and reruns
    FrontTracker tracker;
    for (std::size_t s = 0; s < horse.num_steps(); ++s) {
      INFO("horse OBB step " << s);
      if (s > 0) {
        step.set_positions(horse.frame(s), horse.frame(s + 1));
        bvh.refit(step);
        to_float(s);
        cbvh.refit(f0, f1);
      }
      const auto expected = sorted(cpu::traverse(ctask, {NodePair{0, 0}}, false, cpu::WorkStealingScheduler{}).results);
      const auto& seeds = tracker.seeds(bvh.generation());
      const auto got = s % 3 == 0   ? gpu_pairs<gpu::LazyStealScheduler>(task, seeds, out, true)
                       : s % 3 == 1 ? gpu_pairs<gpu::GProximityBalancer>(task, seeds, out, true)
                                    : gpu_pairs<gpu::StaticTaskList>(task, seeds, out, true);
      REQUIRE(got == expected);
      tracker.update(out.download_front());
    }
  }
  gpu::DeviceStep<float> step(mesh, horse.frame(0), horse.frame(1));
  gpu::Bvh<Aabbf> bvh;
  bvh.build(step);
  gpu::DeviceBuffer<Face> faces;
  faces.upload(mesh.faces());
  SelfCollisionTask<Aabbf> task{bvh.view(), LeafFilter{nullptr, nullptr, faces.data(), false}};
  gpu::TraversalOutput<SelfCollisionTask<Aabbf>> out;
  gpu_pairs<gpu::StaticTaskList>(task, {NodePair{0, 0}}, out, true);
  FrontTracker tracker;
  tracker.update(out.download_front());
  for (std::size_t s = 1; s < horse.num_steps(); ++s) {
    INFO("horse step " << s);
    step.set_positions(horse.frame(s), horse.frame(s + 1));
    bvh.refit(step);
    std::vector<Vec3f> f0(horse.frame(s).size()), f1(f0.size());
    for (std::size_t v = 0; v < f0.size(); ++v) f0[v] = horse.frame(s)[v].cast<float>(), f1[v] = horse.frame(s + 1)[v].cast<float>();
    const auto oracle = sweep_and_prune_pairs(mesh, swept_triangle_bvs<Aabbf>(mesh, f0, f1));
    const auto& seeds = tracker.seeds(bvh.generation());
    const auto got = s % 3 == 0   ? gpu_pairs<gpu::LazyStealScheduler>(task, seeds, out, true)
                     : s % 3 == 1 ? gpu_pairs<gpu::GProximityBalancer>(task, seeds, out, true)
                                  : gpu_pairs<gpu::StaticTaskList>(task, seeds, out, true);
    REQUIRE(got == oracle);
    tracker.update(out.download_front());
  }
}
