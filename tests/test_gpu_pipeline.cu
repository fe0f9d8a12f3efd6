// The GPU pipeline against the CPU pipeline: same contacts, same TOIs, step after step.
#include <catch2/catch.hpp>

#include <cstring>

#include "lwsccd/dataset.hpp"
#include "lwsccd/pipeline.cuh"
#include "lwsccd/pipeline.hpp"
#include "lwsccd/scenes.hpp"
#include "contact_compare.hpp"
#include "scene_fixtures.hpp"
#include "test_support.hpp"

using namespace lwsccd;

namespace {

template <class T>
void require_same_contacts(const StepResult<T>& gpu, const StepResult<T>& cpu) {
  REQUIRE(gpu.stats.triangle_pairs == cpu.stats.triangle_pairs);
  REQUIRE(gpu.stats.feature_pairs_vf == cpu.stats.feature_pairs_vf);
  REQUIRE(gpu.stats.feature_pairs_ee == cpu.stats.feature_pairs_ee);
  lwsccd_test::require_same_contacts(gpu.contacts, cpu.contacts);
}

}  // namespace

TEST_CASE("GPU pipeline equals the CPU pipeline over several steps of a folded cloth", "[gpu][pipeline]") {
  const auto first = lwsccd_test::folded_cloth(50, 1);
  auto mesh = std::make_shared<const TriangleMesh>(first.mesh);
  gpu::CcdPipeline<> gpu_pipeline(mesh);
  cpu::CcdPipeline<> cpu_pipeline(mesh);
  for (int s = 0; s < 4; ++s) {
    INFO("step " << s);
    const auto m = lwsccd_test::folded_cloth(50, 1 + s);
    const auto g = gpu_pipeline.step(m.x0, m.x1);
    const auto c = cpu_pipeline.step(m.x0, m.x1);
    require_same_contacts(g, c);
    CHECK(g.stats.hits_vf + g.stats.hits_ee > 0);
    CHECK(g.stats.peak_device_bytes > 0);
  }
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
    // No ground-truth contact is missed by the whole pipeline.
    const std::size_t missed = score_against_truth(scene.truth, g.contacts).false_negatives;
    std::printf("%s: GPU pipeline %.2f ms (refit %.3f, traverse %.3f, features %.3f, narrow %.3f), %zu + %zu contacts, "
                "earliest TOI %.9g, %zu ground-truth contacts missed\n",
                name, g.stats.total_ms, g.stats.refit_ms, g.stats.traverse_ms, g.stats.features_ms, g.stats.narrow_ms,
                g.stats.hits_vf, g.stats.hits_ee, g.contacts.earliest_toi, missed);
    CHECK(missed == 0);
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
  // The same step from device-resident positions, in a fresh pipeline and in this one.
  gpu::DeviceBuffer<Vec3d> x0, x1;
  x0.upload(scene.step.x0);
  x1.upload(scene.step.x1);
  gpu::CcdPipeline<> fresh(scene.step.mesh, scene.layout);
  require_same_contacts(fresh.step_from_device(x0.data(), x1.data()), c);
  require_same_contacts(gpu_pipeline.step_from_device(x0.data(), x1.data()), c);
  CHECK_THROWS_AS(fresh.step_from_device(scene.step.x0.data(), x1.data()), InputError);
  CHECK_THROWS_AS(fresh.step_from_device(x0.data(), nullptr), InputError);
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
  for (std::size_t s = 0; s < seq.num_steps(); ++s) {
    INFO("step " << s);
    const Step step = seq.step(s);
    const auto a = tracked.step(step.x0, step.x1);
    require_same_contacts(a, fresh.step(step.x0, step.x1));
    require_same_contacts(a, cpu_tracked.step(step.x0, step.x1));
    restarts += a.stats.restarted_from_root;
    contacts += a.stats.hits_vf + a.stats.hits_ee;
  }
  std::printf("horse-gallop (GPU pipeline): 47 steps, %zu contacts, %zu restarts from the root; equal to fresh "
              "traversals and to the CPU pipeline at every step\n",
              contacts, restarts);
  CHECK(restarts < seq.num_steps());
}
