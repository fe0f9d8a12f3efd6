// lwsccd-ccd — what the main program prints: a step's report, and all steps' as a per-stage table
// or as JSON (every count of StepStats, ground-truth scores, the oracle check).
#pragma once

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "ccd_app.hpp"
#include "ccd_inputs.hpp"
#include "ccd_options.hpp"

namespace ccd_app {

struct StepReport {
  std::string name;
  ccd_app::StepOutcome outcome;
  bool has_truth = false;
  lwsccd::TruthScore truth;
  bool checked = false;
  std::size_t check_differences = 0;
};

/// Where a step's feature pairs were decided: in single precision (the screen, the filter, the
/// search), contacts searched in single precision with the certain descent's last levels in double,
/// the double-precision certified path (its screen and refinement), the fallback search. Contacts
/// whose leaf pairs of floats proved (CcdParams::leaves_in_float_pairs: no FP64) count as single.
struct Decided {
  std::size_t single = 0, single_then_double = 0, double_ = 0, fallback = 0;
  std::size_t float_pair_leaves = 0;  ///< of `single`, contacts whose leaf pairs of floats proved
};
inline Decided decided_by(const lwsccd::StepStats& s) {
  Decided d;
  for (const lwsccd::NarrowPhaseCounts* c : {&s.narrow_vf, &s.narrow_ee}) {
    d.single += c->single_misses + c->float_pair_leaves;
    d.float_pair_leaves += c->float_pair_leaves;
    d.single_then_double += c->single_descents - c->float_pair_leaves;
    d.fallback += c->fallbacks;
    d.double_ += c->pairs - c->single_misses - c->single_descents - c->fallbacks;
  }
  return d;
}

inline const char* mode_name(lwsccd::CcdMode m) {
  return m == lwsccd::CcdMode::earliest ? "earliest" : m == lwsccd::CcdMode::set ? "set" : "contacts";
}

inline void print_table(const StepSource& src, const std::string& backend, const Options& o, const std::vector<StepReport>& reports) {
  std::printf("lwsccd-ccd: %s\n", src.description.c_str());
  const std::string cpu = "work stealing, " + std::to_string(ccd_app::cpu_threads(o.params)) + " threads" +
                          (lwsccd::cpu::kUsesTbb ? " (oneTBB)" : "");
  std::printf("  %d vertices, %d triangles; %s | BV %s | %s%s | %s, %s, mode %s | front tracking %s\n", src.mesh->num_vertices(),
              src.mesh->num_faces(), backend.c_str(), o.policies.bv.c_str(),
              backend == "CPU" ? "" : "scheduler ", backend == "CPU" ? cpu.c_str() : o.policies.scheduler.c_str(),
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
    if (o.policies.method == "certified") {
      std::printf("  narrow phase: screened %zu + %zu, certified hits %zu + %zu, certified misses %zu + %zu, "
                  "fallbacks %zu + %zu (VF + EE)\n",
                  s.narrow_vf.screened, s.narrow_ee.screened, s.narrow_vf.certified_hits, s.narrow_ee.certified_hits,
                  s.narrow_vf.certified_misses, s.narrow_ee.certified_misses, s.narrow_vf.fallbacks, s.narrow_ee.fallbacks);
      const Decided d = decided_by(s);
      std::printf("  pairs decided in FP32 %zu (of them contacts whose leaf pairs of floats proved %zu), in FP32 with an FP64 "
                  "tail %zu, in FP64 %zu, by the fallback %zu\n",
                  d.single, d.float_pair_leaves, d.single_then_double, d.double_, d.fallback);
    }
    if (s.narrow_survivors)
      std::printf("  narrow phase: %zu pairs past the first pass, %zu of them searched by a warp\n", s.narrow_survivors,
                  s.narrow_warp_searches);
    if (s.gave_up) std::printf("  %zu contacts from the method's work bound (conservative answers)\n", s.gave_up);
    if (s.peak_device_bytes) std::printf("  peak device memory %.1f MiB\n", double(s.peak_device_bytes) / (1 << 20));
    if (s.device_memory.total()) {
      std::printf("  device memory held, MiB:");
      lwsccd::for_each_part(s.device_memory, [](const char* name, std::size_t bytes) {
        std::printf(" %s %.1f", name, double(bytes) / (1 << 20));
      });
      std::printf("\n");
    }
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

// JSON through a library, so that any input name (quotes, backslashes) and any number (NaN, which
// JSON cannot hold, is written as null) still make a valid document.
inline void print_json(const StepSource& src, const std::string& backend, const Options& o, const std::vector<StepReport>& reports) {
  nlohmann::ordered_json doc;
  doc["input"] = src.description;
  doc["vertices"] = src.mesh->num_vertices();
  doc["triangles"] = src.mesh->num_faces();
  doc["backend"] = backend;
  doc["bv"] = o.policies.bv;
  doc["scheduler"] = backend == "CPU" ? std::string("work-stealing") : o.policies.scheduler;
  if (backend == "CPU") doc["threads"] = ccd_app::cpu_threads(o.params);
  doc["method"] = o.policies.method;
  doc["precision"] = o.policies.precision;
  doc["mode"] = mode_name(o.params.mode);
  doc["front_tracking"] = o.params.front_tracking;
  doc["steps"] = nlohmann::ordered_json::array();
  for (const StepReport& r : reports) {
    const lwsccd::StepStats& s = r.outcome.stats;
    nlohmann::ordered_json step;
    step["name"] = r.name;
    step["ms"] = {{"total", s.total_ms}, {"refit", s.refit_ms}, {"traverse", s.traverse_ms}, {"features", s.features_ms},
                  {"narrow", s.narrow_ms}};
    step["rebuilt"] = s.rebuilt;
    step["restarted_from_root"] = s.restarted_from_root;
    step["bvtt_nodes"] = s.bvtt_nodes;
    step["front"] = s.front_size;
    step["triangle_pairs"] = s.triangle_pairs;
    step["vf_pairs"] = s.feature_pairs_vf;
    step["ee_pairs"] = s.feature_pairs_ee;
    step["vf_hits"] = s.hits_vf;
    step["ee_hits"] = s.hits_ee;
    step["gave_up"] = s.gave_up;
    step["narrow_survivors"] = s.narrow_survivors;
    step["narrow_warp_searches"] = s.narrow_warp_searches;
    step["earliest_toi"] = r.outcome.contacts.earliest_toi;
    step["peak_device_bytes"] = s.peak_device_bytes;
    if (s.device_memory.total())
      lwsccd::for_each_part(s.device_memory, [&](const char* name, std::size_t bytes) { step["device_memory"][name] = bytes; });
    step["traversal_parts"] = s.traversal_parts;
    step["narrow_parts"] = s.narrow_parts;
    // Per feature kind: certified hits, certified misses, fallbacks, screened.
    auto certified = [](const lwsccd::NarrowPhaseCounts& c) {
      return nlohmann::ordered_json::array({c.certified_hits, c.certified_misses, c.fallbacks, c.screened});
    };
    step["certified"] = {{"vf", certified(s.narrow_vf)}, {"ee", certified(s.narrow_ee)}};
    const Decided d = decided_by(s);
    step["decided"] = {{"fp32", d.single},
                       {"fp32_float_pair_leaf", d.float_pair_leaves},
                       {"fp32_fp64_tail", d.single_then_double},
                       {"fp64", d.double_},
                       {"fallback", d.fallback}};
    if (r.has_truth)
      step["truth"] = {{"true_contacts", r.truth.true_contacts}, {"false_negatives", r.truth.false_negatives},
                       {"false_positives", r.truth.false_positives}};
    if (r.checked) step["check_differences"] = r.check_differences;
    doc["steps"].push_back(std::move(step));
  }
  std::printf("%s\n", doc.dump(2).c_str());
}

}  // namespace ccd_app
