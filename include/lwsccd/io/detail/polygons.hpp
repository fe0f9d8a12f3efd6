// lwsccd — polygons read from mesh files, triangulated keeping their winding (fans for convex
// ones, ear clipping otherwise), with why one cannot be.
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
#include "lwsccd/io/mesh_io.hpp"

namespace lwsccd {

namespace detail {

// ---------------------------------------------------------------------------------------------
// Polygons

// Triangulates one polygon (vertex ids `ids`, n >= 3, in the file's order) into `out`, keeping its
// winding. Returns an empty string, or why it cannot: a repeated vertex, no area (Newell's normal
// is zero: collinear or coincident corners), no ear left (self-intersecting in its best-fit plane).
// A convex polygon becomes a fan from its first corner; any other, ear clipping in the plane
// normal to its largest Newell component, O(n^2) per ear.
inline std::string triangulate_polygon(const std::vector<Vec3d>& positions, const index_t* ids, int n, std::vector<Face>& out) {
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j)
      if (ids[i] == ids[j]) return "repeats vertex " + std::to_string(ids[i]);
  if (n == 3) {
    out.push_back(Face{{ids[0], ids[1], ids[2]}});
    return "";
  }
  Vec3d normal{0, 0, 0};  // Newell: twice the vector area
  for (int i = 0; i < n; ++i) {
    const Vec3d& a = positions[static_cast<std::size_t>(ids[i])];
    const Vec3d& b = positions[static_cast<std::size_t>(ids[(i + 1) % n])];
    normal.x += (a.y - b.y) * (a.z + b.z);
    normal.y += (a.z - b.z) * (a.x + b.x);
    normal.z += (a.x - b.x) * (a.y + b.y);
  }
  const double nx = std::fabs(normal.x), ny = std::fabs(normal.y), nz = std::fabs(normal.z);
  if (!(nx > 0 || ny > 0 || nz > 0)) return "has no area (its corners are collinear or coincide)";
  // 2D coordinates in the plane of the largest normal component, turned so that the polygon
  // winds counter-clockwise there.
  const int drop = nx >= ny && nx >= nz ? 0 : (ny >= nz ? 1 : 2);
  const double sign = normal[drop] > 0 ? 1.0 : -1.0;
  std::vector<double> u(static_cast<std::size_t>(n)), v(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    const Vec3d& a = positions[static_cast<std::size_t>(ids[i])];
    const double c[3] = {a.x, a.y, a.z};
    u[i] = c[(drop + 1) % 3];
    v[i] = sign * c[(drop + 2) % 3];
  }
  auto turn = [&](int a, int b, int c) { return (u[b] - u[a]) * (v[c] - v[a]) - (v[b] - v[a]) * (u[c] - u[a]); };
  bool convex = true;
  for (int i = 0; i < n && convex; ++i) convex = turn(i, (i + 1) % n, (i + 2) % n) >= 0;
  if (convex) {
    for (int i = 1; i + 1 < n; ++i) out.push_back(Face{{ids[0], ids[i], ids[i + 1]}});
    return "";
  }
  std::vector<int> left(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) left[i] = i;
  auto inside_or_on = [&](int p, int a, int b, int c) { return turn(a, b, p) >= 0 && turn(b, c, p) >= 0 && turn(c, a, p) >= 0; };
  while (left.size() > 3) {
    const int m = static_cast<int>(left.size());
    bool clipped = false;
    for (int k = 0; k < m && !clipped; ++k) {
      const int a = left[(k + m - 1) % m], b = left[k], c = left[(k + 1) % m];
      if (!(turn(a, b, c) > 0)) continue;  // reflex or flat corner: not an ear
      bool empty = true;
      for (int j = 0; j < m && empty; ++j) {
        const int p = left[j];
        if (p == a || p == b || p == c) continue;
        empty = !inside_or_on(p, a, b, c);
      }
      if (!empty) continue;
      out.push_back(Face{{ids[a], ids[b], ids[c]}});
      left.erase(left.begin() + k);
      clipped = true;
    }
    if (!clipped) return "cannot be triangulated (it intersects itself in its plane)";
  }
  out.push_back(Face{{ids[left[0]], ids[left[1]], ids[left[2]]}});
  return "";
}

// Turns the file's faces (polygon_offsets / polygon_vertices, indices already checked) into
// triangles. Where every face was a triangle the polygon arrays are dropped (Frame's contract).
// `where(f)` names face f in messages (its line, or "face f").
template <class Where>
void triangulate_frame(Frame& frame, Where&& where) {
  const std::size_t num_polygons = frame.polygon_offsets.empty() ? 0 : frame.polygon_offsets.size() - 1;
  bool only_triangles = true;
  for (std::size_t f = 0; f < num_polygons; ++f) only_triangles = only_triangles && frame.polygon_offsets[f + 1] - frame.polygon_offsets[f] == 3;
  frame.faces.clear();
  frame.faces.reserve(num_polygons);
  frame.face_source.clear();
  for (std::size_t f = 0; f < num_polygons; ++f) {
    const index_t begin = frame.polygon_offsets[f];
    const int n = static_cast<int>(frame.polygon_offsets[f + 1] - begin);
    const std::size_t before = frame.faces.size();
    const std::string problem = triangulate_polygon(frame.positions, frame.polygon_vertices.data() + begin, n, frame.faces);
    if (!problem.empty()) throw InputError(frame.source, where(f), "face of " + std::to_string(n) + " vertices " + problem);
    if (!only_triangles) frame.face_source.insert(frame.face_source.end(), frame.faces.size() - before, static_cast<index_t>(f));
  }
  if (only_triangles) {
    frame.polygon_offsets.clear();
    frame.polygon_vertices.clear();
  }
}

}  // namespace detail

}  // namespace lwsccd
