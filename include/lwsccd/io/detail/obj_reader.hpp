// lwsccd — the OBJ reader: vertices and faces (polygons triangulated), comments and the other
// statements skipped, errors naming the line.
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
#include "lwsccd/io/detail/mesh_file_common.hpp"
#include "lwsccd/io/detail/polygons.hpp"
#include "lwsccd/io/mesh_io.hpp"

namespace lwsccd {

namespace detail {

// ---------------------------------------------------------------------------------------------
// OBJ

// One whitespace-separated token of an OBJ line; '#' starts a comment that ends the line.
inline bool next_obj_token(const char*& p, const char* line_end, const char*& token, const char*& token_end) {
  while (p < line_end && (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\f' || *p == '\v')) ++p;
  if (p >= line_end || *p == '#') return false;
  token = p;
  while (p < line_end && !(*p == ' ' || *p == '\t' || *p == '\r' || *p == '\f' || *p == '\v' || *p == '#')) ++p;
  token_end = p;
  return true;
}

}  // namespace detail

inline Frame load_obj(const std::string& path) {
  const std::string bytes = detail::read_whole_file(path);
  Frame frame;
  frame.source = path;
  std::vector<int> face_lines;  // for range messages, checked once every vertex is known

  const char* p = bytes.data();
  const char* const end = p + bytes.size();
  int line_number = 0;
  while (p < end) {
    ++line_number;
    const char* line_end = static_cast<const char*>(std::memchr(p, '\n', static_cast<std::size_t>(end - p)));
    if (!line_end) line_end = end;
    const auto where = [&] { return "line " + std::to_string(line_number); };

    const char *token = nullptr, *token_end = nullptr;
    const char* cursor = p;
    p = line_end + 1;
    if (!detail::next_obj_token(cursor, line_end, token, token_end)) continue;
    const std::size_t keyword_length = static_cast<std::size_t>(token_end - token);

    if (keyword_length == 1 && token[0] == 'v') {
      double xyz[3];
      for (int k = 0; k < 3; ++k) {
        if (!detail::next_obj_token(cursor, line_end, token, token_end))
          throw InputError(path, where(), "vertex has fewer than 3 coordinates");
        if (!detail::parse_double(token, token_end, xyz[k]))
          throw InputError(path, where(), "bad number '" + std::string(token, token_end) + "'");
      }
      const Vec3d position{xyz[0], xyz[1], xyz[2]};
      if (!is_finite(position))
        throw InputError(path, where(), "vertex " + std::to_string(frame.positions.size()) +
                                            " coordinate is NaN or infinite " +
                                            detail::coordinates_text(xyz[0], xyz[1], xyz[2]));
      frame.positions.push_back(position);  // any further values (w, colors) are ignored
    } else if (keyword_length == 1 && token[0] == 'f') {
      if (frame.polygon_offsets.empty()) frame.polygon_offsets.push_back(0);
      int corners = 0;
      while (detail::next_obj_token(cursor, line_end, token, token_end)) {
        // Only the position index matters: "a", "a/b", "a//c", "a/b/c".
        const char* slash = std::find(token, token_end, '/');
        long long index = 0;
        const auto result = std::from_chars(token, slash, index);
        if (result.ec != std::errc() || result.ptr != slash)
          throw InputError(path, where(), "bad vertex index '" + std::string(token, token_end) + "'");
        if (index == 0) throw InputError(path, where(), "vertex index 0 (OBJ indices start at 1)");
        const auto defined = static_cast<long long>(frame.positions.size());
        if (index < 0) {
          if (-index > defined)
            throw InputError(path, where(), "relative vertex index " + std::to_string(index) + " reaches before the first vertex (" +
                                                std::to_string(defined) + " defined so far)");
          index += defined;  // -1 is the latest vertex
        } else {
          --index;
        }
        if (index > std::numeric_limits<index_t>::max())
          throw InputError(path, where(), "vertex index " + std::string(token, slash) + " is too large");
        frame.polygon_vertices.push_back(static_cast<index_t>(index));
        ++corners;
      }
      if (corners < 3) throw InputError(path, where(), "face has " + std::to_string(corners) + " vertices (at least 3 needed)");
      frame.polygon_offsets.push_back(static_cast<index_t>(frame.polygon_vertices.size()));
      face_lines.push_back(line_number);
    }
    // Everything else (vn, vt, o, g, s, usemtl, mtllib, l, ...) does not affect the geometry.
  }

  if (frame.positions.empty()) throw InputError(frame.source, "", "mesh has no vertices");
  const auto num_vertices = static_cast<index_t>(frame.positions.size());
  for (std::size_t f = 0; f + 1 < frame.polygon_offsets.size(); ++f) {
    for (index_t k = frame.polygon_offsets[f]; k < frame.polygon_offsets[f + 1]; ++k) {
      const index_t v = frame.polygon_vertices[static_cast<std::size_t>(k)];
      if (v >= num_vertices)
        throw InputError(path, "line " + std::to_string(face_lines[f]),
                         "vertex index " + std::to_string(v + 1) + " out of range (the file has " +
                             std::to_string(num_vertices) + " vertices)");
    }
  }
  detail::triangulate_frame(frame, [&](std::size_t f) { return "line " + std::to_string(face_lines[f]); });
  detail::check_frame_not_empty(frame);
  return frame;
}

}  // namespace lwsccd
