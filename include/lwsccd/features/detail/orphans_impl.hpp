// lwsccd — definitions for orphans.hpp.
#pragma once

#include <algorithm>
#include <iterator>
#include <limits>

#include "lwsccd/features/orphans.hpp"

namespace lwsccd {

namespace detail {

// The faces that share a vertex with face f, f excluded, ascending.
inline void vertex_ring_of_face(const TriangleMesh& mesh, index_t f, std::vector<index_t>& ring) {
  // The vertices' face lists are sorted (TriangleMesh's rows): merged in one pass, each face once,
  // f left out (a pipeline's construction makes a ring per vertex and per edge).
  ring.clear();
  const Face& t = mesh.face(f);
  const Span<const index_t> rows[3] = {mesh.vertex_faces(t.v[0]), mesh.vertex_faces(t.v[1]), mesh.vertex_faces(t.v[2])};
  std::size_t at[3] = {0, 0, 0};
  constexpr index_t kDone = std::numeric_limits<index_t>::max();
  for (;;) {
    index_t next = kDone;
    for (int k = 0; k < 3; ++k)
      if (at[k] < rows[k].size()) next = std::min(next, rows[k][at[k]]);
    if (next == kDone) return;
    for (int k = 0; k < 3; ++k)
      if (at[k] < rows[k].size() && rows[k][at[k]] == next) ++at[k];
    if (next != f) ring.push_back(next);
  }
}

// For each face, the other faces that share at least one vertex with it (CSR, ascending).
inline void face_vertex_rings(const TriangleMesh& mesh, std::vector<index_t>& offsets, std::vector<index_t>& ids) {
  const index_t nf = mesh.num_faces();
  offsets.assign(static_cast<std::size_t>(nf) + 1, 0);
  ids.clear();
  std::vector<index_t> row;
  for (index_t f = 0; f < nf; ++f) {
    vertex_ring_of_face(mesh, f, row);
    ids.insert(ids.end(), row.begin(), row.end());
    offsets[f + 1] = static_cast<index_t>(ids.size());
  }
}

inline bool face_has_vertex(const Face& t, index_t v) { return t.v[0] == v || t.v[1] == v || t.v[2] == v; }

inline bool edges_share_vertex(const Edge& x, const Edge& y) {
  return x.v[0] == y.v[0] || x.v[0] == y.v[1] || x.v[1] == y.v[0] || x.v[1] == y.v[1];
}

// Counts, for every face g, how many faces of `incident` share a vertex with g (g itself
// excluded from its own ring). Faces with a nonzero count are listed in `touched`.
template <class Faces>
void count_adjacent(const Faces& incident, const std::vector<index_t>& ring_offsets,
                    const std::vector<index_t>& ring_ids, std::vector<index_t>& count, std::vector<index_t>& touched) {
  touched.clear();
  for (const index_t t : incident)
    for (index_t k = ring_offsets[t]; k < ring_offsets[t + 1]; ++k) {
      const index_t g = ring_ids[k];
      if (count[g]++ == 0) touched.push_back(g);
    }
}

}  // namespace detail

inline OrphanSets find_orphan_sets(const TriangleMesh& mesh) {
  std::vector<index_t> ring_offsets, ring_ids;
  detail::face_vertex_rings(mesh, ring_offsets, ring_ids);
  std::vector<index_t> count(static_cast<std::size_t>(mesh.num_faces()), 0);
  std::vector<index_t> touched;
  OrphanSets out;

  // VF: OIS(v) = faces of v; an orphan face shares a vertex with all of them and misses v.
  for (index_t v = 0; v < mesh.num_vertices(); ++v) {
    const auto ois = mesh.vertex_faces(v);
    if (ois.size() == 0) continue;
    detail::count_adjacent(ois, ring_offsets, ring_ids, count, touched);
    for (const index_t g : touched) {
      if (count[g] == static_cast<index_t>(ois.size()) && !detail::face_has_vertex(mesh.face(g), v))
        out.vf.emplace_back(mesh.vertex_feature_id(v), mesh.face_feature_id(g));
      count[g] = 0;
    }
  }

  // EE: OIS(e) = faces of e. Faces adjacent to all of OIS(e) have count == |OIS(e)|; an edge e'
  // of such a face, sharing no vertex with e, is an orphan partner when all its faces are.
  for (index_t e = 0; e < mesh.num_edges(); ++e) {
    const auto ois = mesh.edge_faces(e);
    const auto m = static_cast<index_t>(ois.size());
    detail::count_adjacent(ois, ring_offsets, ring_ids, count, touched);
    for (const index_t g : touched) {
      if (count[g] != m) continue;
      for (const index_t ea : mesh.face_edges(g)) {
        if (ea <= e || detail::edges_share_vertex(mesh.edge(e), mesh.edge(ea))) continue;
        const auto ois_a = mesh.edge_faces(ea);
        if (std::all_of(ois_a.begin(), ois_a.end(), [&](index_t t) { return count[t] == m; }))
          out.ee.emplace_back(mesh.edge_feature_id(e), mesh.edge_feature_id(ea));
      }
    }
    for (const index_t g : touched) count[g] = 0;
  }

  for (auto* list : {&out.vf, &out.ee}) {
    std::sort(list->begin(), list->end());
    list->erase(std::unique(list->begin(), list->end()), list->end());
  }
  return out;
}

inline FeaturePairs culled_feature_pairs(const TriangleMesh& mesh, const std::vector<TrianglePair>& pairs,
                                         const OrphanSets& orphans) {
  std::vector<TrianglePair> separated;
  separated.reserve(pairs.size());
  std::copy_if(pairs.begin(), pairs.end(), std::back_inserter(separated),
               [](const TrianglePair& p) { return !p.adjacent; });
  FeaturePairs base = feature_pairs(mesh, separated);
  FeaturePairs out;
  out.vf.reserve(base.vf.size() + orphans.vf.size());
  out.ee.reserve(base.ee.size() + orphans.ee.size());
  std::set_union(base.vf.begin(), base.vf.end(), orphans.vf.begin(), orphans.vf.end(), std::back_inserter(out.vf));
  std::set_union(base.ee.begin(), base.ee.end(), orphans.ee.begin(), orphans.ee.end(), std::back_inserter(out.ee));
  return out;
}

inline OrphanSets orphans_for_layout(const TriangleMesh& mesh, const OrphanSets& orphans, const BodyLayout& layout) {
  layout.validate(mesh);
  if (layout.face_body.empty()) return orphans;
  // Body of each vertex and edge feature: the one body of its faces, or kMixed when shared.
  constexpr index_t kUnset = -2, kMixed = -1;
  const std::size_t features = static_cast<std::size_t>(mesh.num_vertices() + mesh.num_edges() + mesh.num_faces());
  std::vector<index_t> body(features, kUnset);
  auto assign = [&](index_t feature, index_t b) {
    index_t& slot = body[static_cast<std::size_t>(feature)];
    slot = slot == kUnset || slot == b ? b : kMixed;
  };
  for (index_t f = 0; f < mesh.num_faces(); ++f) {
    const index_t b = layout.face_body[f];
    assign(mesh.face_feature_id(f), b);
    for (int k = 0; k < 3; ++k) {
      assign(mesh.vertex_feature_id(mesh.face(f).v[k]), b);
      assign(mesh.edge_feature_id(mesh.face_edges(f)[k]), b);
    }
  }
  auto keep = [&](const std::pair<index_t, index_t>& p) {
    const index_t a = body[static_cast<std::size_t>(p.first)], b = body[static_cast<std::size_t>(p.second)];
    return a < 0 || a != b || layout.body_self_collides.empty() || layout.body_self_collides[a];
  };
  OrphanSets out;
  std::copy_if(orphans.vf.begin(), orphans.vf.end(), std::back_inserter(out.vf), keep);
  std::copy_if(orphans.ee.begin(), orphans.ee.end(), std::back_inserter(out.ee), keep);
  return out;
}

}  // namespace lwsccd
