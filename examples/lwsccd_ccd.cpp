// lwsccd-ccd — the main program: continuous collision detection on a scene, step after step,
// through the library's pipeline (GPU when one is present, else the CPU backend).
//
// Inputs: the built-in cloth-on-a-ball simulation (default, no data needed), two frames, a folder
// of frames (a sequence), or a scene folder with ground truth, against which it then reports false
// negatives and false positives. Prints a per-stage table, or JSON with --json.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "ccd_app.hpp"
#include "ccd_inputs.hpp"
#include "ccd_options.hpp"
#include "ccd_report.hpp"
#include "lwsccd/io/render.hpp"
#include "lwsccd/simulation/simulation.hpp"

namespace {

using namespace ccd_app;

// The CPU oracle for --check: every feature pair whose swept feature boxes overlap, found by
// sort-and-sweep over the boxes (no BVH, no triangle pairs), the same narrow phase. Counts
// contacts that differ.
std::size_t oracle_differences(const lwsccd::Step& step, const lwsccd::BodyLayout& layout, const Options& o,
                               const lwsccd::NarrowPhaseResult<double>& contacts) {
  return ccd_app::dispatch_policies(o.policies, [&](auto, auto method, auto scalar) {
    using Method = typename decltype(method)::type;
    using T = typename decltype(scalar)::type;
    const lwsccd::TriangleMesh& mesh = *step.mesh;
    const lwsccd::RepresentativeTriangles rep(mesh, layout);
    lwsccd::CcdParams<T> ccd;
    ccd.min_separation = static_cast<T>(o.params.min_separation);
    ccd.tolerance = static_cast<T>(o.params.tolerance);
    ccd.max_iterations = o.params.max_iterations;
    ccd.mode = o.params.mode;
    const auto expected = ccd_app::to_double(lwsccd::cpu::test_feature_pairs<Method, T>(
        mesh, step.x0, step.x1, lwsccd::sweep_feature_pairs(rep, lwsccd::feature_boxes(mesh, step.x0, step.x1, o.params.min_separation / 2)),
        ccd));
    auto differences = [](const auto& a, const auto& b) {
      std::size_t d = 0, i = 0, j = 0;
      while (i < a.size() || j < b.size()) {
        if (j == b.size() || (i < a.size() && a[i] < b[j])) ++d, ++i;
        else if (i == a.size() || b[j] < a[i]) ++d, ++j;
        else d += a[i].toi != b[j].toi, ++i, ++j;
      }
      return d;
    };
    return differences(contacts.vf, expected.vf) + differences(contacts.ee, expected.ee) +
           (contacts.earliest_toi != expected.earliest_toi ? 1 : 0);
  });
}

void print_progress(std::size_t done, std::size_t total) {
  const int width = 40;
  const int filled = static_cast<int>(width * done / std::max<std::size_t>(total, 1));
  std::fprintf(stderr, "\r[%s%s] %zu/%zu steps", std::string(static_cast<std::size_t>(filled), '#').c_str(),
               std::string(static_cast<std::size_t>(width - filled), '.').c_str(), done, total);
  if (done == total) std::fprintf(stderr, "\n");
  std::fflush(stderr);
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Options o = parse_options(argc, argv);
    Inputs in;
    const StepSource src = open_source(o, in);
    const std::string gpu = ccd_app::gpu_name();
    if (o.device == "gpu" && gpu.empty())
      throw lwsccd::Error("--device gpu: no CUDA device found (or lwsccd-ccd was built without CUDA); use --device cpu");
    const bool on_gpu = o.device == "gpu" || (o.device == "auto" && !gpu.empty());
    if (o.gpus > 1 && !on_gpu) throw lwsccd::Error("--gpus " + std::to_string(o.gpus) + ": needs the GPU backend (no CUDA device, or --device cpu)");
    const std::string backend = on_gpu ? (o.gpus > 1 ? std::to_string(o.gpus) + " x GPU " : "GPU ") + gpu : "CPU";
    auto pipeline = o.gpus > 1 ? ccd_app::make_multi_gpu_pipeline(src.mesh, src.layout, o.params, o.policies, o.gpus)
                    : on_gpu   ? ccd_app::make_gpu_pipeline(src.mesh, src.layout, o.params, o.policies)
                               : ccd_app::make_cpu_pipeline(src.mesh, src.layout, o.params, o.policies);
    const bool progress = src.num_steps > 1 && isatty(STDERR_FILENO);
    std::vector<StepReport> reports;
    for (std::size_t i = 0; i < src.num_steps; ++i) {
      const lwsccd::Step step = src.step(i);
      StepReport r;
      r.name = step.name;
      r.outcome = pipeline->step(step.x0, step.x1);
      if (src.truth && o.params.mode != lwsccd::CcdMode::earliest) {  // (earliest: no pairs to score)
        r.has_truth = true;
        r.truth = lwsccd::score_against_truth(*src.truth, r.outcome.contacts);
      }
      if (o.check) {
        r.checked = true;
        r.check_differences = oracle_differences(step, src.layout, o, r.outcome.contacts);
      }
      if (!o.render.empty()) {
        std::string path = o.render;
        if (src.num_steps > 1) {
          char index[16];
          std::snprintf(index, sizeof index, "_%03zu", i);
          path.insert(path.size() - 4, index);
        }
        lwsccd::cpu::render_contacts(path, *step.mesh, step.x0, step.x1, r.outcome.contacts, o.render_width, o.render_height);
        std::fprintf(stderr, "lwsccd-ccd: wrote %s (t = %.6g)\n", path.c_str(), std::min(1.0, r.outcome.contacts.earliest_toi));
      }
      reports.push_back(std::move(r));
      if (progress) print_progress(i + 1, src.num_steps);
    }
    if (o.json) print_json(src, backend, o, reports);
    else print_table(src, backend, o, reports);
    const bool conservative = o.policies.method != "cubic";
    for (const auto& r : reports)
      if ((conservative && r.truth.false_negatives > 0) || r.check_differences > 0) return 2;
    return 0;
  } catch (const lwsccd::Error& e) {
    std::fprintf(stderr, "lwsccd-ccd: error: %s\n", e.what());
    return 1;
  }
}
