// Shared helpers for the benchmark programs: statistics and small command-line parsing.
#pragma once

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

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

/// The options every benchmark takes: --data DIR, --reps N, --json FILE, plus its own flags.
struct BenchArgs {
  std::string data, json;
  int reps = 1;
  std::vector<std::string> flags;  ///< extra flags that were given (from `known_flags`)
  std::vector<std::pair<std::string, std::string>> values;  ///< extra options with a value ("--name=" in known_flags)
  bool has(const std::string& flag) const {
    for (const auto& f : flags)
      if (f == flag) return true;
    return false;
  }
  std::string value(const std::string& option, const std::string& otherwise) const {
    for (const auto& v : values)
      if (v.first == option) return v.second;
    return otherwise;
  }
};

/// Parses the common options; prints `usage` and exits (0 for -h/--help, 1 otherwise) on anything
/// else.
inline BenchArgs parse_bench_args(int argc, char** argv, int default_reps, const std::vector<std::string>& known_flags,
                                  const char* usage) {
  BenchArgs args;
  args.reps = default_reps;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    bool known = false, with_value = false;
    for (const auto& f : known_flags) {
      known = known || a == f;
      with_value = with_value || (!f.empty() && f.back() == '=' && a == f.substr(0, f.size() - 1));
    }
    if (with_value && i + 1 < argc) args.values.emplace_back(a, argv[++i]);
    else if (a == "--data" && i + 1 < argc) args.data = argv[++i];
    else if (a == "--json" && i + 1 < argc) args.json = argv[++i];
    else if (a == "--reps" && i + 1 < argc) args.reps = std::max(1, std::atoi(argv[++i]));
    else if (known) args.flags.push_back(a);
    else {
      std::fprintf(stderr, "%s\n", usage);
      std::exit(a == "-h" || a == "--help" ? 0 : 1);
    }
  }
  return args;
}

using Json = nlohmann::ordered_json;

/// Writes a JSON array to `path` (nothing when it is empty), one object per row: row(i) makes
/// object i. Through a JSON library, so any name stays valid JSON and a NaN is written as null.
template <class MakeRow>
void write_json_rows(const std::string& path, std::size_t n, MakeRow&& row) {
  if (path.empty()) return;
  std::ofstream f(path);
  if (!f) throw std::runtime_error("cannot write " + path);
  f << "[\n";
  for (std::size_t i = 0; i < n; ++i) f << "  " << Json(row(i)).dump() << (i + 1 < n ? ",\n" : "\n");
  f << "]\n";
  if (!f) throw std::runtime_error("error writing " + path);
}

}  // namespace lwsccd_bench
