// The narrow phase against the exact ground truth of ../shared/data: the conservative method
// misses nothing, in float and in double; the seed's method's misses are reported.
#include <catch2/catch.hpp>

#include <cstdio>
#include <filesystem>
#include <functional>

#include "lwsccd/cubic_ccd.hpp"
#include "lwsccd/dataset.hpp"
#include "lwsccd/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase.hpp"
#include "test_support.hpp"

using namespace lwsccd;
namespace fs = std::filesystem;

namespace {

struct Counts {
  std::size_t queries = 0, positives = 0, false_negatives = 0, false_positives = 0;
};

// Runs Method in precision T over every query file of every set; `transform` may alter the points.
template <class Method, class T>
Counts run_query_sets(const std::function<void(std::array<Vec3d, 8>&, bool vertex_face)>& transform = {}) {
  Counts c;
  const CcdParams<T> params;
  for (const auto& set : fs::directory_iterator(lwsccd_test::data_dir() + "/queries")) {
    for (const bool vf : {true, false}) {
      const fs::path folder = set.path() / (vf ? "vertex-face" : "edge-edge");
      if (!fs::is_directory(folder)) continue;
      for (const auto& file : fs::directory_iterator(folder)) {
        const QueryFile qf = load_query_csv(file.path().string());
        for (std::size_t i = 0; i < qf.queries.size(); ++i) {
          auto pts = qf.queries[i];
          if (transform) transform(pts, vf);
          const bool hit = vf ? Method::vertex_face(vertex_face_query<T>(pts), params).hit
                              : Method::edge_edge(edge_edge_query<T>(pts), params).hit;
          ++c.queries;
          c.positives += qf.truth[i] == 1;
          c.false_negatives += qf.truth[i] == 1 && !hit;
          c.false_positives += qf.truth[i] == 0 && hit;
        }
      }
    }
  }
  return c;
}

template <class Method, class T>
Counts run_scene(const Scene& scene, T* earliest = nullptr) {
  const FeaturePairs pairs{scene.truth.vf, scene.truth.ee};
  const auto result = cpu::test_feature_pairs<Method, T>(*scene.step.mesh, scene.step.x0, scene.step.x1, pairs);
  if (earliest) *earliest = result.earliest_toi;
  Counts c;
  auto count = [&](const auto& truth_pairs, const std::vector<bool>& truth, const std::vector<FeatureHit<T>>& hits) {
    for (std::size_t i = 0; i < truth_pairs.size(); ++i) {
      const FeatureHit<T> key{truth_pairs[i].first, truth_pairs[i].second, T(0)};
      const bool hit = std::binary_search(hits.begin(), hits.end(), key);
      ++c.queries;
      c.positives += truth[i];
      c.false_negatives += truth[i] && !hit;
      c.false_positives += !truth[i] && hit;
    }
  };
  count(scene.truth.vf, scene.truth.vf_collides, result.vf);
  count(scene.truth.ee, scene.truth.ee_collides, result.ee);
  return c;
}

void report(const char* what, const Counts& c) {
  std::printf("%-44s %6zu queries, %6zu true: %zu false negatives, %zu false positives\n", what, c.queries, c.positives,
              c.false_negatives, c.false_positives);
}

}  // namespace

TEST_CASE("query sets: the conservative method misses nothing, float and double", "[data][narrow]") {
  const Counts d = run_query_sets<InclusionCcd, double>();
  const Counts f = run_query_sets<InclusionCcd, float>();
  const Counts fd = run_query_sets<Filtered<InclusionCcd>, double>();
  report("query sets, inclusion, double", d);
  report("query sets, inclusion, float", f);
  report("query sets, filtered inclusion, double", fd);
  REQUIRE(d.positives > 200);
  CHECK(d.false_negatives == 0);
  CHECK(f.false_negatives == 0);
  CHECK(fd.false_negatives == 0);
  // The seed's method: its misses are the reason the conservative method exists; reported here.
  report("query sets, cubic (seed), double", run_query_sets<CubicCcd, double>());
  report("query sets, cubic (seed), float", run_query_sets<CubicCcd, float>());
}

TEST_CASE("query sets: the conservative answer survives translation, scaling, permutation and time reversal", "[data][narrow]") {
  using Transform = std::function<void(std::array<Vec3d, 8>&, bool)>;
  const std::vector<std::pair<const char*, Transform>> transforms = {
      {"translated far from the origin", [](std::array<Vec3d, 8>& p, bool) { for (auto& x : p) x += Vec3d{1000.5, -2000.25, 4096}; }},
      {"scaled by 2^-20", [](std::array<Vec3d, 8>& p, bool) { for (auto& x : p) x *= std::ldexp(1.0, -20); }},
      {"scaled by 2^30", [](std::array<Vec3d, 8>& p, bool) { for (auto& x : p) x *= std::ldexp(1.0, 30); }},
      {"triangle vertices / edge ends permuted", [](std::array<Vec3d, 8>& p, bool vf) {
         if (vf) {  // (a, b, c) -> (b, c, a) at both times
           std::swap(p[1], p[2]), std::swap(p[2], p[3]);
           std::swap(p[5], p[6]), std::swap(p[6], p[7]);
         } else {  // edges swapped, first edge reversed
           std::swap(p[0], p[2]), std::swap(p[1], p[3]), std::swap(p[4], p[6]), std::swap(p[5], p[7]);
           std::swap(p[0], p[1]), std::swap(p[4], p[5]);
         }
       }},
      {"time reversed (t0 <-> t1)", [](std::array<Vec3d, 8>& p, bool) { for (int i = 0; i < 4; ++i) std::swap(p[i], p[i + 4]); }},
  };
  for (const auto& [name, transform] : transforms) {
    INFO(name);
    const Counts d = run_query_sets<InclusionCcd, double>(transform);
    const Counts f = run_query_sets<InclusionCcd, float>(transform);
    std::printf("%s: ", name);
    report("inclusion double", d);
    CHECK(d.false_negatives == 0);
    CHECK(f.false_negatives == 0);
  }
}

TEST_CASE("scenes: the conservative method misses nothing; cloth-ball's earliest TOI", "[data][narrow]") {
  for (const char* name : {"cloth-funnel", "armadillo-rollers", "cloth-ball"}) {
    INFO(name);
    const Scene scene = load_scene(lwsccd_test::data_dir() + "/scenes/" + name);
    REQUIRE(scene.has_ground_truth);
    double earliest = 1;
    const Counts d = run_scene<Filtered<InclusionCcd>, double>(scene, &earliest);
    const Counts f = run_scene<Filtered<InclusionCcd>, float>(scene);
    std::printf("%s: ", name);
    report("filtered inclusion, double", d);
    std::printf("%s: ", name);
    report("filtered inclusion, float", f);
    CHECK(d.false_negatives == 0);
    CHECK(f.false_negatives == 0);
    std::printf("%s: earliest TOI (double) %.15g\n", name, earliest);
    if (std::string(name) == "cloth-ball") {
      // The earliest contact is at 7.4916e-6: the inclusion method in long double with a 1e-9
      // tolerance bounds it from below at 7.49155879e-6 (edge-edge pair 130643/152260) and the
      // cubic's root is 7.49207e-6. (The peer figure 3.814697265625e-06 in ANCHORS.md is that
      // solver's lower bound, 2^-18, at its tolerance.) Never later than the true time, and within
      // the tolerance (1e-6) of it:
      CHECK(earliest <= 7.49155879e-06);
      CHECK(earliest >= 7.49155879e-06 - 1e-6);
    }
    std::printf("%s: ", name);
    report("cubic (seed), double", run_scene<CubicCcd, double>(scene));
  }
}
