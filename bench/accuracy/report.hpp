// lwsccd-accuracy — the results: rows and totals, the table printed, the JSON written (with the
// machine it ran on and the clock's own cost).
#pragma once

#include "common.hpp"
#include "methods.hpp"

namespace {

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
  // Through a JSON library: any path stays valid JSON, and a number JSON cannot hold (NaN) is null.
  using Json = nlohmann::ordered_json;
  auto number = [](double x) { return std::isfinite(x) ? Json(x) : Json(nullptr); };
  auto rate = [&](std::size_t part, std::size_t whole) {
    return whole ? number(static_cast<double>(part) / static_cast<double>(whole)) : Json(nullptr);
  };
  Json all = Json::array();
  for (const Row& r : rows) {
    const Stats s = stats_of(r.m.us);
    const bool toi = r.scene && r.reports_toi && r.kind != "group" && r.kind != "everything";
    all.push_back(Json{{"input", r.input}, {"kind", r.kind}, {"path", r.path}, {"method", r.method},
                       {"conservative", r.conservative}, {"precision", r.precision}, {"queries", r.m.queries},
                       {"vf_queries", r.m.vf_queries}, {"ee_queries", r.m.ee_queries}, {"true", r.m.truth_true},
                       {"false", r.m.truth_false}, {"unknown_truth", r.m.unknown}, {"hits", r.m.hits},
                       {"false_negatives", r.m.fn}, {"false_positives", r.m.fp}, {"gave_up", r.m.gave_up},
                       {"false_negative_rate", rate(r.m.fn, r.m.truth_true)},
                       {"false_positive_rate", rate(r.m.fp, r.m.truth_false)}, {"median_us", number(s.median)},
                       {"p99_us", number(s.p99)}, {"max_us", number(s.max)}, {"mean_us", number(s.mean)},
                       {"queries_per_second", r.seconds > 0 ? number(static_cast<double>(r.m.queries) / r.seconds) : Json(nullptr)},
                       {"earliest_toi", toi && r.m.earliest_toi <= 1.0 ? number(r.m.earliest_toi) : Json(nullptr)},
                       {"float_changed_queries", r.float_changed}, {"double_inexact_coordinates", r.double_inexact},
                       {"min_separation", o.min_separation}, {"tolerance", o.tolerance},
                       {"max_iterations", o.max_iterations}, {"limit", o.limit}, {"clock_overhead_us", number(overhead_us)},
                       {"cpu", cpu}, {"compiler", __VERSION__}, {"optimized", optimized}, {"assertions", assertions}});
  }
  f << all.dump(1) << "\n";
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

}  // namespace
