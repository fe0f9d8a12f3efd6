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

}  // namespace
