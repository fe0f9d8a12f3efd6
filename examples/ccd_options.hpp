// lwsccd-ccd — the main program's command line: its options, their usage text, and their parse
// (numbers, byte counts and choices checked, each error naming the option).
#pragma once

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "ccd_app.hpp"

namespace ccd_app {

struct Options {
  std::vector<std::string> inputs;
  std::size_t triangles = 20000;
  std::size_t first_frame = 30;
  std::size_t steps = 0;  // 0: 3 for the built-in scene, all for a sequence
  std::string device = "auto";
  int gpus = 1;  // > 1: the step split over GPUs 0 .. gpus - 1 (gpu::MultiGpuPipeline)
  ccd_app::PolicyChoice policies;
  lwsccd::PipelineParams params;
  bool check = false;
  bool json = false;
  std::string render;  // PNG path ("" : no picture)
  int render_width = 800, render_height = 600;
};

inline void print_usage(std::FILE* out) {
  std::fprintf(out,
               "usage: lwsccd-ccd [options] [INPUT...]\n"
               "\n"
               "Continuous collision detection with lwsccd: every vertex-face and edge-edge pair that comes\n"
               "into contact during each step, with its time of impact.\n"
               "\n"
               "INPUT (none: the built-in scene, a cloth dropped folded onto a ball)\n"
               "  SCENE_DIR        a folder laid out like shared/data/scenes/<scene>/ (frames/ with two\n"
               "                   frames; boxes/ + mma_bool/ ground truth, when present, is checked)\n"
               "  T0 T1            a two-frame step (PLY or OBJ files, same topology)\n"
               "  FRAMES_DIR       a folder of OBJ/PLY frames: each consecutive pair is a step\n"
               "\n"
               "built-in scene\n"
               "  --triangles N    resolution, 64 .. 100000000 (default 20000; e.g. 1000 to 10000000)\n"
               "  --frame F        first frame (default 30: the folded cloth is landing on the ball)\n"
               "  --steps K        steps to run (default 3; for FRAMES_DIR: all; for two frames or a scene\n"
               "                   folder: 1, and K > 1 repeats that step, a steady state)\n"
               "\n"
               "pipeline\n"
               "  --device D       auto (default: the GPU when there is one), gpu, cpu\n"
               "  --gpus N         split each step over GPUs 0 .. N-1 (NCCL; default policies, no memory\n"
               "                   budget or parts; same contacts as one GPU)\n"
               "  --bv B           bounding volume of the swept triangles: aabb (default), obb\n"
               "  --scheduler S    GPU traversal load balancer: lazy (default, lazy work stealing),\n"
               "                   gproximity, static\n"
               "  --method M       narrow phase: certified (default; a certified floating-point test,\n"
               "                   the inclusion search where it cannot decide; never misses a contact),\n"
               "                   filtered-inclusion, inclusion (conservative), cubic (can miss contacts)\n"
               "  --mode M         contacts (default: every colliding pair with its TOI), earliest (only\n"
               "                   the earliest TOI of the step), set (colliding pairs, TOIs unrefined)\n"
               "  --precision P    narrow-phase precision: double (default), float\n"
               "  --separation D   minimum separation: report features that come closer than D (default 0)\n"
               "  --tolerance T    time resolution of the times of impact (default 1e-6)\n"
               "  --max-iterations N  narrow-phase work bound per pair; past it a pair counts as a\n"
               "                   contact (default 16384)\n"
               "  --memory-budget B  GPU: device memory the pipeline may hold, e.g. 4G, 512M (default: no\n"
               "                   limit); a step that needs more runs in parts that fit (same contacts)\n"
               "  --part-pairs N   run each step in parts of at most N candidate triangle pairs (both\n"
               "                   devices; same contacts, less memory at once)\n"
               "  --threads N      CPU backend: at most N threads (default: every core)\n"
               "  --fp64-ratio R   GPU: plan the narrow phase as for a GPU whose FP32 runs R times its\n"
               "                   FP64 (default: the device's own; e.g. 64 to count on an H100 what an\n"
               "                   RTX-class GPU runs; same contacts). From 8 on, both backends prove\n"
               "                   contacts' leaves in pairs of floats first (same contacts)\n"
               "  --no-front-tracking  traverse from the root every step\n"
               "  --check          also run the CPU oracle (sort-and-sweep, every candidate pair) and\n"
               "                   compare contacts pair for pair (slow on large scenes)\n"
               "\n"
               "output\n"
               "  --json           machine-readable output on stdout\n"
               "  --render F.png   a picture of each step at its earliest contact, colliding triangles\n"
               "                   in red (several steps: F_000.png, F_001.png, ...; CPU ray casting)\n"
               "  --render-size WxH  the picture's size (default 800x600)\n"
               "  -h, --help       this text\n"
               "\n"
               "Exit status: 0 done; 1 bad input or error; 2 a ground-truth contact was missed (or --check\n"
               "found a difference).\n");
}

inline long long parse_integer(const std::string& option, const std::string& text, long long lo, long long hi) {
  char* end = nullptr;
  const long long v = std::strtoll(text.c_str(), &end, 10);
  if (text.empty() || *end != '\0' || v < lo || v > hi)
    throw lwsccd::InputError("command line", option,
                             "expected an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got '" + text + "'");
  return v;
}

inline double parse_number(const std::string& option, const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0') throw lwsccd::InputError("command line", option, "expected a number, got '" + text + "'");
  return v;
}

// A byte count: a number with an optional K, M or G (binary multiples).
inline std::size_t parse_bytes(const std::string& option, const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  const std::string unit = end ? std::string(end) : std::string();
  const double scale = unit.empty() ? 1.0 : unit == "K" ? 1024.0 : unit == "M" ? 1048576.0 : unit == "G" ? 1073741824.0 : -1.0;
  if (text.empty() || scale < 0 || !(v > 0) || v * scale > 1e15)
    throw lwsccd::InputError("command line", option, "expected a positive size such as 4G, 512M or 1000000, got '" + text + "'");
  return static_cast<std::size_t>(v * scale);
}

inline std::string parse_choice(const std::string& option, const std::string& text, const std::vector<std::string>& allowed) {
  if (std::find(allowed.begin(), allowed.end(), text) != allowed.end()) return text;
  std::string list;
  for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
  throw lwsccd::InputError("command line", option, "expected one of " + list + ", got '" + text + "'");
}

inline Options parse_options(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw lwsccd::InputError("command line", a, "needs a value");
      return argv[++i];
    };
    if (a == "-h" || a == "--help") {
      print_usage(stdout);
      std::exit(0);
    } else if (a == "--triangles") {
      o.triangles = static_cast<std::size_t>(parse_integer(a, value(), 64, 100000000));
    } else if (a == "--frame") {
      o.first_frame = static_cast<std::size_t>(parse_integer(a, value(), 0, 100000));
    } else if (a == "--steps") {
      o.steps = static_cast<std::size_t>(parse_integer(a, value(), 1, 100000));
    } else if (a == "--device") {
      o.device = parse_choice(a, value(), {"auto", "gpu", "cpu"});
    } else if (a == "--gpus") {
      o.gpus = static_cast<int>(parse_integer(a, value(), 1, 64));
    } else if (a == "--bv") {
      o.policies.bv = parse_choice(a, value(), {"aabb", "obb"});
    } else if (a == "--scheduler") {
      o.policies.scheduler = parse_choice(a, value(), {"lazy", "gproximity", "static"});
    } else if (a == "--method") {
      o.policies.method = parse_choice(a, value(), {"certified", "filtered-inclusion", "inclusion", "cubic"});
    } else if (a == "--mode") {
      const std::string m = parse_choice(a, value(), {"contacts", "earliest", "set"});
      o.params.mode = m == "earliest" ? lwsccd::CcdMode::earliest : m == "set" ? lwsccd::CcdMode::set : lwsccd::CcdMode::contacts;
    } else if (a == "--precision") {
      o.policies.precision = parse_choice(a, value(), {"double", "float"});
    } else if (a == "--separation") {
      o.params.min_separation = parse_number(a, value());
    } else if (a == "--tolerance") {
      o.params.tolerance = parse_number(a, value());
    } else if (a == "--memory-budget") {
      o.params.device_memory_budget = parse_bytes(a, value());
    } else if (a == "--part-pairs") {
      o.params.part_pairs = static_cast<std::size_t>(parse_integer(a, value(), 1, 1LL << 40));
    } else if (a == "--threads") {
      o.params.threads = static_cast<unsigned>(parse_integer(a, value(), 1, 1 << 16));
    } else if (a == "--fp64-ratio") {
      o.params.fp64_ratio = static_cast<int>(parse_integer(a, value(), 1, 1 << 16));
    } else if (a == "--max-iterations") {
      o.params.max_iterations = static_cast<int>(parse_integer(a, value(), 1, 1 << 30));
    } else if (a == "--no-front-tracking") {
      o.params.front_tracking = false;
    } else if (a == "--check") {
      o.check = true;
    } else if (a == "--json") {
      o.json = true;
    } else if (a == "--render") {
      o.render = value();
      if (o.render.size() < 5 || o.render.compare(o.render.size() - 4, 4, ".png") != 0)
        throw lwsccd::InputError("command line", a, "expects a file name ending in .png, got '" + o.render + "'");
    } else if (a == "--render-size") {
      const std::string size = value();
      if (std::sscanf(size.c_str(), "%dx%d", &o.render_width, &o.render_height) != 2 || o.render_width < 1 ||
          o.render_height < 1 || o.render_width > 16384 || o.render_height > 16384)
        throw lwsccd::InputError("command line", a, "expects WxH in 1..16384, e.g. 1280x720, got '" + size + "'");
    } else if (!a.empty() && a[0] == '-') {
      throw lwsccd::InputError("command line", a, "unknown option (see --help)");
    } else {
      o.inputs.push_back(a);
    }
  }
  if (o.inputs.size() > 2) throw lwsccd::InputError("command line", "", "at most two inputs (see --help)");
  o.params.validate();
  return o;
}

}  // namespace ccd_app
