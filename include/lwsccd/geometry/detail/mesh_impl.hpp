// lwsccd — definitions for mesh.hpp.
#pragma once

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>

#include "lwsccd/core/error.hpp"
#include "lwsccd/core/parallel.hpp"
#include "lwsccd/geometry/mesh.hpp"

namespace lwsccd {

namespace detail {

// Prefix sums of per-row counts stored at offsets[r + 1] (offsets[0] = 0): row r's first index.
inline void counts_to_offsets(std::vector<index_t>& offsets) {
  std::partial_sum(offsets.begin(), offsets.end(), offsets.begin());
}

}  // namespace detail

// Every derived list is built per vertex, per edge or per face on all cores, with no global sort:
// a face list per vertex (a counting sort in face order, so each row is ascending), then each
// vertex's edges to smaller vertices from its faces, which is the dataset's (max, min) edge order
// group by group. Why: one pass of sorts and searches over every face's three edges took 86-90 ms
// for cloth-ball's 92 K triangles, more than a CPU pipeline's own construction.
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
  const index_t nf = num_faces();
  const auto nv = static_cast<std::size_t>(num_vertices_);

  // Faces of each vertex, ascending.
  vertex_face_offsets_.assign(nv + 1, 0);
  for (const Face& t : faces_)
    for (int k = 0; k < 3; ++k) ++vertex_face_offsets_[t.v[k] + 1];
  detail::counts_to_offsets(vertex_face_offsets_);
  vertex_face_ids_.resize(3 * faces_.size());
  {
    std::vector<index_t> cursor(vertex_face_offsets_.begin(), vertex_face_offsets_.end() - 1);
    for (index_t f = 0; f < nf; ++f)
      for (int k = 0; k < 3; ++k) vertex_face_ids_[cursor[faces_[f].v[k]]++] = f;
  }

  // Edges (lo, hi) grouped by hi ascending, lo ascending in a group: edge_begin[hi] is the group's
  // first edge id.
  std::vector<index_t> edge_begin(nv + 1, 0);
  auto smaller_neighbors = [this](index_t hi, std::vector<index_t>& lows) {
    lows.clear();
    for (const index_t f : vertex_faces(hi))
      for (int k = 0; k < 3; ++k)
        if (faces_[f].v[k] < hi) lows.push_back(faces_[f].v[k]);
    std::sort(lows.begin(), lows.end());
    lows.erase(std::unique(lows.begin(), lows.end()), lows.end());
  };
  const std::size_t vertex_grain = detail::grain_for(nv);
  detail::parallel_ranges(nv, vertex_grain, [&](std::size_t begin, std::size_t end) {
    std::vector<index_t> lows;
    for (std::size_t hi = begin; hi < end; ++hi) {
      smaller_neighbors(static_cast<index_t>(hi), lows);
      edge_begin[hi + 1] = static_cast<index_t>(lows.size());
    }
  });
  detail::counts_to_offsets(edge_begin);
  if (static_cast<std::size_t>(edge_begin[nv]) + nv + faces_.size() > static_cast<std::size_t>(std::numeric_limits<index_t>::max()))
    throw InputError(source, "", "too many features for 32-bit feature ids");
  edges_.resize(static_cast<std::size_t>(edge_begin[nv]));
  // The id of edge (lo, hi), lo < hi, of the mesh: a search in hi's group.
  auto edge_id = [&](index_t lo, index_t hi) {
    const auto first = edges_.begin() + edge_begin[hi], last = edges_.begin() + edge_begin[hi + 1];
    return static_cast<index_t>(std::lower_bound(first, last, lo, [](const Edge& e, index_t v) { return e.v[0] < v; }) - edges_.begin());
  };
  // Faces of each edge, ascending (counted, then listed, group by group: a group's faces are its
  // hi's face row).
  edge_face_offsets_.assign(edges_.size() + 1, 0);
  detail::parallel_ranges(nv, vertex_grain, [&](std::size_t begin, std::size_t end) {
    std::vector<index_t> lows;
    for (std::size_t v = begin; v < end; ++v) {
      const auto hi = static_cast<index_t>(v);
      smaller_neighbors(hi, lows);
      for (std::size_t i = 0; i < lows.size(); ++i) edges_[edge_begin[hi] + i] = Edge{{lows[i], hi}};
      for (const index_t f : vertex_faces(hi))
        for (int k = 0; k < 3; ++k)
          if (faces_[f].v[k] < hi) ++edge_face_offsets_[edge_id(faces_[f].v[k], hi) + 1];
    }
  });
  detail::counts_to_offsets(edge_face_offsets_);
  edge_face_ids_.resize(3 * faces_.size());
  detail::parallel_ranges(nv, vertex_grain, [&](std::size_t begin, std::size_t end) {
    std::vector<index_t> filled;
    for (std::size_t v = begin; v < end; ++v) {
      const auto hi = static_cast<index_t>(v);
      filled.assign(static_cast<std::size_t>(edge_begin[hi + 1] - edge_begin[hi]), 0);
      for (const index_t f : vertex_faces(hi))
        for (int k = 0; k < 3; ++k)
          if (faces_[f].v[k] < hi) {
            const index_t e = edge_id(faces_[f].v[k], hi);
            edge_face_ids_[edge_face_offsets_[e] + filled[e - edge_begin[hi]]++] = f;
          }
    }
  });
  face_edges_.resize(faces_.size());
  const std::size_t face_grain = detail::grain_for(faces_.size());
  detail::parallel_ranges(faces_.size(), face_grain, [&](std::size_t begin, std::size_t end) {
    for (std::size_t f = begin; f < end; ++f)
      for (int k = 0; k < 3; ++k) {
        const index_t a = faces_[f].v[k], b = faces_[f].v[(k + 1) % 3];
        face_edges_[f][k] = edge_id(std::min(a, b), std::max(a, b));
      }
  });

  // Two faces with the same three vertices would make the topology ambiguous: the first edge
  // (in id order) that has two such faces is reported, as a pass over the edges in order would.
  auto duplicate_on = [this](index_t e, index_t& first, index_t& second) {
    const auto fs = edge_faces(e);
    for (std::size_t i = 0; i + 1 < fs.size(); ++i)
      for (std::size_t j = i + 1; j < fs.size(); ++j) {
        auto a = face_edges_[fs[i]], b = face_edges_[fs[j]];
        std::sort(a.begin(), a.end());
        std::sort(b.begin(), b.end());
        if (a == b) {
          first = fs[i], second = fs[j];
          return true;
        }
      }
    return false;
  };
  std::atomic<index_t> first_duplicate_edge{num_edges()};
  detail::parallel_ranges(edges_.size(), detail::grain_for(edges_.size()), [&](std::size_t begin, std::size_t end) {
    index_t first = 0, second = 0;
    for (std::size_t e = begin; e < end; ++e)
      if (duplicate_on(static_cast<index_t>(e), first, second)) {
        index_t seen = first_duplicate_edge.load();
        while (static_cast<index_t>(e) < seen && !first_duplicate_edge.compare_exchange_weak(seen, static_cast<index_t>(e))) {
        }
        return;
      }
  });
  if (first_duplicate_edge.load() < num_edges()) {
    index_t first = 0, second = 0;
    duplicate_on(first_duplicate_edge.load(), first, second);
    throw InputError(source, "face " + std::to_string(second), "duplicate of face " + std::to_string(first) + " (same three vertices)");
  }

  // Faces sharing an edge with each face, ascending (counted, then listed).
  auto neighbors_of = [this](std::size_t f, std::vector<index_t>& out) {
    out.clear();
    for (int k = 0; k < 3; ++k)
      for (const index_t g : edge_faces(face_edges_[f][k]))
        if (g != static_cast<index_t>(f)) out.push_back(g);
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
  };
  face_neighbor_offsets_.assign(faces_.size() + 1, 0);
  detail::parallel_ranges(faces_.size(), face_grain, [&](std::size_t begin, std::size_t end) {
    std::vector<index_t> around;
    for (std::size_t f = begin; f < end; ++f) {
      neighbors_of(f, around);
      face_neighbor_offsets_[f + 1] = static_cast<index_t>(around.size());
    }
  });
  detail::counts_to_offsets(face_neighbor_offsets_);
  face_neighbor_ids_.resize(static_cast<std::size_t>(face_neighbor_offsets_.back()));
  detail::parallel_ranges(faces_.size(), face_grain, [&](std::size_t begin, std::size_t end) {
    std::vector<index_t> around;
    for (std::size_t f = begin; f < end; ++f) {
      neighbors_of(f, around);
      std::copy(around.begin(), around.end(), face_neighbor_ids_.begin() + face_neighbor_offsets_[f]);
    }
  });
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
