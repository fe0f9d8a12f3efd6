// lwsccd-accuracy — the inputs: query sets, single CSV files and scenes, found from a path and
// loaded with their ground truth (and --limit applied).
#pragma once

#include "common.hpp"
#include "options.hpp"

namespace {

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

}  // namespace
