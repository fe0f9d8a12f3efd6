// lwsccd-accuracy — accuracy and time per query of the narrow-phase methods against exact ground
// truth: the query sets (../shared/data/queries/<set>/{vertex-face,edge-edge}/*.csv), single query
// CSV files, and the scenes (../shared/data/scenes/<scene>/: candidate pairs from boxes/, truth
// from mma_bool/). Plain C++ (CPU), one core. See docs/NARROW_PHASE.md.
//
// Exit status: 0 on success, 1 on bad arguments or input, 2 when a method that declares itself
// conservative produced a false negative.
//
// The parts: accuracy/common.hpp (shared names), options.hpp (command line), inputs.hpp (query
// sets, CSV files, scenes), methods.hpp (methods table, measurement), report.hpp (table, JSON).
#include "accuracy/common.hpp"
#include "accuracy/inputs.hpp"
#include "accuracy/methods.hpp"
#include "accuracy/options.hpp"
#include "accuracy/report.hpp"

namespace {

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
