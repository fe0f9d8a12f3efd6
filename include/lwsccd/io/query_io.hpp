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

#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/geometry/mesh.hpp"
#include "lwsccd/narrow_phase/ccd_query.hpp"

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

/// Queries are expressed relative to their first point (translated in the input precision, then
/// rounded to T): CCD is translation invariant, and small relative coordinates keep far more of
/// the features' geometry when T is float.
template <class T, class P>
LWSCCD_HD Vec3<T> local_point(const Vec3<P>& x, const Vec3<P>& origin) {
  return detail::vsub(x, origin).template cast<T>();
}

template <class T>
VertexFaceQuery<T> vertex_face_query(const std::array<Vec3d, 8>& p) {
  const Vec3d o = p[0];
  return {local_point<T>(p[0], o), local_point<T>(p[1], o), local_point<T>(p[2], o), local_point<T>(p[3], o),
          local_point<T>(p[4], o), local_point<T>(p[5], o), local_point<T>(p[6], o), local_point<T>(p[7], o)};
}
template <class T>
EdgeEdgeQuery<T> edge_edge_query(const std::array<Vec3d, 8>& p) {
  const Vec3d o = p[0];
  return {local_point<T>(p[0], o), local_point<T>(p[1], o), local_point<T>(p[2], o), local_point<T>(p[3], o),
          local_point<T>(p[4], o), local_point<T>(p[5], o), local_point<T>(p[6], o), local_point<T>(p[7], o)};
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
  const Vec3<P> o = x0[vertex];
  return VertexFaceQuery<T>{local_point<T>(x0[vertex], o),  local_point<T>(x0[f.v[0]], o), local_point<T>(x0[f.v[1]], o),
                            local_point<T>(x0[f.v[2]], o),  local_point<T>(x1[vertex], o), local_point<T>(x1[f.v[0]], o),
                            local_point<T>(x1[f.v[1]], o), local_point<T>(x1[f.v[2]], o)};
}

/// Edge-edge query of two edge feature ids.
template <class T, class P>
LWSCCD_HD EdgeEdgeQuery<T> gather_edge_edge(const MeshFeatures& m, const Vec3<P>* x0, const Vec3<P>* x1,
                                            index_t edge_a, index_t edge_b) {
  const Edge a = m.edges[edge_a - m.num_vertices], b = m.edges[edge_b - m.num_vertices];
  const Vec3<P> o = x0[a.v[0]];
  return EdgeEdgeQuery<T>{local_point<T>(x0[a.v[0]], o), local_point<T>(x0[a.v[1]], o), local_point<T>(x0[b.v[0]], o),
                          local_point<T>(x0[b.v[1]], o), local_point<T>(x1[a.v[0]], o), local_point<T>(x1[a.v[1]], o),
                          local_point<T>(x1[b.v[0]], o), local_point<T>(x1[b.v[1]], o)};
}

/// A vertex's positions at t = 0 and t = 1 rounded to float (to nearest; float input exactly),
/// in one 32-byte record: the certified path's single-precision passes (FP32 first) read a
/// vertex in one memory transaction, and compute in float alone (no double subtraction of an
/// origin: they subtract theirs in float, with a bound that covers the rounding to float).
struct alignas(32) SingleVertex {
  Vec3f x0, x1;
  float unused[2];
};

template <class P>
LWSCCD_HD SingleVertex single_vertex(const Vec3<P>& x0, const Vec3<P>& x1) {
  return {x0.template cast<float>(), x1.template cast<float>(), {0.0f, 0.0f}};
}

/// Every vertex's SingleVertex (the CPU batch; the GPU builds the same records in a kernel).
template <class P>
std::vector<SingleVertex> single_vertices(const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1) {
  std::vector<SingleVertex> v(x0.size());
  for (std::size_t i = 0; i < x0.size(); ++i) v[i] = single_vertex(x0[i], x1[i]);
  return v;
}

/// The pair's query in float from SingleVertex records, in absolute coordinates (the
/// single-precision passes take it as it is: detail::relative_single).
LWSCCD_HD inline VertexFaceQuery<float> gather_single_vertex_face(const MeshFeatures& m, const SingleVertex* x, index_t vertex,
                                                                  index_t face_feature) {
  const Face f = m.faces[face_feature - m.num_vertices - m.num_edges];
  const SingleVertex p = x[vertex], a = x[f.v[0]], b = x[f.v[1]], c = x[f.v[2]];
  return {p.x0, a.x0, b.x0, c.x0, p.x1, a.x1, b.x1, c.x1};
}
LWSCCD_HD inline EdgeEdgeQuery<float> gather_single_edge_edge(const MeshFeatures& m, const SingleVertex* x, index_t edge_a,
                                                              index_t edge_b) {
  const Edge e = m.edges[edge_a - m.num_vertices], g = m.edges[edge_b - m.num_vertices];
  const SingleVertex a = x[e.v[0]], b = x[e.v[1]], c = x[g.v[0]], d = x[g.v[1]];
  return {a.x0, b.x0, c.x0, d.x0, a.x1, b.x1, c.x1, d.x1};
}

inline MeshFeatures mesh_features(const TriangleMesh& mesh) {
  return {mesh.faces().data(), mesh.edges().data(), mesh.num_vertices(), mesh.num_edges()};
}

}  // namespace lwsccd

#include "lwsccd/io/detail/query_io_impl.hpp"
