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
#include "lwsccd/io/render.hpp"
#include "lwsccd/simulation/simulation.hpp"

namespace {

struct Options {
  std::vector<std::string> inputs;
  std::size_t triangles = 20000;
  std::size_t first_frame = 30;
  std::size_t steps = 0;  // 0: 3 for the built-in scene, all for a sequence
  std::string device = "auto";
  ccd_app::PolicyChoice policies;
  lwsccd::PipelineParams params;
  bool check = false;
  bool json = false;
  std::string render;  // PNG path ("" : no picture)
  int render_width = 800, render_height = 600;
};

void print_usage(std::FILE* out) {
  std::fprintf(out,
               "usage: lwsccd-ccd [options] [INPUT...]\n"
               "\n"
               "Continuous collision detection with lwsccd: every vertex-face and edge-edge pair that comes\n"
               "into contact during each step, with its time of impact.\n"
               "\n"
               "INPUT (none: the built-in scene, a cloth dropped folded onto a ball)\n"
               "  SCENE_DIR        a folder laid out like shared/data/scenes/<scene>/ (frames/ with two\n"
               "                   frames; boxes/ + mma_bool/ ground truth, when present, is checked)\n"
               "  T0 T1            a two-frame step (PLY or OBJ files, same topology)\n"
               "  FRAMES_DIR       a folder of OBJ/PLY frames: each consecutive pair is a step\n"
               "\n"
               "built-in scene\n"
               "  --triangles N    resolution, 64 .. 100000000 (default 20000; e.g. 1000 to 10000000)\n"
               "  --frame F        first frame (default 30: the folded cloth is landing on the ball)\n"
               "  --steps K        steps to run (default 3; for FRAMES_DIR: all)\n"
               "\n"
               "pipeline\n"
               "  --device D       auto (default: the GPU when there is one), gpu, cpu\n"
               "  --bv B           bounding volume of the swept triangles: aabb (default), obb\n"
               "  --scheduler S    GPU traversal load balancer: lazy (default, lazy work stealing),\n"
               "                   gproximity, static\n"
               "  --method M       narrow phase: certified (default; a certified floating-point test,\n"
               "                   the inclusion search where it cannot decide; never misses a contact),\n"
               "                   filtered-inclusion, inclusion (conservative), cubic (can miss contacts)\n"
               "  --mode M         contacts (default: every colliding pair with its TOI), earliest (only\n"
               "                   the earliest TOI of the step), set (colliding pairs, TOIs unrefined)\n"
               "  --precision P    narrow-phase precision: double (default), float\n"
               "  --separation D   minimum separation: report features that come closer than D (default 0)\n"
               "  --tolerance T    time resolution of the times of impact (default 1e-6)\n"
               "  --max-iterations N  narrow-phase work bound per pair; past it a pair counts as a\n"
               "                   contact (default 16384)\n"
               "  --memory-budget B  GPU: device memory the pipeline may hold, e.g. 4G, 512M (default: no\n"
               "                   limit); a step that needs more runs in parts that fit (same contacts)\n"
               "  --part-pairs N   run each step in parts of at most N candidate triangle pairs (both\n"
               "                   devices; same contacts, less memory at once)\n"
               "  --no-front-tracking  traverse from the root every step\n"
               "  --check          also run the CPU oracle (sort-and-sweep, every candidate pair) and\n"
               "                   compare contacts pair for pair (slow on large scenes)\n"
               "\n"
               "output\n"
               "  --json           machine-readable output on stdout\n"
               "  --render F.png   a picture of each step at its earliest contact, colliding triangles\n"
               "                   in red (several steps: F_000.png, F_001.png, ...; CPU ray casting)\n"
               "  --render-size WxH  the picture's size (default 800x600)\n"
               "  -h, --help       this text\n"
               "\n"
               "Exit status: 0 done; 1 bad input or error; 2 a ground-truth contact was missed (or --check\n"
               "found a difference).\n");
}

long long parse_integer(const std::string& option, const std::string& text, long long lo, long long hi) {
  char* end = nullptr;
  const long long v = std::strtoll(text.c_str(), &end, 10);
  if (text.empty() || *end != '\0' || v < lo || v > hi)
    throw lwsccd::InputError("command line", option,
                             "expected an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got '" + text + "'");
  return v;
}

double parse_number(const std::string& option, const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0') throw lwsccd::InputError("command line", option, "expected a number, got '" + text + "'");
  return v;
}

// A byte count: a number with an optional K, M or G (binary multiples).
std::size_t parse_bytes(const std::string& option, const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  const std::string unit = end ? std::string(end) : std::string();
  const double scale = unit.empty() ? 1.0 : unit == "K" ? 1024.0 : unit == "M" ? 1048576.0 : unit == "G" ? 1073741824.0 : -1.0;
  if (text.empty() || scale < 0 || !(v > 0) || v * scale > 1e15)
    throw lwsccd::InputError("command line", option, "expected a positive size such as 4G, 512M or 1000000, got '" + text + "'");
  return static_cast<std::size_t>(v * scale);
}

std::string parse_choice(const std::string& option, const std::string& text, const std::vector<std::string>& allowed) {
  if (std::find(allowed.begin(), allowed.end(), text) != allowed.end()) return text;
  std::string list;
  for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
  throw lwsccd::InputError("command line", option, "expected one of " + list + ", got '" + text + "'");
}

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw lwsccd::InputError("command line", a, "needs a value");
      return argv[++i];
    };
    if (a == "-h" || a == "--help") {
      print_usage(stdout);
      std::exit(0);
    } else if (a == "--triangles") {
      o.triangles = static_cast<std::size_t>(parse_integer(a, value(), 64, 100000000));
    } else if (a == "--frame") {
      o.first_frame = static_cast<std::size_t>(parse_integer(a, value(), 0, 100000));
    } else if (a == "--steps") {
      o.steps = static_cast<std::size_t>(parse_integer(a, value(), 1, 100000));
    } else if (a == "--device") {
      o.device = parse_choice(a, value(), {"auto", "gpu", "cpu"});
    } else if (a == "--bv") {
      o.policies.bv = parse_choice(a, value(), {"aabb", "obb"});
    } else if (a == "--scheduler") {
      o.policies.scheduler = parse_choice(a, value(), {"lazy", "gproximity", "static"});
    } else if (a == "--method") {
      o.policies.method = parse_choice(a, value(), {"certified", "filtered-inclusion", "inclusion", "cubic"});
    } else if (a == "--mode") {
      const std::string m = parse_choice(a, value(), {"contacts", "earliest", "set"});
      o.params.mode = m == "earliest" ? lwsccd::CcdMode::earliest : m == "set" ? lwsccd::CcdMode::set : lwsccd::CcdMode::contacts;
    } else if (a == "--precision") {
      o.policies.precision = parse_choice(a, value(), {"double", "float"});
    } else if (a == "--separation") {
      o.params.min_separation = parse_number(a, value());
    } else if (a == "--tolerance") {
      o.params.tolerance = parse_number(a, value());
    } else if (a == "--memory-budget") {
      o.params.device_memory_budget = parse_bytes(a, value());
    } else if (a == "--part-pairs") {
      o.params.part_pairs = static_cast<std::size_t>(parse_integer(a, value(), 1, 1LL << 40));
    } else if (a == "--max-iterations") {
      o.params.max_iterations = static_cast<int>(parse_integer(a, value(), 1, 1 << 30));
    } else if (a == "--no-front-tracking") {
      o.params.front_tracking = false;
    } else if (a == "--check") {
      o.check = true;
    } else if (a == "--json") {
      o.json = true;
    } else if (a == "--render") {
      o.render = value();
      if (o.render.size() < 5 || o.render.compare(o.render.size() - 4, 4, ".png") != 0)
        throw lwsccd::InputError("command line", a, "expects a file name ending in .png, got '" + o.render + "'");
    } else if (a == "--render-size") {
      const std::string size = value();
      if (std::sscanf(size.c_str(), "%dx%d", &o.render_width, &o.render_height) != 2 || o.render_width < 1 ||
          o.render_height < 1 || o.render_width > 16384 || o.render_height > 16384)
        throw lwsccd::InputError("command line", a, "expects WxH in 1..16384, e.g. 1280x720, got '" + size + "'");
    } else if (!a.empty() && a[0] == '-') {
      throw lwsccd::InputError("command line", a, "unknown option (see --help)");
    } else {
      o.inputs.push_back(a);
    }
  }
  if (o.inputs.size() > 2) throw lwsccd::InputError("command line", "", "at most two inputs (see --help)");
  o.params.validate();
  return o;
}

/// Where the steps come from: one topology (and body layout), then steps until there are none.
struct StepSource {
  std::string description;
  std::shared_ptr<const lwsccd::TriangleMesh> mesh;
  lwsccd::BodyLayout layout;
  std::size_t num_steps = 0;
  std::function<lwsccd::Step(std::size_t)> step;  ///< step i, in order
  const lwsccd::GroundTruth* truth = nullptr;     ///< for a scene folder with ground truth
};

struct Inputs {
  std::unique_ptr<lwsccd::ClothBallSimulation> simulation;
  std::unique_ptr<lwsccd::Scene> scene;
  std::unique_ptr<lwsccd::Sequence> sequence;
  std::unique_ptr<lwsccd::Step> two_frames;
};

StepSource open_source(const Options& o, Inputs& in) {
  namespace fs = std::filesystem;
  StepSource src;
  if (o.inputs.empty()) {
    in.simulation = std::make_unique<lwsccd::ClothBallSimulation>(o.triangles);
    in.simulation->advance(o.first_frame);
    src.mesh = in.simulation->mesh();
    src.layout = in.simulation->layout();
    src.num_steps = o.steps ? o.steps : 3;
    src.description = "built-in scene: a folded cloth (" + std::to_string(in.simulation->cloth_triangles()) +
                      " triangles, self-colliding) dropped on a rigid ball (" +
                      std::to_string(src.mesh->num_faces() - in.simulation->cloth_triangles()) + " triangles), frames " +
                      std::to_string(o.first_frame) + " to " + std::to_string(o.first_frame + src.num_steps);
    src.step = [&in](std::size_t) { return in.simulation->next_step(); };
  } else if (o.inputs.size() == 2) {
    in.two_frames = std::make_unique<lwsccd::Step>(lwsccd::load_step(o.inputs[0], o.inputs[1]));
    src.mesh = in.two_frames->mesh;
    src.num_steps = 1;
    src.description = "two frames: " + o.inputs[0] + " -> " + o.inputs[1];
    src.step = [&in](std::size_t) { return *in.two_frames; };
  } else if (fs::is_directory(fs::path(o.inputs[0]) / "frames")) {
    in.scene = std::make_unique<lwsccd::Scene>(lwsccd::load_scene(o.inputs[0]));
    src.mesh = in.scene->step.mesh;
    src.num_steps = 1;
    src.truth = in.scene->has_ground_truth ? &in.scene->truth : nullptr;
    src.description = "scene " + in.scene->name + " (" + in.scene->step.name + ")" +
                      (src.truth ? ", with ground truth" : ", no ground truth");
    src.step = [&in](std::size_t) { return in.scene->step; };
  } else if (fs::is_directory(o.inputs[0])) {
    in.sequence = std::make_unique<lwsccd::Sequence>(lwsccd::load_sequence(o.inputs[0]));
    src.mesh = in.sequence->mesh();
    src.num_steps = o.steps ? std::min(o.steps, in.sequence->num_steps()) : in.sequence->num_steps();
    src.description = "sequence " + o.inputs[0] + ": " + std::to_string(in.sequence->num_frames()) + " frames";
    src.step = [&in](std::size_t i) { return in.sequence->step(i); };
  } else {
    throw lwsccd::InputError(o.inputs[0], "", "is neither a scene folder, a folder of frames, nor one of two frame files");
  }
  return src;
}

struct StepReport {
  std::string name;
  ccd_app::StepOutcome outcome;
  bool has_truth = false;
  lwsccd::TruthScore truth;
  bool checked = false;
  std::size_t check_differences = 0;
};

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

const char* mode_name(lwsccd::CcdMode m) {
  return m == lwsccd::CcdMode::earliest ? "earliest" : m == lwsccd::CcdMode::set ? "set" : "contacts";
}

void print_progress(std::size_t done, std::size_t total) {
  const int width = 40;
  const int filled = static_cast<int>(width * done / std::max<std::size_t>(total, 1));
  std::fprintf(stderr, "\r[%s%s] %zu/%zu steps", std::string(static_cast<std::size_t>(filled), '#').c_str(),
               std::string(static_cast<std::size_t>(width - filled), '.').c_str(), done, total);
  if (done == total) std::fprintf(stderr, "\n");
  std::fflush(stderr);
}

void print_table(const StepSource& src, const std::string& backend, const Options& o, const std::vector<StepReport>& reports) {
  std::printf("lwsccd-ccd: %s\n", src.description.c_str());
  std::printf("  %d vertices, %d triangles; %s | BV %s | %s%s | %s, %s, mode %s | front tracking %s\n", src.mesh->num_vertices(),
              src.mesh->num_faces(), backend.c_str(), o.policies.bv.c_str(),
              backend == "CPU" ? "" : "scheduler ", backend == "CPU" ? "work stealing" : o.policies.scheduler.c_str(),
              o.policies.method.c_str(), o.policies.precision.c_str(), mode_name(o.params.mode),
              o.params.front_tracking ? "on" : "off");
  std::printf("\n%-40s | %8s %7s %8s %8s %8s | %10s %9s %9s %9s %9s | %7s %7s %12s\n", "step", "total ms", "refit",
              "traverse", "features", "narrow", "BVTT nodes", "front", "tri pairs", "VF pairs", "EE pairs", "VF hits",
              "EE hits", "earliest TOI");
  for (const StepReport& r : reports) {
    const lwsccd::StepStats& s = r.outcome.stats;
    std::printf("%-40s | %8.2f %7.3f %8.3f %8.3f %8.2f | %10zu %9zu %9zu %9zu %9zu | %7zu %7zu %12.6g\n", r.name.c_str(),
                s.total_ms, s.refit_ms, s.traverse_ms, s.features_ms, s.narrow_ms, s.bvtt_nodes, s.front_size,
                s.triangle_pairs, s.feature_pairs_vf, s.feature_pairs_ee, s.hits_vf, s.hits_ee,
                r.outcome.contacts.earliest_toi);
    if (o.policies.method == "certified")
      std::printf("  narrow phase: screened %zu + %zu, certified hits %zu + %zu, certified misses %zu + %zu, "
                  "fallbacks %zu + %zu (VF + EE)\n",
                  s.narrow_vf.screened, s.narrow_ee.screened, s.narrow_vf.certified_hits, s.narrow_ee.certified_hits,
                  s.narrow_vf.certified_misses, s.narrow_ee.certified_misses, s.narrow_vf.fallbacks, s.narrow_ee.fallbacks);
    if (s.narrow_survivors)
      std::printf("  narrow phase: %zu pairs past the first pass, %zu of them searched by a warp\n", s.narrow_survivors,
                  s.narrow_warp_searches);
    if (s.gave_up) std::printf("  %zu contacts from the method's work bound (conservative answers)\n", s.gave_up);
    if (s.peak_device_bytes) std::printf("  peak device memory %.1f MiB\n", double(s.peak_device_bytes) / (1 << 20));
    if (s.narrow_parts)
      std::printf("  in parts: %zu traversal parts, %zu narrow-phase parts\n", s.traversal_parts,
                  s.narrow_parts);
    if (r.has_truth)
      std::printf("  ground truth: %zu true contacts; %zu false negatives, %zu false positives\n", r.truth.true_contacts,
                  r.truth.false_negatives, r.truth.false_positives);
    if (r.checked) std::printf("  CPU oracle check: %zu contacts differ\n", r.check_differences);
  }
  if (reports.size() > 2) {
    std::vector<double> totals;
    for (const auto& r : reports) totals.push_back(r.outcome.stats.total_ms);
    std::sort(totals.begin(), totals.end());
    std::printf("\n%zu steps: median %.2f ms per step (first step, with the BVH build: %.2f ms)\n", reports.size(),
                totals[totals.size() / 2], reports.front().outcome.stats.total_ms);
  }
}

void print_json(const StepSource& src, const std::string& backend, const Options& o, const std::vector<StepReport>& reports) {
  std::printf("{\n  \"input\": \"%s\", \"vertices\": %d, \"triangles\": %d,\n", src.description.c_str(),
              src.mesh->num_vertices(), src.mesh->num_faces());
  std::printf("  \"backend\": \"%s\", \"bv\": \"%s\", \"scheduler\": \"%s\", \"method\": \"%s\", \"precision\": \"%s\", "
              "\"mode\": \"%s\", \"front_tracking\": %s,\n  \"steps\": [\n",
              backend.c_str(), o.policies.bv.c_str(), backend == "CPU" ? "work-stealing" : o.policies.scheduler.c_str(),
              o.policies.method.c_str(), o.policies.precision.c_str(), mode_name(o.params.mode),
              o.params.front_tracking ? "true" : "false");
  for (std::size_t i = 0; i < reports.size(); ++i) {
    const StepReport& r = reports[i];
    const lwsccd::StepStats& s = r.outcome.stats;
    std::printf("    {\"name\": \"%s\", \"ms\": {\"total\": %.4f, \"refit\": %.4f, \"traverse\": %.4f, \"features\": %.4f, "
                "\"narrow\": %.4f}, \"rebuilt\": %s, \"restarted_from_root\": %s, \"bvtt_nodes\": %zu, \"front\": %zu, "
                "\"triangle_pairs\": %zu, \"vf_pairs\": %zu, \"ee_pairs\": %zu, \"vf_hits\": %zu, \"ee_hits\": %zu, "
                "\"gave_up\": %zu, \"narrow_survivors\": %zu, \"narrow_warp_searches\": %zu, \"earliest_toi\": %.17g, "
                "\"peak_device_bytes\": %zu, \"traversal_parts\": %zu, \"narrow_parts\": %zu, \"certified\": {\"vf\": [%zu, %zu, %zu, %zu], \"ee\": [%zu, %zu, %zu, %zu]}",
                r.name.c_str(), s.total_ms, s.refit_ms, s.traverse_ms, s.features_ms, s.narrow_ms, s.rebuilt ? "true" : "false",
                s.restarted_from_root ? "true" : "false", s.bvtt_nodes, s.front_size, s.triangle_pairs, s.feature_pairs_vf,
                s.feature_pairs_ee, s.hits_vf, s.hits_ee, s.gave_up, s.narrow_survivors, s.narrow_warp_searches,
                r.outcome.contacts.earliest_toi, s.peak_device_bytes, s.traversal_parts, s.narrow_parts, s.narrow_vf.certified_hits, s.narrow_vf.certified_misses,
                s.narrow_vf.fallbacks, s.narrow_vf.screened, s.narrow_ee.certified_hits, s.narrow_ee.certified_misses,
                s.narrow_ee.fallbacks, s.narrow_ee.screened);
    if (r.has_truth)
      std::printf(", \"truth\": {\"true_contacts\": %zu, \"false_negatives\": %zu, \"false_positives\": %zu}", r.truth.true_contacts,
                  r.truth.false_negatives, r.truth.false_positives);
    if (r.checked) std::printf(", \"check_differences\": %zu", r.check_differences);
    std::printf("}%s\n", i + 1 < reports.size() ? "," : "");
  }
  std::printf("  ]\n}\n");
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Options o = parse(argc, argv);
    Inputs in;
    const StepSource src = open_source(o, in);
    const std::string gpu = ccd_app::gpu_name();
    if (o.device == "gpu" && gpu.empty())
      throw lwsccd::Error("--device gpu: no CUDA device found (or lwsccd-ccd was built without CUDA); use --device cpu");
    const bool on_gpu = o.device == "gpu" || (o.device == "auto" && !gpu.empty());
    const std::string backend = on_gpu ? "GPU " + gpu : "CPU";
    auto pipeline = on_gpu ? ccd_app::make_gpu_pipeline(src.mesh, src.layout, o.params, o.policies)
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
