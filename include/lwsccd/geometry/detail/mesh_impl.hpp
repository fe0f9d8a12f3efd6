// lwsccd — definitions for mesh.hpp.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>

#include "lwsccd/core/error.hpp"
#include "lwsccd/geometry/mesh.hpp"

namespace lwsccd {

namespace detail {

// Builds a CSR adjacency (offsets of size rows+1, ids sorted per row) from (row, id) pairs.
inline void build_csr(index_t rows, const std::vector<std::pair<index_t, index_t>>& row_id,
                      std::vector<index_t>& offsets, std::vector<index_t>& ids) {
  offsets.assign(static_cast<std::size_t>(rows) + 1, 0);
  for (const auto& p : row_id) ++offsets[p.first + 1];
  std::partial_sum(offsets.begin(), offsets.end(), offsets.begin());
  ids.resize(row_id.size());
  std::vector<index_t> cursor(offsets.begin(), offsets.end() - 1);
  for (const auto& p : row_id) ids[cursor[p.first]++] = p.second;
  for (index_t r = 0; r < rows; ++r) std::sort(ids.begin() + offsets[r], ids.begin() + offsets[r + 1]);
}

// Key that orders undirected edges by (max, min), the dataset's edge order.
inline std::uint64_t edge_key(index_t a, index_t b) {
  const auto lo = static_cast<std::uint64_t>(std::min(a, b));
  const auto hi = static_cast<std::uint64_t>(std::max(a, b));
  return (hi << 32) | lo;
}

}  // namespace detail

inline TriangleMesh::TriangleMesh(index_t num_vertices, std::vector<Face> faces, const std::string& source)
    : num_vertices_(num_vertices), faces_(std::move(faces)) {
  if (num_vertices_ <= 0) throw InputError(source, "", "mesh has no vertices");
  if (faces_.empty()) throw InputError(source, "", "mesh has no faces");
  if (faces_.size() > static_cast<std::size_t>(std::numeric_limits<index_t>::max() / 4))
    throw InputError(source, "", "too many faces for 32-bit feature ids");
  for (std::size_t f = 0; f < faces_.size(); ++f) {
    const Face& t = faces_[f];
    for (int k = 0; k < 3; ++k) {
      if (t.v[k] < 0 || t.v[k] >= num_vertices_)
        throw InputError(source, "face " + std::to_string(f),
                         "vertex index " + std::to_string(t.v[k]) + " out of range [0, " +
                             std::to_string(num_vertices_) + ")");
    }
    if (t.v[0] == t.v[1] || t.v[1] == t.v[2] || t.v[0] == t.v[2])
      throw InputError(source, "face " + std::to_string(f),
                       "repeated vertex index (" + std::to_string(t.v[0]) + " " + std::to_string(t.v[1]) + " " +
                           std::to_string(t.v[2]) + ")");
  }

  // Unique edges sorted by (max, min); face_edges found by binary search in the sorted keys.
  const index_t nf = num_faces();
  std::vector<std::uint64_t> keys;
  keys.reserve(3 * faces_.size());
  for (const Face& t : faces_)
    for (int k = 0; k < 3; ++k) keys.push_back(detail::edge_key(t.v[k], t.v[(k + 1) % 3]));
  std::vector<std::uint64_t> unique_keys = keys;
  std::sort(unique_keys.begin(), unique_keys.end());
  unique_keys.erase(std::unique(unique_keys.begin(), unique_keys.end()), unique_keys.end());
  edges_.resize(unique_keys.size());
  for (std::size_t e = 0; e < unique_keys.size(); ++e)
    edges_[e] = Edge{{static_cast<index_t>(unique_keys[e] & 0xffffffffu), static_cast<index_t>(unique_keys[e] >> 32)}};

  face_edges_.resize(faces_.size());
  std::vector<std::pair<index_t, index_t>> edge_face, vertex_face;
  edge_face.reserve(keys.size());
  vertex_face.reserve(keys.size());
  for (index_t f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) {
      const auto it = std::lower_bound(unique_keys.begin(), unique_keys.end(), keys[3 * f + k]);
      const auto e = static_cast<index_t>(it - unique_keys.begin());
      face_edges_[f][k] = e;
      edge_face.emplace_back(e, f);
      vertex_face.emplace_back(faces_[f].v[k], f);
    }
  }
  detail::build_csr(num_edges(), edge_face, edge_face_offsets_, edge_face_ids_);
  detail::build_csr(num_vertices_, vertex_face, vertex_face_offsets_, vertex_face_ids_);

  // Two faces with the same three vertices would make the topology ambiguous.
  for (index_t e = 0; e < num_edges(); ++e) {
    const auto fs = edge_faces(e);
    for (std::size_t i = 0; i + 1 < fs.size(); ++i) {
      for (std::size_t j = i + 1; j < fs.size(); ++j) {
        auto a = face_edges_[fs[i]], b = face_edges_[fs[j]];
        std::sort(a.begin(), a.end());
        std::sort(b.begin(), b.end());
        if (a == b)
          throw InputError(source, "face " + std::to_string(fs[j]),
                           "duplicate of face " + std::to_string(fs[i]) + " (same three vertices)");
      }
    }
  }

  std::vector<std::pair<index_t, index_t>> neighbor;
  for (index_t e = 0; e < num_edges(); ++e) {
    const auto fs = edge_faces(e);
    for (std::size_t i = 0; i < fs.size(); ++i)
      for (std::size_t j = 0; j < fs.size(); ++j)
        if (i != j) neighbor.emplace_back(fs[i], fs[j]);
  }
  std::sort(neighbor.begin(), neighbor.end());
  neighbor.erase(std::unique(neighbor.begin(), neighbor.end()), neighbor.end());
  detail::build_csr(nf, neighbor, face_neighbor_offsets_, face_neighbor_ids_);
}

inline bool TriangleMesh::faces_share_vertex(index_t f, index_t g) const {
  const Face& a = faces_[f];
  const Face& b = faces_[g];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (a.v[i] == b.v[j]) return true;
  return false;
}

inline index_t TriangleMesh::find_edge(index_t a, index_t b) const {
  if (a < 0 || b < 0 || a >= num_vertices_ || b >= num_vertices_ || a == b) return -1;
  const Edge wanted{{std::min(a, b), std::max(a, b)}};
  const auto it = std::lower_bound(edges_.begin(), edges_.end(), wanted, [](const Edge& x, const Edge& y) {
    return x.v[1] != y.v[1] ? x.v[1] < y.v[1] : x.v[0] < y.v[0];
  });
  if (it != edges_.end() && it->v[0] == wanted.v[0] && it->v[1] == wanted.v[1])
    return static_cast<index_t>(it - edges_.begin());
  return -1;
}

inline bool TriangleMesh::operator==(const TriangleMesh& o) const {
  if (num_vertices_ != o.num_vertices_ || faces_.size() != o.faces_.size()) return false;
  for (std::size_t f = 0; f < faces_.size(); ++f)
    for (int k = 0; k < 3; ++k)
      if (faces_[f].v[k] != o.faces_[f].v[k]) return false;
  return true;
}

template <class T>
void validate_positions(const TriangleMesh& mesh, const std::vector<Vec3<T>>& positions, const std::string& source) {
  if (positions.size() != static_cast<std::size_t>(mesh.num_vertices()))
    throw InputError(source, "", "has " + std::to_string(positions.size()) + " vertex positions, the mesh has " +
                                     std::to_string(mesh.num_vertices()) + " vertices");
  for (std::size_t v = 0; v < positions.size(); ++v) {
    if (!is_finite(positions[v]))
      throw InputError(source, "vertex " + std::to_string(v), "coordinate is NaN or infinite");
  }
}

template <class T>
std::vector<index_t> find_degenerate_faces(const TriangleMesh& mesh, const std::vector<Vec3<T>>& positions) {
  std::vector<index_t> degenerate;
  for (index_t f = 0; f < mesh.num_faces(); ++f) {
    const Face& t = mesh.face(f);
    const Vec3d a = positions[t.v[0]].template cast<double>();
    const Vec3d u = positions[t.v[1]].template cast<double>() - a;
    const Vec3d w = positions[t.v[2]].template cast<double>() - a;
    // |u x w| = |u||w| sin(angle); zero area when the sine is below what rounding can resolve.
    const double area2 = norm(cross(u, w));
    const double scale = norm(u) * norm(w);
    if (!(area2 > 16 * std::numeric_limits<double>::epsilon() * scale) || scale == 0.0) degenerate.push_back(f);
  }
  return degenerate;
}

}  // namespace lwsccd
