// lwsccd — triangle mesh topology: faces, derived unique edges, adjacency, feature ids.
//
// Positions are not part of the topology: a Step (mesh_io.hpp) pairs one mesh with the vertex
// positions at t0 and t1.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "lwsccd/core/config.hpp"
#include "lwsccd/core/span.hpp"
#include "lwsccd/geometry/vec.hpp"

namespace lwsccd {

/// Index of a vertex, edge, face or feature. 32 bits cover meshes well beyond 10M triangles.
using index_t = std::int32_t;

struct Face {
  index_t v[3];
};
struct Edge {
  index_t v[2];  ///< v[0] < v[1]
};

/// Topology of a triangle mesh with derived edges and adjacency.
///
/// Edge ids reproduce the convention of the Belgrod et al. CCD dataset (../shared/data/scenes):
/// the unique undirected edges (min, max) of all faces, sorted by (max, min). Feature ids follow
/// the same convention: vertex v -> v, edge e -> V + e, face f -> V + E + f.
class TriangleMesh {
 public:
  TriangleMesh() = default;

  /// Validates the faces (throws InputError naming `source`, the face and the problem for
  /// out-of-range or repeated indices, or an empty mesh) and derives edges and adjacency.
  TriangleMesh(index_t num_vertices, std::vector<Face> faces, const std::string& source = "mesh");

  index_t num_vertices() const { return num_vertices_; }
  index_t num_faces() const { return static_cast<index_t>(faces_.size()); }
  index_t num_edges() const { return static_cast<index_t>(edges_.size()); }

  const std::vector<Face>& faces() const { return faces_; }
  const std::vector<Edge>& edges() const { return edges_; }
  const Face& face(index_t f) const { return faces_[f]; }
  const Edge& edge(index_t e) const { return edges_[e]; }

  /// Edge ids of face f: (v0,v1), (v1,v2), (v2,v0).
  const std::array<index_t, 3>& face_edges(index_t f) const { return face_edges_[f]; }
  /// Faces that use vertex v, ascending.
  Span<const index_t> vertex_faces(index_t v) const { return csr_row(vertex_face_offsets_, vertex_face_ids_, v); }
  /// Faces that use edge e, ascending (two on a manifold interior edge, one on the boundary).
  Span<const index_t> edge_faces(index_t e) const { return csr_row(edge_face_offsets_, edge_face_ids_, e); }
  /// Faces that share an edge with face f, ascending, without f itself.
  Span<const index_t> face_neighbors(index_t f) const { return csr_row(face_neighbor_offsets_, face_neighbor_ids_, f); }

  /// True when faces f and g (f != g) share at least one vertex.
  bool faces_share_vertex(index_t f, index_t g) const;
  /// True when edge e is incident to one face only.
  bool is_boundary_edge(index_t e) const { return edge_faces(e).size() == 1; }
  /// The edge id of (a, b) in either order, or -1 when the mesh has no such edge.
  index_t find_edge(index_t a, index_t b) const;

  index_t vertex_feature_id(index_t v) const { return v; }
  index_t edge_feature_id(index_t e) const { return num_vertices_ + e; }
  index_t face_feature_id(index_t f) const { return num_vertices_ + num_edges() + f; }

  bool operator==(const TriangleMesh& o) const;  ///< same vertex count and identical faces

 private:
  static Span<const index_t> csr_row(const std::vector<index_t>& offsets, const std::vector<index_t>& ids,
                                     index_t row) {
    return {ids.data() + offsets[row], static_cast<std::size_t>(offsets[row + 1] - offsets[row])};
  }

  index_t num_vertices_ = 0;
  std::vector<Face> faces_;
  std::vector<Edge> edges_;
  std::vector<std::array<index_t, 3>> face_edges_;
  std::vector<index_t> vertex_face_offsets_, vertex_face_ids_;
  std::vector<index_t> edge_face_offsets_, edge_face_ids_;
  std::vector<index_t> face_neighbor_offsets_, face_neighbor_ids_;
};

/// Throws InputError naming `source` and the vertex when a position is NaN or infinite, or when
/// the count differs from the mesh's vertex count.
template <class T>
void validate_positions(const TriangleMesh& mesh, const std::vector<Vec3<T>>& positions, const std::string& source);

/// Faces whose three vertices are collinear or coincident up to rounding (zero area).
/// Degenerate faces are legal input; callers report them, they are not fatal.
template <class T>
std::vector<index_t> find_degenerate_faces(const TriangleMesh& mesh, const std::vector<Vec3<T>>& positions);

}  // namespace lwsccd

#include "lwsccd/geometry/detail/mesh_impl.hpp"
