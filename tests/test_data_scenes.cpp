#include <catch2/catch.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>

#include "lwsccd/features/oracle.hpp"
#include "lwsccd/io/dataset.hpp"
#include "test_support.hpp"

using namespace lwsccd;

namespace {

// Every ground-truth-true pair must be among the oracle's candidate feature pairs: the broad
// phase (swept AABBs of triangles, incident features culled) misses no real contact.
void check_truth_covered(const std::string& scene_name) {
  const auto start = std::chrono::steady_clock::now();
  const Scene scene = load_scene(lwsccd_test::data_dir() + "/scenes/" + scene_name);
  REQUIRE(scene.has_ground_truth);
  const TriangleMesh& mesh = *scene.step.mesh;
  const auto bvs = swept_triangle_bvs<Aabbd>(mesh, scene.step.x0, scene.step.x1);
  const auto pairs = sweep_and_prune_pairs(mesh, bvs);
  const FeaturePairs fp = feature_pairs(mesh, pairs);
  std::size_t true_vf = 0, true_ee = 0, missed = 0;
  for (std::size_t i = 0; i < scene.truth.vf.size(); ++i) {
    if (!scene.truth.vf_collides[i]) continue;
    ++true_vf;
    if (!std::binary_search(fp.vf.begin(), fp.vf.end(), scene.truth.vf[i])) ++missed;
  }
  for (std::size_t i = 0; i < scene.truth.ee.size(); ++i) {
    if (!scene.truth.ee_collides[i]) continue;
    ++true_ee;
    if (!std::binary_search(fp.ee.begin(), fp.ee.end(), scene.truth.ee[i])) ++missed;
  }
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("%s: %d faces, %zu candidate triangle pairs, %zu vf + %zu ee feature pairs; "
              "ground truth %zu vf + %zu ee true, %zu missed (%.2f s)\n",
              scene_name.c_str(), mesh.num_faces(), pairs.size(), fp.vf.size(), fp.ee.size(), true_vf, true_ee,
              missed, secs);
  REQUIRE(true_vf + true_ee > 0);
  CHECK(missed == 0);
}

}  // namespace

TEST_CASE("oracle candidate feature pairs cover the ground truth: cloth-funnel", "[data][oracle]") {
  check_truth_covered("cloth-funnel");
}

TEST_CASE("oracle candidate feature pairs cover the ground truth: armadillo-rollers", "[data][oracle]") {
  check_truth_covered("armadillo-rollers");
}

TEST_CASE("oracle candidate feature pairs cover the ground truth: cloth-ball", "[data][oracle]") {
  check_truth_covered("cloth-ball");
}

TEST_CASE("OBB and AABB oracles agree on the ground truth of cloth-funnel", "[data][oracle]") {
  // O(n^2) brute force with OBBs on the 18K-face scene: slow but bounded (seconds).
  const Scene scene = load_scene(lwsccd_test::data_dir() + "/scenes/cloth-funnel");
  const TriangleMesh& mesh = *scene.step.mesh;
  const auto obb_pairs = brute_force_pairs(mesh, swept_triangle_bvs<Obbf>(mesh, scene.step.x0, scene.step.x1));
  const FeaturePairs fp = feature_pairs(mesh, obb_pairs);
  for (std::size_t i = 0; i < scene.truth.vf.size(); ++i)
    if (scene.truth.vf_collides[i]) REQUIRE(std::binary_search(fp.vf.begin(), fp.vf.end(), scene.truth.vf[i]));
  for (std::size_t i = 0; i < scene.truth.ee.size(); ++i)
    if (scene.truth.ee_collides[i]) REQUIRE(std::binary_search(fp.ee.begin(), fp.ee.end(), scene.truth.ee[i]));
  const auto aabb_pairs = sweep_and_prune_pairs(mesh, swept_triangle_bvs<Aabbd>(mesh, scene.step.x0, scene.step.x1));
  std::printf("cloth-funnel: %zu OBB (float) candidate pairs vs %zu AABB (double)\n", obb_pairs.size(), aabb_pairs.size());
  CHECK(obb_pairs.size() > 0);
}
