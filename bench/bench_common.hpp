// Shared helpers for the benchmark programs: statistics and small command-line parsing.
#pragma once

#include <algorithm>
#include <cstdlib>
#include <string>
#include <vector>

namespace lwsccd_bench {

inline double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

inline double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const auto i = static_cast<std::size_t>(p * static_cast<double>(v.size() - 1) + 0.5);
  return v[std::min(i, v.size() - 1)];
}

/// The shared data folder: --data, else $LWSCCD_DATA_DIR, else the configured default.
inline std::string data_dir(const std::string& from_args, const char* configured) {
  if (!from_args.empty()) return from_args;
  if (const char* env = std::getenv("LWSCCD_DATA_DIR")) return env;
  return configured;
}

}  // namespace lwsccd_bench
