// The GPU pipeline against the CPU pipeline: same contacts, same TOIs, step after step.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <exception>
#include <limits>
#include <thread>
#include <type_traits>

#include "lwsccd/features/representative.cuh"
#include "lwsccd/io/dataset.hpp"
#include "lwsccd/pipeline.cuh"
#include "lwsccd/pipeline/cpu_pipeline.hpp"
#include "lwsccd/simulation/scenes.hpp"
#include "lwsccd/simulation/simulation.hpp"
#include "contact_compare.hpp"
#include "scene_fixtures.hpp"
#include "test_support.hpp"

using namespace lwsccd;

namespace {

// Scheduler policies measured or tested beside the defaults (knobs overridden by name).
struct SmallLazy : gpu::LazyStealScheduler {
  static constexpr int kBlockThreads = 128;
  static constexpr int kSharedStack = 1024;
  static constexpr int kDequeCapacity = 1024;
  static constexpr int kPopSize = 256;
  static constexpr int kPushThreshold = 512;
  static constexpr int kBlocksPerSm = 1;
};
struct SmallStatic : gpu::StaticTaskList {
  static constexpr int kGlobalStack = 2048;
  static constexpr int kItemsPerBlock = 64;
};

template <class T>
void require_same_contacts(const StepResult<T>& gpu, const StepResult<T>& cpu) {
  REQUIRE(gpu.stats.triangle_pairs == cpu.stats.triangle_pairs);
  REQUIRE(gpu.stats.feature_pairs_vf == cpu.stats.feature_pairs_vf);
  REQUIRE(gpu.stats.feature_pairs_ee == cpu.stats.feature_pairs_ee);
  lwsccd_test::require_same_contacts(gpu.contacts, cpu.contacts);
}

}  // namespace

namespace {

// The GPU emitter over a candidate list equals the CPU emission over the same list: same pairs in
// the same order; and, sorted, the brute-force (or sweep) feature oracle. The emitter tests the
// faces' relative motion by default (the CPU's with face_corners); without it, the boxes' lists.
void require_gpu_emission_equals_cpu(const TriangleMesh& mesh, const std::vector<Vec3d>& x0, const std::vector<Vec3d>& x1,
                                     const BodyLayout& layout, bool brute_force) {
  const RepresentativeTriangles rep(mesh, layout);
  const std::vector<Aabbf> boxes = feature_boxes(mesh, x0, x1);
  const std::vector<FaceCorners> corners = face_corners(mesh, x0, x1);
  std::vector<TrianglePair> candidates =
      brute_force ? brute_force_pairs(mesh, swept_triangle_bvs<Aabbf>(mesh, x0, x1), layout)
                  : sweep_and_prune_pairs(mesh, swept_triangle_bvs<Aabbf>(mesh, x0, x1), layout);
  const FeaturePairs cpu = emit_feature_pairs(rep, candidates, boxes, &corners);  // adjacent candidates kept: both skip them
  const FeaturePairs cpu_boxes_only = emit_feature_pairs(rep, candidates, boxes);
  gpu::DeviceBuffer<TrianglePair> d_candidates;
  gpu::DeviceBuffer<Vec3d> d_x0, d_x1;
  d_candidates.upload(candidates);
  d_x0.upload(x0);
  d_x1.upload(x1);
  gpu::FeatureEmitter<> emitter(rep);
  REQUIRE(emitter.face_motion_test());
  // Runs 0, 1 (the buffers reused), without the test, and with it again (its corners recomputed
  // though the boxes are current).
  for (int run = 0; run < 4; ++run) {
    emitter.set_face_motion_test(run != 2);
    emitter.enqueue(d_x0.data(), d_x1.data(), d_candidates.data(), candidates.size(), nullptr, true, run == 3);
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(nullptr));
    if (!emitter.collect()) LWSCCD_CUDA_CHECK(cudaStreamSynchronize(nullptr));
    const FeaturePairs gpu_pairs = emitter.download();
    const FeaturePairs& expected = run == 2 ? cpu_boxes_only : cpu;
    REQUIRE(gpu_pairs.vf == expected.vf);
    REQUIRE(gpu_pairs.ee == expected.ee);
  }
  // The boxes enqueued apart on a stream of their own (as a pipeline's step does beside its
  // traversal), the emission after them on another stream: the same pairs.
  {
    gpu::CudaStream side(cudaStreamNonBlocking), main_stream(cudaStreamNonBlocking);
    gpu::CudaEvent boxes_done(cudaEventDisableTiming);
    gpu::FeatureEmitter<> apart(rep);
    for (int run = 0; run < 2; ++run) {
      apart.enqueue_boxes(d_x0.data(), d_x1.data(), side);
      LWSCCD_CUDA_CHECK(cudaEventRecord(boxes_done, side));
      LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(main_stream, boxes_done, 0));
      apart.enqueue(d_x0.data(), d_x1.data(), d_candidates.data(), candidates.size(), main_stream, true, true);
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(main_stream));
      if (!apart.collect(main_stream)) LWSCCD_CUDA_CHECK(cudaStreamSynchronize(main_stream));
      const FeaturePairs apart_pairs = apart.download();
      REQUIRE(apart_pairs.vf == cpu.vf);
      REQUIRE(apart_pairs.ee == cpu.ee);
    }
  }
  // A box margin (a minimum separation) turns the test off.
  emitter.set_box_margin(1e-3);
  CHECK_FALSE(emitter.face_motion_test());
  emitter.set_box_margin(0);
  // Without waiting: buffers sized by a run over an eighth of the candidates; the whole list may
  // outgrow them (collect() says so, grows them and writes again) and nothing is lost.
  gpu::FeatureEmitter<> unwaited(rep);
  unwaited.run(d_x0.data(), d_x1.data(), d_candidates.data(), candidates.size() / 8);
  const std::size_t part_vf = unwaited.num_vf(), part_ee = unwaited.num_ee();
  unwaited.enqueue(d_x0.data(), d_x1.data(), d_candidates.data(), candidates.size());
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(nullptr));
  const bool fitted = unwaited.collect();
  CHECK(fitted == (cpu.vf.size() <= part_vf + part_vf / 4 && cpu.ee.size() <= part_ee + part_ee / 4));
  const FeaturePairs unwaited_pairs = unwaited.download();
  REQUIRE(unwaited_pairs.vf == cpu.vf);
  REQUIRE(unwaited_pairs.ee == cpu.ee);
  // The candidates' number read on the device (as after gpu::traverse_async), with launches sized
  // for more: half of the list gives the CPU's emission over that half.
  const std::size_t half = candidates.size() / 2;
  gpu::DeviceBuffer<unsigned long long> count;
  count.upload(std::vector<unsigned long long>{half});
  unwaited.enqueue(d_x0.data(), d_x1.data(), d_candidates.data(),
                   gpu::DeviceCount{count.data(), gpu::DeviceCount::Part::whole, candidates.size() + 100}, nullptr,
                   gpu::FeatureEmitter<>::OrphanRange{0, unwaited.num_orphans()}, false);
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(nullptr));
  if (!unwaited.collect()) LWSCCD_CUDA_CHECK(cudaStreamSynchronize(nullptr));
  const FeaturePairs half_pairs = unwaited.download();
  const FeaturePairs cpu_half = emit_feature_pairs(rep, candidates.data(), half, boxes, true, &corners);
  REQUIRE(half_pairs.vf == cpu_half.vf);
  REQUIRE(half_pairs.ee == cpu_half.ee);
  FeaturePairs sorted = cpu;
  std::sort(sorted.vf.begin(), sorted.vf.end());
  std::sort(sorted.ee.begin(), sorted.ee.end());
  const FeaturePairs oracle =
      brute_force ? brute_force_feature_pairs(rep, boxes, &corners) : sweep_feature_pairs(rep, boxes, &corners);
  REQUIRE(sorted.vf == oracle.vf);
  REQUIRE(sorted.ee == oracle.ee);
  std::printf("GPU emission: %d faces, %zu candidates -> %zu + %zu feature pairs (%zu + %zu by the boxes alone; %zu + %zu "
              "orphans listed), equal to the CPU's in order and to the feature oracle\n",
              mesh.num_faces(), candidates.size(), cpu.vf.size(), cpu.ee.size(), cpu_boxes_only.vf.size(),
              cpu_boxes_only.ee.size(), rep.orphans().vf.size(), rep.orphans().ee.size());
}

}  // namespace

TEST_CASE("GPU feature emission equals the CPU's pair for pair and the feature oracle", "[gpu][pipeline][representative]") {
  for (std::uint64_t seed = 1; seed <= 3; ++seed) {
    const auto m = lwsccd_test::folded_cloth(30, seed);
    require_gpu_emission_equals_cpu(m.mesh, m.x0, m.x1, {}, true);
  }
  const MultiBodyStep scene = make_cloth_ball_scene(4000);
  require_gpu_emission_equals_cpu(*scene.step.mesh, scene.step.x0, scene.step.x1, scene.layout, true);
  const auto soup = lwsccd_test::random_soup(2000, 9, 0.05);
  require_gpu_emission_equals_cpu(soup.mesh, soup.x0, soup.x1, {}, true);
  // No candidates at all: only the orphans.
  const auto small = lwsccd_test::folded_cloth(6, 1);
  const RepresentativeTriangles rep(small.mesh);
  gpu::FeatureEmitter<> emitter(rep);
  gpu::DeviceBuffer<Vec3d> d_x0, d_x1;
  d_x0.upload(small.x0);
  d_x1.upload(small.x1);
  emitter.run(d_x0.data(), d_x1.data(), static_cast<const TrianglePair*>(nullptr), 0);
  const FeaturePairs only_orphans = emitter.download();
  const FeaturePairs expected = emit_feature_pairs(rep, {}, feature_boxes(small.mesh, small.x0, small.x1));
  CHECK(only_orphans.vf == expected.vf);
  CHECK(only_orphans.ee == expected.ee);
  if (!lwsccd_test::have_data()) {
    WARN("SKIPPED (scenes part): shared data not found at " << lwsccd_test::data_dir());
    return;
  }
  for (const char* name : {"cloth-funnel", "armadillo-rollers", "cloth-ball"}) {
    INFO(name);
    const Scene s = load_scene(lwsccd_test::data_dir() + "/scenes/" + name);
    require_gpu_emission_equals_cpu(*s.step.mesh, s.step.x0, s.step.x1, {}, false);
  }
}

TEST_CASE("GPU pipeline equals the CPU pipeline over several steps of a folded cloth", "[gpu][pipeline]") {
  const auto first = lwsccd_test::folded_cloth(50, 1);
  auto mesh = std::make_shared<const TriangleMesh>(first.mesh);
  gpu::CcdPipeline<> gpu_pipeline(mesh);
  cpu::CcdPipeline<> cpu_pipeline(mesh);
  PipelineParams planned;  // as on a GPU with little FP64: the same answers
  planned.fp64_ratio = 64;
  gpu::CcdPipeline<> planned_pipeline(mesh, planned);
  for (int s = 0; s < 4; ++s) {
    INFO("step " << s);
    const auto m = lwsccd_test::folded_cloth(50, 1 + s);
    const auto g = gpu_pipeline.step(m.x0, m.x1);
    const auto c = cpu_pipeline.step(m.x0, m.x1);
    require_same_contacts(g, c);
    require_same_contacts(planned_pipeline.step(m.x0, m.x1), c);
    CHECK(g.stats.hits_vf + g.stats.hits_ee > 0);
    CHECK(g.stats.peak_device_bytes > 0);
    // What the pipeline holds, by purpose, adds up to its count and names every stage's buffers.
    const DeviceMemoryUse& held = g.stats.device_memory;
    CHECK(held.total() == gpu_pipeline.device_bytes());
    CHECK(held.resident() == gpu_pipeline.resident_bytes());
    CHECK(held.total() <= g.stats.peak_device_bytes);
    for (std::size_t part : {held.mesh, held.bvh, held.feature_boxes, held.candidates, held.front, held.feature_pairs,
                             held.narrow_hits, held.narrow_work})
      CHECK(part > 0);
  }
}

TEST_CASE("A GPU pipeline's first step on new memory counts its cudaMalloc calls; a steady step makes none",
          "[gpu][pipeline][pool]") {
  const auto m = lwsccd_test::folded_cloth(60, 2);
  auto mesh = std::make_shared<const TriangleMesh>(m.mesh);
  gpu::release_cached_memory();
  const std::size_t before = gpu::memory_stats().allocations;
  gpu::CcdPipeline<> pipeline(mesh);
  std::size_t counted = 0;
  for (int s = 0; s < 4; ++s) {
    INFO("step " << s);
    const auto r = pipeline.step(m.x0, m.x1);
    CHECK(r.stats.hits_vf + r.stats.hits_ee > 0);
    counted += r.stats.device_allocations;
    if (s == 0) CHECK(r.stats.device_allocations > 0);  // (nothing cached: new memory)
    if (s >= 2) CHECK(r.stats.device_allocations == 0);  // the same positions again: every buffer fits
  }
  // The steps' counts are the pool's calls (the pipeline's construction may add its own).
  CHECK(counted <= gpu::memory_stats().allocations - before);
  CHECK(counted > 0);
}

TEST_CASE("GPU pipeline equals the CPU pipeline on the real scenes; ground truth kept", "[gpu][pipeline][data]") {
  if (!lwsccd_test::have_data()) {
    WARN("SKIPPED: shared data not found at " << lwsccd_test::data_dir());
    return;
  }
  for (const char* name : {"cloth-funnel", "armadillo-rollers", "cloth-ball"}) {
    INFO(name);
    const Scene scene = load_scene(lwsccd_test::data_dir() + "/scenes/" + name);
    gpu::CcdPipeline<> gpu_pipeline(scene.step.mesh);
    cpu::CcdPipeline<> cpu_pipeline(scene.step.mesh);
    const auto g = gpu_pipeline.step(scene.step.x0, scene.step.x1);
    const auto c = cpu_pipeline.step(scene.step.x0, scene.step.x1);
    require_same_contacts(g, c);
    // Every pair answered where the CPU answers it (single precision, a double tail, double, the fallback).
    lwsccd_test::require_same_counts(g.stats.narrow_vf, c.stats.narrow_vf);
    lwsccd_test::require_same_counts(g.stats.narrow_ee, c.stats.narrow_ee);
    // No ground-truth contact is missed by the whole pipeline.
    const std::size_t missed = score_against_truth(scene.truth, g.contacts).false_negatives;
    std::printf("%s: GPU pipeline %.2f ms (refit %.3f, traverse %.3f, features %.3f, narrow %.3f), %zu + %zu contacts, "
                "earliest TOI %.9g, %zu ground-truth contacts missed\n",
                name, g.stats.total_ms, g.stats.refit_ms, g.stats.traverse_ms, g.stats.features_ms, g.stats.narrow_ms,
                g.stats.hits_vf, g.stats.hits_ee, g.contacts.earliest_toi, missed);
    CHECK(missed == 0);
    // A first step sizes its lists from counts (the narrow phase counts its screen's survivors
    // first): nothing runs twice for want of room.
    CHECK(g.stats.reruns == 0);
    // A second, identical step restarts from the front and gives the same answer.
    const auto g2 = gpu_pipeline.step(scene.step.x0, scene.step.x1);
    CHECK_FALSE(g2.stats.restarted_from_root);
    require_same_contacts(g2, c);
    // The other query modes: the same on both backends; earliest never later than the contacts'
    // minimum, set misses no ground-truth contact.
    for (CcdMode mode : {CcdMode::earliest, CcdMode::set}) {
      PipelineParams params;
      params.mode = mode;
      gpu::CcdPipeline<> gm(scene.step.mesh, params);
      cpu::CcdPipeline<> cm(scene.step.mesh, params);
      const auto gr = gm.step(scene.step.x0, scene.step.x1);
      const auto cr = cm.step(scene.step.x0, scene.step.x1);
      require_same_contacts(gr, cr);
      lwsccd_test::require_same_counts(gr.stats.narrow_vf, cr.stats.narrow_vf);
      lwsccd_test::require_same_counts(gr.stats.narrow_ee, cr.stats.narrow_ee);
      std::printf("  mode %s: GPU narrow %.3f ms, earliest TOI %.9g, %zu + %zu pairs\n",
                  mode == CcdMode::earliest ? "earliest" : "set", gr.stats.narrow_ms, gr.contacts.earliest_toi,
                  gr.contacts.vf.size(), gr.contacts.ee.size());
      if (mode == CcdMode::earliest) {
        CHECK(gr.contacts.vf.empty());
        CHECK(gr.contacts.earliest_toi <= c.contacts.earliest_toi);
      } else {
        CHECK(score_against_truth(scene.truth, gr.contacts).false_negatives == 0);
      }
    }
  }
}

namespace {
// A flat start for any front of at least one item per block (the default asks 512): the small
// cloth's steps take the path without a host round trip inside the traversal; tiny deques make
// blocks hand items back, which collect() reports and the pipeline reruns.
struct FlatFrontLazy : gpu::LazyStealScheduler {
  static constexpr int kFlatStartPerBlock = 1;
};
struct TinyFlatFrontLazy : gpu::LazyStealScheduler {
  static constexpr int kBlockThreads = 32;
  static constexpr int kSharedStack = 192;
  static constexpr int kDequeCapacity = 64;
  static constexpr int kPopSize = 32;
  static constexpr int kPushThreshold = 64;
  static constexpr int kFlatStartPerBlock = 1;
};

template <class Scheduler>
void pipeline_from_fronts_equals_cpu() {
  const auto first = lwsccd_test::folded_cloth(50, 1);
  auto mesh = std::make_shared<const TriangleMesh>(first.mesh);
  gpu::CcdPipeline<Aabbf, Scheduler> gpu_pipeline(mesh);
  cpu::CcdPipeline<> cpu_pipeline(mesh);
  std::size_t from_front = 0, reruns = 0;
  for (int s = 0; s < 6; ++s) {
    INFO("step " << s);
    const auto m = lwsccd_test::folded_cloth(50, 1 + s / 2);  // pairs of equal steps: fronts that fit
    const auto g = gpu_pipeline.step(m.x0, m.x1);
    require_same_contacts(g, cpu_pipeline.step(m.x0, m.x1));
    from_front += !g.stats.restarted_from_root;
    reruns += g.stats.reruns;
  }
  CHECK(from_front >= 3);
  std::printf("GPU pipeline from fronts (traversal enqueued): %zu of 6 steps from a front, %zu reruns\n", from_front, reruns);
}
}  // namespace

TEST_CASE("GPU pipeline from a front without a host round trip equals the CPU pipeline; tiny deques rerun it",
          "[gpu][pipeline][front]") {
  pipeline_from_fronts_equals_cpu<FlatFrontLazy>();
  pipeline_from_fronts_equals_cpu<TinyFlatFrontLazy>();
}

TEST_CASE("GPU pipeline: a front that outgrows its buffer is not kept, the step's contacts are, and the next step starts "
          "from that step's start",
          "[gpu][pipeline][front]") {
  const auto m = lwsccd_test::folded_cloth(20, 1);
  auto mesh = std::make_shared<const TriangleMesh>(m.mesh);
  // The cloth shrunk to 6.5% of its size with the same motion: its swept boxes overlap many more,
  // and the front deepens sevenfold in one step (no rebuild, no restart: both backends go on
  // from fronts).
  std::vector<Vec3d> small0(m.x0.size()), small1(m.x1.size());
  for (std::size_t v = 0; v < m.x0.size(); ++v) {
    small0[v] = m.x0[v] * 0.065;
    small1[v] = small0[v] + (m.x1[v] - m.x0[v]);
  }
  PipelineParams params;
  params.rebuild_factor = 1e9;
  params.front_growth_limit = 1e9;
  gpu::CcdPipeline<Aabbf, FlatFrontLazy> gpu_pipeline(mesh, params);
  cpu::CcdPipeline<> cpu_pipeline(mesh, params);
  const auto g0 = gpu_pipeline.step(m.x0, m.x1);
  const auto c0 = cpu_pipeline.step(m.x0, m.x1);
  require_same_contacts(g0, c0);
  const auto g1 = gpu_pipeline.step(small0, small1);
  const auto c1 = cpu_pipeline.step(small0, small1);
  require_same_contacts(g1, c1);
  REQUIRE_FALSE(c1.stats.restarted_from_root);
  // The traversal's outputs start with room for 2^16 entries each, which the first step's fit:
  // the second step's front outgrows its room, its results do not (no rerun of the traversal).
  REQUIRE(c0.stats.front_size < (1 << 16) / 2);
  REQUIRE(c1.stats.front_size > (1 << 16));
  REQUIRE(c1.stats.triangle_pairs < (1 << 16));
  CHECK_FALSE(g1.stats.restarted_from_root);
  CHECK(g1.stats.front_outgrown);
  CHECK(g1.stats.front_size == g0.stats.front_size);  // the step's seeds are kept for the next
  for (int s = 2; s < 4; ++s) {
    INFO("step " << s);
    const auto g = gpu_pipeline.step(small0, small1);
    const auto c = cpu_pipeline.step(small0, small1);
    require_same_contacts(g, c);
    CHECK_FALSE(g.stats.restarted_from_root);
    CHECK_FALSE(g.stats.front_outgrown);  // its output was grown
    CHECK(g.stats.front_size == c.stats.front_size);
  }
}

TEST_CASE("GPU pipeline: non-finite positions (infinite or NaN) are an InputError at the step's end, and the next step starts afresh",
          "[gpu][pipeline][front]") {
  const auto m = lwsccd_test::folded_cloth(40, 1);
  auto mesh = std::make_shared<const TriangleMesh>(m.mesh);
  gpu::CcdPipeline<Aabbf, FlatFrontLazy> gpu_pipeline(mesh);
  cpu::CcdPipeline<> cpu_pipeline(mesh);
  const auto expected = cpu_pipeline.step(m.x0, m.x1);
  require_same_contacts(gpu_pipeline.step(m.x0, m.x1), expected);
  require_same_contacts(gpu_pipeline.step(m.x0, m.x1), expected);  // from the front
  std::vector<Vec3d> bad = m.x1;
  bad[7].y = std::numeric_limits<double>::infinity();
  gpu::DeviceBuffer<Vec3d> x0, x1;
  x0.upload(m.x0);
  x1.upload(bad);
  CHECK_THROWS_AS(gpu_pipeline.step_from_device(x0.data(), x1.data()), InputError);
  x1.upload(m.x1);
  const auto after = gpu_pipeline.step_from_device(x0.data(), x1.data());
  CHECK(after.stats.restarted_from_root);  // the front recorded over non-finite boxes was dropped
  require_same_contacts(after, expected);
  require_same_contacts(gpu_pipeline.step_from_device(x0.data(), x1.data()), expected);
  // A NaN coordinate in a refit step (a box's min and max pass over it), from host arrays and
  // from device memory, at t = 0 and t = 1.
  for (int at_end = 0; at_end < 2; ++at_end) {
    std::vector<Vec3d> nan = at_end ? m.x1 : m.x0;
    nan[11].x = std::numeric_limits<double>::quiet_NaN();
    CHECK_THROWS_AS(gpu_pipeline.step(at_end ? m.x0 : nan, at_end ? nan : m.x1), InputError);
    require_same_contacts(gpu_pipeline.step(m.x0, m.x1), expected);
    (at_end ? x1 : x0).upload(nan);
    CHECK_THROWS_AS(gpu_pipeline.step_from_device(x0.data(), x1.data()), InputError);
    (at_end ? x1 : x0).upload(at_end ? m.x1 : m.x0);
    require_same_contacts(gpu_pipeline.step_from_device(x0.data(), x1.data()), expected);
  }
}

TEST_CASE("GPU pipeline with bodies equals the CPU pipeline; positions from device memory equal host ones",
          "[gpu][pipeline][bodies]") {
  const MultiBodyStep scene = make_cloth_ball_scene(20000);
  gpu::CcdPipeline<> gpu_pipeline(scene.step.mesh, scene.layout);
  cpu::CcdPipeline<> cpu_pipeline(scene.step.mesh, scene.layout);
  const auto g = gpu_pipeline.step(scene.step.x0, scene.step.x1);
  const auto c = cpu_pipeline.step(scene.step.x0, scene.step.x1);
  require_same_contacts(g, c);
  CHECK(g.stats.hits_vf + g.stats.hits_ee > 0);
  CHECK(g.stats.bvtt_nodes == c.stats.bvtt_nodes);  // the same pruning on both sides
  CHECK(g.stats.reruns == 0);  // a first step's lists sized from counts
  // The same step from device-resident positions, in a fresh pipeline and in this one.
  gpu::DeviceBuffer<Vec3d> x0, x1;
  x0.upload(scene.step.x0);
  x1.upload(scene.step.x1);
  gpu::CcdPipeline<> fresh(scene.step.mesh, scene.layout);
  require_same_contacts(fresh.step_from_device(x0.data(), x1.data()), c);
  require_same_contacts(gpu_pipeline.step_from_device(x0.data(), x1.data()), c);
  CHECK_THROWS_AS(fresh.step_from_device(scene.step.x0.data(), x1.data()), InputError);
  CHECK_THROWS_AS(fresh.step_from_device(x0.data(), nullptr), InputError);
  // Contacts left on the device: the same pairs, times and counts once copied.
  for (int repeat = 0; repeat < 2; ++repeat) {
    const DeviceStepResult<double> d = gpu_pipeline.step_on_device(x0.data(), x1.data());
    NarrowPhaseResult<double> copied;
    copied.vf.resize(d.contacts.num_vf);
    copied.ee.resize(d.contacts.num_ee);
    LWSCCD_CUDA_CHECK(cudaMemcpy(copied.vf.data(), d.contacts.vf, copied.vf.size() * sizeof(FeatureHit<double>),
                                 cudaMemcpyDeviceToHost));
    LWSCCD_CUDA_CHECK(cudaMemcpy(copied.ee.data(), d.contacts.ee, copied.ee.size() * sizeof(FeatureHit<double>),
                                 cudaMemcpyDeviceToHost));
    copied.earliest_toi = d.contacts.earliest_toi;
    copied.gave_up = d.contacts.gave_up;
    copied.vf_counts = d.contacts.vf_counts;
    copied.ee_counts = d.contacts.ee_counts;
    lwsccd_test::require_same_contacts(copied, c.contacts);
    lwsccd_test::require_same_counts(d.contacts.vf_counts, c.contacts.vf_counts);
    lwsccd_test::require_same_counts(d.contacts.ee_counts, c.contacts.ee_counts);
    CHECK(d.stats.hits_vf == c.stats.hits_vf);
    CHECK(d.stats.feature_pairs_vf + d.stats.feature_pairs_ee == c.stats.feature_pairs_vf + c.stats.feature_pairs_ee);
  }
  CHECK_THROWS_AS(fresh.step_on_device(scene.step.x0.data(), x1.data()), InputError);
}

TEST_CASE("GPU pipeline reads double positions in device memory in place, for the step only", "[gpu][pipeline][bodies]") {
  const MultiBodyStep scene = make_cloth_ball_scene(20000);
  // A second motion from the same start: half the step's displacement, fewer contacts.
  std::vector<Vec3d> half_x1 = scene.step.x1;
  for (std::size_t v = 0; v < half_x1.size(); ++v) half_x1[v] = scene.step.x0[v] + (scene.step.x1[v] - scene.step.x0[v]) * 0.5;
  cpu::CcdPipeline<> cpu_pipeline(scene.step.mesh, scene.layout);
  const auto whole = cpu_pipeline.step(scene.step.x0, scene.step.x1);
  const auto half = cpu_pipeline.step(scene.step.x0, half_x1);
  REQUIRE(whole.stats.hits_vf + whole.stats.hits_ee != half.stats.hits_vf + half.stats.hits_ee);
  gpu::DeviceBuffer<Vec3d> d0, d1;
  d0.upload(scene.step.x0);
  d1.upload(scene.step.x1);
  gpu::CcdPipeline<> pipeline(scene.step.mesh, scene.layout);
  require_same_contacts(pipeline.step_from_device(d0.data(), d1.data()), whole);
  // The caller's arrays change between steps (same addresses): each step reads what they hold then.
  d1.upload(half_x1);
  require_same_contacts(pipeline.step_from_device(d0.data(), d1.data()), half);
  // A host step after steps read in place uses the pipeline's own arrays again, and so on.
  require_same_contacts(pipeline.step(scene.step.x0, scene.step.x1), whole);
  const DeviceStepResult<double> d = pipeline.step_on_device(d0.data(), d1.data());
  CHECK(d.contacts.num_vf == half.contacts.vf.size());
  CHECK(d.contacts.num_ee == half.contacts.ee.size());
  CHECK(d.contacts.earliest_toi == half.contacts.earliest_toi);
  require_same_contacts(pipeline.step(scene.step.x0, half_x1), half);

  // gpu::DeviceStep: where its work reads the positions.
  gpu::DeviceStep<double> step(*scene.step.mesh);
  step.set_positions(scene.step.x0, scene.step.x1);
  CHECK(step.x0_data() == step.x0.data());
  step.use_device_positions(d0.data(), d1.data());
  CHECK(step.x0_data() == d0.data());
  CHECK(step.x1_data() == d1.data());
  CHECK_THROWS_AS(step.use_device_positions(scene.step.x0.data(), d1.data()), InputError);
  CHECK_THROWS_AS(step.use_device_positions(d0.data(), nullptr), InputError);
  step.set_positions_from_device(d0.data(), d1.data());
  CHECK(step.x0_data() == step.x0.data());
  CHECK(step.x1_data() == step.x1.data());
}

TEST_CASE("GPU pipeline from float positions, host and device, equals the CPU pipeline on their exact double values",
          "[gpu][pipeline][float_input]") {
  const MultiBodyStep scene = make_cloth_ball_scene(20000);
  std::vector<Vec3f> f0, f1;
  std::vector<Vec3d> w0, w1;
  for (std::size_t v = 0; v < scene.step.x0.size(); ++v) {
    f0.push_back(scene.step.x0[v].cast<float>());
    f1.push_back(scene.step.x1[v].cast<float>());
    w0.push_back(f0.back().cast<double>());
    w1.push_back(f1.back().cast<double>());
  }
  cpu::CcdPipeline<> cpu_pipeline(scene.step.mesh, scene.layout);
  const auto c = cpu_pipeline.step(w0, w1);
  CHECK(c.stats.hits_vf + c.stats.hits_ee > 0);
  gpu::CcdPipeline<> host_input(scene.step.mesh, scene.layout);
  const auto g = host_input.step(f0, f1);
  require_same_contacts(g, c);
  lwsccd_test::require_same_counts(g.contacts.vf_counts, c.contacts.vf_counts);
  lwsccd_test::require_same_counts(g.contacts.ee_counts, c.contacts.ee_counts);
  // Float positions in device memory, in a fresh pipeline, then the same one again (its front).
  gpu::DeviceBuffer<Vec3f> d0, d1;
  d0.upload(f0);
  d1.upload(f1);
  gpu::CcdPipeline<> device_input(scene.step.mesh, scene.layout);
  for (int repeat = 0; repeat < 2; ++repeat) {
    const auto d = device_input.step_from_device(d0.data(), d1.data());
    require_same_contacts(d, c);
    lwsccd_test::require_same_counts(d.contacts.ee_counts, c.contacts.ee_counts);
  }
  const DeviceStepResult<double> on_device = device_input.step_on_device(d0.data(), d1.data());
  CHECK(on_device.contacts.num_vf == c.contacts.vf.size());
  CHECK(on_device.contacts.num_ee == c.contacts.ee.size());
  CHECK(on_device.contacts.earliest_toi == c.contacts.earliest_toi);
  CHECK_THROWS_AS(device_input.step_from_device(f0.data(), d1.data()), InputError);
  // Host float input after double input in the same pipeline: the positions are replaced whole.
  require_same_contacts(host_input.step(scene.step.x0, scene.step.x1), cpu_pipeline.step(scene.step.x0, scene.step.x1));
  require_same_contacts(host_input.step(f0, f1), c);

  // Float arrays in device memory that change between steps (the same addresses): the refit reads
  // them where they are, the later stages their copies widened beside it. Every step from the
  // front, every step rebuilt (rebuild_factor 1: the step after a costlier refit builds anew), and
  // in parts; a NaN among them is an InputError and the next step starts afresh.
  std::vector<Vec3f> half_f1(f1.size());
  std::vector<Vec3d> half_w1(f1.size());
  for (std::size_t v = 0; v < f1.size(); ++v) {
    half_f1[v] = (f0[v].cast<double>() + (f1[v].cast<double>() - f0[v].cast<double>()) * 0.5).cast<float>();
    half_w1[v] = half_f1[v].cast<double>();
  }
  const auto half = cpu_pipeline.step(w0, half_w1);
  REQUIRE(half.stats.hits_vf + half.stats.hits_ee != c.stats.hits_vf + c.stats.hits_ee);
  PipelineParams rebuilding, in_parts;
  rebuilding.rebuild_factor = 1;
  in_parts.part_pairs = 4000;
  for (const PipelineParams& params : {PipelineParams{}, rebuilding, in_parts}) {
    INFO("rebuild_factor " << params.rebuild_factor << ", part_pairs " << params.part_pairs);
    gpu::CcdPipeline<> pipeline(scene.step.mesh, scene.layout, params);
    // Host float arrays take the same route (uploaded as float, the refit reading them in place).
    gpu::CcdPipeline<> host_pipeline(scene.step.mesh, scene.layout, params);
    cpu::CcdPipeline<> reference(scene.step.mesh, scene.layout, params);
    std::size_t rebuilt = 0, host_rebuilt = 0;
    for (int s = 0; s < 4; ++s) {
      INFO("step " << s);
      d1.upload(s % 2 ? f1 : half_f1);
      const auto d = pipeline.step_from_device(d0.data(), d1.data());
      const auto expected = reference.step(w0, s % 2 ? w1 : half_w1);
      require_same_contacts(d, expected);
      require_same_contacts(d, s % 2 ? c : half);
      rebuilt += d.stats.rebuilt;
      const auto h = host_pipeline.step(f0, s % 2 ? f1 : half_f1);
      require_same_contacts(h, expected);
      lwsccd_test::require_same_counts(h.contacts.ee_counts, expected.contacts.ee_counts);
      host_rebuilt += h.stats.rebuilt;
    }
    CHECK(host_rebuilt == rebuilt);
    // The float array the host input crossed into is counted with the mesh's positions.
    CHECK(host_pipeline.memory_use().mesh >= pipeline.memory_use().mesh + 2 * f0.size() * sizeof(Vec3f));
    std::printf("float device positions (rebuild_factor %.1f, part_pairs %zu): %zu of 4 steps built the BVH\n",
                params.rebuild_factor, params.part_pairs, rebuilt);
    if (params.rebuild_factor == 1) CHECK(rebuilt >= 2);  // (the first step's build and one after a costlier refit)
    std::vector<Vec3f> nan = f1;
    nan[23].z = std::numeric_limits<float>::quiet_NaN();
    d1.upload(nan);
    CHECK_THROWS_AS(pipeline.step_from_device(d0.data(), d1.data()), InputError);
    CHECK_THROWS_AS(host_pipeline.step(f0, nan), InputError);
    d1.upload(f1);
    require_same_contacts(pipeline.step_from_device(d0.data(), d1.data()), c);
    require_same_contacts(host_pipeline.step(f0, f1), c);
    CHECK_THROWS_AS(host_pipeline.step(f0, std::vector<Vec3f>(f1.begin(), f1.end() - 1)), InputError);
    require_same_contacts(host_pipeline.step(f0, half_f1), half);
  }
}

namespace {

// Staging of a page in two chunks, every copy through it (no copy is small enough to go straight
// to pageable memory), so that a few kilobytes take every path of the ring.
struct PageStaging : gpu::HostStagingPolicy {
  static constexpr std::size_t kChunkBytes = 4096;
  static constexpr int kChunks = 2;
  static constexpr std::size_t kDirectUploadBytes = 1;  // (only empty copies, which return at once)
  static constexpr std::size_t kDirectDownloadBytes = 1;
  static constexpr std::size_t kThreadBytes = 1024;
};

}  // namespace

TEST_CASE("HostStaging: copies of any size cross whole both ways through a ring of page-locked chunks",
          "[gpu][staging]") {
  gpu::CudaStream stream(cudaStreamNonBlocking);
  using Pages = gpu::HostStaging<PageStaging>;
  using Default = gpu::HostStaging<>;
  for (const std::size_t bytes : {std::size_t(1), std::size_t(4095), std::size_t(4096), std::size_t(4097),
                                  std::size_t(3 * 4096 + 17), std::size_t(100003)}) {
    INFO(bytes << " bytes");
    std::vector<unsigned char> source(bytes), back(bytes, 0), again(bytes, 0);
    for (std::size_t i = 0; i < bytes; ++i) source[i] = static_cast<unsigned char>((i * 131 + bytes) % 251);
    const std::vector<unsigned char> expected = source;
    gpu::DeviceBuffer<unsigned char> device(bytes);
    Pages::to_device(device.data(), source.data(), bytes, stream);
    std::fill(source.begin(), source.end(), 0);  // read once to_device returns: changing it now changes nothing
    Pages::to_host(back.data(), device.data(), bytes, stream);
    CHECK(back == expected);
    Default::to_host(again.data(), device.data(), bytes, stream);
    CHECK(again == expected);
  }
  // Two host threads copying at once borrow chunks of their own.
  const std::size_t bytes = 3 * 4096 * 50 + 1;
  std::vector<unsigned char> a(bytes), b(bytes);
  for (std::size_t i = 0; i < bytes; ++i) a[i] = static_cast<unsigned char>(i % 253), b[i] = static_cast<unsigned char>(i % 241);
  gpu::DeviceBuffer<unsigned char> da(bytes), db(bytes);
  std::vector<unsigned char> back_a(bytes), back_b(bytes);
  gpu::CudaStream other(cudaStreamNonBlocking);
  std::thread t([&] {
    for (int r = 0; r < 20; ++r) {
      Pages::to_device(db.data(), b.data(), bytes, other);
      Pages::to_host(back_b.data(), db.data(), bytes, other);
    }
  });
  for (int r = 0; r < 20; ++r) {
    Pages::to_device(da.data(), a.data(), bytes, stream);
    Pages::to_host(back_a.data(), da.data(), bytes, stream);
  }
  t.join();
  CHECK(back_a == a);
  CHECK(back_b == b);
}

TEST_CASE("GPU pipeline: step_into one kept result equals step() and the CPU pipeline as the counts grow and shrink",
          "[gpu][pipeline][step_into]") {
  const auto first = lwsccd_test::folded_cloth(60, 1);
  auto mesh = std::make_shared<const TriangleMesh>(first.mesh);
  gpu::CcdPipeline<> into(mesh), stepped(mesh);
  cpu::CcdPipeline<> cpu_pipeline(mesh);
  StepResult<double> kept;
  std::size_t largest = 0, smallest = ~std::size_t(0);
  for (const int s : {1, 5, 2, 6, 1}) {
    INFO("fold step " << s);
    const auto m = lwsccd_test::folded_cloth(60, s);
    into.step_into(m.x0, m.x1, kept);
    const auto g = stepped.step(m.x0, m.x1);
    const auto c = cpu_pipeline.step(m.x0, m.x1);
    require_same_contacts(kept, c);
    require_same_contacts(g, c);
    CHECK(kept.stats.hits_vf == kept.contacts.vf.size());
    CHECK(kept.stats.hits_ee == kept.contacts.ee.size());
    const std::size_t n = kept.contacts.vf.size() + kept.contacts.ee.size();
    largest = std::max(largest, n);
    smallest = std::min(smallest, n);
  }
  CHECK(largest > smallest);  // the kept lists grew and shrank
  CHECK(largest * sizeof(FeatureHit<double>) > gpu::HostStagingPolicy::kDirectDownloadBytes);  // (through the staging)
  // Float arrays into the same result.
  const auto m = lwsccd_test::folded_cloth(60, 3);
  const lwsccd_test::FloatRounded r = lwsccd_test::float_rounded(m.x0, m.x1);
  into.step_into(Span<const Vec3f>(r.f0), Span<const Vec3f>(r.f1), kept);
  require_same_contacts(kept, cpu_pipeline.step(r.w0, r.w1));
}

TEST_CASE("GPU pipeline: fresh steps (positions unrelated to the last step's) from a stale front or from the root "
          "equal the CPU pipeline",
          "[gpu][pipeline][fresh]") {
  const auto first = lwsccd_test::folded_cloth(40, 1);
  auto mesh = std::make_shared<const TriangleMesh>(first.mesh);
  gpu::CcdPipeline<> stale(mesh), restarted(mesh);
  cpu::CcdPipeline<> cpu_stale(mesh), cpu_restarted(mesh);
  // Steps of the fold far apart in turn: each step's front is another configuration's.
  for (const int s : {1, 7, 2, 8, 3}) {
    INFO("fold step " << s);
    const auto m = lwsccd_test::folded_cloth(40, s);
    restarted.restart_from_root();
    cpu_restarted.restart_from_root();
    const auto g_stale = stale.step(m.x0, m.x1);
    const auto g_root = restarted.step(m.x0, m.x1);
    const auto c_stale = cpu_stale.step(m.x0, m.x1);
    const auto c_root = cpu_restarted.step(m.x0, m.x1);
    require_same_contacts(g_stale, c_stale);
    require_same_contacts(g_root, c_root);
    require_same_contacts(g_root, c_stale);
    CHECK(g_root.stats.restarted_from_root);
    CHECK(c_root.stats.restarted_from_root);
    CHECK(g_root.stats.hits_vf + g_root.stats.hits_ee > 0);
  }
  // Without a call, the next step starts from the front again.
  const auto m = lwsccd_test::folded_cloth(40, 3);
  const auto g = restarted.step(m.x0, m.x1);
  CHECK_FALSE(g.stats.restarted_from_root);
  require_same_contacts(g, cpu_restarted.step(m.x0, m.x1));
}

TEST_CASE("GPU pipeline over horse-gallop: front tracking equals fresh traversals and the CPU pipeline at every step",
          "[gpu][pipeline][data]") {
  if (!lwsccd_test::have_data()) {
    WARN("SKIPPED: shared data not found at " << lwsccd_test::data_dir());
    return;
  }
  const Sequence seq = load_sequence(lwsccd_test::data_dir() + "/sequences/horse-gallop");
  REQUIRE(seq.num_steps() == 47);
  PipelineParams fresh_params;
  fresh_params.front_tracking = false;
  gpu::CcdPipeline<> tracked(seq.mesh()), fresh(seq.mesh(), fresh_params);
  cpu::CcdPipeline<> cpu_tracked(seq.mesh());
  std::size_t restarts = 0, contacts = 0;
  std::vector<bool> restarted, rebuilt;
  std::vector<std::size_t> front;
  for (std::size_t s = 0; s < seq.num_steps(); ++s) {
    INFO("step " << s);
    const Step step = seq.step(s);
    const auto a = tracked.step(step.x0, step.x1);
    require_same_contacts(a, fresh.step(step.x0, step.x1));
    require_same_contacts(a, cpu_tracked.step(step.x0, step.x1));
    restarts += a.stats.restarted_from_root;
    contacts += a.stats.hits_vf + a.stats.hits_ee;
    restarted.push_back(a.stats.restarted_from_root);
    rebuilt.push_back(a.stats.rebuilt);
    front.push_back(a.stats.front_size);
  }
  // The default growth limit is the GPU's (a front of the GPU may grow further than the CPU's).
  CHECK(lwsccd_test::restarts_follow_growth_limit(restarted, rebuilt, front, kGpuFrontGrowthLimit));
  std::printf("horse-gallop (GPU pipeline): 47 steps, %zu contacts, %zu restarts from the root; equal to fresh "
              "traversals and to the CPU pipeline at every step\n",
              contacts, restarts);
  CHECK(restarts < seq.num_steps());
}

namespace {

// A folded cloth of n x n quads stepped with a minimum separation: GPU == CPU, and the separation
// finds more triangle pairs and more hits than contact alone.
void require_min_separation_agrees(int n) {
  const auto m = lwsccd_test::folded_cloth(n, 2);
  auto mesh = std::make_shared<const TriangleMesh>(m.mesh);
  PipelineParams params;
  params.min_separation = 0.01;
  gpu::CcdPipeline<> gpu_pipeline(mesh, params);
  cpu::CcdPipeline<> cpu_pipeline(mesh, params);
  const auto g = gpu_pipeline.step(m.x0, m.x1);
  const auto c = cpu_pipeline.step(m.x0, m.x1);
  require_same_contacts(g, c);
  cpu::CcdPipeline<> contact_only(mesh);
  const auto c0 = contact_only.step(m.x0, m.x1);
  CHECK(c.stats.triangle_pairs > c0.stats.triangle_pairs);
  CHECK(c.stats.hits_vf + c.stats.hits_ee > c0.stats.hits_vf + c0.stats.hits_ee);
  std::printf("folded cloth %dx%d, min separation 0.01: %zu + %zu pairs closer (contact only: %zu + %zu)\n", n, n,
              c.stats.hits_vf, c.stats.hits_ee, c0.stats.hits_vf, c0.stats.hits_ee);
}

}  // namespace

// [large]: under compute-sanitizer's racecheck this case alone ran past 470 s (every closer pair
// is an inclusion search in shared memory); the sanitizer runs take the small one below instead.
TEST_CASE("GPU pipeline with a minimum separation equals the CPU pipeline (boxes grown by half of it)",
          "[gpu][pipeline][separation][large]") {
  require_min_separation_agrees(40);
}

TEST_CASE("GPU pipeline with a minimum separation equals the CPU pipeline on a small cloth (sanitizer-sized)",
          "[gpu][pipeline][separation]") {
  require_min_separation_agrees(12);
}

namespace {

// A pipeline under a budget that forces its steps into parts against one without a budget: the
// same pairs and TOIs bit for bit, the same counts, step after step (the kept front included).
template <class Scheduler>
void require_streaming_changes_nothing(const std::shared_ptr<const TriangleMesh>& mesh, const BodyLayout& layout,
                                       const std::vector<std::pair<std::vector<Vec3d>, std::vector<Vec3d>>>& steps, CcdMode mode,
                                       double budget_share) {
  PipelineParams params;
  params.mode = mode;
  std::vector<StepResult<double>> expected;
  std::size_t resident = 0, held = 0;
  // A budget is kept by the pipeline's own count of what it holds (device_bytes): that count
  // must be every byte it holds (a streamed step's list of the pairs met below the root, 4.8-15 KB
  // here, was once left out of it, and a step's peak passed a budget by 332 bytes).
  const std::size_t held_elsewhere = gpu::memory_stats().in_use;
  {
    gpu::CcdPipeline<Aabbf, Scheduler> whole(mesh, layout, params);
    for (const auto& s : steps) expected.push_back(whole.step(s.first, s.second));
    resident = whole.resident_bytes();
    held = whole.device_bytes();
    CHECK(gpu::memory_stats().in_use - held_elsewhere == held);
  }
  // A share of what the unstreamed steps held beyond the resident data.
  params.device_memory_budget = resident + static_cast<std::size_t>(budget_share * static_cast<double>(held - resident));
  gpu::CcdPipeline<Aabbf, Scheduler> streamed(mesh, layout, params);
  std::size_t parts = 0;
  for (std::size_t i = 0; i < steps.size(); ++i) {
    INFO("step " << i << ", mode " << static_cast<int>(mode) << ", budget " << params.device_memory_budget);
    const auto r = streamed.step(steps[i].first, steps[i].second);
    lwsccd_test::require_same_contacts(r.contacts, expected[i].contacts);
    REQUIRE(r.contacts.earliest_toi == expected[i].contacts.earliest_toi);
    REQUIRE(r.stats.triangle_pairs == expected[i].stats.triangle_pairs);
    REQUIRE(r.stats.feature_pairs_vf == expected[i].stats.feature_pairs_vf);
    REQUIRE(r.stats.feature_pairs_ee == expected[i].stats.feature_pairs_ee);
    if (mode == CcdMode::contacts) {
      lwsccd_test::require_same_counts(r.contacts.vf_counts, expected[i].contacts.vf_counts);
      lwsccd_test::require_same_counts(r.contacts.ee_counts, expected[i].contacts.ee_counts);
    }
    CHECK(gpu::memory_stats().in_use - held_elsewhere == streamed.device_bytes());
    CHECK(streamed.device_bytes() <= params.device_memory_budget);
    if (i > 0) CHECK(r.stats.peak_device_bytes <= params.device_memory_budget);  // the first builds the BVH
    parts = std::max(parts, r.stats.narrow_parts);
    std::printf("streamed step %zu (mode %d): %zu traversal parts, %zu narrow parts, %zu triangle pairs, %zu contacts, "
                "held %.1f of %.1f MiB (unstreamed %.1f)\n",
                i, static_cast<int>(mode), r.stats.traversal_parts, r.stats.narrow_parts, r.stats.triangle_pairs,
                r.contacts.vf.size() + r.contacts.ee.size(), streamed.device_bytes() / 1048576.0,
                params.device_memory_budget / 1048576.0, held / 1048576.0);
  }
  REQUIRE(parts > 2);  // the budget did split the steps
}

}  // namespace

namespace {

// Cloth-ball scenes of `triangles` stepped under a budget of `budget_share` of what they held
// unstreamed beyond their data (every mode, a repeated step and a moving sequence; the static
// scheduler too where `with_static`) answer as without one.
void require_budgeted_cloth_ball_agrees(std::size_t triangles, double budget_share, bool with_static) {
  // Schedulers with small lists of their own, so that what a step needs is mostly what grows with
  // its pairs (the part a budget can split).
  const MultiBodyStep scene = make_cloth_ball_scene(triangles);
  // The same positions three times: the first step starts from the root, the others from the
  // kept front.
  const std::vector<std::pair<std::vector<Vec3d>, std::vector<Vec3d>>> repeated(3, {scene.step.x0, scene.step.x1});
  for (const CcdMode mode : {CcdMode::contacts, CcdMode::earliest, CcdMode::set})
    require_streaming_changes_nothing<SmallLazy>(scene.step.mesh, scene.layout, repeated, mode, budget_share);
  if (with_static) require_streaming_changes_nothing<SmallStatic>(scene.step.mesh, scene.layout, repeated, CcdMode::contacts, budget_share);
  // Consecutive steps of the built-in simulation (the front moves with the cloth).
  ClothBallSimulation simulation(triangles);
  simulation.advance(30);
  std::vector<std::pair<std::vector<Vec3d>, std::vector<Vec3d>>> sequence;
  for (int s = 0; s < 4; ++s) {
    const Step step = simulation.next_step();
    sequence.push_back({step.x0, step.x1});
  }
  require_streaming_changes_nothing<SmallLazy>(simulation.mesh(), simulation.layout(), sequence, CcdMode::contacts, budget_share);
}

}  // namespace

// [large]: under compute-sanitizer's racecheck this case ran past 560 s; the sanitizer runs take
// the small one below instead.
TEST_CASE("GPU pipeline under a device-memory budget streams its steps in parts and answers as without one",
          "[gpu][pipeline][streaming][large]") {
  require_budgeted_cloth_ball_agrees(150000, 0.5, true);
}

// At this size the schedulers' own lists, which no split reduces, are most of what a step holds
// beyond the scene's data (H100: the lazy one's 13-14 MB of 30; the static one's 21 MB), hence no
// static scheduler here. At three quarters, mode set's second step (the first from a front) was
// once refused, 0.3% short (the front recorded for the next step goes before the pipeline
// refuses), and a step's peak passed the budget by 332 bytes when the pairs met below the root
// were missing from the pipeline's count of its bytes (they are counted, and checked above).
// Under racecheck: 344 s at 0.85, 321 s at 0.75 (0 hazards).
TEST_CASE("GPU pipeline under a device-memory budget answers as without one on a small scene (sanitizer-sized)",
          "[gpu][pipeline][streaming]") {
  require_budgeted_cloth_ball_agrees(24000, 0.75, false);
}

namespace {

// A cloth-ball simulation of `triangles` stepped in parts of at most 500 candidate or feature
// pairs, on the GPU and on the CPU, against the CPU pipeline whole, `steps` steps.
void require_parts_agree(std::size_t triangles, int steps) {
  ClothBallSimulation simulation(triangles);
  simulation.advance(30);
  PipelineParams params;
  params.part_pairs = 500;
  params.front_growth_limit = kCpuFrontGrowthLimit;  // the fronts are compared: one limit for both backends
  gpu::CcdPipeline<> gpu_parts(simulation.mesh(), simulation.layout(), params);
  cpu::CcdPipeline<> cpu_parts(simulation.mesh(), simulation.layout(), params);
  cpu::CcdPipeline<> cpu_whole(simulation.mesh(), simulation.layout());
  for (int s = 0; s < steps; ++s) {
    INFO("step " << s);
    const Step step = simulation.next_step();
    const auto g = gpu_parts.step(step.x0, step.x1);
    const auto c = cpu_parts.step(step.x0, step.x1);
    require_same_contacts(g, cpu_whole.step(step.x0, step.x1));
    require_same_contacts(g, c);
    CHECK(g.stats.front_size == c.stats.front_size);
    REQUIRE(g.stats.narrow_parts > g.stats.triangle_pairs / 500);
    // From the root a small tree can be all cut (its candidates met by the expansion, no part).
    if (!g.stats.restarted_from_root) REQUIRE(g.stats.traversal_parts > 1);
  }
}

}  // namespace

// [large]: compute-sanitizer's racecheck did not finish it in 430 s on an H100 (thousands of parts,
// each a few launches and a synchronisation); the sanitizer runs take the small one below.
TEST_CASE("GPU pipeline in parts (part_pairs) equals the CPU pipeline in parts and whole, step after step",
          "[gpu][pipeline][streaming][large]") {
  require_parts_agree(12000, 4);
}

TEST_CASE("GPU pipeline in parts (part_pairs) equals the CPU pipeline in parts and whole on a small scene (sanitizer-sized)",
          "[gpu][pipeline][streaming]") {
  require_parts_agree(2000, 2);
}

TEST_CASE("GPU pipeline: a device-memory budget below the mesh's own data is refused with the numbers",
          "[gpu][pipeline][streaming]") {
  const MultiBodyStep scene = make_cloth_ball_scene(20000);
  PipelineParams params;
  params.device_memory_budget = 1 << 20;
  gpu::CcdPipeline<> pipeline(scene.step.mesh, scene.layout, params);
  try {
    pipeline.step(scene.step.x0, scene.step.x1);
    FAIL("a 1 MiB budget was accepted");
  } catch (const InputError& e) {
    CHECK(std::string(e.what()).find("device_memory_budget") != std::string::npos);
    CHECK(std::string(e.what()).find("positions, BVH and topology take") != std::string::npos);
  }
  // Raised, the same pipeline steps.
  pipeline.set_device_memory_budget(std::size_t(1) << 34);
  CHECK(pipeline.step(scene.step.x0, scene.step.x1).stats.narrow_parts >= 1);
}

TEST_CASE("GPU pipeline: a budget that leaves the parts no room is an error naming what it needs, not a crawl",
          "[gpu][pipeline][streaming]") {
  const MultiBodyStep scene = make_cloth_ball_scene(20000);
  std::size_t resident = 0;
  {
    gpu::CcdPipeline<> measure(scene.step.mesh, scene.layout);
    measure.step(scene.step.x0, scene.step.x1);
    resident = measure.resident_bytes();
  }
  // Above the least the mesh's data need, below what the default scheduler's own lists take.
  PipelineParams params;
  params.device_memory_budget = resident + (std::size_t(5) << 20);
  gpu::CcdPipeline<> pipeline(scene.step.mesh, scene.layout, params);
  try {
    pipeline.step(scene.step.x0, scene.step.x1);
    FAIL("a budget of the resident data + 5 MiB was accepted");
  } catch (const Error& e) {
    INFO(e.what());
    CHECK(std::string(e.what()).find("device memory budget") != std::string::npos);
  }
}

// ---- A guest in another program's CUDA code: streams and moves ----

static_assert(std::is_move_constructible_v<gpu::CcdPipeline<>> && std::is_move_assignable_v<gpu::CcdPipeline<>> &&
                  !std::is_copy_constructible_v<gpu::CcdPipeline<>>,
              "gpu::CcdPipeline: movable, not copyable");
static_assert(std::is_move_constructible_v<gpu::NarrowPhase<CertifiedCcd, double>> &&
                  std::is_move_assignable_v<gpu::NarrowPhase<CertifiedCcd, double>>,
              "gpu::NarrowPhase: movable");

namespace {

// Writes `n` positions on `stream` after a wait of about `spin` clock cycles per block: a step
// that did not follow the stream's order would read the buffer's old (non-finite) contents.
__global__ void write_positions_late_kernel(const Vec3d* from, Vec3d* to, std::size_t n, long long spin) {
  const long long start = clock64();
  while (clock64() - start < spin) {
  }
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += static_cast<std::size_t>(gridDim.x) * blockDim.x)
    to[i] = from[i];
}

}  // namespace

TEST_CASE("GPU pipelines on two non-blocking streams at once, from two host threads, each equal the CPU pipeline",
          "[gpu][pipeline][streams]") {
  // Two scenes of different sizes, three steps each (the first from the root, then fronts).
  const auto cloth = [](int s) { return lwsccd_test::folded_cloth(40, 1 + s); };
  const MultiBodyStep ball = make_cloth_ball_scene(20000);
  auto cloth_mesh = std::make_shared<const TriangleMesh>(cloth(0).mesh);
  std::vector<StepResult<double>> cpu_cloth, cpu_ball;
  {
    cpu::CcdPipeline<> a(cloth_mesh);
    cpu::CcdPipeline<> b(ball.step.mesh, ball.layout);
    for (int s = 0; s < 3; ++s) {
      const auto m = cloth(s);
      cpu_cloth.push_back(a.step(m.x0, m.x1));
      cpu_ball.push_back(b.step(ball.step.x0, ball.step.x1));
    }
  }
  gpu::CudaStream stream_a(cudaStreamNonBlocking), stream_b(cudaStreamNonBlocking);
  gpu::CcdPipeline<> pipeline_a(cloth_mesh, PipelineParams{}, stream_a);
  gpu::CcdPipeline<> pipeline_b(ball.step.mesh, ball.layout, PipelineParams{}, stream_b);
  std::vector<StepResult<double>> gpu_cloth(3), gpu_ball(3);
  std::exception_ptr failed_a, failed_b;
  std::thread thread_a([&] {
    try {
      for (int s = 0; s < 3; ++s) {
        const auto m = cloth(s);
        gpu_cloth[s] = pipeline_a.step(m.x0, m.x1, stream_a);
      }
    } catch (...) {
      failed_a = std::current_exception();
    }
  });
  std::thread thread_b([&] {
    try {
      gpu::DeviceBuffer<Vec3d> x0, x1;
      x0.upload(ball.step.x0, stream_b);
      x1.upload(ball.step.x1, stream_b);
      for (int s = 0; s < 3; ++s) gpu_ball[s] = pipeline_b.step_from_device(x0.data(), x1.data(), stream_b);
    } catch (...) {
      failed_b = std::current_exception();
    }
  });
  thread_a.join();
  thread_b.join();
  if (failed_a) std::rethrow_exception(failed_a);
  if (failed_b) std::rethrow_exception(failed_b);
  for (int s = 0; s < 3; ++s) {
    INFO("step " << s);
    require_same_contacts(gpu_cloth[s], cpu_cloth[s]);
    require_same_contacts(gpu_ball[s], cpu_ball[s]);
    CHECK(gpu_ball[s].stats.hits_vf + gpu_ball[s].stats.hits_ee > 0);
  }
  CHECK_FALSE(gpu_ball[2].stats.restarted_from_root);  // the later steps ran from their fronts
}

TEST_CASE("GPU pipeline reads positions a kernel wrote on the caller's stream, without a host synchronisation between",
          "[gpu][pipeline][streams]") {
  const MultiBodyStep scene = make_cloth_ball_scene(20000);
  cpu::CcdPipeline<> cpu_pipeline(scene.step.mesh, scene.layout);
  const auto c = cpu_pipeline.step(scene.step.x0, scene.step.x1);
  REQUIRE(c.stats.hits_vf + c.stats.hits_ee > 0);
  const std::size_t n = scene.step.x0.size();
  gpu::DeviceBuffer<Vec3d> source0, source1, x0, x1;
  source0.upload(scene.step.x0);
  source1.upload(scene.step.x1);
  // The step's buffers hold NaN until the late kernel overwrites them.
  const double q = std::numeric_limits<double>::quiet_NaN();
  const std::vector<Vec3d> nan(n, Vec3d{q, q, q});
  x0.upload(nan);
  x1.upload(nan);
  LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
  gpu::CudaStream stream(cudaStreamNonBlocking);
  gpu::CcdPipeline<> pipeline(scene.step.mesh, scene.layout, PipelineParams{}, stream);
  for (int repeat = 0; repeat < 3; ++repeat) {
    INFO("step " << repeat);
    // Each step first sees NaN again, then the positions, written late on the same stream.
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(x0.data(), nan.data(), n * sizeof(Vec3d), cudaMemcpyHostToDevice, stream));
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(x1.data(), nan.data(), n * sizeof(Vec3d), cudaMemcpyHostToDevice, stream));
    write_positions_late_kernel<<<64, 256, 0, stream>>>(source0.data(), x0.data(), n, 2000000);
    write_positions_late_kernel<<<64, 256, 0, stream>>>(source1.data(), x1.data(), n, 2000000);
    LWSCCD_CUDA_CHECK_LAUNCH();
    if (repeat < 2) {
      require_same_contacts(pipeline.step_from_device(x0.data(), x1.data(), stream), c);
    } else {
      // Contacts left on the device, copied on the same stream.
      const DeviceStepResult<double> d = pipeline.step_on_device(x0.data(), x1.data(), stream);
      std::vector<FeatureHit<double>> vf(d.contacts.num_vf);
      LWSCCD_CUDA_CHECK(
          cudaMemcpyAsync(vf.data(), d.contacts.vf, vf.size() * sizeof(FeatureHit<double>), cudaMemcpyDeviceToHost, stream));
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
      REQUIRE(vf.size() == c.contacts.vf.size());
      for (std::size_t k = 0; k < vf.size(); ++k) {
        REQUIRE(vf[k].first == c.contacts.vf[k].first);
        REQUIRE(vf[k].second == c.contacts.vf[k].second);
        REQUIRE(vf[k].toi == c.contacts.vf[k].toi);
      }
    }
  }
}

TEST_CASE("GPU pipeline moved mid-sequence keeps stepping as the pipeline it was (front, buffers, answers)",
          "[gpu][pipeline][streams][move]") {
  const auto first = lwsccd_test::folded_cloth(50, 1);
  auto mesh = std::make_shared<const TriangleMesh>(first.mesh);
  gpu::CcdPipeline<> unmoved(mesh);
  cpu::CcdPipeline<> cpu_pipeline(mesh);
  gpu::CcdPipeline<> moving(mesh);
  for (int s = 0; s < 6; ++s) {
    INFO("step " << s);
    if (s == 2) {
      gpu::CcdPipeline<> constructed(std::move(moving));  // move construction mid-sequence
      const auto m = lwsccd_test::folded_cloth(50, 1 + s);
      const auto g = constructed.step(m.x0, m.x1);
      const auto u = unmoved.step(m.x0, m.x1);
      require_same_contacts(g, cpu_pipeline.step(m.x0, m.x1));
      CHECK(g.stats.restarted_from_root == u.stats.restarted_from_root);  // the front moved with it
      CHECK(g.stats.bvtt_nodes == u.stats.bvtt_nodes);
      moving = std::move(constructed);  // and back by move assignment
      continue;
    }
    const auto m = lwsccd_test::folded_cloth(50, 1 + s);
    const auto g = moving.step(m.x0, m.x1);
    const auto u = unmoved.step(m.x0, m.x1);
    require_same_contacts(g, cpu_pipeline.step(m.x0, m.x1));
    CHECK(g.stats.restarted_from_root == u.stats.restarted_from_root);
    CHECK(g.stats.bvtt_nodes == u.stats.bvtt_nodes);
    CHECK(g.stats.rebuilt == u.stats.rebuilt);
  }
}
