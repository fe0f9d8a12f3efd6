// lwsccd-bench-pipeline — the whole GPU CCD step (host positions in, contacts out) per scene:
// per-stage times of gpu::CcdPipeline, the first step (BVH build, traversal from the root) and
// the steady state (refit, traversal from the front), medians of repeated steps.
#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "bench_gpu.cuh"
#include "lwsccd/dataset.hpp"
#include "lwsccd/pipeline.cuh"

using namespace lwsccd;

int main(int argc, char** argv) {
  const lwsccd_bench::BenchArgs args =
      lwsccd_bench::parse_bench_args(argc, argv, 5, {}, "usage: lwsccd-bench-pipeline [--data DIR] [--reps N] [--json FILE]");
  cudaDeviceProp prop{};
  if (!lwsccd_bench::first_gpu(prop, "lwsccd-bench-pipeline")) return 77;
  try {
    const std::string dir = lwsccd_bench::data_dir(args.data, LWSCCD_BENCH_DATA_DIR);
    std::FILE* json = args.json.empty() ? nullptr : std::fopen(args.json.c_str(), "w");
    if (json) std::fprintf(json, "[\n");
    std::printf("GPU: %s; gpu::CcdPipeline<Aabbf, LazyStealScheduler, Filtered<InclusionCcd>, double>; "
                "medians of %d steady steps\n",
                prop.name, args.reps);
    std::printf("%-18s %-7s %9s %9s %9s %9s %9s %9s %11s %11s %9s %10s\n", "scene", "step", "total ms", "refit", "traverse",
                "features", "narrow", "tri pairs", "feat pairs", "contacts", "TOI", "peak MB");
    bool first_row = true;
    for (const char* name : {"cloth-ball", "cloth-funnel", "armadillo-rollers"}) {
      const Scene scene = load_scene(dir + "/scenes/" + name);
      gpu::CcdPipeline<> pipeline(scene.step.mesh);
      std::vector<StepResult<double>> steps;
      for (int r = 0; r <= args.reps; ++r) steps.push_back(pipeline.step(scene.step.x0, scene.step.x1));
      auto median_of = [&](double StepStats::*field) {
        std::vector<double> v;
        for (std::size_t i = 1; i < steps.size(); ++i) v.push_back(steps[i].stats.*field);
        return lwsccd_bench::median(v);
      };
      struct Line {
        const char* which;
        double total, refit, traverse, features, narrow;
        const StepResult<double>& r;
      };
      const Line lines[2] = {
          {"first", steps[0].stats.total_ms, steps[0].stats.refit_ms, steps[0].stats.traverse_ms, steps[0].stats.features_ms,
           steps[0].stats.narrow_ms, steps[0]},
          {"steady", median_of(&StepStats::total_ms), median_of(&StepStats::refit_ms), median_of(&StepStats::traverse_ms),
           median_of(&StepStats::features_ms), median_of(&StepStats::narrow_ms), steps.back()}};
      for (const Line& l : lines) {
        const StepStats& s = l.r.stats;
        std::printf("%-18s %-7s %9.2f %9.3f %9.3f %9.3f %9.2f %9zu %11zu %11zu %9.3g %10.1f\n", name, l.which, l.total, l.refit,
                    l.traverse, l.features, l.narrow, s.triangle_pairs, s.feature_pairs_vf + s.feature_pairs_ee,
                    s.hits_vf + s.hits_ee, double(l.r.contacts.earliest_toi), s.peak_device_bytes / 1048576.0);
        if (json) {
          std::fprintf(json,
                       "%s  {\"gpu\": \"%s\", \"scene\": \"%s\", \"step\": \"%s\", \"total_ms\": %.4f, \"refit_ms\": %.4f, "
                       "\"traverse_ms\": %.4f, \"features_ms\": %.4f, \"narrow_ms\": %.4f, \"triangle_pairs\": %zu, "
                       "\"feature_pairs\": %zu, \"contacts\": %zu, \"earliest_toi\": %.17g, \"peak_device_bytes\": %zu}",
                       first_row ? "" : ",\n", prop.name, name, l.which, l.total, l.refit, l.traverse, l.features, l.narrow,
                       s.triangle_pairs, s.feature_pairs_vf + s.feature_pairs_ee, s.hits_vf + s.hits_ee,
                       double(l.r.contacts.earliest_toi), s.peak_device_bytes);
          first_row = false;
        }
      }
    }
    if (json) {
      std::fprintf(json, "\n]\n");
      std::fclose(json);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lwsccd-bench-pipeline: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
