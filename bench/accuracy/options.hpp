// lwsccd-accuracy — the command line: options, their checks and the usage text.
#pragma once

#include "common.hpp"

namespace {

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

}  // namespace
