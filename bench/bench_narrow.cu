// lwsccd-bench-narrow — the GPU narrow phase on the whole candidate feature-pair stream of a
// scene (the CPU oracle's: swept AABBs, sort-and-sweep, feature pairs): per method x precision,
// CUDA-event time (median of repeated runs), hits, earliest TOI, and the filter's cull rate.
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "lwsccd/cubic_ccd.hpp"
#include "lwsccd/dataset.hpp"
#include "lwsccd/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase.cuh"
#include "lwsccd/oracle.hpp"

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
  narrow.run(features, step.x0.data(), step.x1.data(), vf.data(), vf.size(), ee.data(), ee.size(), params);  // warm-up
  cudaEvent_t start, stop;
  LWSCCD_CUDA_CHECK(cudaEventCreate(&start));
  LWSCCD_CUDA_CHECK(cudaEventCreate(&stop));
  std::vector<double> ms;
  for (int r = 0; r < reps; ++r) {
    LWSCCD_CUDA_CHECK(cudaEventRecord(start));
    narrow.run(features, step.x0.data(), step.x1.data(), vf.data(), vf.size(), ee.data(), ee.size(), params);
    LWSCCD_CUDA_CHECK(cudaEventRecord(stop));
    LWSCCD_CUDA_CHECK(cudaEventSynchronize(stop));
    float t = 0;
    LWSCCD_CUDA_CHECK(cudaEventElapsedTime(&t, start, stop));
    ms.push_back(t);
  }
  LWSCCD_CUDA_CHECK(cudaEventDestroy(start));
  LWSCCD_CUDA_CHECK(cudaEventDestroy(stop));
  return {scene, Method::name, sizeof(T) == 4 ? "float" : "double", vf.size() + ee.size(),
          narrow.num_vf_hits() + narrow.num_ee_hits(), narrow.gave_up(), lwsccd_bench::median(ms),
          lwsccd_bench::percentile(ms, 0.1), lwsccd_bench::percentile(ms, 0.9), double(narrow.earliest_toi()), reps};
}

}  // namespace

int main(int argc, char** argv) {
  std::string data, json_path;
  int reps = 5;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--data" && i + 1 < argc) data = argv[++i];
    else if (a == "--json" && i + 1 < argc) json_path = argv[++i];
    else if (a == "--reps" && i + 1 < argc) reps = std::max(1, std::atoi(argv[++i]));
    else {
      std::fprintf(stderr, "usage: lwsccd-bench-narrow [--data DIR] [--reps N] [--json FILE]\n");
      return a == "-h" || a == "--help" ? 0 : 1;
    }
  }
  int devices = 0;
  if (cudaGetDeviceCount(&devices) != cudaSuccess || devices == 0) {
    std::fprintf(stderr, "lwsccd-bench-narrow: no CUDA device; nothing to measure\n");
    return 77;
  }
  cudaDeviceProp prop{};
  LWSCCD_CUDA_CHECK(cudaGetDeviceProperties(&prop, 0));
  try {
    const std::string dir = lwsccd_bench::data_dir(data, LWSCCD_BENCH_DATA_DIR);
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
    if (!json_path.empty()) {
      std::FILE* f = std::fopen(json_path.c_str(), "w");
      if (!f) throw Error("cannot write " + json_path);
      std::fprintf(f, "[\n");
      for (std::size_t i = 0; i < rows.size(); ++i) {
        const Row& r = rows[i];
        std::fprintf(f,
                     "  {\"gpu\": \"%s\", \"scene\": \"%s\", \"method\": \"%s\", \"precision\": \"%s\", \"pairs\": %zu, "
                     "\"hits\": %zu, \"gave_up\": %zu, \"median_ms\": %.6f, \"p10_ms\": %.6f, \"p90_ms\": %.6f, "
                     "\"earliest_toi\": %.17g, \"reps\": %d}%s\n",
                     prop.name, r.scene.c_str(), r.method.c_str(), r.precision.c_str(), r.pairs, r.hits, r.gave_up,
                     r.median_ms, r.p10_ms, r.p90_ms, r.earliest, r.reps, i + 1 < rows.size() ? "," : "");
      }
      std::fprintf(f, "]\n");
      std::fclose(f);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lwsccd-bench-narrow: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
