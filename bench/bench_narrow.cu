// lwsccd-bench-narrow — the GPU narrow phase on the whole candidate feature-pair stream of a
// scene (the CPU oracle's: swept AABBs, sort-and-sweep, feature pairs): per method x precision,
// CUDA-event time (median of repeated runs), hits, earliest TOI, and the filter's cull rate.
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "bench_gpu.cuh"
#include "lwsccd/features/oracle.hpp"
#include "lwsccd/io/dataset.hpp"
#include "lwsccd/narrow_phase/cubic_ccd.hpp"
#include "lwsccd/narrow_phase/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.cuh"

using namespace lwsccd;

/// The non-penetration filter alone, as a method: "hit" = may collide (for the cull rate).
struct FilterOnly {
  static constexpr const char* name = "filter-only";
  static constexpr bool conservative = true;
  template <class T>
  LWSCCD_HD static CcdResult<T> vertex_face(const VertexFaceQuery<T>& q, const CcdParams<T>& p) {
    return {non_penetration_filter(q, p), T(0), false};
  }
  template <class T>
  LWSCCD_HD static CcdResult<T> edge_edge(const EdgeEdgeQuery<T>& q, const CcdParams<T>& p) {
    return {non_penetration_filter(q, p), T(0), false};
  }
};

namespace {

struct Row {
  std::string scene, method, precision;
  std::size_t pairs, hits, gave_up;
  double median_ms, p10_ms, p90_ms, earliest;
  int reps;
};

template <class Method, class T>
Row measure(const std::string& scene, const gpu::DeviceMeshFeatures& features, const gpu::DeviceStep<double>& step,
            const gpu::DeviceBuffer<std::pair<index_t, index_t>>& vf, const gpu::DeviceBuffer<std::pair<index_t, index_t>>& ee,
            int reps) {
  gpu::NarrowPhase<Method, T> narrow;
  const CcdParams<T> params;
  auto run = [&] { narrow.run(features, step.x0.data(), step.x1.data(), vf.data(), vf.size(), ee.data(), ee.size(), params); };
  run();  // warm-up
  const std::vector<double> ms = lwsccd_bench::time_with_events(reps, run);
  return {scene, Method::name, sizeof(T) == 4 ? "float" : "double", vf.size() + ee.size(),
          narrow.num_vf_hits() + narrow.num_ee_hits(), narrow.gave_up(), lwsccd_bench::median(ms),
          lwsccd_bench::percentile(ms, 0.1), lwsccd_bench::percentile(ms, 0.9), double(narrow.earliest_toi()), reps};
}

}  // namespace

int main(int argc, char** argv) {
  const lwsccd_bench::BenchArgs args =
      lwsccd_bench::parse_bench_args(argc, argv, 5, {}, "usage: lwsccd-bench-narrow [--data DIR] [--reps N] [--json FILE]");
  const int reps = args.reps;
  cudaDeviceProp prop{};
  if (!lwsccd_bench::first_gpu(prop, "lwsccd-bench-narrow")) return 77;
  try {
    const std::string dir = lwsccd_bench::data_dir(args.data, LWSCCD_BENCH_DATA_DIR);
    std::vector<Row> rows;
    for (const char* name : {"cloth-ball", "cloth-funnel", "armadillo-rollers"}) {
      const Scene scene = load_scene(dir + "/scenes/" + name);
      const TriangleMesh& mesh = *scene.step.mesh;
      const auto t0 = std::chrono::steady_clock::now();
      const auto tri = sweep_and_prune_pairs(mesh, swept_triangle_bvs<Aabbd>(mesh, scene.step.x0, scene.step.x1));
      const FeaturePairs fp = feature_pairs(mesh, tri);
      std::fprintf(stderr, "%s: %zu vf + %zu ee candidate pairs (CPU oracle, %.1f s)\n", name, fp.vf.size(), fp.ee.size(),
                   std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      gpu::DeviceMeshFeatures features(mesh);
      gpu::DeviceStep<double> step(mesh, scene.step.x0, scene.step.x1);
      gpu::DeviceBuffer<std::pair<index_t, index_t>> vf, ee;
      vf.upload(fp.vf);
      ee.upload(fp.ee);
      rows.push_back(measure<FilterOnly, double>(name, features, step, vf, ee, reps));
      rows.push_back(measure<FilterOnly, float>(name, features, step, vf, ee, reps));
      rows.push_back(measure<Filtered<InclusionCcd>, double>(name, features, step, vf, ee, reps));
      rows.push_back(measure<Filtered<InclusionCcd>, float>(name, features, step, vf, ee, reps));
      rows.push_back(measure<InclusionCcd, double>(name, features, step, vf, ee, reps));
      rows.push_back(measure<CubicCcd, double>(name, features, step, vf, ee, reps));
      rows.push_back(measure<Filtered<CubicCcd>, double>(name, features, step, vf, ee, reps));
      rows.push_back(measure<CubicCcd, float>(name, features, step, vf, ee, reps));
    }
    std::printf("GPU: %s (sm_%d%d); whole candidate feature-pair stream from the host oracle; CUDA events, median of %d runs\n",
                prop.name, prop.major, prop.minor, reps);
    std::printf("%-18s %-20s %-7s %11s %10s %8s %11s %21s %16s\n", "scene", "method", "prec", "pairs", "hits", "gave_up",
                "median ms", "p10 - p90 ms", "earliest TOI");
    for (const Row& r : rows)
      std::printf("%-18s %-20s %-7s %11zu %10zu %8zu %11.3f %10.3f - %8.3f %16.9g\n", r.scene.c_str(), r.method.c_str(),
                  r.precision.c_str(), r.pairs, r.hits, r.gave_up, r.median_ms, r.p10_ms, r.p90_ms, r.earliest);
    lwsccd_bench::write_json_rows(args.json, rows.size(), [&](std::size_t i) {
      const Row& r = rows[i];
      return lwsccd_bench::Json{{"gpu", prop.name}, {"scene", r.scene}, {"method", r.method}, {"precision", r.precision},
                                {"pairs", r.pairs}, {"hits", r.hits}, {"gave_up", r.gave_up}, {"median_ms", r.median_ms},
                                {"p10_ms", r.p10_ms}, {"p90_ms", r.p90_ms}, {"earliest_toi", r.earliest}, {"reps", r.reps}};
    });
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lwsccd-bench-narrow: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
