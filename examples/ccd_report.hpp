// lwsccd-ccd — what the main program prints: a step's report, and all steps' as a per-stage table
// or as JSON (every count of StepStats, ground-truth scores, the oracle check).
#pragma once

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

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

inline const char* mode_name(lwsccd::CcdMode m) {
  return m == lwsccd::CcdMode::earliest ? "earliest" : m == lwsccd::CcdMode::set ? "set" : "contacts";
}

inline void print_table(const StepSource& src, const std::string& backend, const Options& o, const std::vector<StepReport>& reports) {
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

inline void print_json(const StepSource& src, const std::string& backend, const Options& o, const std::vector<StepReport>& reports) {
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

}  // namespace ccd_app
