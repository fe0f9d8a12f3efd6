// lwsccd-ccd — the main program: loads a scene (or builds one) and runs the CCD pipeline on it.
//
// At this stage of the library it runs the CPU backend: swept bounding volumes, candidate
// triangle pairs (sort-and-sweep or brute force), feature pairs with adjacent triangles culled
// through orphan sets, then the narrow phase (by default the conservative inclusion method behind
// the non-penetration filter). With a scene folder that has ground truth, it reports false
// negatives and false positives against it.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "lwsccd/lwsccd.hpp"

namespace {

struct Options {
  std::vector<std::string> inputs;
  std::size_t builtin_triangles = 20000;
  std::string bv = "aabb";
  std::string precision = "double";
  std::string method = "filtered-inclusion";
  double min_separation = 0;
  bool brute = false;
  bool json = false;
};

void print_usage(std::FILE* out) {
  std::fprintf(out,
               "usage: lwsccd-ccd [options] [INPUT...]\n"
               "\n"
               "INPUT (none: the built-in cloth-ball scene)\n"
               "  SCENE_DIR        a folder laid out like shared/data/scenes/<scene>/ (frames/, and\n"
               "                   boxes/ + mma_bool/ ground truth, which is then checked)\n"
               "  T0.ply T1.ply    a two-frame step (PLY or OBJ)\n"
               "  FRAMES_DIR       a folder of OBJ/PLY frames: every consecutive pair is a step\n"
               "\n"
               "options\n"
               "  --triangles N    size of the built-in scene (default 20000)\n"
               "  --bv aabb|obb    bounding volume of the swept triangles (default aabb)\n"
               "  --precision float|double  precision of the bounding volumes and the narrow phase\n"
               "                   (default double)\n"
               "  --method M       narrow phase: filtered-inclusion (default, conservative), inclusion,\n"
               "                   cubic (the seed's method, not conservative), none\n"
               "  --separation D   minimum separation reported as contact (default 0)\n"
               "  --brute          test all triangle pairs (O(n^2)) instead of sort-and-sweep\n"
               "                   (always for --bv obb)\n"
               "  --json           machine-readable output\n"
               "  -h, --help       this text\n");
}

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&](const char* name) -> std::string {
      if (i + 1 >= argc) throw lwsccd::InputError("command line", name, "needs a value");
      return argv[++i];
    };
    if (a == "-h" || a == "--help") {
      print_usage(stdout);
      std::exit(0);
    } else if (a == "--triangles") {
      const std::string v = value("--triangles");
      char* end = nullptr;
      const long long n = std::strtoll(v.c_str(), &end, 10);
      if (*end != '\0' || n < 64 || n > 100000000)
        throw lwsccd::InputError("command line", "--triangles", "expected an integer in [64, 1e8], got '" + v + "'");
      o.builtin_triangles = static_cast<std::size_t>(n);
    } else if (a == "--bv") {
      o.bv = value("--bv");
      if (o.bv != "aabb" && o.bv != "obb") throw lwsccd::InputError("command line", "--bv", "expected aabb or obb, got '" + o.bv + "'");
    } else if (a == "--precision") {
      o.precision = value("--precision");
      if (o.precision != "float" && o.precision != "double")
        throw lwsccd::InputError("command line", "--precision", "expected float or double, got '" + o.precision + "'");
    } else if (a == "--method") {
      o.method = value("--method");
      if (o.method != "filtered-inclusion" && o.method != "inclusion" && o.method != "cubic" && o.method != "none")
        throw lwsccd::InputError("command line", "--method",
                                 "expected filtered-inclusion, inclusion, cubic or none, got '" + o.method + "'");
    } else if (a == "--separation") {
      const std::string v = value("--separation");
      char* end = nullptr;
      o.min_separation = std::strtod(v.c_str(), &end);
      if (*end != '\0' || !(o.min_separation >= 0))
        throw lwsccd::InputError("command line", "--separation", "expected a number >= 0, got '" + v + "'");
    } else if (a == "--brute") {
      o.brute = true;
    } else if (a == "--json") {
      o.json = true;
    } else if (!a.empty() && a[0] == '-') {
      throw lwsccd::InputError("command line", a, "unknown option (see --help)");
    } else {
      o.inputs.push_back(a);
    }
  }
  if (o.inputs.size() > 2) throw lwsccd::InputError("command line", "", "at most two inputs (see --help)");
  return o;
}

struct StepReport {
  std::string name;
  lwsccd::index_t vertices = 0, edges = 0, faces = 0;
  std::size_t degenerate_faces = 0, triangle_pairs = 0, adjacent_pairs = 0, vf_pairs = 0, ee_pairs = 0;
  std::size_t tested_vf = 0, tested_ee = 0, hits_vf = 0, hits_ee = 0, gave_up = 0;
  double earliest_toi = 1;
  double ms_bvs = 0, ms_pairs = 0, ms_features = 0, ms_narrow = 0;
  bool has_truth = false;
  std::size_t true_vf = 0, true_ee = 0, missed_vf = 0, missed_ee = 0;  // by the broad phase
  std::size_t false_negatives = 0, false_positives = 0;                 // of the narrow phase
};

double ms_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

template <class BV>
void candidate_pairs(const lwsccd::Step& step, const lwsccd::BodyLayout& layout, bool brute, StepReport& r,
                     std::vector<lwsccd::TrianglePair>& pairs) {
  auto t = std::chrono::steady_clock::now();
  const auto bvs = lwsccd::swept_triangle_bvs<BV>(*step.mesh, step.x0, step.x1);
  r.ms_bvs = ms_since(t);
  t = std::chrono::steady_clock::now();
  if constexpr (std::is_same<BV, lwsccd::Aabb<typename BV::scalar_type>>::value) {
    pairs = brute ? lwsccd::brute_force_pairs(*step.mesh, bvs, layout) : lwsccd::sweep_and_prune_pairs(*step.mesh, bvs, layout);
  } else {
    pairs = lwsccd::brute_force_pairs(*step.mesh, bvs, layout);
  }
  r.ms_pairs = ms_since(t);
}

template <class Method, class T>
void run_method(const lwsccd::Step& step, const lwsccd::FeaturePairs& tested, const lwsccd::CcdParams<T>& params,
                StepReport& r, std::vector<std::pair<lwsccd::index_t, lwsccd::index_t>>& hit_vf,
                std::vector<std::pair<lwsccd::index_t, lwsccd::index_t>>& hit_ee) {
  const auto result = lwsccd::cpu::test_feature_pairs<Method, T>(*step.mesh, step.x0, step.x1, tested, params);
  r.hits_vf = result.vf.size();
  r.hits_ee = result.ee.size();
  r.gave_up = result.gave_up;
  r.earliest_toi = static_cast<double>(result.earliest_toi);
  for (const auto& h : result.vf) hit_vf.emplace_back(h.first, h.second);
  for (const auto& h : result.ee) hit_ee.emplace_back(h.first, h.second);
}

template <class T>
void narrow_phase(const lwsccd::Step& step, const lwsccd::FeaturePairs& tested, const Options& o, StepReport& r,
                  std::vector<std::pair<lwsccd::index_t, lwsccd::index_t>>& hit_vf,
                  std::vector<std::pair<lwsccd::index_t, lwsccd::index_t>>& hit_ee) {
  lwsccd::CcdParams<T> params;
  params.min_separation = static_cast<T>(o.min_separation);
  if (o.method == "filtered-inclusion") run_method<lwsccd::Filtered<lwsccd::InclusionCcd>, T>(step, tested, params, r, hit_vf, hit_ee);
  if (o.method == "inclusion") run_method<lwsccd::InclusionCcd, T>(step, tested, params, r, hit_vf, hit_ee);
  if (o.method == "cubic") run_method<lwsccd::CubicCcd, T>(step, tested, params, r, hit_vf, hit_ee);
}

StepReport run_step(const lwsccd::Step& step, const lwsccd::BodyLayout& layout, const Options& o,
                    const lwsccd::GroundTruth* truth) {
  StepReport r;
  const lwsccd::TriangleMesh& mesh = *step.mesh;
  r.name = step.name;
  r.vertices = mesh.num_vertices();
  r.edges = mesh.num_edges();
  r.faces = mesh.num_faces();
  r.degenerate_faces = lwsccd::find_degenerate_faces(mesh, step.x0).size();
  std::vector<lwsccd::TrianglePair> pairs;
  if (o.bv == "aabb" && o.precision == "double") candidate_pairs<lwsccd::Aabbd>(step, layout, o.brute, r, pairs);
  if (o.bv == "aabb" && o.precision == "float") candidate_pairs<lwsccd::Aabbf>(step, layout, o.brute, r, pairs);
  if (o.bv == "obb" && o.precision == "double") candidate_pairs<lwsccd::Obbd>(step, layout, o.brute, r, pairs);
  if (o.bv == "obb" && o.precision == "float") candidate_pairs<lwsccd::Obbf>(step, layout, o.brute, r, pairs);
  r.triangle_pairs = pairs.size();
  for (const auto& p : pairs) r.adjacent_pairs += p.adjacent;
  auto t = std::chrono::steady_clock::now();
  const lwsccd::FeaturePairs fp = lwsccd::feature_pairs(mesh, pairs);
  // What the narrow phase tests: adjacent triangle pairs culled, their orphan pairs kept.
  const lwsccd::FeaturePairs tested = lwsccd::culled_feature_pairs(mesh, pairs, lwsccd::find_orphan_sets(mesh));
  r.ms_features = ms_since(t);
  r.vf_pairs = fp.vf.size();
  r.ee_pairs = fp.ee.size();
  r.tested_vf = tested.vf.size();
  r.tested_ee = tested.ee.size();
  std::vector<std::pair<lwsccd::index_t, lwsccd::index_t>> hit_vf, hit_ee;
  if (o.method != "none") {
    t = std::chrono::steady_clock::now();
    if (o.precision == "double") narrow_phase<double>(step, tested, o, r, hit_vf, hit_ee);
    else narrow_phase<float>(step, tested, o, r, hit_vf, hit_ee);
    r.ms_narrow = ms_since(t);
  }
  if (truth) {
    r.has_truth = true;
    for (std::size_t i = 0; i < truth->vf.size(); ++i)
      if (truth->vf_collides[i]) {
        ++r.true_vf;
        r.missed_vf += !std::binary_search(fp.vf.begin(), fp.vf.end(), truth->vf[i]);
      }
    for (std::size_t i = 0; i < truth->ee.size(); ++i)
      if (truth->ee_collides[i]) {
        ++r.true_ee;
        r.missed_ee += !std::binary_search(fp.ee.begin(), fp.ee.end(), truth->ee[i]);
      }
    if (o.method != "none") {
      auto score = [&](const auto& truth_pairs, const std::vector<bool>& collides, const auto& hits) {
        for (std::size_t i = 0; i < truth_pairs.size(); ++i) {
          const bool hit = std::binary_search(hits.begin(), hits.end(), truth_pairs[i]);
          r.false_negatives += collides[i] && !hit;
          r.false_positives += !collides[i] && hit;
        }
      };
      score(truth->vf, truth->vf_collides, hit_vf);
      score(truth->ee, truth->ee_collides, hit_ee);
    }
  }
  return r;
}

void print_text(const StepReport& r, bool first) {
  if (first) {
    std::printf("%-26s %8s %8s %5s | %10s %10s %10s | %9s %9s %8s %8s %12s | %7s %7s %7s %8s\n", "step", "vertices",
                "faces", "degen", "tri pairs", "adjacent", "feat pairs", "tested vf", "tested ee", "hits vf", "hits ee",
                "earliest TOI", "bv ms", "pair ms", "feat ms", "ccd ms");
  }
  std::printf("%-26s %8d %8d %5zu | %10zu %10zu %10zu | %9zu %9zu %8zu %8zu %12.6g | %7.1f %7.1f %7.1f %8.1f\n",
              r.name.c_str(), r.vertices, r.faces, r.degenerate_faces, r.triangle_pairs, r.adjacent_pairs,
              r.vf_pairs + r.ee_pairs, r.tested_vf, r.tested_ee, r.hits_vf, r.hits_ee, r.earliest_toi, r.ms_bvs,
              r.ms_pairs, r.ms_features, r.ms_narrow);
  if (r.gave_up) std::printf("  %zu hits came from the method's bounded-work fallback (conservative)\n", r.gave_up);
  if (r.has_truth)
    std::printf("  ground truth: %zu vf + %zu ee true pairs; missed by the broad phase: %zu vf, %zu ee; "
                "narrow phase: %zu false negatives, %zu false positives\n",
                r.true_vf, r.true_ee, r.missed_vf, r.missed_ee, r.false_negatives, r.false_positives);
}

void print_json(const std::vector<StepReport>& reports, const Options& o) {
  std::printf("{\n  \"bv\": \"%s\", \"precision\": \"%s\", \"method\": \"%s\", \"backend\": \"cpu\",\n  \"steps\": [\n",
              o.bv.c_str(), o.precision.c_str(), o.method.c_str());
  for (std::size_t i = 0; i < reports.size(); ++i) {
    const StepReport& r = reports[i];
    std::printf("    {\"name\": \"%s\", \"vertices\": %d, \"edges\": %d, \"faces\": %d, \"degenerate_faces\": %zu, "
                "\"triangle_pairs\": %zu, \"adjacent_pairs\": %zu, \"vf_pairs\": %zu, \"ee_pairs\": %zu, "
                "\"tested_vf\": %zu, \"tested_ee\": %zu, \"hits_vf\": %zu, \"hits_ee\": %zu, \"gave_up\": %zu, "
                "\"earliest_toi\": %.17g, \"ms\": {\"bvs\": %.3f, \"pairs\": %.3f, \"features\": %.3f, \"narrow\": %.3f}",
                r.name.c_str(), r.vertices, r.edges, r.faces, r.degenerate_faces, r.triangle_pairs, r.adjacent_pairs,
                r.vf_pairs, r.ee_pairs, r.tested_vf, r.tested_ee, r.hits_vf, r.hits_ee, r.gave_up, r.earliest_toi,
                r.ms_bvs, r.ms_pairs, r.ms_features, r.ms_narrow);
    if (r.has_truth)
      std::printf(", \"truth\": {\"true_vf\": %zu, \"true_ee\": %zu, \"missed_vf\": %zu, \"missed_ee\": %zu, "
                  "\"false_negatives\": %zu, \"false_positives\": %zu}",
                  r.true_vf, r.true_ee, r.missed_vf, r.missed_ee, r.false_negatives, r.false_positives);
    std::printf("}%s\n", i + 1 < reports.size() ? "," : "");
  }
  std::printf("  ]\n}\n");
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Options o = parse(argc, argv);
    std::vector<StepReport> reports;
    namespace fs = std::filesystem;
    if (o.inputs.empty()) {
      const lwsccd::MultiBodyStep scene = lwsccd::make_cloth_ball_scene(o.builtin_triangles);
      if (!o.json) std::printf("built-in scene: cloth (self-colliding) over a rigid ball, CPU backend\n");
      reports.push_back(run_step(scene.step, scene.layout, o, nullptr));
    } else if (o.inputs.size() == 2) {
      reports.push_back(run_step(lwsccd::load_step(o.inputs[0], o.inputs[1]), {}, o, nullptr));
    } else if (fs::is_directory(fs::path(o.inputs[0]) / "frames")) {
      const lwsccd::Scene scene = lwsccd::load_scene(o.inputs[0]);
      reports.push_back(run_step(scene.step, {}, o, scene.has_ground_truth ? &scene.truth : nullptr));
    } else if (fs::is_directory(o.inputs[0])) {
      const lwsccd::Sequence seq = lwsccd::load_sequence(o.inputs[0]);
      for (std::size_t s = 0; s < seq.num_steps(); ++s) {
        reports.push_back(run_step(seq.step(s), {}, o, nullptr));
        if (!o.json) std::fprintf(stderr, "\rstep %zu/%zu", s + 1, seq.num_steps());
      }
      if (!o.json) std::fprintf(stderr, "\n");
    } else {
      throw lwsccd::InputError(o.inputs[0], "", "is neither a scene folder, a folder of frames, nor one of two frame files");
    }
    if (o.json) {
      print_json(reports, o);
    } else {
      for (std::size_t i = 0; i < reports.size(); ++i) print_text(reports[i], i == 0);
    }
    for (const auto& r : reports)
      if (r.missed_vf + r.missed_ee > 0 || (o.method != "cubic" && r.false_negatives > 0)) return 2;  // a missed contact
    return 0;
  } catch (const lwsccd::Error& e) {
    std::fprintf(stderr, "lwsccd-ccd: error: %s\n", e.what());
    return 1;
  }
}
