// lwsccd — reading elemental CCD queries: the CSV files of the Wang et al. 2021 query sets
// (../shared/data/queries/<set>/{vertex-face,edge-edge}/*.csv) and of the scenes' queries/ folder,
// and building queries from a mesh's feature ids.
//
// CSV: 8 rows per query, each row x_num,x_den,y_num,y_den,z_num,z_den[,truth]. Rationals are
// converted to the nearest double, which is exact when the numerator fits in 53 bits and the
// denominator is a power of two (the case in the dataset); `inexact` counts the values that were not.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "lwsccd/ccd_query.hpp"
#include "lwsccd/mesh.hpp"

namespace lwsccd {

struct QueryFile {
  std::vector<std::array<Vec3d, 8>> queries;  ///< the eight points in file order
  std::vector<signed char> truth;             ///< 1/0 from the 7th column, -1 where absent
  std::size_t inexact = 0;                    ///< coordinates not exactly representable in double
};

/// Reads one query CSV. Throws InputError naming the file, line and problem (bad number, zero
/// denominator, wrong column count, a row count not a multiple of 8, rows of one query with
/// different truth values).
QueryFile load_query_csv(const std::string& path);

template <class T>
VertexFaceQuery<T> vertex_face_query(const std::array<Vec3d, 8>& p) {
  return VertexFaceQuery<double>{p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7]}.template cast<T>();
}
template <class T>
EdgeEdgeQuery<T> edge_edge_query(const std::array<Vec3d, 8>& p) {
  return EdgeEdgeQuery<double>{p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7]}.template cast<T>();
}

/// The arrays a kernel needs to turn feature ids into query points.
struct MeshFeatures {
  const Face* faces;
  const Edge* edges;
  index_t num_vertices;
  index_t num_edges;
};

/// Vertex-face query of (vertex id, face feature id) in the dataset's id convention.
template <class T, class P>
LWSCCD_HD VertexFaceQuery<T> gather_vertex_face(const MeshFeatures& m, const Vec3<P>* x0, const Vec3<P>* x1,
                                                index_t vertex, index_t face_feature) {
  const Face f = m.faces[face_feature - m.num_vertices - m.num_edges];
  return VertexFaceQuery<T>{x0[vertex].template cast<T>(),  x0[f.v[0]].template cast<T>(), x0[f.v[1]].template cast<T>(),
                            x0[f.v[2]].template cast<T>(),  x1[vertex].template cast<T>(), x1[f.v[0]].template cast<T>(),
                            x1[f.v[1]].template cast<T>(), x1[f.v[2]].template cast<T>()};
}

/// Edge-edge query of two edge feature ids.
template <class T, class P>
LWSCCD_HD EdgeEdgeQuery<T> gather_edge_edge(const MeshFeatures& m, const Vec3<P>* x0, const Vec3<P>* x1,
                                            index_t edge_a, index_t edge_b) {
  const Edge a = m.edges[edge_a - m.num_vertices], b = m.edges[edge_b - m.num_vertices];
  return EdgeEdgeQuery<T>{x0[a.v[0]].template cast<T>(), x0[a.v[1]].template cast<T>(), x0[b.v[0]].template cast<T>(),
                          x0[b.v[1]].template cast<T>(), x1[a.v[0]].template cast<T>(), x1[a.v[1]].template cast<T>(),
                          x1[b.v[0]].template cast<T>(), x1[b.v[1]].template cast<T>()};
}

inline MeshFeatures mesh_features(const TriangleMesh& mesh) {
  return {mesh.faces().data(), mesh.edges().data(), mesh.num_vertices(), mesh.num_edges()};
}

}  // namespace lwsccd

#include "lwsccd/detail/query_io_impl.hpp"
