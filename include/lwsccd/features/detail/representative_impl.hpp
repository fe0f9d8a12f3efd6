// lwsccd — definitions for representative.hpp.
#pragma once

#include <algorithm>
#include <numeric>
#include <string>
#include <utility>

#include "lwsccd/core/error.hpp"
#include "lwsccd/core/parallel.hpp"

#include "lwsccd/features/representative.hpp"

namespace lwsccd {

namespace detail {

// (vertex_ring_of_face and edges_share_vertex: orphans_impl.hpp.)

// Empties a part, keeping its memory.
inline void clear_part(FeaturePairs& p) { p.vf.clear(), p.ee.clear(); }
template <class T>
void clear_part(std::vector<T>& p) { p.clear(); }

// Splits [0, n) into contiguous ranges, several per worker (emission is uneven: contacts
// cluster), runs body(begin, end, part) on each in parallel, each with its own of `parts`
// (emptied first, their memory kept), in range order (so that their concatenation keeps the
// input order).
template <class Part, class Body>
void ordered_parts(std::size_t n, std::vector<Part>& parts, Body body) {
  const std::size_t count = std::max<std::size_t>(1, std::min<std::size_t>(n / 256 + 1, std::size_t(worker_count()) * 8));
  parts.resize(count);
  parallel_parts(n, count, [&](std::size_t begin, std::size_t end, std::size_t k) {
    // Filled in this frame (the parts' list headers sit side by side: appending through them
    // would bounce their cache lines between threads), then moved back.
    Part part;
    std::swap(part, parts[k]);
    clear_part(part);
    body(begin, end, part);
    std::swap(part, parts[k]);
  });
}

// Appends the parts' lists, then the extra vf and ee lists, to out's from (vf_at, ee_at) on, in
// order: one reservation per list (its new pages made present by all threads), the copies in
// parallel.
using PairLists = std::vector<std::vector<std::pair<index_t, index_t>>>;
inline void copy_parts(const std::vector<FeaturePairs>& parts, FeaturePairs& out, std::size_t vf_at, std::size_t ee_at,
                       const PairLists& more_vf = {}, const PairLists& more_ee = {}) {
  using Pairs = std::vector<std::pair<index_t, index_t>>;
  struct Source {
    const Pairs* from;
    Pairs* to;
    std::size_t at;
  };
  std::vector<Source> sources;
  sources.reserve(2 * parts.size() + more_vf.size() + more_ee.size());
  std::size_t vf_total = vf_at, ee_total = ee_at;
  auto add = [&](const Pairs& from, Pairs& to, std::size_t& total) {
    sources.push_back(Source{&from, &to, total});
    total += from.size();
  };
  for (const auto& p : parts) add(p.vf, out.vf, vf_total), add(p.ee, out.ee, ee_total);
  for (const auto& l : more_vf) add(l, out.vf, vf_total);
  for (const auto& l : more_ee) add(l, out.ee, ee_total);
  reserve_large(out.vf, vf_total, true);
  reserve_large(out.ee, ee_total, true);
  out.vf.resize(vf_total);
  out.ee.resize(ee_total);
  parallel_ranges(sources.size(), 1, [&](std::size_t first, std::size_t last) {
    for (std::size_t j = first; j < last; ++j)
      std::copy(sources[j].from->begin(), sources[j].from->end(), sources[j].to->begin() + static_cast<std::ptrdiff_t>(sources[j].at));
  });
}
inline void append_parts(const std::vector<FeaturePairs>& parts, FeaturePairs& out) {
  copy_parts(parts, out, out.vf.size(), out.ee.size());
}

}  // namespace detail

inline RepresentativeTriangles::RepresentativeTriangles(const TriangleMesh& mesh, BodyLayout layout)
    : mesh_(&mesh), layout_(std::move(layout)) {
  layout_.validate(mesh);
  const index_t nf = mesh.num_faces(), nv = mesh.num_vertices(), ne = mesh.num_edges();
  represents_.assign(static_cast<std::size_t>(nf), 0);
  face_edges_.resize(static_cast<std::size_t>(nf));
  for (index_t f = 0; f < nf; ++f) face_edges_[f] = {{mesh.face_edges(f)[0], mesh.face_edges(f)[1], mesh.face_edges(f)[2]}};

  // Greedy balance: each feature goes to the incident face that represents the fewest of its kind
  // so far (ties: the lowest face id), so that no triangle pair carries much more than another.
  std::vector<unsigned char> vertices_held(static_cast<std::size_t>(nf), 0), edges_held(static_cast<std::size_t>(nf), 0);
  vertex_owner_.assign(static_cast<std::size_t>(nv), -1);
  for (index_t v = 0; v < nv; ++v) {
    index_t best = -1;
    for (const index_t f : mesh.vertex_faces(v))
      if (best < 0 || vertices_held[f] < vertices_held[best]) best = f;
    if (best < 0) continue;  // a vertex of no face is not part of the surface
    vertex_owner_[v] = best;
    ++vertices_held[best];
    const Face& t = mesh.face(best);
    for (int k = 0; k < 3; ++k)
      if (t.v[k] == v) represents_[best] |= static_cast<unsigned char>(1u << k);
  }
  edge_owner_.assign(static_cast<std::size_t>(ne), -1);
  // Edges with the fewest faces first (a boundary edge has no choice), then the others.
  std::vector<index_t> edge_order(static_cast<std::size_t>(ne));
  std::iota(edge_order.begin(), edge_order.end(), 0);
  std::stable_sort(edge_order.begin(), edge_order.end(),
                   [&](index_t a, index_t b) { return mesh.edge_faces(a).size() < mesh.edge_faces(b).size(); });
  for (const index_t e : edge_order) {
    index_t best = -1;
    for (const index_t f : mesh.edge_faces(e))
      if (best < 0 || edges_held[f] < edges_held[best]) best = f;
    edge_owner_[e] = best;
    ++edges_held[best];
    for (int k = 0; k < 3; ++k)
      if (face_edges_[best].e[k] == e) represents_[best] |= static_cast<unsigned char>(1u << (3 + k));
  }

  // Repair: a face left with three edges passes one along a short chain of faces (each hands an
  // edge it holds to the face across it) to a face that holds at most one: an augmenting path,
  // searched breadth-first within a bounded neighbourhood.
  auto move_edge = [&](index_t e, index_t from, index_t to) {
    for (int j = 0; j < 3; ++j) {
      if (face_edges_[from].e[j] == e) represents_[from] &= static_cast<unsigned char>(~(1u << (3 + j)));
      if (face_edges_[to].e[j] == e) represents_[to] |= static_cast<unsigned char>(1u << (3 + j));
    }
    --edges_held[from], ++edges_held[to];
    edge_owner_[e] = to;
  };
  constexpr std::size_t kSearchFaces = 256;
  std::vector<index_t> queue, parent_face, parent_edge;
  for (index_t f = 0; f < nf; ++f) {
    if (edges_held[f] <= 2) continue;
    queue.assign(1, f);
    parent_face.assign(1, -1);
    parent_edge.assign(1, -1);
    for (std::size_t head = 0; head < queue.size() && queue.size() < kSearchFaces; ++head) {
      const index_t x = queue[head];
      index_t found = -1;
      for (int k = 0; k < 3 && found < 0; ++k) {
        if (!((represents_[x] >> (3 + k)) & 1u)) continue;
        const index_t e = face_edges_[x].e[k];
        for (const index_t y : mesh.edge_faces(e)) {
          if (std::find(queue.begin(), queue.end(), y) != queue.end()) continue;
          queue.push_back(y);
          parent_face.push_back(static_cast<index_t>(head));
          parent_edge.push_back(e);
          if (edges_held[y] < 2) {
            found = static_cast<index_t>(queue.size() - 1);
            break;
          }
        }
      }
      if (found >= 0) {
        for (index_t at = found; parent_face[at] >= 0; at = parent_face[at])
          move_edge(parent_edge[at], queue[parent_face[at]], queue[at]);
        break;
      }
    }
  }

  // Orphans: the pairs whose representing faces share a vertex (the traversal skips those
  // triangle pairs). A vertex's face partners lie in its representing face's vertex ring; an
  // edge's edge partners are the edges that faces of that ring represent. Found on all cores in
  // contiguous ranges of vertices and of edges, each range's pairs in order (a vertex's in its
  // ring's ascending order, an edge's sorted), so that the ranges joined are sorted: feature ids
  // grow with vertex, edge and face ids.
  using Pairs = std::vector<std::pair<index_t, index_t>>;
  std::vector<Pairs> parts;
  detail::ordered_parts(static_cast<std::size_t>(nv), parts, [&](std::size_t begin, std::size_t end, Pairs& out) {
    std::vector<index_t> ring;
    for (auto v = static_cast<index_t>(begin); v < static_cast<index_t>(end); ++v) {
      const index_t owner = vertex_owner_[v];
      if (owner < 0) continue;
      detail::vertex_ring_of_face(mesh, owner, ring);
      for (const index_t g : ring) {
        const Face& t = mesh.face(g);
        if (t.v[0] == v || t.v[1] == v || t.v[2] == v) continue;  // incident: never a query
        if (layout_.considers(owner, g)) out.emplace_back(mesh.vertex_feature_id(v), mesh.face_feature_id(g));
      }
    }
  });
  detail::concatenate_in_parallel(parts, orphans_.vf);
  detail::ordered_parts(static_cast<std::size_t>(ne), parts, [&](std::size_t begin, std::size_t end, Pairs& out) {
    std::vector<index_t> ring;
    for (auto e = static_cast<index_t>(begin); e < static_cast<index_t>(end); ++e) {
      const index_t owner = edge_owner_[e];
      detail::vertex_ring_of_face(mesh, owner, ring);
      const std::size_t first = out.size();
      for (const index_t g : ring) {
        for (int k = 0; k < 3; ++k) {
          if (!((represents_[g] >> (3 + k)) & 1u)) continue;
          const index_t other = face_edges_[g].e[k];
          if (other <= e || detail::edges_share_vertex(mesh.edge(e), mesh.edge(other))) continue;  // listed once; adjacent edges never
          if (layout_.considers(owner, g)) out.emplace_back(mesh.edge_feature_id(e), mesh.edge_feature_id(other));
        }
      }
      std::sort(out.begin() + static_cast<std::ptrdiff_t>(first), out.end());
    }
  });
  detail::concatenate_in_parallel(parts, orphans_.ee);
}

inline index_t RepresentativeTriangles::owner_of_feature(index_t id) const {
  const index_t nv = mesh_->num_vertices(), ne = mesh_->num_edges();
  if (id < nv) return vertex_owner_[id];
  if (id < nv + ne) return edge_owner_[id - nv];
  return id - nv - ne;
}

template <class P>
std::vector<Aabbf> feature_boxes(const TriangleMesh& mesh, const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1,
                                 double margin) {
  const float grow = detail::checked_margin<Aabbf>(margin, "feature_boxes");
  const index_t n = mesh.num_vertices() + mesh.num_edges() + mesh.num_faces();
  std::vector<Aabbf> boxes(static_cast<std::size_t>(n));
  detail::parallel_ranges(static_cast<std::size_t>(n), detail::grain_for(static_cast<std::size_t>(n)),
                          [&](std::size_t begin, std::size_t end) {
                            for (auto id = static_cast<index_t>(begin); id < static_cast<index_t>(end); ++id)
                              boxes[id] = feature_box(mesh.faces().data(), mesh.edges().data(), mesh.num_vertices(),
                                                      mesh.num_edges(), x0.data(), x1.data(), id, grow);
                          });
  return boxes;
}

template <class P>
std::vector<FaceCorners> face_corners(const TriangleMesh& mesh, const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1) {
  const auto nv = static_cast<std::size_t>(mesh.num_vertices());
  if (x0.size() != nv || x1.size() != nv)
    throw InputError("face_corners", x0.size() != nv ? "x0" : "x1",
                     "has " + std::to_string((x0.size() != nv ? x0 : x1).size()) + " positions, the mesh has " +
                         std::to_string(nv) + " vertices");
  const auto nf = static_cast<std::size_t>(mesh.num_faces());
  std::vector<FaceCorners> corners(nf);
  detail::parallel_ranges(nf, detail::grain_for(nf), [&](std::size_t begin, std::size_t end) {
    for (std::size_t f = begin; f < end; ++f) corners[f] = face_corners(mesh.faces()[f], x0.data(), x1.data());
  });
  return corners;
}

inline FeaturePairs emit_feature_pairs(const RepresentativeTriangles& rep, const std::vector<TrianglePair>& candidates,
                                       const std::vector<Aabbf>& boxes, const std::vector<FaceCorners>* corners) {
  return emit_feature_pairs(rep, candidates.data(), candidates.size(), boxes, true, corners);
}

inline FeaturePairs emit_feature_pairs(const RepresentativeTriangles& rep, const TrianglePair* candidates, std::size_t n,
                                       const std::vector<Aabbf>& boxes, bool with_orphans,
                                       const std::vector<FaceCorners>* corners) {
  FeaturePairs out;
  FeaturePairParts parts;
  emit_feature_pairs_into(rep, candidates, n, boxes, with_orphans, out, parts, corners);
  return out;
}

namespace detail {

inline unsigned count_bits(unsigned bits) {
  unsigned n = 0;
  for (; bits; bits &= bits - 1) ++n;
  return n;
}

// Fills `out` from the view's boxes: each face's box and the boxes and ids of the features it
// represents, face after face (the offsets a serial pass, the boxes on all cores), and with corners
// each face's summary of them.
inline void pack_emission(const EmissionView& view, index_t num_faces, PackedEmission& out) {
  const auto nf = static_cast<std::size_t>(num_faces);
  out.faces.resize(nf);
  out.face_feature_base = view.face_feature(0);
  out.corners = view.corners;
  std::uint32_t at = 0;
  for (std::size_t f = 0; f < nf; ++f) {
    out.faces[f].first = at;
    out.faces[f].represents = view.represents[f];
    at += count_bits(view.represents[f] & 0x3fu);
  }
  out.features.resize(at);
  out.corner_summaries.resize(view.corners ? nf : 0);
  parallel_ranges(nf, grain_for(nf), [&](std::size_t begin, std::size_t end) {
    for (std::size_t f = begin; f < end; ++f) {
      if (view.corners) out.corner_summaries[f] = summarize_corners(view.corners[f]);
      PackedEmissionFace& face = out.faces[f];
      face.box = view.boxes[view.face_feature(static_cast<index_t>(f))];
      PackedFeature* next = out.features.data() + face.first;
      const unsigned r = face.represents;
      for (int k = 0; k < 3; ++k)
        if ((r >> k) & 1u) {
          const index_t v = view.faces[f].v[k];
          *next++ = {view.boxes[v], v};
        }
      for (int k = 0; k < 3; ++k)
        if ((r >> (3 + k)) & 1u) {
          const index_t id = view.edge_feature(view.face_edges[f].e[k]);
          *next++ = {view.boxes[id], id};
        }
    }
  });
}

// emit_triangle_pair over the packed boxes: the same pairs in the same order (vertices of a, of
// b, then edge pairs in (a's, b's) order), each kept when emission_mask keeps it.
// (With corners, faces_apart first, from the faces' summaries: the pairs apart skip the boxes'
// tests, as on the GPU. Boxes first took cloth-ball's emission 87 -> 120 ms on two cores.)
template <class OnVf, class OnEe>
void emit_packed_triangle_pair(const PackedEmission& packed, index_t a, index_t b, OnVf&& on_vf, OnEe&& on_ee) {
  const PackedEmissionFace& fa = packed.faces[static_cast<std::size_t>(a)];
  const PackedEmissionFace& fb = packed.faces[static_cast<std::size_t>(b)];
  const unsigned ra = fa.represents, rb = fb.represents;
  if ((ra | rb) == 0) return;
  if (packed.corners) {
    const auto fa_id = static_cast<std::size_t>(a), fb_id = static_cast<std::size_t>(b);
    if (faces_apart(packed.corner_summaries[fa_id], packed.corners[fa_id], packed.corner_summaries[fb_id], packed.corners[fb_id]))
      return;
  }
  const PackedFeature* of_a = packed.features.data() + fa.first;
  const PackedFeature* of_b = packed.features.data() + fb.first;
  const unsigned vertices_a = count_bits(ra & 7u), vertices_b = count_bits(rb & 7u);
  for (unsigned i = 0; i < vertices_a; ++i)
    if (of_a[i].box.overlaps(fb.box)) on_vf(of_a[i].id, packed.face_feature_base + b);
  for (unsigned i = 0; i < vertices_b; ++i)
    if (of_b[i].box.overlaps(fa.box)) on_vf(of_b[i].id, packed.face_feature_base + a);
  const unsigned edges_a = count_bits(ra >> 3), edges_b = count_bits(rb >> 3);
  for (unsigned x = 0; x < edges_a; ++x) {
    const PackedFeature& edge_x = of_a[vertices_a + x];
    for (unsigned y = 0; y < edges_b; ++y) {
      const PackedFeature& edge_y = of_b[vertices_b + y];
      if (edge_x.box.overlaps(edge_y.box)) edge_x.id < edge_y.id ? on_ee(edge_x.id, edge_y.id) : on_ee(edge_y.id, edge_x.id);
    }
  }
}

// The corners an emission or an oracle was given (null: none), checked to hold one per face.
inline const FaceCorners* checked_corners(const RepresentativeTriangles& rep, const std::vector<FaceCorners>* corners,
                                          const char* where) {
  if (corners && corners->size() != static_cast<std::size_t>(rep.mesh().num_faces()))
    throw InputError(where, "corners",
                     "has " + std::to_string(corners->size()) + " entries, the mesh has " +
                         std::to_string(rep.mesh().num_faces()) + " faces");
  return corners ? corners->data() : nullptr;
}

// The feature pairs of n candidates, candidates_in(begin, end, fn) calling fn on the candidates
// [begin, end) in order, left in `parts` (FeaturePairParts: each list emptied first, its memory
// kept): the candidates' parts, then the orphans' kept pairs when `with_orphans`.
template <class CandidatesIn>
void emit_feature_pair_parts(const RepresentativeTriangles& rep, std::size_t n, CandidatesIn&& candidates_in,
                             const std::vector<Aabbf>& boxes, bool with_orphans, FeaturePairParts& parts,
                             const std::vector<FaceCorners>* corners) {
  const TriangleMesh& mesh = rep.mesh();
  const std::size_t features = static_cast<std::size_t>(mesh.num_vertices() + mesh.num_edges() + mesh.num_faces());
  if (boxes.size() != features)
    throw InputError("emit_feature_pairs", "boxes",
                     "has " + std::to_string(boxes.size()) + " entries, the mesh has " + std::to_string(features) + " features");
  const EmissionView view = rep.view(boxes.data(), checked_corners(rep, corners, "emit_feature_pairs"));
  pack_emission(view, mesh.num_faces(), parts.packed);
  const PackedEmission& packed = parts.packed;
  ordered_parts(n, parts.candidates, [&](std::size_t begin, std::size_t end, FeaturePairs& part) {
    candidates_in(begin, end, [&](const TrianglePair& p) {
      if (p.adjacent) return;
      emit_packed_triangle_pair(
          packed, p.a, p.b, [&](index_t v, index_t f) { push_back_large(part.vf, {v, f}); },
          [&](index_t x, index_t y) { push_back_large(part.ee, {x, y}); });
    });
  });
  for (auto* kept : {&parts.orphans_vf, &parts.orphans_ee}) {
    const auto& list = kept == &parts.orphans_vf ? rep.orphans().vf : rep.orphans().ee;
    if (!with_orphans) {
      for (auto& part : *kept) part.clear();
      continue;
    }
    ordered_parts(list.size(), *kept, [&](std::size_t begin, std::size_t end, std::vector<std::pair<index_t, index_t>>& part) {
      for (std::size_t i = begin; i < end; ++i)
        if (orphan_kept(view, list[i].first, list[i].second)) part.push_back(list[i]);
    });
  }
}

}  // namespace detail

inline void emit_feature_pairs_into(const RepresentativeTriangles& rep, const TrianglePair* candidates, std::size_t n,
                                    const std::vector<Aabbf>& boxes, bool with_orphans, FeaturePairs& out,
                                    FeaturePairParts& parts, const std::vector<FaceCorners>* corners) {
  detail::emit_feature_pair_parts(
      rep, n,
      [candidates](std::size_t begin, std::size_t end, auto&& fn) {
        for (std::size_t i = begin; i < end; ++i) fn(candidates[i]);
      },
      boxes, with_orphans, parts, corners);
  // One copy into `out`, each list reserved once (the orphans' pairs included).
  detail::copy_parts(parts.candidates, out, 0, 0, parts.orphans_vf, parts.orphans_ee);
}

inline void emit_feature_pairs_into(const RepresentativeTriangles& rep, const std::vector<std::vector<TrianglePair>>& candidate_lists,
                                    const std::vector<Aabbf>& boxes, bool with_orphans, FeaturePairParts& out,
                                    const std::vector<FaceCorners>* corners) {
  std::size_t n = 0;
  for (const auto& list : candidate_lists) n += list.size();
  detail::emit_feature_pair_parts(
      rep, n,
      [&candidate_lists](std::size_t begin, std::size_t end, auto&& fn) { detail::for_each_in_lists(candidate_lists, begin, end, fn); },
      boxes, with_orphans, out, corners);
}

inline FeaturePairs FeaturePairParts::joined() const {
  FeaturePairs out;
  detail::copy_parts(candidates, out, 0, 0, orphans_vf, orphans_ee);
  return out;
}

namespace detail {

// Classifies a pair of features with overlapping boxes as a query (or none) and appends it;
// with corners, not when the two representing faces are apart by faces_apart.
inline void add_feature_query(const RepresentativeTriangles& rep, index_t x, index_t y, FeaturePairs& out,
                              const FaceCorners* corners) {
  if (corners) {
    const index_t fx = rep.owner_of_feature(x), fy = rep.owner_of_feature(y);
    if (fx >= 0 && fy >= 0 && faces_apart(corners[fx], corners[fy])) return;
  }
  const TriangleMesh& mesh = rep.mesh();
  const index_t nv = mesh.num_vertices(), ne = mesh.num_edges();
  auto kind = [&](index_t id) { return id < nv ? 0 : id < nv + ne ? 1 : 2; };
  if (kind(x) > kind(y)) std::swap(x, y);
  const int kx = kind(x), ky = kind(y);
  if (kx == 0 && ky == 2) {
    if (rep.vertex_owner(x) < 0) return;
    const Face& t = mesh.face(y - nv - ne);
    if (t.v[0] == x || t.v[1] == x || t.v[2] == x || !rep.considers(x, y)) return;
    out.vf.emplace_back(x, y);
  } else if (kx == 1 && ky == 1) {
    if (edges_share_vertex(mesh.edge(x - nv), mesh.edge(y - nv)) || !rep.considers(x, y)) return;
    out.ee.emplace_back(std::min(x, y), std::max(x, y));
  }
}

inline FeaturePairs sorted_union(const std::vector<FeaturePairs>& parts) {
  FeaturePairs out;
  append_parts(parts, out);
  parallel_sort(out.vf.begin(), out.vf.end());
  parallel_sort(out.ee.begin(), out.ee.end());
  return out;
}

}  // namespace detail

inline FeaturePairs brute_force_feature_pairs(const RepresentativeTriangles& rep, const std::vector<Aabbf>& boxes,
                                              const std::vector<FaceCorners>* corners) {
  const FaceCorners* with = detail::checked_corners(rep, corners, "brute_force_feature_pairs");
  const TriangleMesh& mesh = rep.mesh();
  const index_t nv = mesh.num_vertices(), ne = mesh.num_edges(), nf = mesh.num_faces();
  const unsigned workers = detail::worker_count();
  std::vector<FeaturePairs> parts(workers);
  detail::for_each_worker([&](unsigned w, unsigned nw) {
    FeaturePairs& out = parts[w];
    for (index_t v = static_cast<index_t>(w); v < nv; v += static_cast<index_t>(nw))
      for (index_t f = 0; f < nf; ++f) {
        const index_t id = mesh.face_feature_id(f);
        if (boxes[v].overlaps(boxes[id])) detail::add_feature_query(rep, v, id, out, with);
      }
    for (index_t e = static_cast<index_t>(w); e < ne; e += static_cast<index_t>(nw))
      for (index_t g = e + 1; g < ne; ++g)
        if (boxes[nv + e].overlaps(boxes[nv + g])) detail::add_feature_query(rep, nv + e, nv + g, out, with);
  }, workers);
  return detail::sorted_union(parts);
}

inline FeaturePairs sweep_feature_pairs(const RepresentativeTriangles& rep, const std::vector<Aabbf>& boxes,
                                        const std::vector<FaceCorners>* corners) {
  const FaceCorners* with = detail::checked_corners(rep, corners, "sweep_feature_pairs");
  const index_t n = static_cast<index_t>(boxes.size());
  std::vector<index_t> order(static_cast<std::size_t>(n));
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](index_t i, index_t j) {
    return boxes[i].lo.x != boxes[j].lo.x ? boxes[i].lo.x < boxes[j].lo.x : i < j;
  });
  const unsigned workers = detail::worker_count();
  std::vector<FeaturePairs> parts(workers);
  detail::for_each_worker([&](unsigned w, unsigned nw) {
    for (index_t k = static_cast<index_t>(w); k < n; k += static_cast<index_t>(nw)) {
      const Aabbf& box = boxes[order[k]];
      for (index_t m = k + 1; m < n && boxes[order[m]].lo.x <= box.hi.x; ++m)
        if (box.overlaps(boxes[order[m]])) detail::add_feature_query(rep, order[k], order[m], parts[w], with);
    }
  }, workers);
  return detail::sorted_union(parts);
}

}  // namespace lwsccd
