// lwsccd-accuracy — accuracy and time per query of the narrow-phase methods against exact ground
// truth: the query sets (../shared/data/queries/<set>/{vertex-face,edge-edge}/*.csv), single query
// CSV files, and the scenes (../shared/data/scenes/<scene>/: candidate pairs from boxes/, truth
// from mma_bool/). Plain C++ (CPU), one core. See docs/NARROW_PHASE.md.
//
// Exit status: 0 on success, 1 on bad arguments or input, 2 when a method that declares itself
// conservative produced a false negative.
#include <algorithm>
#include <array>
#include <chrono>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "lwsccd/core/error.hpp"
#include "lwsccd/io/dataset.hpp"
#include "lwsccd/io/query_io.hpp"
#include "lwsccd/narrow_phase/ccd_filters.hpp"
#include "lwsccd/narrow_phase/ccd_query.hpp"
#include "lwsccd/narrow_phase/certified_ccd.hpp"
#include "lwsccd/narrow_phase/cubic_ccd.hpp"
#include "lwsccd/narrow_phase/inclusion_ccd.hpp"

#ifndef LWSCCD_BENCH_DATA_DIR
#define LWSCCD_BENCH_DATA_DIR "../shared/data"
#endif

namespace {

namespace fs = std::filesystem;
using lwsccd::CcdParams;
using lwsccd::CcdResult;
using lwsccd::EdgeEdgeQuery;
using lwsccd::InputError;
using lwsccd::Vec3d;
using lwsccd::VertexFaceQuery;
using Points = std::array<Vec3d, 8>;

/// The non-penetration filter alone as a method: "hit" means "may collide". Its toi (0) is only a
/// trivial lower bound. It is declared conservative because ccd_filters.hpp states that it culls
/// a pair only when it proves that the pair cannot touch.
struct FilterOnly {
  static constexpr const char* name = "filter-only";
  static constexpr bool conservative = true;
  template <class T>
  static CcdResult<T> vertex_face(const VertexFaceQuery<T>& q, const CcdParams<T>& p) {
    return lwsccd::non_penetration_filter(q, p) ? CcdResult<T>{true, T(0), false} : CcdResult<T>{};
  }
  template <class T>
  static CcdResult<T> edge_edge(const EdgeEdgeQuery<T>& q, const CcdParams<T>& p) {
    return lwsccd::non_penetration_filter(q, p) ? CcdResult<T>{true, T(0), false} : CcdResult<T>{};
  }
};
static_assert(lwsccd::require_ccd_method<FilterOnly>::value, "");
static_assert(lwsccd::require_ccd_method<lwsccd::CubicCcd>::value, "");
static_assert(lwsccd::require_ccd_method<lwsccd::InclusionCcd>::value, "");
static_assert(lwsccd::require_ccd_method<lwsccd::Filtered<lwsccd::InclusionCcd>>::value, "");

// ---------------------------------------------------------------------------------------------
// Command line

struct Options {
  std::vector<std::string> inputs;
  std::vector<std::string> methods;
  std::vector<std::string> precisions;
  double min_separation = 0.0;
  double tolerance = 1e-6;
  int max_iterations = CcdParams<double>{}.max_iterations;
  std::string json;
  std::string kind;  // "", "vf" or "ee"
  std::size_t limit = 0;  // 0: all
};

const char* const kAllMethods[] = {"certified", "cubic", "inclusion", "filtered-inclusion", "filter-only"};

void print_usage(std::FILE* out) {
  std::fprintf(out,
               "usage: lwsccd-accuracy [options] [INPUT...]\n"
               "\n"
               "Runs narrow-phase CCD methods on queries with exact ground truth and reports false\n"
               "negatives / positives and the time per query (one CPU core).\n"
               "\n"
               "INPUT (any number; none: the data root from $LWSCCD_DATA_DIR, else %s)\n"
               "  SET_DIR     a query set laid out like shared/data/queries/<set>/: vertex-face/*.csv and\n"
               "              edge-edge/*.csv (8 rows per query: 3 rationals num,den + truth 0/1)\n"
               "  FILE.csv    one query file; its kind comes from the parent folder name (vertex-face,\n"
               "              edge-edge) or --kind\n"
               "  SCENE_DIR   a scene like shared/data/scenes/<scene>/: frames/ (two meshes), boxes/ (candidate\n"
               "              pairs) and mma_bool/ (truth); queries are gathered from the frames\n"
               "  DATA_DIR    a data root with queries/<set>/ and scenes/<scene>/: every set and scene\n"
               "\n"
               "options\n"
               "  --methods LIST        comma-separated from certified, cubic, inclusion, filtered-inclusion,\n"
               "                        filter-only\n"
               "                        (default all; filter-only = the non-penetration filter alone, hit = may collide)\n"
               "  --precision LIST      float, double or both (default float,double); float queries are the\n"
               "                        double queries rounded to float\n"
               "  --min-separation D    minimum separation (default 0)\n"
               "  --tolerance T         time tolerance (default 1e-6)\n"
               "  --max-iterations N    inclusion: boxes examined before answering hit (default %d)\n"
               "  --kind vf|ee          kind of the CSV file inputs\n"
               "  --limit N             at most N queries per input (quick runs)\n"
               "  --json FILE           also write the results as a JSON array of objects\n"
               "  -h, --help            this text\n"
               "\n"
               "exit status: 0 success, 1 bad arguments or input, 2 a conservative method missed a contact\n",
               LWSCCD_BENCH_DATA_DIR, CcdParams<double>{}.max_iterations);
}

std::vector<std::string> split_list(const std::string& s, const std::string& option) {
  std::vector<std::string> out;
  std::stringstream in(s);
  std::string item;
  while (std::getline(in, item, ','))
    if (!item.empty() && std::find(out.begin(), out.end(), item) == out.end()) out.push_back(item);
  if (out.empty()) throw InputError("command line", option, "empty list");
  return out;
}

double parse_double(const std::string& v, const std::string& option) {
  char* end = nullptr;
  const double x = std::strtod(v.c_str(), &end);
  if (v.empty() || *end != '\0' || !std::isfinite(x))
    throw InputError("command line", option, "expected a finite number, got '" + v + "'");
  return x;
}

long long parse_integer(const std::string& v, const std::string& option, long long lo, long long hi) {
  char* end = nullptr;
  errno = 0;
  const long long x = std::strtoll(v.c_str(), &end, 10);
  if (v.empty() || *end != '\0' || errno != 0 || x < lo || x > hi)
    throw InputError("command line", option,
                     "expected an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got '" + v + "'");
  return x;
}

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    std::string inline_value;
    bool has_inline = false;
    if (a.rfind("--", 0) == 0 && a.find('=') != std::string::npos) {
      inline_value = a.substr(a.find('=') + 1);
      a = a.substr(0, a.find('='));
      has_inline = true;
    }
    auto value = [&]() -> std::string {
      if (has_inline) return inline_value;
      if (i + 1 >= argc) throw InputError("command line", a, "needs a value");
      return argv[++i];
    };
    if (a == "-h" || a == "--help") {
      print_usage(stdout);
      std::exit(0);
    } else if (a == "--methods") {
      o.methods = split_list(value(), a);
      for (const auto& m : o.methods)
        if (std::find(std::begin(kAllMethods), std::end(kAllMethods), m) == std::end(kAllMethods))
          throw InputError("command line", a,
                           "unknown method '" + m + "' (expected certified, cubic, inclusion, filtered-inclusion, filter-only)");
    } else if (a == "--precision") {
      o.precisions = split_list(value(), a);
      for (const auto& p : o.precisions)
        if (p != "float" && p != "double")
          throw InputError("command line", a, "unknown precision '" + p + "' (expected float, double)");
    } else if (a == "--min-separation") {
      o.min_separation = parse_double(value(), a);
      if (o.min_separation < 0) throw InputError("command line", a, "must be >= 0");
    } else if (a == "--tolerance") {
      o.tolerance = parse_double(value(), a);
      if (!(o.tolerance > 0 && o.tolerance < 1)) throw InputError("command line", a, "must be in (0, 1)");
    } else if (a == "--max-iterations") {
      o.max_iterations = static_cast<int>(parse_integer(value(), a, 1, std::numeric_limits<int>::max()));
    } else if (a == "--kind") {
      o.kind = value();
      if (o.kind != "vf" && o.kind != "ee") throw InputError("command line", a, "expected vf or ee, got '" + o.kind + "'");
    } else if (a == "--limit") {
      o.limit = static_cast<std::size_t>(parse_integer(value(), a, 1, std::numeric_limits<long long>::max()));
    } else if (a == "--json") {
      o.json = value();
      if (o.json.empty()) throw InputError("command line", a, "needs a file name");
    } else if (a.size() > 1 && a[0] == '-') {
      throw InputError("command line", a, "unknown option (see --help)");
    } else {
      o.inputs.push_back(a);
    }
  }
  if (o.methods.empty()) o.methods.assign(std::begin(kAllMethods), std::end(kAllMethods));
  if (o.precisions.empty()) o.precisions = {"float", "double"};
  return o;
}

// ---------------------------------------------------------------------------------------------
// Inputs

enum class Kind { QuerySet, Csv, Scene };
const char* kind_name(Kind k) { return k == Kind::QuerySet ? "query-set" : k == Kind::Csv ? "csv" : "scene"; }
const char* group_name(Kind k) {
  return k == Kind::QuerySet ? "all query sets" : k == Kind::Csv ? "all CSV files" : "all scenes";
}

struct Input {
  std::string name, path;
  Kind kind = Kind::QuerySet;
  std::vector<Points> vf, ee;
  std::vector<signed char> vf_truth, ee_truth;  // 1, 0, or -1 (unknown)
  std::size_t double_inexact = 0;  // CSV coordinates not exactly representable in double
  std::size_t float_changed = 0;   // queries with a coordinate that rounding to float changes
};

struct InputSpec {
  Kind kind;
  std::string path;
  std::string csv_kind;  // for Kind::Csv: "vf" or "ee"
};

std::vector<fs::path> sorted_entries(const fs::path& dir, bool want_dirs, const std::string& ext) {
  std::vector<fs::path> out;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (want_dirs ? e.is_directory() : (e.is_regular_file() && e.path().extension() == ext)) out.push_back(e.path());
  }
  std::sort(out.begin(), out.end());
  return out;
}

bool is_query_set(const fs::path& p) {
  return fs::is_directory(p / "vertex-face") || fs::is_directory(p / "edge-edge");
}

std::vector<InputSpec> expand_input(const std::string& arg, const Options& o) {
  const fs::path p(arg);
  if (!fs::exists(p)) throw InputError(arg, "", "no such file or folder");
  if (fs::is_regular_file(p)) {
    if (p.extension() != ".csv") throw InputError(arg, "", "not a .csv query file, query set, scene or data folder");
    std::string k = o.kind;
    if (k.empty()) {
      const std::string parent = fs::absolute(p).parent_path().filename().string();
      if (parent == "vertex-face") k = "vf";
      else if (parent == "edge-edge") k = "ee";
      else
        throw InputError(arg, "", "cannot tell vertex-face from edge-edge (parent folder is '" + parent +
                                      "', not vertex-face or edge-edge): pass --kind vf or --kind ee");
    }
    return {{Kind::Csv, arg, k}};
  }
  if (!fs::is_directory(p)) throw InputError(arg, "", "neither a file nor a folder");
  if (is_query_set(p)) return {{Kind::QuerySet, arg, ""}};
  if (fs::is_directory(p / "frames")) return {{Kind::Scene, arg, ""}};
  if (fs::is_directory(p / "queries") || fs::is_directory(p / "scenes")) {
    std::vector<InputSpec> out;
    if (fs::is_directory(p / "queries"))
      for (const auto& s : sorted_entries(p / "queries", true, ""))
        if (is_query_set(s)) out.push_back({Kind::QuerySet, s.string(), ""});
    if (fs::is_directory(p / "scenes"))
      for (const auto& s : sorted_entries(p / "scenes", true, ""))
        if (fs::is_directory(s / "frames")) out.push_back({Kind::Scene, s.string(), ""});
    if (out.empty()) throw InputError(arg, "", "data folder without query sets (queries/<set>/) or scenes (scenes/<scene>/)");
    return out;
  }
  throw InputError(arg, "",
                   "not a query set (vertex-face/, edge-edge/), a scene (frames/) or a data root (queries/, scenes/)");
}

std::string folder_name(const std::string& path) {
  fs::path p = fs::path(path).lexically_normal();
  if (p.filename().empty()) p = p.parent_path();
  if (p.filename() == "." || p.filename().empty()) p = fs::absolute(p).lexically_normal();
  if (p.filename().empty()) p = p.parent_path();
  return p.filename().string();
}

void append_csv(const std::string& path, std::vector<Points>& qs, std::vector<signed char>& truth, Input& in) {
  lwsccd::QueryFile f = lwsccd::load_query_csv(path);
  qs.insert(qs.end(), f.queries.begin(), f.queries.end());
  truth.insert(truth.end(), f.truth.begin(), f.truth.end());
  in.double_inexact += f.inexact;
}

// Keeps at most `limit` queries, split between vf and ee in proportion to their counts.
void apply_limit(std::size_t limit, std::size_t nvf, std::size_t nee, std::size_t& keep_vf, std::size_t& keep_ee) {
  keep_vf = nvf;
  keep_ee = nee;
  if (limit == 0 || nvf + nee <= limit) return;
  keep_vf = static_cast<std::size_t>(std::llround(static_cast<double>(limit) * static_cast<double>(nvf) /
                                                  static_cast<double>(nvf + nee)));
  keep_vf = std::min(keep_vf, nvf);
  keep_ee = std::min(limit - keep_vf, nee);
}

Input load_input(const InputSpec& spec, const Options& o) {
  Input in;
  in.kind = spec.kind;
  in.path = spec.path;
  if (spec.kind == Kind::Csv) {
    const fs::path parent = fs::absolute(spec.path).lexically_normal().parent_path();
    in.name = parent.parent_path().filename().string() + "/" + parent.filename().string() + "/" +
              fs::path(spec.path).filename().string();
    if (spec.csv_kind == "vf") append_csv(spec.path, in.vf, in.vf_truth, in);
    else append_csv(spec.path, in.ee, in.ee_truth, in);
  } else if (spec.kind == Kind::QuerySet) {
    in.name = folder_name(spec.path);
    const fs::path root(spec.path);
    if (fs::is_directory(root / "vertex-face"))
      for (const auto& f : sorted_entries(root / "vertex-face", false, ".csv")) append_csv(f.string(), in.vf, in.vf_truth, in);
    if (fs::is_directory(root / "edge-edge"))
      for (const auto& f : sorted_entries(root / "edge-edge", false, ".csv")) append_csv(f.string(), in.ee, in.ee_truth, in);
  } else {
    const lwsccd::Scene scene = lwsccd::load_scene(spec.path);
    in.name = scene.name.empty() ? folder_name(spec.path) : scene.name;
    if (scene.truth.vf.empty() && scene.truth.ee.empty())
      throw InputError(spec.path, "boxes/", "no candidate pairs (the scene needs boxes/<step>{vf,ee}.json)");
    const lwsccd::MeshFeatures mf = lwsccd::mesh_features(*scene.step.mesh);
    const Vec3d* x0 = scene.step.x0.data();
    const Vec3d* x1 = scene.step.x1.data();
    std::size_t keep_vf, keep_ee;
    apply_limit(o.limit, scene.truth.vf.size(), scene.truth.ee.size(), keep_vf, keep_ee);
    auto to_points = [](const Vec3d* pts) {
      Points out;
      for (int k = 0; k < 8; ++k) out[static_cast<std::size_t>(k)] = pts[k];
      return out;
    };
    for (std::size_t i = 0; i < keep_vf; ++i) {
      const auto q = lwsccd::gather_vertex_face<double>(mf, x0, x1, scene.truth.vf[i].first, scene.truth.vf[i].second);
      in.vf.push_back(to_points(q.points()));
      in.vf_truth.push_back(scene.has_ground_truth ? static_cast<signed char>(scene.truth.vf_collides[i]) : -1);
    }
    for (std::size_t i = 0; i < keep_ee; ++i) {
      const auto q = lwsccd::gather_edge_edge<double>(mf, x0, x1, scene.truth.ee[i].first, scene.truth.ee[i].second);
      in.ee.push_back(to_points(q.points()));
      in.ee_truth.push_back(scene.has_ground_truth ? static_cast<signed char>(scene.truth.ee_collides[i]) : -1);
    }
  }
  if (spec.kind != Kind::Scene && o.limit) {
    std::size_t keep_vf, keep_ee;
    apply_limit(o.limit, in.vf.size(), in.ee.size(), keep_vf, keep_ee);
    in.vf.resize(keep_vf);
    in.vf_truth.resize(keep_vf);
    in.ee.resize(keep_ee);
    in.ee_truth.resize(keep_ee);
  }
  if (in.vf.empty() && in.ee.empty()) throw InputError(spec.path, "", "no queries");
  // Compare the float query with the double one as the library builds them (vertex_face_query<T>,
  // edge_edge_query<T>), so that whatever the library does before rounding is taken into account.
  auto differs = [](const Vec3d* d, const lwsccd::Vec3f* f) {
    for (int k = 0; k < 8; ++k)
      if (static_cast<double>(f[k].x) != d[k].x || static_cast<double>(f[k].y) != d[k].y ||
          static_cast<double>(f[k].z) != d[k].z)
        return true;
    return false;
  };
  for (const auto& p : in.vf)
    in.float_changed +=
        differs(lwsccd::vertex_face_query<double>(p).points(), lwsccd::vertex_face_query<float>(p).points());
  for (const auto& p : in.ee)
    in.float_changed += differs(lwsccd::edge_edge_query<double>(p).points(), lwsccd::edge_edge_query<float>(p).points());
  return in;
}

// ---------------------------------------------------------------------------------------------
// Measurement

template <class T>
struct Typed {
  std::vector<VertexFaceQuery<T>> vf;
  std::vector<EdgeEdgeQuery<T>> ee;
};

template <class T>
Typed<T> typed_queries(const Input& in) {
  Typed<T> out;
  out.vf.reserve(in.vf.size());
  out.ee.reserve(in.ee.size());
  for (const auto& p : in.vf) out.vf.push_back(lwsccd::vertex_face_query<T>(p));
  for (const auto& p : in.ee) out.ee.push_back(lwsccd::edge_edge_query<T>(p));
  return out;
}

struct Measure {
  std::vector<double> us;  // time per query, microseconds
  std::size_t queries = 0, vf_queries = 0, ee_queries = 0, truth_true = 0, truth_false = 0, unknown = 0;
  std::size_t hits = 0, fn = 0, fp = 0, gave_up = 0;
  double earliest_toi = std::numeric_limits<double>::infinity();
};

// Keeps the compiler from moving the query's work across the clock reads.
template <class V>
inline void keep(V& v) {
#if defined(__GNUC__) || defined(__clang__)
  asm volatile("" : : "g"(&v) : "memory");
#else
  (void)v;
#endif
}

template <class M, class T>
CcdResult<T> call(const VertexFaceQuery<T>& q, const CcdParams<T>& p) {
  return M::vertex_face(q, p);
}
template <class M, class T>
CcdResult<T> call(const EdgeEdgeQuery<T>& q, const CcdParams<T>& p) {
  return M::edge_edge(q, p);
}

template <class M, class T, class Q>
void run_queries(const std::vector<Q>& qs, const std::vector<signed char>& truth, const CcdParams<T>& p, Measure& m) {
  using clock = std::chrono::steady_clock;
  for (std::size_t i = 0; i < qs.size(); ++i) {
    const auto t0 = clock::now();
    CcdResult<T> r = call<M>(qs[i], p);
    keep(r);
    const auto t1 = clock::now();
    m.us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
    m.hits += r.hit;
    m.gave_up += r.gave_up;
    if (r.hit) m.earliest_toi = std::min(m.earliest_toi, static_cast<double>(r.toi));
    if (truth[i] < 0) ++m.unknown;
    else if (truth[i] == 1) {
      ++m.truth_true;
      m.fn += !r.hit;
    } else {
      ++m.truth_false;
      m.fp += r.hit;
    }
  }
}

template <class M, class T>
Measure measure(const Typed<T>& tq, const Input& in, const CcdParams<T>& p) {
  Measure m;
  m.vf_queries = tq.vf.size();
  m.ee_queries = tq.ee.size();
  m.queries = m.vf_queries + m.ee_queries;
  m.us.reserve(m.queries);
  // Warm the method (code and data caches) once, untimed.
  if (!tq.vf.empty()) {
    CcdResult<T> r = call<M>(tq.vf[0], p);
    keep(r);
  } else {
    CcdResult<T> r = call<M>(tq.ee[0], p);
    keep(r);
  }
  run_queries<M>(tq.vf, in.vf_truth, p, m);
  run_queries<M>(tq.ee, in.ee_truth, p, m);
  return m;
}

struct MethodEntry {
  const char* name;
  bool conservative;
  bool reports_toi;
  Measure (*run_float)(const Typed<float>&, const Input&, const CcdParams<float>&);
  Measure (*run_double)(const Typed<double>&, const Input&, const CcdParams<double>&);
};

template <class M>
MethodEntry entry(const char* name, bool reports_toi) {
  return {name, M::conservative, reports_toi, &measure<M, float>, &measure<M, double>};
}

const MethodEntry& method_entry(const std::string& name) {
  static const MethodEntry entries[] = {
      entry<lwsccd::CertifiedCcd>("certified", true),
      entry<lwsccd::CubicCcd>("cubic", true),
      entry<lwsccd::InclusionCcd>("inclusion", true),
      entry<lwsccd::Filtered<lwsccd::InclusionCcd>>("filtered-inclusion", true),
      entry<FilterOnly>("filter-only", false),
  };
  for (const auto& e : entries)
    if (name == e.name) return e;
  throw InputError("command line", "--methods", "unknown method '" + name + "'");
}

// ---------------------------------------------------------------------------------------------
// Results

struct Row {
  std::string input, path, kind;  // kind: query-set, csv, scene, or "group" / "everything" for totals
  std::string method, precision;
  bool conservative = false, reports_toi = false, scene = false;
  Measure m;
  std::size_t double_inexact = 0, float_changed = 0;
  double seconds = 0;  // sum of the per-query times
};

struct Stats {
  double median = 0, p99 = 0, max = 0, mean = 0;
};
Stats stats_of(const std::vector<double>& us) {
  Stats s;
  if (us.empty()) return s;
  s.median = lwsccd_bench::median(us);
  s.p99 = lwsccd_bench::percentile(us, 0.99);
  s.max = *std::max_element(us.begin(), us.end());
  double sum = 0;
  for (double x : us) sum += x;
  s.mean = sum / static_cast<double>(us.size());
  return s;
}

Row total_row(const std::vector<const Row*>& parts, const std::string& label, const std::string& kind) {
  Row t;
  t.input = label;
  t.kind = kind;
  t.method = parts.front()->method;
  t.precision = parts.front()->precision;
  t.conservative = parts.front()->conservative;
  t.reports_toi = parts.front()->reports_toi;
  t.scene = std::all_of(parts.begin(), parts.end(), [](const Row* r) { return r->scene; });
  for (const Row* r : parts) {
    const Measure& m = r->m;
    t.m.us.insert(t.m.us.end(), m.us.begin(), m.us.end());
    t.m.queries += m.queries;
    t.m.vf_queries += m.vf_queries;
    t.m.ee_queries += m.ee_queries;
    t.m.truth_true += m.truth_true;
    t.m.truth_false += m.truth_false;
    t.m.unknown += m.unknown;
    t.m.hits += m.hits;
    t.m.fn += m.fn;
    t.m.fp += m.fp;
    t.m.gave_up += m.gave_up;
    t.double_inexact += r->double_inexact;
    t.float_changed += r->float_changed;
    t.seconds += r->seconds;
  }
  return t;
}

std::string fmt_us(double us) {
  char b[32];
  if (us < 10) std::snprintf(b, sizeof b, "%.3f", us);
  else if (us < 1000) std::snprintf(b, sizeof b, "%.1f", us);
  else std::snprintf(b, sizeof b, "%.0f", us);
  return b;
}

std::string toi_text(const Row& r) {
  if (!r.scene || !r.reports_toi || r.kind == "group") return "";
  if (!(r.m.earliest_toi <= 1.0)) return "none";
  char b[40];
  std::snprintf(b, sizeof b, "%.10g", r.m.earliest_toi);
  return b;
}

void print_table(const std::vector<Row>& rows) {
  std::printf("| input | method | precision | queries | true | FN | FP | gave up | median us | p99 us | max us | mean us "
              "| earliest TOI | float-changed |\n");
  std::printf("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|\n");
  for (const Row& r : rows) {
    const Stats s = stats_of(r.m.us);
    const bool bold = r.kind == "group";
    const std::string name = bold ? "**" + r.input + "**" : r.input;
    const std::string truth =
        std::to_string(r.m.truth_true) + (r.m.unknown ? " (+" + std::to_string(r.m.unknown) + " unknown)" : "");
    std::printf("| %s | %s | %s | %zu | %s | %zu | %zu | %zu | %s | %s | %s | %s | %s | %s |\n", name.c_str(),
                r.method.c_str(), r.precision.c_str(), r.m.queries, truth.c_str(), r.m.fn, r.m.fp, r.m.gave_up,
                fmt_us(s.median).c_str(), fmt_us(s.p99).c_str(), fmt_us(s.max).c_str(), fmt_us(s.mean).c_str(),
                toi_text(r).c_str(), r.precision == "float" ? std::to_string(r.float_changed).c_str() : "");
  }
}

std::string json_escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\', out += c;
    else if (static_cast<unsigned char>(c) < 0x20) {
      char b[8];
      std::snprintf(b, sizeof b, "\\u%04x", c);
      out += b;
    } else out += c;
  }
  return out;
}

std::string json_number(double x, const char* fmt = "%.6g") {
  if (!std::isfinite(x)) return "null";
  char b[40];
  std::snprintf(b, sizeof b, fmt, x);
  return b;
}

std::string cpu_model() {
  std::ifstream f("/proc/cpuinfo");
  std::string line;
  while (std::getline(f, line)) {
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) {
        std::string v = line.substr(colon + 1);
        v.erase(0, v.find_first_not_of(" \t"));
        return v;
      }
    }
  }
  return "unknown";
}

void write_json(const std::string& path, const std::vector<Row>& rows, const Options& o, const std::string& cpu,
                double overhead_us) {
  std::ofstream f(path);
  if (!f) throw InputError(path, "", "cannot open for writing");
#if defined(__OPTIMIZE__)
  const bool optimized = true;
#else
  const bool optimized = false;
#endif
#if defined(NDEBUG)
  const bool assertions = false;
#else
  const bool assertions = true;
#endif
  f << "[\n";
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    const Stats s = stats_of(r.m.us);
    const bool toi = r.scene && r.reports_toi && r.kind != "group" && r.kind != "everything";
    f << "  {\"input\": \"" << json_escape(r.input) << "\", \"kind\": \"" << r.kind << "\", \"path\": \""
      << json_escape(r.path) << "\", \"method\": \"" << r.method << "\", \"conservative\": "
      << (r.conservative ? "true" : "false") << ", \"precision\": \"" << r.precision << "\",\n   \"queries\": "
      << r.m.queries << ", \"vf_queries\": " << r.m.vf_queries << ", \"ee_queries\": " << r.m.ee_queries
      << ", \"true\": " << r.m.truth_true << ", \"false\": " << r.m.truth_false << ", \"unknown_truth\": " << r.m.unknown
      << ", \"hits\": " << r.m.hits << ", \"false_negatives\": " << r.m.fn << ", \"false_positives\": " << r.m.fp
      << ", \"gave_up\": " << r.m.gave_up << ",\n   \"false_negative_rate\": "
      << (r.m.truth_true ? json_number(static_cast<double>(r.m.fn) / static_cast<double>(r.m.truth_true)) : "null")
      << ", \"false_positive_rate\": "
      << (r.m.truth_false ? json_number(static_cast<double>(r.m.fp) / static_cast<double>(r.m.truth_false)) : "null")
      << ",\n   \"median_us\": " << json_number(s.median) << ", \"p99_us\": " << json_number(s.p99)
      << ", \"max_us\": " << json_number(s.max) << ", \"mean_us\": " << json_number(s.mean)
      << ", \"queries_per_second\": "
      << json_number(r.seconds > 0 ? static_cast<double>(r.m.queries) / r.seconds : std::nan(""))
      << ", \"earliest_toi\": "
      << (toi && r.m.earliest_toi <= 1.0 ? json_number(r.m.earliest_toi, "%.17g") : std::string("null"))
      << ",\n   \"float_changed_queries\": " << r.float_changed << ", \"double_inexact_coordinates\": "
      << r.double_inexact << ", \"min_separation\": " << json_number(o.min_separation, "%.17g")
      << ", \"tolerance\": " << json_number(o.tolerance, "%.17g") << ", \"max_iterations\": " << o.max_iterations
      << ", \"limit\": " << o.limit << ", \"clock_overhead_us\": " << json_number(overhead_us)
      << ",\n   \"cpu\": \"" << json_escape(cpu) << "\", \"compiler\": \""
      << json_escape(__VERSION__) << "\", \"optimized\": " << (optimized ? "true" : "false")
      << ", \"assertions\": " << (assertions ? "true" : "false") << "}" << (i + 1 < rows.size() ? "," : "") << "\n";
  }
  f << "]\n";
  if (!f) throw InputError(path, "", "write failed");
}

// Median cost of an empty timed region (two clock reads): included in every per-query time.
double clock_overhead_us() {
  using clock = std::chrono::steady_clock;
  std::vector<double> us;
  us.reserve(20000);
  for (int i = 0; i < 20000; ++i) {
    const auto t0 = clock::now();
    int x = i;
    keep(x);
    const auto t1 = clock::now();
    us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
  }
  return lwsccd_bench::median(us);
}

int run(const Options& o) {
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::string> args = o.inputs;
  if (args.empty()) {
    const std::string root = lwsccd_bench::data_dir("", LWSCCD_BENCH_DATA_DIR);
    if (!fs::is_directory(root)) {
      std::fprintf(stderr,
                   "lwsccd-accuracy: no input given and the data folder '%s' does not exist; set LWSCCD_DATA_DIR or "
                   "pass query sets, CSV files or scenes (see --help)\n",
                   root.c_str());
      return 1;
    }
    args.push_back(root);
  }
  std::vector<InputSpec> specs;
  for (const auto& a : args) {
    const auto s = expand_input(a, o);
    specs.insert(specs.end(), s.begin(), s.end());
  }
#if !defined(__OPTIMIZE__)
  std::fprintf(stderr, "lwsccd-accuracy: warning: built without optimization; times are not representative\n");
#endif
  const std::string cpu = cpu_model();
  const double overhead_us = clock_overhead_us();
  CcdParams<double> pd;
  pd.min_separation = o.min_separation;
  pd.tolerance = o.tolerance;
  pd.max_iterations = o.max_iterations;
  CcdParams<float> pf;
  pf.min_separation = static_cast<float>(o.min_separation);
  pf.tolerance = static_cast<float>(o.tolerance);
  pf.max_iterations = o.max_iterations;

  std::vector<Row> rows;
  for (const InputSpec& spec : specs) {
    const auto t_load = std::chrono::steady_clock::now();
    const Input in = load_input(spec, o);
    std::fprintf(stderr, "%s (%s): %zu vf + %zu ee queries, loaded in %.2f s\n", in.name.c_str(), kind_name(in.kind),
                 in.vf.size(), in.ee.size(),
                 std::chrono::duration<double>(std::chrono::steady_clock::now() - t_load).count());
    for (const std::string& precision : o.precisions) {
      Typed<float> tf;
      Typed<double> td;
      if (precision == "float") tf = typed_queries<float>(in);
      else td = typed_queries<double>(in);
      for (const std::string& method : o.methods) {
        const MethodEntry& e = method_entry(method);
        const auto t_run = std::chrono::steady_clock::now();
        Row r;
        r.input = in.name;
        r.path = in.path;
        r.kind = kind_name(in.kind);
        r.scene = in.kind == Kind::Scene;
        r.method = e.name;
        r.precision = precision;
        r.conservative = e.conservative;
        r.reports_toi = e.reports_toi;
        r.m = precision == "float" ? e.run_float(tf, in, pf) : e.run_double(td, in, pd);
        r.double_inexact = in.double_inexact;
        r.float_changed = in.float_changed;
        for (double us : r.m.us) r.seconds += us * 1e-6;
        std::fprintf(stderr, "  %-18s %-6s FN %zu FP %zu  (%.2f s)\n", e.name, precision.c_str(), r.m.fn, r.m.fp,
                     std::chrono::duration<double>(std::chrono::steady_clock::now() - t_run).count());
        rows.push_back(std::move(r));
      }
    }
  }

  // Per-input rows grouped by kind, each group followed by its totals; then totals over everything.
  std::vector<Row> out;
  std::vector<Row> everything;
  for (Kind k : {Kind::QuerySet, Kind::Csv, Kind::Scene}) {
    std::vector<const Row*> group;
    for (const Row& r : rows)
      if (r.kind == kind_name(k)) group.push_back(&r);
    if (group.empty()) continue;
    for (const Row* r : group) out.push_back(*r);
    for (const std::string& method : o.methods)
      for (const std::string& precision : o.precisions) {
        std::vector<const Row*> parts;
        for (const Row* r : group)
          if (r->method == method && r->precision == precision) parts.push_back(r);
        if (!parts.empty()) out.push_back(total_row(parts, group_name(k), "group"));
      }
  }
  for (const std::string& method : o.methods)
    for (const std::string& precision : o.precisions) {
      std::vector<const Row*> parts;
      for (const Row& r : rows)
        if (r.method == method && r.precision == precision) parts.push_back(&r);
      if (!parts.empty()) everything.push_back(total_row(parts, "all inputs", "everything"));
    }

  std::printf("lwsccd-accuracy: %s, one core; min separation %g, tolerance %g, max iterations %d%s\n", cpu.c_str(),
              o.min_separation, o.tolerance, o.max_iterations,
              o.limit ? (", at most " + std::to_string(o.limit) + " queries per input").c_str() : "");
  std::printf("times per query in microseconds (us), steady_clock around each query; they include the clock's own\n"
              "cost, median %.3f us per timed region\n\n",
              overhead_us);
  print_table(out);

  std::printf("\nqueries per second over everything measured (sum of per-query times)\n\n");
  std::printf("| method | precision | queries | FN | FP | gave up | median us | p99 us | max us | queries/s |\n");
  std::printf("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const Row& r : everything) {
    const Stats s = stats_of(r.m.us);
    std::printf("| %s | %s | %zu | %zu | %zu | %zu | %s | %s | %s | %.0f |\n", r.method.c_str(), r.precision.c_str(),
                r.m.queries, r.m.fn, r.m.fp, r.m.gave_up, fmt_us(s.median).c_str(), fmt_us(s.p99).c_str(),
                fmt_us(s.max).c_str(), r.seconds > 0 ? static_cast<double>(r.m.queries) / r.seconds : 0.0);
  }

  if (!o.json.empty()) {
    std::vector<Row> all = out;
    all.insert(all.end(), everything.begin(), everything.end());
    write_json(o.json, all, o, cpu, overhead_us);
    std::printf("\nwrote %s\n", o.json.c_str());
  }

  int status = 0;
  for (const Row& r : rows)
    if (r.conservative && r.m.fn > 0) {
      std::fprintf(stderr, "lwsccd-accuracy: FAIL: %s (declared conservative) missed %zu contacts on %s in %s\n",
                   r.method.c_str(), r.m.fn, r.input.c_str(), r.precision.c_str());
      status = 2;
    }
  std::printf("\ntotal run time %.1f s\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  return status;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(parse(argc, argv));
  } catch (const lwsccd::Error& e) {
    std::fprintf(stderr, "lwsccd-accuracy: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lwsccd-accuracy: %s\n", e.what());
    return 1;
  }
}
