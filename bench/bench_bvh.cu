// lwsccd-bench-bvh — GPU LBVH build and refit times (CUDA events, medians of repeated runs) for
// cloth-ball and the built-in scene at 1M and 10M triangles, AABB and OBB; CPU backend times for
// cloth-ball. Writes a table and, with --json FILE, one JSON object per measurement.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "bench_gpu.cuh"
#include "lwsccd/bvh/bvh.cuh"
#include "lwsccd/io/dataset.hpp"
#include "lwsccd/simulation/scenes.hpp"

using namespace lwsccd;

namespace {

struct Row {
  std::string scene, bv, backend, op;
  index_t faces;
  double median_ms, p10_ms, p90_ms;
  int reps;
  std::size_t device_bytes;
};

template <class BV, class P>
void bench_gpu(const std::string& scene_name, const Step& step, int reps, std::vector<Row>& rows, const char* bv_name) {
  gpu::DeviceStep<P> dstep(*step.mesh, step.x0, step.x1);
  gpu::Bvh<BV> bvh;
  for (int i = 0; i < 3; ++i) bvh.build(dstep);  // warm-up: allocation, module load
  const std::vector<double> build_ms = lwsccd_bench::time_with_events(reps, [&] { bvh.build(dstep); });
  for (int i = 0; i < 3; ++i) bvh.refit(dstep);
  const std::vector<double> refit_ms = lwsccd_bench::time_with_events(reps, [&] { bvh.refit(dstep); });
  bvh.check_status();
  const std::string bv = std::string(bv_name) + (sizeof(P) == 4 ? " (float pos)" : " (double pos)");
  const index_t faces = step.mesh->num_faces();
  rows.push_back({scene_name, bv, "gpu", "build", faces, lwsccd_bench::median(build_ms),
                  lwsccd_bench::percentile(build_ms, 0.1), lwsccd_bench::percentile(build_ms, 0.9), reps,
                  bvh.device_bytes()});
  rows.push_back({scene_name, bv, "gpu", "refit", faces, lwsccd_bench::median(refit_ms),
                  lwsccd_bench::percentile(refit_ms, 0.1), lwsccd_bench::percentile(refit_ms, 0.9), reps,
                  bvh.device_bytes()});
}

template <class BV>
void bench_cpu(const std::string& scene_name, const Step& step, int reps, std::vector<Row>& rows, const char* bv_name) {
  std::vector<double> build_ms, refit_ms;
  cpu::Bvh<BV> bvh;
  for (int r = 0; r < reps; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    bvh.build(*step.mesh, step.x0, step.x1);
    const auto t1 = std::chrono::steady_clock::now();
    bvh.refit(step.x0, step.x1);
    const auto t2 = std::chrono::steady_clock::now();
    build_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
    refit_ms.push_back(std::chrono::duration<double, std::milli>(t2 - t1).count());
  }
  const index_t faces = step.mesh->num_faces();
  rows.push_back({scene_name, bv_name, "cpu (1 thread)", "build", faces, lwsccd_bench::median(build_ms),
                  lwsccd_bench::percentile(build_ms, 0.1), lwsccd_bench::percentile(build_ms, 0.9), reps, 0});
  rows.push_back({scene_name, bv_name, "cpu (1 thread)", "refit", faces, lwsccd_bench::median(refit_ms),
                  lwsccd_bench::percentile(refit_ms, 0.1), lwsccd_bench::percentile(refit_ms, 0.9), reps, 0});
}

void bench_scene(const std::string& name, const Step& step, int reps, bool cpu_too, std::vector<Row>& rows) {
  std::fprintf(stderr, "benchmarking %s (%d faces)\n", name.c_str(), step.mesh->num_faces());
  bench_gpu<Aabbf, float>(name, step, reps, rows, "AABB float");
  bench_gpu<Aabbf, double>(name, step, reps, rows, "AABB float");
  bench_gpu<Obbf, float>(name, step, reps, rows, "OBB float");
  bench_gpu<Aabbd, double>(name, step, reps, rows, "AABB double");
  if (cpu_too) {
    bench_cpu<Aabbf>(name, step, std::max(1, reps / 10), rows, "AABB float");
    bench_cpu<Obbf>(name, step, std::max(1, reps / 10), rows, "OBB float");
  }
}

}  // namespace

int main(int argc, char** argv) {
  const lwsccd_bench::BenchArgs args = lwsccd_bench::parse_bench_args(
      argc, argv, 50, {"--no-big"}, "usage: lwsccd-bench-bvh [--data DIR] [--reps N] [--json FILE] [--no-big]");
  const int reps = args.reps;
  const bool big = !args.has("--no-big");
  cudaDeviceProp prop{};
  if (!lwsccd_bench::first_gpu(prop, "lwsccd-bench-bvh")) return 77;
  try {
    std::vector<Row> rows;
    const std::string dir = lwsccd_bench::data_dir(args.data, LWSCCD_BENCH_DATA_DIR);
    if (std::filesystem::is_directory(dir + "/scenes/cloth-ball")) {
      const Scene s = load_scene(dir + "/scenes/cloth-ball");
      bench_scene("cloth-ball", s.step, reps, true, rows);
    } else {
      std::fprintf(stderr, "cloth-ball skipped: no data at %s\n", dir.c_str());
    }
    const std::vector<std::size_t> sizes = big ? std::vector<std::size_t>{1000000, 10000000} : std::vector<std::size_t>{100000};
    for (std::size_t n : sizes) {
      const MultiBodyStep s = make_cloth_ball_scene(n);
      bench_scene("builtin-" + std::to_string(n / 1000) + "K", s.step, n > 2000000 ? std::max(5, reps / 5) : reps, false, rows);
    }
    std::printf("GPU: %s (sm_%d%d), %d SMs; CUDA events, median of repeated runs (p10-p90)\n", prop.name, prop.major,
                prop.minor, prop.multiProcessorCount);
    std::printf("%-14s %10s %-22s %-15s %-6s %11s %22s %5s %10s\n", "scene", "faces", "bv", "backend", "op", "median ms",
                "p10 - p90 ms", "reps", "dev MB");
    for (const Row& r : rows)
      std::printf("%-14s %10d %-22s %-15s %-6s %11.4f %10.4f - %9.4f %5d %10.1f\n", r.scene.c_str(), r.faces, r.bv.c_str(),
                  r.backend.c_str(), r.op.c_str(), r.median_ms, r.p10_ms, r.p90_ms, r.reps, r.device_bytes / 1048576.0);
    lwsccd_bench::write_json_rows(args.json, rows.size(), [&](std::size_t i) {
      const Row& r = rows[i];
      return lwsccd_bench::Json{{"gpu", prop.name}, {"scene", r.scene}, {"faces", r.faces}, {"bv", r.bv}, {"backend", r.backend},
                                {"op", r.op}, {"median_ms", r.median_ms}, {"p10_ms", r.p10_ms}, {"p90_ms", r.p90_ms},
                                {"reps", r.reps}, {"device_bytes", r.device_bytes}};
    });
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lwsccd-bench-bvh: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
