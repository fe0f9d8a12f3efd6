// The narrow phase against the exact ground truth of ../shared/data: the conservative method
// misses nothing, in float and in double; the seed's method's misses are reported.
#include <catch2/catch.hpp>

#include <cstdio>
#include <filesystem>
#include <functional>

#include "lwsccd/io/dataset.hpp"
#include "lwsccd/narrow_phase/certified_ccd.hpp"
#include "lwsccd/narrow_phase/cubic_ccd.hpp"
#include "lwsccd/narrow_phase/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.hpp"
#include "test_support.hpp"

using namespace lwsccd;
namespace fs = std::filesystem;

namespace {

struct Counts {
  std::size_t queries = 0, positives = 0, false_negatives = 0, false_positives = 0;
};

// Calls f(points, vertex_face, truth) for every query of every set, after `transform`.
template <class F>
void for_each_set_query(const std::function<void(std::array<Vec3d, 8>&, bool vertex_face)>& transform, F&& f) {
  for (const auto& set : fs::directory_iterator(lwsccd_test::data_dir() + "/queries")) {
    for (const bool vf : {true, false}) {
      const fs::path folder = set.path() / (vf ? "vertex-face" : "edge-edge");
      if (!fs::is_directory(folder)) continue;
      for (const auto& file : fs::directory_iterator(folder)) {
        const QueryFile qf = load_query_csv(file.path().string());
        for (std::size_t i = 0; i < qf.queries.size(); ++i) {
          auto pts = qf.queries[i];
          if (transform) transform(pts, vf);
          f(pts, vf, qf.truth[i]);
        }
      }
    }
  }
}

// Runs Method in precision T over every query file of every set; `transform` may alter the points.
template <class Method, class T>
Counts run_query_sets(const std::function<void(std::array<Vec3d, 8>&, bool vertex_face)>& transform = {}) {
  Counts c;
  const CcdParams<T> params;
  for_each_set_query(transform, [&](const std::array<Vec3d, 8>& pts, bool vf, int truth) {
    const bool hit = vf ? Method::vertex_face(vertex_face_query<T>(pts), params).hit
                        : Method::edge_edge(edge_edge_query<T>(pts), params).hit;
    ++c.queries;
    c.positives += truth == 1;
    c.false_negatives += truth == 1 && !hit;
    c.false_positives += truth == 0 && hit;
  });
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

namespace {

// The certified fast path against the truth and against the inclusion search, query by query.
struct CertifiedTally {
  std::size_t queries = 0, hits = 0, misses = 0, undecided = 0;
  std::size_t tolerance_hits = 0;       ///< hits by a contact within the tolerance (kToleranceContacts)
  std::size_t missed_truth = 0;         ///< certified "no contact" on a pair that touches: must stay 0
  std::size_t hit_after_inclusion = 0;  ///< inclusion's TOI later than the certified interval: must stay 0
  std::size_t hit_without_truth = 0;    ///< certified hits on pairs that do not touch (false positives)
  double worst_gap = 0;                 ///< largest lo - (inclusion's TOI), for the report
};

template <class T, class Q>
void certify_one(const Q& q, int truth, CertifiedTally& c) {
  const CcdParams<T> params;
  const CertifiedAnswer<T> a = CertifiedCcd::classify(q, params);
  // The GPU's first refinement step decides only what the whole search answers the same way (on
  // the pairs both the screen and the single-precision filter leave, as a batch runs it).
  using Filter = lwsccd::detail::CertifiedFilter<CertifiedPolicy>;
  lwsccd::detail::Noted<T> noted;
  const bool decided = Filter::decides(q, params, noted);
  const bool single = CertifiedCcd::filter_single(q, params);
  if (single) CHECK(a.certainty == Certainty::miss);
  if (decided && !CertifiedCcd::screen(q, params) && !single) {
    const CertifiedAnswer<T> settled = noted.any ? CertifiedCcd::undecided_from(q, params, noted.lower) : CertifiedAnswer<T>{Certainty::miss};
    CHECK(a.certainty == settled.certainty);
    CHECK(a.lo == settled.lo);
    CHECK(a.tolerance == settled.tolerance);
  }
  CcdResult<T> inc;
  if constexpr (std::is_same_v<Q, VertexFaceQuery<T>>) inc = Filtered<InclusionCcd>::vertex_face(q, params);
  else inc = Filtered<InclusionCcd>::edge_edge(q, params);
  ++c.queries;
  if (a.certainty == Certainty::miss) {
    ++c.misses;
    c.missed_truth += truth == 1;
  } else if (a.certainty == Certainty::hit) {
    ++c.hits;
    c.tolerance_hits += a.tolerance;
    c.hit_without_truth += truth == 0;
    // Both are right: inclusion's TOI is a lower bound of the earliest contact, which lies in [lo, hi].
    c.hit_after_inclusion += !inc.hit || inc.toi > a.hi;
    if (inc.hit) c.worst_gap = std::max(c.worst_gap, double(a.lo) - double(inc.toi));
    // In double the interval is within the tolerance; in float it may be wider by the time the
    // inputs' rounding to float can move the contact (lo stays a lower bound for the exact data).
    if constexpr (std::is_same_v<T, double>) CHECK(a.hi - a.lo <= params.tolerance);
  } else {
    ++c.undecided;
  }
}

template <class T>
CertifiedTally certify_query_sets(const std::function<void(std::array<Vec3d, 8>&, bool)>& transform = {}) {
  CertifiedTally c;
  for_each_set_query(transform, [&](const std::array<Vec3d, 8>& pts, bool vf, int truth) {
    if (vf) certify_one<T>(vertex_face_query<T>(pts), truth, c);
    else certify_one<T>(edge_edge_query<T>(pts), truth, c);
  });
  return c;
}

template <class T>
CertifiedTally certify_scene(const Scene& scene) {
  CertifiedTally c;
  const MeshFeatures f = mesh_features(*scene.step.mesh);
  const auto* x0 = scene.step.x0.data();
  const auto* x1 = scene.step.x1.data();
  for (std::size_t i = 0; i < scene.truth.vf.size(); ++i)
    certify_one<T>(gather_vertex_face<T>(f, x0, x1, scene.truth.vf[i].first, scene.truth.vf[i].second),
                   scene.truth.vf_collides[i], c);
  for (std::size_t i = 0; i < scene.truth.ee.size(); ++i)
    certify_one<T>(gather_edge_edge<T>(f, x0, x1, scene.truth.ee[i].first, scene.truth.ee[i].second),
                   scene.truth.ee_collides[i], c);
  return c;
}

void report(const std::string& what, const CertifiedTally& c) {
  std::printf("%-52s %6zu queries: certified %zu hits (%zu within the tolerance), %zu misses, %zu undecided (%.2f%%); %zu "
              "hits on untouching pairs; lo - inclusion TOI <= %.3g\n",
              what.c_str(), c.queries, c.hits, c.tolerance_hits, c.misses, c.undecided,
              100.0 * double(c.undecided) / double(c.queries), c.hit_without_truth, c.worst_gap);
  CHECK(c.missed_truth == 0);
  CHECK(c.hit_after_inclusion == 0);
}

}  // namespace

TEST_CASE("certified fast path: never 'no' on a contact, intervals consistent with inclusion, float and double",
          "[data][narrow][certified]") {
  const std::vector<std::pair<std::string, std::function<void(std::array<Vec3d, 8>&, bool)>>> transforms = {
      {"as given", {}},
      {"translated by (1e6, -1e6, 1e6)", [](std::array<Vec3d, 8>& p, bool) { for (auto& x : p) x = x + Vec3d{1e6, -1e6, 1e6}; }},
      {"scaled by 2^60", [](std::array<Vec3d, 8>& p, bool) { for (auto& x : p) x *= std::ldexp(1.0, 60); }},
      {"scaled by 2^-60", [](std::array<Vec3d, 8>& p, bool) { for (auto& x : p) x *= std::ldexp(1.0, -60); }},
      {"time reversed", [](std::array<Vec3d, 8>& p, bool) { for (int i = 0; i < 4; ++i) std::swap(p[i], p[i + 4]); }},
  };
  for (const auto& [name, transform] : transforms) {
    INFO(name);
    report("query sets, " + name + ", double", certify_query_sets<double>(transform));
    report("query sets, " + name + ", float", certify_query_sets<float>(transform));
  }
  for (const char* name : {"cloth-funnel", "armadillo-rollers", "cloth-ball"}) {
    INFO(name);
    const Scene scene = load_scene(lwsccd_test::data_dir() + "/scenes/" + name);
    const CertifiedTally d = certify_scene<double>(scene), f = certify_scene<float>(scene);
    report(std::string(name) + ", double", d);
    report(std::string(name) + ", float", f);
    // Real scenes: the fallback is the rare case. cloth-funnel's ground-truth pairs are few (355)
    // and hold its contacts on boundaries: its share of all screened pairs is checked with the
    // CPU pipeline (test_data_pipeline.cpp).
    if (std::string(name) != "cloth-funnel") {
      CHECK(d.undecided * 100 <= d.queries);
      CHECK(f.undecided * 100 <= f.queries);
    }
  }
}

TEST_CASE("CertifiedCcd on the scenes: no false negative, no more false positives than inclusion, the earliest TOI",
          "[data][narrow][certified]") {
  for (const char* name : {"cloth-funnel", "armadillo-rollers", "cloth-ball"}) {
    INFO(name);
    const Scene scene = load_scene(lwsccd_test::data_dir() + "/scenes/" + name);
    double earliest = 1;
    const Counts d = run_scene<CertifiedCcd, double>(scene, &earliest), f = run_scene<CertifiedCcd, float>(scene);
    const Counts ref_d = run_scene<Filtered<InclusionCcd>, double>(scene), ref_f = run_scene<Filtered<InclusionCcd>, float>(scene);
    std::printf("%s: ", name);
    report("certified, double", d);
    std::printf("%s: ", name);
    report("certified, float", f);
    CHECK(d.false_negatives == 0);
    CHECK(f.false_negatives == 0);
    CHECK(d.false_positives <= ref_d.false_positives);
    CHECK(f.false_positives <= ref_f.false_positives);
    if (std::string(name) == "cloth-ball") {  // as for the inclusion method above
      CHECK(earliest <= 7.49155879e-06);
      CHECK(earliest >= 7.49155879e-06 - 1e-6);
    }
  }
  const Counts sets_d = run_query_sets<CertifiedCcd, double>(), sets_f = run_query_sets<CertifiedCcd, float>();
  report("query sets, certified, double", sets_d);
  report("query sets, certified, float", sets_f);
  CHECK(sets_d.false_negatives == 0);
  CHECK(sets_f.false_negatives == 0);
  CHECK(sets_d.false_positives <= run_query_sets<Filtered<InclusionCcd>, double>().false_positives);
  CHECK(sets_f.false_positives <= run_query_sets<Filtered<InclusionCcd>, float>().false_positives);
}
