// lwsccd — what the mesh readers share: whole files read at once, names in natural order, numbers
// parsed without the locale, and the checks every frame passes (not empty, indices in range).
// Part of mesh_io_impl.hpp: include <lwsccd/io/mesh_io.hpp>, not this file.
#pragma once

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "lwsccd/core/error.hpp"
#include "lwsccd/io/mesh_io.hpp"

namespace lwsccd {

namespace detail {

inline std::string read_whole_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "", "cannot open file");
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) throw InputError(path, "", "cannot determine the file size");
  std::string bytes(static_cast<std::size_t>(size), '\0');
  in.seekg(0, std::ios::beg);
  if (size > 0 && !in.read(&bytes[0], size)) throw InputError(path, "", "cannot read file");
  return bytes;
}

inline std::string lowercase(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

inline std::string extension_lowercase(const std::string& path) {
  return lowercase(std::filesystem::path(path).extension().string());
}

inline bool is_mesh_file_extension(const std::string& ext_lowercase) {
  return ext_lowercase == ".ply" || ext_lowercase == ".obj";
}

// Orders names with digit runs compared as numbers, so "frame9" < "frame10" and "227" < "228".
inline bool natural_less(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  const auto is_digit = [](char c) { return c >= '0' && c <= '9'; };
  while (i < a.size() && j < b.size()) {
    if (is_digit(a[i]) && is_digit(b[j])) {
      std::size_t ie = i, je = j;
      while (ie < a.size() && is_digit(a[ie])) ++ie;
      while (je < b.size() && is_digit(b[je])) ++je;
      std::size_t ia = i, jb = j;  // skip leading zeros, then longer run = larger number
      while (ia + 1 < ie && a[ia] == '0') ++ia;
      while (jb + 1 < je && b[jb] == '0') ++jb;
      if (ie - ia != je - jb) return ie - ia < je - jb;
      const int c = a.compare(ia, ie - ia, b, jb, je - jb);
      if (c != 0) return c < 0;
      i = ie;
      j = je;
    } else {
      if (a[i] != b[j]) return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
      ++i;
      ++j;
    }
  }
  if ((i < a.size()) != (j < b.size())) return j < b.size();
  return a < b;  // equal up to zero padding: any fixed tie-break
}

// The mesh files (.ply/.obj, any case) directly inside `folder`, in natural name order.
inline std::vector<std::string> list_mesh_files(const std::string& folder) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) throw InputError(folder, "", "not a folder");
  std::vector<std::pair<std::string, std::string>> name_path;
  for (const auto& entry : fs::directory_iterator(folder, ec)) {
    std::error_code entry_ec;
    if (!entry.is_regular_file(entry_ec)) continue;
    if (!is_mesh_file_extension(extension_lowercase(entry.path().string()))) continue;
    name_path.emplace_back(entry.path().filename().string(), entry.path().string());
  }
  if (ec) throw InputError(folder, "", "cannot list folder: " + ec.message());
  std::sort(name_path.begin(), name_path.end(),
            [](const auto& x, const auto& y) { return natural_less(x.first, y.first); });
  std::vector<std::string> paths;
  for (auto& np : name_path) paths.push_back(std::move(np.second));
  return paths;
}

inline std::string file_stem(const std::string& path) { return std::filesystem::path(path).stem().string(); }

inline std::string face_text(const Face& f) {
  return "(" + std::to_string(f.v[0]) + " " + std::to_string(f.v[1]) + " " + std::to_string(f.v[2]) + ")";
}

inline std::string coordinates_text(double x, double y, double z) {
  std::ostringstream s;
  s << "(" << x << ", " << y << ", " << z << ")";
  return s.str();
}

// Parses a whole token as a double; from_chars is locale-independent and rejects a leading '+'.
inline bool parse_double(const char* first, const char* last, double& out) {
  if (first != last && *first == '+') ++first;
  if (first == last) return false;
  const auto result = std::from_chars(first, last, out);
  return result.ec == std::errc() && result.ptr == last;
}

// Empty meshes and indices beyond the vertex count are checked once the whole file is read,
// since a face may name a vertex that is listed later.
inline void check_frame_not_empty(const Frame& frame) {
  if (frame.positions.empty()) throw InputError(frame.source, "", "mesh has no vertices");
  if (frame.faces.empty()) throw InputError(frame.source, "", "mesh has no faces");
}


// Indices that name no vertex, reported with the face that holds them.
inline void check_face_indices(const Frame& frame) {
  const auto num_vertices = static_cast<index_t>(frame.positions.size());
  const std::size_t num_polygons = frame.polygon_offsets.empty() ? 0 : frame.polygon_offsets.size() - 1;
  for (std::size_t f = 0; f < num_polygons; ++f) {
    for (index_t k = frame.polygon_offsets[f]; k < frame.polygon_offsets[f + 1]; ++k) {
      const index_t v = frame.polygon_vertices[static_cast<std::size_t>(k)];
      if (v < 0 || v >= num_vertices)
        throw InputError(frame.source, "face " + std::to_string(f),
                         "vertex index " + std::to_string(v) + " out of range [0, " + std::to_string(num_vertices) + ")");
    }
  }
}

}  // namespace detail

}  // namespace lwsccd
