// lwsccd — definitions for dataset.hpp: scene folders and their JSON ground truth.
#pragma once

#include <charconv>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "lwsccd/core/error.hpp"
#include "lwsccd/io/dataset.hpp"

namespace lwsccd {

namespace detail {

// Reads the two JSON shapes of the dataset (arrays of integer pairs, arrays of booleans). Not a
// general JSON parser: anything else is reported with the character offset where it went wrong.
class JsonArrayReader {
 public:
  JsonArrayReader(const std::string& text, const std::string& path) : text_(text), path_(path) {}

  // Calls read_item for each element of the array that starts here.
  template <class ReadItem>
  void read_array(ReadItem read_item) {
    expect('[');
    skip_whitespace();
    if (peek_is(']')) {
      ++pos_;
      return;
    }
    while (true) {
      skip_whitespace();
      read_item();
      skip_whitespace();
      if (peek_is(',')) {
        ++pos_;
        continue;
      }
      if (peek_is(']')) {
        ++pos_;
        return;
      }
      fail("expected ',' or ']'");
    }
  }

  index_t read_index() {
    skip_whitespace();
    const char* first = text_.data() + pos_;
    const char* last = text_.data() + text_.size();
    long long value = 0;
    const auto result = std::from_chars(first, last, value);
    if (result.ec == std::errc::result_out_of_range) fail("integer out of range");
    if (result.ec != std::errc() || result.ptr == first) fail("expected an integer");
    if (result.ptr < last && (*result.ptr == '.' || *result.ptr == 'e' || *result.ptr == 'E'))
      fail("expected an integer, found a fractional number");
    if (value < 0 || value > std::numeric_limits<index_t>::max())
      fail("id " + std::to_string(value) + " outside [0, " + std::to_string(std::numeric_limits<index_t>::max()) + "]");
    pos_ += static_cast<std::size_t>(result.ptr - first);
    return static_cast<index_t>(value);
  }

  bool read_bool() {
    skip_whitespace();
    if (text_.compare(pos_, 4, "true") == 0) {
      pos_ += 4;
      return true;
    }
    if (text_.compare(pos_, 5, "false") == 0) {
      pos_ += 5;
      return false;
    }
    fail("expected true or false");
  }

  void expect(char c) {
    skip_whitespace();
    if (!peek_is(c)) fail(std::string("expected '") + c + "'");
    ++pos_;
  }

  // Only whitespace may follow the top-level array.
  void expect_end() {
    skip_whitespace();
    if (pos_ != text_.size()) fail("unexpected text after the array");
  }

 private:
  void skip_whitespace() {
    while (pos_ < text_.size() && (text_[pos_] == ' ' || text_[pos_] == '\n' || text_[pos_] == '\r' || text_[pos_] == '\t'))
      ++pos_;
  }

  bool peek_is(char c) const { return pos_ < text_.size() && text_[pos_] == c; }

  std::string found() const {
    if (pos_ >= text_.size()) return "end of file";
    const auto c = static_cast<unsigned char>(text_[pos_]);
    if (c >= 0x20 && c < 0x7f) return std::string("'") + text_[pos_] + "'";
    char hex[8];
    std::snprintf(hex, sizeof hex, "0x%02x", c);
    return std::string("byte ") + hex;
  }

  [[noreturn]] void fail(const std::string& problem) const {
    throw InputError(path_, "character offset " + std::to_string(pos_), problem + ", found " + found());
  }

  const std::string& text_;
  const std::string& path_;
  std::size_t pos_ = 0;
};

// "a/b/scene/" and "scene" both give "scene".
inline std::string folder_name(const std::string& folder) {
  std::filesystem::path p = std::filesystem::absolute(folder).lexically_normal();
  if (p.filename().empty()) p = p.parent_path();
  return p.filename().string();
}

// The step id is the prefix of the boxes files ("92" for boxes/92vf.json). Without boxes, the
// trailing number of the t0 frame's name stands in (the dataset names frames by step).
inline std::string find_step_id(const std::filesystem::path& boxes_folder, const std::string& frame_t0) {
  namespace fs = std::filesystem;
  std::set<std::string> ids;
  std::error_code ec;
  if (fs::is_directory(boxes_folder, ec)) {
    for (const auto& entry : fs::directory_iterator(boxes_folder, ec)) {
      const std::string name = entry.path().filename().string();
      for (const char* suffix : {"vf.json", "ee.json"}) {
        const std::size_t n = std::char_traits<char>::length(suffix);
        if (name.size() > n && name.compare(name.size() - n, n, suffix) == 0) ids.insert(name.substr(0, name.size() - n));
      }
    }
  }
  if (ids.size() > 1) {
    std::string list;
    for (const auto& id : ids) list += (list.empty() ? "" : ", ") + id;
    throw InputError(boxes_folder.string(), "", "holds the boxes of several steps (" + list + "); a scene has one step");
  }
  if (ids.size() == 1) return *ids.begin();
  const std::string stem = file_stem(frame_t0);
  std::size_t digits = stem.size();
  while (digits > 0 && stem[digits - 1] >= '0' && stem[digits - 1] <= '9') --digits;
  return digits < stem.size() ? stem.substr(digits) : stem;
}

// Throws unless every pair's ids lie in the given feature-id ranges [lo, hi).
inline void check_pair_ranges(const std::vector<std::pair<index_t, index_t>>& pairs, const std::string& path,
                              const char* kind, const char* first_name, std::int64_t first_lo, std::int64_t first_hi,
                              const char* second_name, std::int64_t second_lo, std::int64_t second_hi) {
  const auto range_text = [](std::int64_t lo, std::int64_t hi) {
    return "[" + std::to_string(lo) + ", " + std::to_string(hi) + ")";
  };
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    const std::int64_t a = pairs[i].first, b = pairs[i].second;
    const std::string pair_text = std::string(kind) + " pair (" + std::to_string(a) + ", " + std::to_string(b) + ")";
    if (a < first_lo || a >= first_hi)
      throw InputError(path, "pair " + std::to_string(i),
                       pair_text + ": " + first_name + " id outside " + range_text(first_lo, first_hi));
    if (b < second_lo || b >= second_hi)
      throw InputError(path, "pair " + std::to_string(i),
                       pair_text + ": " + second_name + " id outside " + range_text(second_lo, second_hi));
  }
}

}  // namespace detail

inline std::vector<std::pair<index_t, index_t>> load_json_pairs(const std::string& path) {
  const std::string text = detail::read_whole_file(path);
  detail::JsonArrayReader reader(text, path);
  std::vector<std::pair<index_t, index_t>> pairs;
  pairs.reserve(text.size() / 16);  // a pair of 6-digit ids takes about 16 characters
  reader.read_array([&] {
    reader.expect('[');
    const index_t a = reader.read_index();
    reader.expect(',');
    const index_t b = reader.read_index();
    reader.expect(']');
    pairs.emplace_back(a, b);
  });
  reader.expect_end();
  return pairs;
}

inline std::vector<bool> load_json_bools(const std::string& path) {
  const std::string text = detail::read_whole_file(path);
  detail::JsonArrayReader reader(text, path);
  std::vector<bool> values;
  values.reserve(text.size() / 5);
  reader.read_array([&] { values.push_back(reader.read_bool()); });
  reader.expect_end();
  return values;
}

inline Scene load_scene(const std::string& folder) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) throw InputError(folder, "", "not a folder");
  const fs::path root(folder);

  const std::string frames_folder = (root / "frames").string();
  if (!fs::is_directory(frames_folder, ec))
    throw InputError(frames_folder, "", "missing: a scene needs frames/ with two mesh files");
  const std::vector<std::string> frames = detail::list_mesh_files(frames_folder);
  if (frames.size() != 2)
    throw InputError(frames_folder, "", "has " + std::to_string(frames.size()) +
                                            " mesh files (.ply/.obj); a scene needs exactly 2 (t0 and t1)");

  Scene scene;
  scene.name = detail::folder_name(folder);
  scene.step = load_step(frames[0], frames[1]);
  scene.step_id = detail::find_step_id(root / "boxes", frames[0]);

  const std::string vf_pairs = (root / "boxes" / (scene.step_id + "vf.json")).string();
  const std::string ee_pairs = (root / "boxes" / (scene.step_id + "ee.json")).string();
  const std::string vf_bools = (root / "mma_bool" / (scene.step_id + "vf_mma_bool.json")).string();
  const std::string ee_bools = (root / "mma_bool" / (scene.step_id + "ee_mma_bool.json")).string();
  for (const std::string& path : {vf_pairs, ee_pairs, vf_bools, ee_bools})
    if (!fs::is_regular_file(path, ec)) return scene;
  scene.has_ground_truth = true;

  GroundTruth& truth = scene.truth;
  truth.vf = load_json_pairs(vf_pairs);
  truth.ee = load_json_pairs(ee_pairs);
  truth.vf_collides = load_json_bools(vf_bools);
  truth.ee_collides = load_json_bools(ee_bools);
  if (truth.vf_collides.size() != truth.vf.size())
    throw InputError(vf_bools, "", "has " + std::to_string(truth.vf_collides.size()) + " values but " + vf_pairs +
                                       " has " + std::to_string(truth.vf.size()) + " pairs");
  if (truth.ee_collides.size() != truth.ee.size())
    throw InputError(ee_bools, "", "has " + std::to_string(truth.ee_collides.size()) + " values but " + ee_pairs +
                                       " has " + std::to_string(truth.ee.size()) + " pairs");

  const TriangleMesh& mesh = *scene.step.mesh;
  const std::int64_t num_v = mesh.num_vertices(), num_e = mesh.num_edges(), num_f = mesh.num_faces();
  detail::check_pair_ranges(truth.vf, vf_pairs, "vertex-face", "vertex", 0, num_v, "face", num_v + num_e,
                            num_v + num_e + num_f);
  detail::check_pair_ranges(truth.ee, ee_pairs, "edge-edge", "edge", num_v, num_v + num_e, "edge", num_v,
                            num_v + num_e);
  return scene;
}

}  // namespace lwsccd
