// lwsccd-bench-pipeline — the whole CCD step (host positions in, contacts on the host out), per
// stage, over the real scenes, the horse-gallop sequence and the built-in simulation at several
// sizes, for the policies a sweep names. The first step (BVH build, traversal from the root) is
// reported apart from the steady state (refit, traversal from the front: medians of --reps steps).
// The default sweep adds, on the GPU: a second pipeline's first step on new memory (first2, the
// median of five), device-resident steady steps (device), host-to-host steady steps into one kept
// result (kept), both again from the positions rounded to float (device-f32, kept-f32: float32
// input; device-f32-as-f64, kept-f32-as-f64: the same rounded positions as double, step for step
// beside them), and fresh steps, device-resident, each after a step of another configuration of
// the mesh, from that stale front (fresh) or from the root (fresh-root), and a pipeline's first
// step made after the scene's others are gone (first-warm: their device blocks in the process's
// cache).
// Scenes with ground truth also give false negatives and positives. JSON rows feed
// bench/plot_pipeline.py (docs/BENCHMARKS.md).
//
// Sweeps:
//   schedulers  every GPU scheduler x BV x precision (filtered inclusion): data scenes, horse,
//               built-in 100K
//   methods     every narrow-phase method x precision (lazy, AABB): the scenes with ground truth
//   modes       the certified method in each query mode (contacts, earliest, set) x precision, and
//               filtered inclusion (the method before it) in mode contacts: scenes, built-in 100K
//   scaling     the default policies on the built-in scene at --sizes (default 1K..10M)
//   default     the default policies on every scene (for the CPU backend: a short sweep)
//   threads     CPU backend: the scenes with ground truth and built-in 100K at each thread count of
//               --threads (default 1,2,4,8,16; PipelineParams::threads)
//   front       horse-gallop and built-in 100K, device-resident too, at several front growth
//               limits (PipelineParams::front_growth_limit): restarts from the root against
//               fronts that grow
//   all         schedulers, methods and scaling
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <functional>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "ccd_app.hpp"
#include "lwsccd/io/dataset.hpp"
#include "lwsccd/simulation/simulation.hpp"

namespace {

struct Row {
  std::string sweep, scene, step;  // step: first | steady
  lwsccd::index_t triangles = 0;
  ccd_app::PolicyChoice policies;
  lwsccd::CcdMode mode = lwsccd::CcdMode::contacts;
  int steps_measured = 0;
  double total = 0, refit = 0, traverse = 0, features = 0, narrow = 0;
  double p10_total = 0, p90_total = 0;  // 10th and 90th percentiles of the measured steps' totals
  double mean_total = 0;  // mean over the measured steps
  std::size_t rebuilds = 0, restarts = 0;  // measured steps that rebuilt the BVH / traversed from the root
  std::vector<lwsccd::StepStats> steps;    // every measured step's stats, in order (what the mean averages)
  double front_growth_limit = 0;
  // first2: medians of making each pipeline (its constructor) and of destroying it after its step.
  double make_ms = 0, destroy_ms = 0;
  unsigned threads = 0;  // CPU: PipelineParams::threads (0: every core)
  lwsccd::StepStats last;  // counts of the last measured step
  double earliest_toi = 1;
  bool has_truth = false;
  lwsccd::TruthScore truth;
};

struct Scenario {
  std::string name;
  std::shared_ptr<const lwsccd::TriangleMesh> mesh;
  lwsccd::BodyLayout layout;
  std::function<lwsccd::Step(std::size_t)> step;  // step i (0: the first)
  std::size_t available_steps = 0;                // 0: unbounded
  const lwsccd::GroundTruth* truth = nullptr;
  // Fresh steps: (another configuration of the mesh, the step measured after it), for the i-th
  // measurement; empty: no fresh rows.
  std::function<std::pair<lwsccd::Step, lwsccd::Step>(std::size_t)> fresh;
};

// A step of the same mesh whose motion is `factor` times the step's (x0 -> x0 + factor (x1 - x0)):
// an overshooting line-search trial, the configuration a data scene's fresh step follows.
lwsccd::Step longer_motion(const lwsccd::Step& s, double factor) {
  lwsccd::Step out = s;
  for (std::size_t v = 0; v < out.x1.size(); ++v) out.x1[v] = s.x0[v] + (s.x1[v] - s.x0[v]) * factor;
  return out;
}

// The first step, then `reps` steady steps (the sequence's next steps, or the same step again).
const char* mode_name(lwsccd::CcdMode m) {
  return m == lwsccd::CcdMode::earliest ? "earliest" : m == lwsccd::CcdMode::set ? "set" : "contacts";
}

void measure(const Scenario& sc, const std::string& sweep, const ccd_app::PolicyChoice& policies, const std::string& device,
             int reps, std::vector<Row>& rows, lwsccd::CcdMode mode = lwsccd::CcdMode::contacts, bool resident = false,
             lwsccd::PipelineParams params = {}) {
  const std::size_t first_row = rows.size();
  params.mode = mode;
  auto pipeline = device == "gpu" ? ccd_app::make_gpu_pipeline(sc.mesh, sc.layout, params, policies)
                                  : ccd_app::make_cpu_pipeline(sc.mesh, sc.layout, params, policies);
  // A sequence runs all its steps (its steady state is the median over them); other scenes
  // repeat their step, or go on simulating, for `reps` steps after the first.
  const std::size_t steps = sc.available_steps ? sc.available_steps : static_cast<std::size_t>(reps) + 1;
  std::vector<ccd_app::StepOutcome> outcomes;
  for (std::size_t i = 0; i < steps; ++i) {
    const lwsccd::Step step = sc.step(i);
    outcomes.push_back(pipeline->step(step.x0, step.x1));
  }
  auto make_row = [&](const char* which, std::size_t from, std::size_t to) {
    Row r;
    r.sweep = sweep;
    r.scene = sc.name;
    r.step = which;
    r.triangles = sc.mesh->num_faces();
    r.policies = policies;
    r.mode = mode;
    r.front_growth_limit = params.front_growth_limit;
    r.threads = params.threads;
    r.steps_measured = static_cast<int>(to - from);
    auto med = [&](double lwsccd::StepStats::*field) {
      std::vector<double> v;
      for (std::size_t i = from; i < to; ++i) v.push_back(outcomes[i].stats.*field);
      return lwsccd_bench::median(v);
    };
    r.total = med(&lwsccd::StepStats::total_ms);
    {
      std::vector<double> totals;
      for (std::size_t i = from; i < to; ++i) totals.push_back(outcomes[i].stats.total_ms);
      r.p10_total = lwsccd_bench::percentile(totals, 0.1);
      r.p90_total = lwsccd_bench::percentile(totals, 0.9);
    }
    for (std::size_t i = from; i < to; ++i) {
      const lwsccd::StepStats& st = outcomes[i].stats;
      r.mean_total += st.total_ms / double(to - from);
      r.rebuilds += st.rebuilt;
      r.restarts += st.restarted_from_root;
      r.steps.push_back(st);
    }
    r.refit = med(&lwsccd::StepStats::refit_ms);
    r.traverse = med(&lwsccd::StepStats::traverse_ms);
    r.features = med(&lwsccd::StepStats::features_ms);
    r.narrow = med(&lwsccd::StepStats::narrow_ms);
    r.last = outcomes[to - 1].stats;
    for (std::size_t i = from; i < to; ++i) r.earliest_toi = std::min(r.earliest_toi, outcomes[i].contacts.earliest_toi);
    if (sc.truth && mode != lwsccd::CcdMode::earliest) {  // (earliest: no pairs to score)
      r.has_truth = true;
      r.truth = lwsccd::score_against_truth(*sc.truth, outcomes[to - 1].contacts);
    }
    return r;
  };
  rows.push_back(make_row("first", 0, 1));
  if (outcomes.size() > 1) rows.push_back(make_row("steady", 1, outcomes.size()));
  // GPU: a second pipeline's first step on the same scene (a built-in scene's next step), on new
  // memory: the process's cached blocks are freed before each (the first pipeline keeps its own).
  // The process has loaded the kernels the first one launched (CUDA loads a kernel's module at its
  // first launch), so this is what a program that makes many pipelines pays for each after the
  // first. Medians over kFirstSteps such pipelines, one at a time.
  if (device == "gpu") {
    constexpr int kFirstSteps = 5;
    std::vector<ccd_app::StepOutcome> kept = std::move(outcomes);
    outcomes.clear();
    const lwsccd::Step step = sc.step(0);
    std::vector<double> make_ms, destroy_ms;
    using clock = std::chrono::steady_clock;
    auto ms_since = [](clock::time_point t) { return std::chrono::duration<double, std::milli>(clock::now() - t).count(); };
    for (int k = 0; k < kFirstSteps; ++k) {
      ccd_app::release_gpu_cached_memory();
      clock::time_point t = clock::now();
      auto second = ccd_app::make_gpu_pipeline(sc.mesh, sc.layout, params, policies);
      make_ms.push_back(ms_since(t));
      outcomes.push_back(second->step(step.x0, step.x1));
      t = clock::now();
      second.reset();
      destroy_ms.push_back(ms_since(t));
    }
    Row r = make_row("first2", 0, outcomes.size());
    r.make_ms = lwsccd_bench::percentile(make_ms, 0.5);
    r.destroy_ms = lwsccd_bench::percentile(destroy_ms, 0.5);
    std::printf("first2 pipelines of %s: made in %.3f ms, destroyed in %.3f ms (medians of %d)\n", sc.name.c_str(), r.make_ms,
                r.destroy_ms, kFirstSteps);
    rows.push_back(r);
    outcomes = std::move(kept);
  }
  // Device-resident steps (GPU): a fresh pipeline over the same steps, positions copied to the
  // device before each (not timed) and contacts left there; its steady steps' medians.
  if (resident && device == "gpu" && steps > 1) {
    auto on_device = ccd_app::make_gpu_pipeline(sc.mesh, sc.layout, params, policies);
    const std::vector<ccd_app::StepOutcome> host_outcomes = std::move(outcomes);
    outcomes.clear();
    for (std::size_t i = 0; i < steps; ++i) {
      const lwsccd::Step step = sc.step(i);
      const std::optional<lwsccd::StepStats> stats = ccd_app::device_resident_step(*on_device, step.x0, step.x1);
      ccd_app::StepOutcome o;
      if (stats) o.stats = *stats;
      outcomes.push_back(std::move(o));
    }
    Row r = make_row("device", 1, outcomes.size());
    r.has_truth = false;  // (the contacts stayed on the device)
    rows.push_back(r);
  }
  // Host to host into one result kept between steps (AnyPipeline::step_into, GPU: its contact
  // lists' memory reused, no page faults for them): a fresh pipeline over the same steps.
  if (resident && device == "gpu" && steps > 1) {
    auto p = ccd_app::make_gpu_pipeline(sc.mesh, sc.layout, params, policies);
    const std::vector<ccd_app::StepOutcome> kept_outcomes = std::move(outcomes);
    outcomes.clear();
    lwsccd::StepOutcome kept;
    for (std::size_t i = 0; i < steps; ++i) {
      const lwsccd::Step step = sc.step(i);
      p->step_into(lwsccd::Span<const lwsccd::Vec3d>(step.x0), lwsccd::Span<const lwsccd::Vec3d>(step.x1), kept);
      ccd_app::StepOutcome o;
      o.stats = kept.stats;
      o.contacts.earliest_toi = kept.contacts.earliest_toi;
      outcomes.push_back(std::move(o));
    }
    outcomes.back().contacts = kept.contacts;  // (scored against the ground truth)
    rows.push_back(make_row("kept", 1, outcomes.size()));
    outcomes = kept_outcomes;
  }
  // The same two from float positions (the step's double positions rounded to float: what a
  // simulation that keeps float32 positions passes; they cross as float and are widened on the
  // device): device-f32 and kept-f32. Their contacts are those of the rounded positions, so they
  // are not scored against the ground truth.
  if (resident && device == "gpu" && steps > 1) {
    const auto rounded = [](const std::vector<lwsccd::Vec3d>& x) {
      std::vector<lwsccd::Vec3f> out(x.size());
      for (std::size_t v = 0; v < x.size(); ++v) out[v] = x[v].cast<float>();
      return out;
    };
    const auto widened = [](const std::vector<lwsccd::Vec3f>& x) {
      std::vector<lwsccd::Vec3d> out(x.size());
      for (std::size_t v = 0; v < x.size(); ++v) out[v] = x[v].cast<double>();
      return out;
    };
    const std::vector<ccd_app::StepOutcome> kept_outcomes = std::move(outcomes);
    {
      // Beside it, in a pipeline of its own, step for step (each step's two in turn, the first
      // alternating): the same rounded positions passed as double (device-f32-as-f64), so that
      // the two rows differ by the input's type alone, the work being the same.
      auto p = ccd_app::make_gpu_pipeline(sc.mesh, sc.layout, params, policies);
      auto p64 = ccd_app::make_gpu_pipeline(sc.mesh, sc.layout, params, policies);
      outcomes.clear();
      std::vector<ccd_app::StepOutcome> as_f64;
      for (std::size_t i = 0; i < steps; ++i) {
        const lwsccd::Step step = sc.step(i);
        const std::vector<lwsccd::Vec3f> f0 = rounded(step.x0), f1 = rounded(step.x1);
        const std::vector<lwsccd::Vec3d> d0 = widened(f0), d1 = widened(f1);
        for (int k = 0; k < 2; ++k) {
          const bool as_float = (k == 0) == (i % 2 == 0);
          const std::optional<lwsccd::StepStats> stats =
              as_float ? ccd_app::device_resident_step(*p, f0, f1) : ccd_app::device_resident_step(*p64, d0, d1);
          ccd_app::StepOutcome o;
          if (stats) o.stats = *stats;
          (as_float ? outcomes : as_f64).push_back(std::move(o));
        }
      }
      Row r = make_row("device-f32", 1, outcomes.size());
      r.has_truth = false;
      rows.push_back(r);
      std::swap(outcomes, as_f64);
      Row r64 = make_row("device-f32-as-f64", 1, outcomes.size());
      r64.has_truth = false;
      rows.push_back(r64);
    }
    {
      // Host to host, paired the same way (kept-f32-as-f64: the rounded positions as double).
      auto p = ccd_app::make_gpu_pipeline(sc.mesh, sc.layout, params, policies);
      auto p64 = ccd_app::make_gpu_pipeline(sc.mesh, sc.layout, params, policies);
      outcomes.clear();
      std::vector<ccd_app::StepOutcome> as_f64;
      lwsccd::StepOutcome kept, kept64;
      for (std::size_t i = 0; i < steps; ++i) {
        const lwsccd::Step step = sc.step(i);
        const std::vector<lwsccd::Vec3f> f0 = rounded(step.x0), f1 = rounded(step.x1);
        const std::vector<lwsccd::Vec3d> d0 = widened(f0), d1 = widened(f1);
        for (int k = 0; k < 2; ++k) {
          const bool as_float = (k == 0) == (i % 2 == 0);
          if (as_float)
            p->step_into(lwsccd::Span<const lwsccd::Vec3f>(f0), lwsccd::Span<const lwsccd::Vec3f>(f1), kept);
          else
            p64->step_into(lwsccd::Span<const lwsccd::Vec3d>(d0), lwsccd::Span<const lwsccd::Vec3d>(d1), kept64);
          ccd_app::StepOutcome o;
          o.stats = as_float ? kept.stats : kept64.stats;
          (as_float ? outcomes : as_f64).push_back(std::move(o));
        }
      }
      Row r = make_row("kept-f32", 1, outcomes.size());
      r.has_truth = false;
      rows.push_back(r);
      std::swap(outcomes, as_f64);
      Row r64 = make_row("kept-f32-as-f64", 1, outcomes.size());
      r64.has_truth = false;
      rows.push_back(r64);
    }
    outcomes = kept_outcomes;
  }
  // Fresh steps (GPU, device-resident): each measured step follows a step of another configuration
  // of the same mesh (Scenario::fresh), so the front it finds was recorded elsewhere. Row "fresh"
  // steps from that front, row "fresh-root" calls restart_from_root() first.
  if (resident && device == "gpu" && sc.fresh) {
    const std::vector<ccd_app::StepOutcome> kept = std::move(outcomes);
    for (const bool restart : {false, true}) {
      auto p = ccd_app::make_gpu_pipeline(sc.mesh, sc.layout, params, policies);
      outcomes.clear();
      for (std::size_t i = 0; i <= static_cast<std::size_t>(reps); ++i) {  // (i = 0: the first step, not counted)
        const std::pair<lwsccd::Step, lwsccd::Step> pair = sc.fresh(i);
        ccd_app::device_resident_step(*p, pair.first.x0, pair.first.x1);
        if (restart) p->restart_from_root();
        const std::optional<lwsccd::StepStats> stats = ccd_app::device_resident_step(*p, pair.second.x0, pair.second.x1);
        ccd_app::StepOutcome o;
        if (stats) o.stats = *stats;
        outcomes.push_back(std::move(o));
      }
      Row r = make_row(restart ? "fresh-root" : "fresh", 1, outcomes.size());
      r.has_truth = false;
      rows.push_back(r);
    }
    outcomes = kept;
  }
  // GPU: a pipeline made once every other one of the scene is gone: its first step finds the
  // device blocks they gave back in the process's cache (first-warm; first2 is made while the
  // first pipeline still holds its memory).
  if (resident && device == "gpu") {
    pipeline.reset();
    auto warm = ccd_app::make_gpu_pipeline(sc.mesh, sc.layout, params, policies);
    const std::vector<ccd_app::StepOutcome> kept = std::move(outcomes);
    outcomes.clear();
    const lwsccd::Step step = sc.step(0);
    outcomes.push_back(warm->step(step.x0, step.x1));
    rows.push_back(make_row("first-warm", 0, 1));
    outcomes = kept;
  }
  for (std::size_t k = first_row; k < rows.size(); ++k) {
    const Row& r = rows[k];
    std::printf("%-10s %-24s %9d %-4s %-10s %-18s %-6s %-6s %9.2f %8.3f %8.3f %8.3f %9.2f %10zu %9zu %8zu %9.3g %8.1f", r.sweep.c_str(),
                r.scene.c_str(), r.triangles, r.policies.bv.c_str(),
                device == "gpu" ? r.policies.scheduler.c_str() : r.threads ? ("cpu x" + std::to_string(r.threads)).c_str() : "cpu",
                (r.policies.method + (r.mode == lwsccd::CcdMode::contacts ? "" : std::string("/") + mode_name(r.mode))).c_str(),
                r.policies.precision.c_str(), r.step.c_str(), r.total, r.refit, r.traverse,
                r.features, r.narrow, r.last.triangle_pairs, r.last.feature_pairs_vf + r.last.feature_pairs_ee,
                r.last.hits_vf + r.last.hits_ee, r.earliest_toi, double(r.last.peak_device_bytes) / (1 << 20));
    if (r.has_truth) std::printf("  FN %zu FP %zu", r.truth.false_negatives, r.truth.false_positives);
    std::printf("\n");
    std::fflush(stdout);
  }
}

std::vector<std::size_t> parse_sizes(const std::string& text) {
  std::vector<std::size_t> sizes;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ','))
    if (!item.empty()) sizes.push_back(static_cast<std::size_t>(std::stod(item)));
  return sizes;
}

}  // namespace

int main(int argc, char** argv) {
  const auto args = lwsccd_bench::parse_bench_args(
      argc, argv, 5, {"--sweep=", "--device=", "--sizes=", "--threads="},
      "usage: lwsccd-bench-pipeline [--sweep all|schedulers|methods|modes|scaling|default|front|threads[,...]] [--device gpu|cpu]\n"
      "                             [--sizes 1e3,1e4,...] [--threads 1,2,4,...] [--data DIR] [--reps N] [--json FILE]");
  try {
    // One sweep or several, comma-separated (one run, one JSON file: what run_benchmarks.sh uses).
    const std::string sweep = args.value("--sweep", "all");
    std::vector<std::string> sweeps;
    {
      std::stringstream in(sweep);
      std::string item;
      while (std::getline(in, item, ',')) {
        if (item != "all" && item != "schedulers" && item != "methods" && item != "modes" && item != "scaling" &&
            item != "default" && item != "front" && item != "threads")
          throw lwsccd::InputError("command line", "--sweep",
                                   "expected all, schedulers, methods, modes, scaling, default, front or threads (or a comma-separated list), got '" +
                                       item + "'");
        sweeps.push_back(item);
      }
      if (sweeps.empty()) throw lwsccd::InputError("command line", "--sweep", "no sweep named");
    }
    // `all` means schedulers, methods, modes and scaling.
    auto wants = [&](const std::string& name) {
      for (const std::string& w : sweeps)
        if (w == name || (w == "all" && name != "default" && name != "front" && name != "threads")) return true;
      return false;
    };
    const std::string gpu = ccd_app::gpu_name();
    const std::string device = args.value("--device", gpu.empty() ? "cpu" : "gpu");
    if (device == "gpu" && gpu.empty()) {
      std::fprintf(stderr, "lwsccd-bench-pipeline: no CUDA device; nothing to measure (--device cpu runs the CPU backend)\n");
      return 77;
    }
    const std::vector<std::size_t> sizes = parse_sizes(args.value("--sizes", "1000,10000,100000,1000000,10000000"));
    const std::vector<std::size_t> thread_counts = parse_sizes(args.value("--threads", "1,2,4,8,16"));
    if (wants("threads") && device != "cpu")
      throw lwsccd::InputError("command line", "--sweep threads", "measures the CPU backend: add --device cpu");
    const std::string dir = lwsccd_bench::data_dir(args.data, LWSCCD_BENCH_DATA_DIR);
    std::printf("lwsccd-bench-pipeline: %s; sweep %s; medians of %d steady steps; times in ms, host to host\n",
                device == "gpu" ? ("GPU " + gpu).c_str() : "CPU backend", sweep.c_str(), args.reps);
    std::printf("%-10s %-24s %9s %-4s %-10s %-18s %-6s %-6s %9s %8s %8s %8s %9s %10s %9s %8s %9s %8s\n", "sweep", "scene",
                "triangles", "bv", "scheduler", "method", "prec", "step", "total", "refit", "traverse", "features", "narrow",
                "tri pairs", "feat prs", "contacts", "TOI", "peak MiB");
    std::vector<Row> rows;

    // Scenarios, made on demand (the large built-in ones take memory).
    std::vector<std::unique_ptr<lwsccd::Scene>> scenes;
    auto data_scenario = [&](const std::string& name) {
      scenes.push_back(std::make_unique<lwsccd::Scene>(lwsccd::load_scene(dir + "/scenes/" + name)));
      const lwsccd::Scene* s = scenes.back().get();
      Scenario sc{name, s->step.mesh, {}, [s](std::size_t) { return s->step; }, 0, s->has_ground_truth ? &s->truth : nullptr, {}};
      sc.fresh = [s](std::size_t) { return std::make_pair(longer_motion(s->step, 4.0), s->step); };
      return sc;
    };
    std::unique_ptr<lwsccd::Sequence> horse;
    auto horse_scenario = [&]() {
      if (!horse) horse = std::make_unique<lwsccd::Sequence>(lwsccd::load_sequence(dir + "/sequences/horse-gallop"));
      const lwsccd::Sequence* h = horse.get();
      Scenario sc{"horse-gallop", h->mesh(), {}, [h](std::size_t i) { return h->step(i); }, h->num_steps(), nullptr, {}};
      // Half the gallop apart: step i after step i + 23.
      sc.fresh = [h](std::size_t i) {
        const std::size_t n = h->num_steps();
        return std::make_pair(h->step((i + n / 2) % n), h->step(i % n));
      };
      return sc;
    };
    auto builtin_scenario = [&](std::size_t triangles, std::shared_ptr<lwsccd::ClothBallSimulation>& sim) {
      sim = std::make_shared<lwsccd::ClothBallSimulation>(triangles);
      sim->advance(30);
      lwsccd::ClothBallSimulation* s = sim.get();
      Scenario sc{"builtin-" + std::to_string(s->mesh()->num_faces()), s->mesh(), s->layout(),
                  [s](std::size_t) { return s->next_step(); }, 0, nullptr, {}};
      // The steady steps' configuration after 60 frames more, then again the one before them.
      auto early_late = std::make_shared<std::pair<lwsccd::Step, lwsccd::Step>>();
      sc.fresh = [s, early_late](std::size_t) {
        if (!early_late->first.mesh) {
          early_late->first = s->next_step();
          s->advance(60);
          early_late->second = s->next_step();
        }
        return std::make_pair(early_late->second, early_late->first);
      };
      return sc;
    };
    const std::vector<std::string> truth_scenes = {"cloth-ball", "cloth-funnel", "armadillo-rollers"};
    const bool have_data = std::ifstream(dir + "/scenes/cloth-ball/frames/cloth_ball92.ply").good();
    if (!have_data) std::printf("(no shared data at %s: built-in scenes only)\n", dir.c_str());
    // The sequence may be absent where the scenes are (a copy of scenes/ alone): its rows are left out.
    const bool have_horse = have_data && std::ifstream(dir + "/sequences/horse-gallop/0001.obj").good();
    if (have_data && !have_horse) std::printf("(no sequences/horse-gallop at %s: its rows left out)\n", dir.c_str());

    if (wants("schedulers")) {
      const std::vector<std::string> schedulers =
          device == "gpu" ? std::vector<std::string>{"static", "gproximity", "lazy"} : std::vector<std::string>{"lazy"};
      auto sweep_policies = [&](const std::function<Scenario()>& make) {
        for (const char* bv : {"aabb", "obb"})
          for (const char* precision : {"double", "float"})
            for (const auto& scheduler : schedulers) {
              ccd_app::PolicyChoice p;
              p.bv = bv;
              p.precision = precision;
              p.scheduler = scheduler;
              measure(make(), "schedulers", p, device, args.reps, rows);
            }
      };
      if (have_data) {
        for (const auto& name : truth_scenes) sweep_policies([&] { return data_scenario(name); });
        if (have_horse) sweep_policies([&] { return horse_scenario(); });
      }
      std::shared_ptr<lwsccd::ClothBallSimulation> sim;
      sweep_policies([&] { return builtin_scenario(100000, sim); });
    }
    if (wants("methods") && have_data) {
      for (const auto& name : truth_scenes)
        for (const char* method : {"certified", "filtered-inclusion", "inclusion", "cubic"})
          for (const char* precision : {"double", "float"}) {
            ccd_app::PolicyChoice p;
            p.method = method;
            p.precision = precision;
            measure(data_scenario(name), "methods", p, device, args.reps, rows);
          }
    }
    if (wants("modes")) {
      auto sweep_modes = [&](const std::function<Scenario()>& make) {
        for (const char* precision : {"double", "float"}) {
          ccd_app::PolicyChoice p;
          p.precision = precision;
          for (lwsccd::CcdMode mode : {lwsccd::CcdMode::contacts, lwsccd::CcdMode::earliest, lwsccd::CcdMode::set})
            measure(make(), "modes", p, device, args.reps, rows, mode);
          p.method = "filtered-inclusion";
          measure(make(), "modes", p, device, args.reps, rows);
        }
      };
      if (have_data)
        for (const auto& name : truth_scenes) sweep_modes([&] { return data_scenario(name); });
      std::shared_ptr<lwsccd::ClothBallSimulation> sim;
      sweep_modes([&] { return builtin_scenario(100000, sim); });
    }
    if (wants("default")) {
      if (have_data) {
        for (const auto& name : truth_scenes)
          measure(data_scenario(name), "default", ccd_app::PolicyChoice{}, device, args.reps, rows, lwsccd::CcdMode::contacts, true);
        if (have_horse)
          measure(horse_scenario(), "default", ccd_app::PolicyChoice{}, device, args.reps, rows, lwsccd::CcdMode::contacts, true);
      }
      std::shared_ptr<lwsccd::ClothBallSimulation> sim;
      measure(builtin_scenario(100000, sim), "default", ccd_app::PolicyChoice{}, device, args.reps, rows, lwsccd::CcdMode::contacts, true);
    }
    if (wants("front")) {
      for (const double limit : {1.25, 1.5, 2.0, 3.0, 1e9}) {
        lwsccd::PipelineParams params;
        params.front_growth_limit = limit;
        if (have_horse)
          measure(horse_scenario(), "front", ccd_app::PolicyChoice{}, device, args.reps, rows, lwsccd::CcdMode::contacts, true,
                  params);
        std::shared_ptr<lwsccd::ClothBallSimulation> sim;
        measure(builtin_scenario(100000, sim), "front", ccd_app::PolicyChoice{}, device, std::max(args.reps, 40), rows,
                lwsccd::CcdMode::contacts, true, params);
      }
    }
    if (wants("threads")) {
      for (const std::size_t t : thread_counts) {
        lwsccd::PipelineParams params;
        params.threads = static_cast<unsigned>(t);
        if (have_data)
          for (const auto& name : truth_scenes)
            measure(data_scenario(name), "threads", ccd_app::PolicyChoice{}, device, args.reps, rows, lwsccd::CcdMode::contacts,
                    false, params);
        std::shared_ptr<lwsccd::ClothBallSimulation> sim;
        measure(builtin_scenario(100000, sim), "threads", ccd_app::PolicyChoice{}, device, args.reps, rows,
                lwsccd::CcdMode::contacts, false, params);
      }
    }
    if (wants("scaling")) {
      for (const std::size_t n : sizes) {
        std::shared_ptr<lwsccd::ClothBallSimulation> sim;
        measure(builtin_scenario(n, sim), "scaling", ccd_app::PolicyChoice{}, device, args.reps, rows);
      }
    }

    lwsccd_bench::write_json_rows(args.json, rows.size(), [&](std::size_t i) {
      const Row& r = rows[i];
      lwsccd_bench::Json j{{"device", device == "gpu" ? gpu : std::string("CPU")},
                           {"sweep", r.sweep},
                           {"scene", r.scene},
                           {"triangles", r.triangles},
                           {"bv", r.policies.bv},
                           {"scheduler", device == "gpu" ? r.policies.scheduler : std::string("cpu-work-stealing")},
                           {"threads", device == "gpu" ? 0u : r.threads ? r.threads : ccd_app::cpu_threads()},
                           {"method", r.policies.method},
                           {"precision", r.policies.precision},
                           {"mode", mode_name(r.mode)},
                           {"step", r.step},
                           {"steps_measured", r.steps_measured},
                           {"total_ms", r.total},
                           {"p10_total_ms", r.p10_total},
                           {"p90_total_ms", r.p90_total},
                           {"mean_total_ms", r.mean_total},
                           {"refit_ms", r.refit},
                           {"traverse_ms", r.traverse},
                           {"features_ms", r.features},
                           {"narrow_ms", r.narrow},
                           {"bvtt_nodes", r.last.bvtt_nodes},
                           {"front", r.last.front_size},
                           {"triangle_pairs", r.last.triangle_pairs},
                           {"feature_pairs", r.last.feature_pairs_vf + r.last.feature_pairs_ee},
                           {"contacts", r.last.hits_vf + r.last.hits_ee},
                           {"gave_up", r.last.gave_up},
                           {"narrow_survivors", r.last.narrow_survivors},
                           {"narrow_warp_searches", r.last.narrow_warp_searches},
                           {"earliest_toi", r.earliest_toi},
                           {"peak_device_bytes", r.last.peak_device_bytes},
                           {"reruns", r.last.reruns},
                           {"device_allocations", r.last.device_allocations},
                           {"traversal_relaunches", r.last.traversal_relaunches}};
      if (r.last.device_memory.total())
        lwsccd::for_each_part(r.last.device_memory, [&](const char* name, std::size_t bytes) { j["device_memory"][name] = bytes; });
      if (r.has_truth) {
        j["false_negatives"] = r.truth.false_negatives;
        j["false_positives"] = r.truth.false_positives;
      }
      const lwsccd::NarrowPhaseCounts& v = r.last.narrow_vf;
      const lwsccd::NarrowPhaseCounts& e = r.last.narrow_ee;
      j["certified_hits"] = v.certified_hits + e.certified_hits;
      j["certified_misses"] = v.certified_misses + e.certified_misses;
      j["fallbacks"] = v.fallbacks + e.fallbacks;
      j["screened"] = v.screened + e.screened;
      // Where the pairs were decided: single precision, contacts in single precision with a double
      // tail, double, the fallback search.
      // (Contacts whose leaf pairs of floats proved took no FP64: decided in FP32.)
      j["decided_fp32"] = v.single_misses + e.single_misses + v.float_pair_leaves + e.float_pair_leaves;
      j["decided_fp32_float_pair_leaf"] = v.float_pair_leaves + e.float_pair_leaves;
      j["decided_fp32_fp64_tail"] = v.single_descents + e.single_descents - v.float_pair_leaves - e.float_pair_leaves;
      j["decided_fp64"] = v.pairs + e.pairs - v.single_misses - e.single_misses - v.single_descents - e.single_descents -
                          v.fallbacks - e.fallbacks;
      j["rebuilds"] = r.rebuilds;
      j["restarts_from_root"] = r.restarts;
      j["front_growth_limit"] = r.front_growth_limit;
      if (r.step == "first2") {
        j["make_ms"] = r.make_ms;
        j["destroy_ms"] = r.destroy_ms;
      }
      // Every measured step, in order: its total and stages (ms), whether it traversed from the
      // root, its front and BVTT nodes (what a mean over steps hides).
      auto list = [&](const char* name, auto value) {
        lwsccd_bench::Json a = lwsccd_bench::Json::array();
        for (const lwsccd::StepStats& st : r.steps) a.push_back(value(st));
        j[name] = std::move(a);
      };
      using S = lwsccd::StepStats;
      list("step_total_ms", [](const S& st) { return st.total_ms; });
      list("step_refit_ms", [](const S& st) { return st.refit_ms; });
      list("step_traverse_ms", [](const S& st) { return st.traverse_ms; });
      list("step_features_ms", [](const S& st) { return st.features_ms; });
      list("step_narrow_ms", [](const S& st) { return st.narrow_ms; });
      list("step_restarted", [](const S& st) { return st.restarted_from_root ? 1 : 0; });
      list("step_rebuilt", [](const S& st) { return st.rebuilt ? 1 : 0; });
      list("step_reruns", [](const S& st) { return st.reruns; });
      list("step_device_allocations", [](const S& st) { return st.device_allocations; });
      list("step_traversal_relaunches", [](const S& st) { return st.traversal_relaunches; });
      list("step_front_outgrown", [](const S& st) { return st.front_outgrown ? 1 : 0; });
      list("step_front", [](const S& st) { return st.front_size; });
      list("step_bvtt_nodes", [](const S& st) { return st.bvtt_nodes; });
      return j;
    });
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lwsccd-bench-pipeline: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
