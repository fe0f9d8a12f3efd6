// lwsccd — feature pairs produced once: representative triangles (Curtis, Tamstorf & Manocha
// 2008) and feature-box culling.
//
// Every vertex and every edge is represented by exactly one of its faces. A candidate triangle
// pair (a, b) then produces the vertex-face pairs (v, b) for the vertices a represents (and
// (v, a) for b's) and the edge-edge pairs of the edges a represents with those b represents: each
// feature pair comes from one triangle pair only, so no sort and no de-duplication are needed.
// Each pair is kept only when the swept boxes of its two features overlap (the features' points at
// t0 and t1, rounded outward to float as the BVH's boxes are); a feature's box lies inside its
// face's, so a feature pair whose boxes overlap comes from a triangle pair whose boxes overlap.
//
// The traversal skips triangle pairs that share a vertex. The feature pairs that only such a pair
// would produce here - non-incident pairs whose representing faces share a vertex - are the
// orphans of this assignment, listed once per topology and box-tested every step.
//
// What is produced equals, pair for pair, the brute-force set (brute_force_feature_pairs): every
// vertex-face pair of a vertex and a face that does not contain it, every edge-edge pair of edges
// with no common vertex, whose feature boxes overlap. With bodies, a feature belongs to the body
// of the face that represents it (a vertex or edge shared by faces of several bodies belongs to
// one of them: the lowest-numbered face among those with the fewest features represented).
#pragma once

#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "lwsccd/core/config.hpp"
#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/core/detail/rounding.hpp"
#include "lwsccd/features/oracle.hpp"
#include "lwsccd/features/orphans.hpp"
#include "lwsccd/geometry/aabb.hpp"
#include "lwsccd/geometry/bv_traits.hpp"
#include "lwsccd/geometry/mesh.hpp"

namespace lwsccd {

/// The three edge ids of a face (TriangleMesh::face_edges, as a plain struct for device code).
struct FaceEdgeIds {
  index_t e[3];
};

/// A face's corners at t0 (at[0..2], in Face::v order) and at t1 (at[3..5]), each coordinate
/// rounded to float: what the emission's test of two faces' relative motion reads (faces_apart).
struct FaceCorners {
  Vec3<float> at[6];
};

/// The corners of face `f` for positions x0, x1 (float input taken exactly).
template <class P>
LWSCCD_HD FaceCorners face_corners(const Face& f, const Vec3<P>* x0, const Vec3<P>* x1) {
  FaceCorners c;
  LWSCCD_UNROLL for (int k = 0; k < 3; ++k) {
    c.at[k] = x0[f.v[k]].template cast<float>();
    c.at[3 + k] = x1[f.v[k]].template cast<float>();
  }
  return c;
}

/// Knobs of faces_apart.
struct FaceMotionPolicy {
  /// Scales the test's margins (1 = as derived, bound B16 of docs/NARROW_PHASE.md; the mutation
  /// tests show that less is unsound).
  static constexpr double kDifferenceBound = 1.0;
};

namespace detail {

// faces_apart's margins (B16): u, p and the smallest normal, all scaled by Policy::kDifferenceBound.
template <class Policy>
struct FaceMotionMargins {
  float u = unit_roundoff<float>(), p = fadd(u, u * 0x1p-18f), scale = static_cast<float>(Policy::kDifferenceBound);
  float smallest = scale > 0.0f ? 0x1p-126f : 0.0f;
  // Along c: (2 p + 8 u) |c| . m + the smallest normal (not finite where a corner is not).
  LWSCCD_HD float along(const Vec3<float>& c, const Vec3<float>& m) const {
    return fadd(fmul(fmul(fadd(2.0f * p, 8.0f * u), scale), vabs_dot(c, m)), smallest);
  }
  // On axis k: (2 p + 4 u) m_k + the smallest normal.
  LWSCCD_HD float axis(const Vec3<float>& m, int k) const { return fadd(fmul(fmul(fadd(2.0f * p, 4.0f * u), scale), m[k]), smallest); }
};

// The faces apart on an axis, from each face's smallest and largest coordinates at each time.
template <class Margins>
LWSCCD_HD bool faces_apart_on_axes(const Margins& margins, const Vec3<float>& m, const Vec3<float> (&lo_a)[2], const Vec3<float> (&hi_a)[2],
                                   const Vec3<float> (&lo_b)[2], const Vec3<float> (&hi_b)[2]) {
  LWSCCD_UNROLL for (int k = 0; k < 3; ++k) {
    const float margin = margins.axis(m, k);
    const bool above = fsub(lo_a[0][k], hi_b[0][k]) > margin && fsub(lo_a[1][k], hi_b[1][k]) > margin;
    const bool below = fsub(hi_a[0][k], lo_b[0][k]) < -margin && fsub(hi_a[1][k], lo_b[1][k]) < -margin;
    if (above || below) return true;
  }
  return false;
}

// The faces apart along c at both times: a's lowest projection above b's highest by the margin.
LWSCCD_HD inline bool faces_apart_along(const Vec3<float>& c, float along_c, const FaceCorners& a, const FaceCorners& b) {
  LWSCCD_UNROLL for (int t = 0; t < 2; ++t) {
    float lowest_a = vdot(c, a.at[3 * t]), highest_b = vdot(c, b.at[3 * t]);
    LWSCCD_UNROLL for (int i = 1; i < 3; ++i) {
      const float pa = vdot(c, a.at[3 * t + i]), pb = vdot(c, b.at[3 * t + i]);
      lowest_a = pa < lowest_a ? pa : lowest_a;
      highest_b = pb > highest_b ? pb : highest_b;
    }
    if (!(finite_value(lowest_a) && finite_value(highest_b) && fsub(lowest_a, highest_b) > along_c)) return false;
  }
  return true;
}

// c of faces_apart: the sum of the six corner differences a_s - b_s, in that order.
LWSCCD_HD inline Vec3<float> summed_corner_difference(const FaceCorners& a, const FaceCorners& b) {
  Vec3<float> c = vsub(a.at[0], b.at[0]);
  LWSCCD_UNROLL for (int s = 1; s < 6; ++s) c = vadd(c, vsub(a.at[s], b.at[s]));
  return c;
}

}  // namespace detail

/// True when no point of face a ever meets a point of face b during the step (each corner moving
/// linearly from t0 to t1), for the positions as given and for any within the certified narrow
/// phase's perturbation of them: then none of the feature pairs the two faces represent touches.
/// A contact at time t is a point of a equal to a point of b, and their difference is a convex
/// combination of the corner differences a_i(t) - b_j(t), each on the segment between its values
/// at t0 and t1 (B14 of docs/NARROW_PHASE.md, on 18 differences), so a direction along which all
/// 18 are beyond their error parts the faces for the whole step. Tried: each axis (through each
/// face's extremes at each time: rounding is monotone, so the smallest rounded difference is the
/// rounded difference of the extremes), then c, the sum of the six corner differences, through
/// each face's projections on c at each time, which needs 12 dot products instead of 18. In
/// float, on the corners rounded to float; the margins (bound B16) cover that rounding, the narrow
/// phase's perturbation, float's arithmetic and underflow. A value that is not finite decides
/// nothing. Policy::kDifferenceBound scales the margins (1 = as derived).
template <class Policy = FaceMotionPolicy>
LWSCCD_HD bool faces_apart(const FaceCorners& a, const FaceCorners& b) {
  const detail::FaceMotionMargins<Policy> margins;
  Vec3<float> m = abs(a.at[0]);
  LWSCCD_UNROLL for (int s = 1; s < 6; ++s) m = max(m, abs(a.at[s]));
  LWSCCD_UNROLL for (int s = 0; s < 6; ++s) m = max(m, abs(b.at[s]));
  const Vec3<float> c = detail::summed_corner_difference(a, b);
  // (A corner that is not finite makes c, and so this margin, not finite.)
  const float along_c = margins.along(c, m);
  if (!detail::finite_value(along_c)) return false;
  Vec3<float> lo_a[2], hi_a[2], lo_b[2], hi_b[2];
  LWSCCD_UNROLL for (int t = 0; t < 2; ++t) {
    lo_a[t] = min(a.at[3 * t], min(a.at[3 * t + 1], a.at[3 * t + 2]));
    hi_a[t] = max(a.at[3 * t], max(a.at[3 * t + 1], a.at[3 * t + 2]));
    lo_b[t] = min(b.at[3 * t], min(b.at[3 * t + 1], b.at[3 * t + 2]));
    hi_b[t] = max(b.at[3 * t], max(b.at[3 * t + 1], b.at[3 * t + 2]));
  }
  if (detail::faces_apart_on_axes(margins, m, lo_a, hi_a, lo_b, hi_b)) return true;
  return detail::faces_apart_along(c, along_c, a, b);
}

/// What faces_apart reads of a face besides its corners, computed from them alone: each time's
/// smallest and largest coordinates and the largest magnitudes. The CPU emission makes it once a
/// face and step (a face is in dozens of candidates) and tests the pairs with the overload below.
/// (The GPU's counting kernel tests from the corners alone, in faces_apart's order: testing from
/// summaries made per candidate there took cloth-ball's feature-pairs stage 0.29 -> 0.32 ms on an
/// H200, and 96-byte records holding summaries were slower than the 80-byte corners alone.)
struct FaceCornerSummary {
  Vec3<float> lo[2], hi[2];  ///< per time (0: t0, 1: t1), the smallest and largest coordinates of the three corners
  Vec3<float> magnitude;     ///< per axis, the largest |coordinate| of the six corners (exact)
  bool tame = false;         ///< every coordinate finite and below 2^60 in magnitude
};

/// The summary of a face's corners (FaceCornerSummary).
LWSCCD_HD inline FaceCornerSummary summarize_corners(const FaceCorners& f) {
  FaceCornerSummary s;
  LWSCCD_UNROLL for (int t = 0; t < 2; ++t) {
    s.lo[t] = min(f.at[3 * t], min(f.at[3 * t + 1], f.at[3 * t + 2]));
    s.hi[t] = max(f.at[3 * t], max(f.at[3 * t + 1], f.at[3 * t + 2]));
  }
  // (A largest magnitude is at a smallest or a largest coordinate.)
  s.magnitude = max(max(abs(s.lo[0]), abs(s.hi[0])), max(abs(s.lo[1]), abs(s.hi[1])));
  s.tame = true;
  for (const Vec3<float>& corner : f.at)
    for (int k = 0; k < 3; ++k) s.tame = s.tame && std::fabs(corner[k]) < 0x1p60f;  // (false for NaN)
  return s;
}

/// faces_apart(a, b) from the faces' summaries (sa = summarize_corners(a), sb = summarize_corners(b)):
/// the same values in the same tests, so the same verdict (tested on random and non-finite corners).
template <class Policy = FaceMotionPolicy>
LWSCCD_HD bool faces_apart(const FaceCornerSummary& sa, const FaceCorners& a, const FaceCornerSummary& sb, const FaceCorners& b) {
  const detail::FaceMotionMargins<Policy> margins;
  const Vec3<float> m = max(sa.magnitude, sb.magnitude);
  // Tame corners make c's margin finite (|c_k| < 12 2^60, |c| . m < 2^126), so faces_apart's check
  // of it cannot decide and the axes may go first: a pair parted by an axis then needs no c.
  if (Policy::kDifferenceBound <= 1.0 && sa.tame && sb.tame) {
    if (detail::faces_apart_on_axes(margins, m, sa.lo, sa.hi, sb.lo, sb.hi)) return true;
    const Vec3<float> c = detail::summed_corner_difference(a, b);
    return detail::faces_apart_along(c, margins.along(c, m), a, b);
  }
  const Vec3<float> c = detail::summed_corner_difference(a, b);
  const float along_c = margins.along(c, m);
  if (!detail::finite_value(along_c)) return false;
  if (detail::faces_apart_on_axes(margins, m, sa.lo, sa.hi, sb.lo, sb.hi)) return true;
  return detail::faces_apart_along(c, along_c, a, b);
}

/// What the emission reads, as plain pointers (host or device memory): the faces, which features
/// each face represents, and one box per feature id (vertices, then edges, then faces).
struct EmissionView {
  const Face* faces = nullptr;
  const FaceEdgeIds* face_edges = nullptr;
  const Edge* edges = nullptr;
  /// Per face: bit k (k < 3) set when it represents vertex faces[f].v[k], bit 3 + k when it
  /// represents edge face_edges[f].e[k].
  const unsigned char* represents = nullptr;
  const Aabbf* boxes = nullptr;  ///< indexed by feature id
  index_t num_vertices = 0, num_edges = 0;
  /// Per face, or null: a candidate pair whose faces are apart by their relative motion
  /// (faces_apart) keeps none of its feature pairs.
  const FaceCorners* corners = nullptr;

  LWSCCD_HD index_t face_feature(index_t f) const { return num_vertices + num_edges + f; }
  LWSCCD_HD index_t edge_feature(index_t e) const { return num_vertices + e; }
};

/// The swept box of feature `id` (dataset convention) from its points at t0 and t1, grown by
/// `margin` on every side when it is positive (proximity queries: half the minimum separation).
template <class P>
LWSCCD_HD Aabbf feature_box(const Face* faces, const Edge* edges, index_t num_vertices, index_t num_edges,
                            const Vec3<P>* x0, const Vec3<P>* x1, index_t id, float margin = 0) {
  Vec3<P> points[6];
  int n = 0;
  auto add = [&](index_t v) {
    points[n++] = x0[v];
    points[n++] = x1[v];
  };
  if (id < num_vertices) {
    add(id);
  } else if (id < num_vertices + num_edges) {
    const Edge e = edges[id - num_vertices];
    add(e.v[0]);
    add(e.v[1]);
  } else {
    const Face f = faces[id - num_vertices - num_edges];
    add(f.v[0]);
    add(f.v[1]);
    add(f.v[2]);
  }
  const Aabbf box = bv_traits<Aabbf>::fit(points, n);  // (each coordinate rounded outward once)
  return margin > 0 ? box.inflated(margin) : box;
}

/// Which feature pairs the non-adjacent candidate triangle pair (a, b) keeps (represented by a
/// and b, boxes overlapping; none when the view has corners and the faces are apart by them), as
/// a mask: bit k (k < 3) the vertex faces[a].v[k] with face b, bit
/// 3 + k the vertex faces[b].v[k] with face a, bit 6 + 3x + y the edges face_edges[a].e[x] and
/// face_edges[b].e[y]. The GPU's counting pass stores it; its writing pass only decodes it.
LWSCCD_HD inline unsigned emission_mask(const EmissionView& m, index_t a, index_t b) {
  const unsigned ra = m.represents[a], rb = m.represents[b];
  if (ra == 0 && rb == 0) return 0;
  unsigned mask = 0;
  const Aabbf box_a = m.boxes[m.face_feature(a)], box_b = m.boxes[m.face_feature(b)];
  if (ra & 7u) {
    const Face t = m.faces[a];
    for (int k = 0; k < 3; ++k)
      if ((ra >> k) & 1u && m.boxes[t.v[k]].overlaps(box_b)) mask |= 1u << k;
  }
  if (rb & 7u) {
    const Face t = m.faces[b];
    for (int k = 0; k < 3; ++k)
      if ((rb >> k) & 1u && m.boxes[t.v[k]].overlaps(box_a)) mask |= 1u << (3 + k);
  }
  if ((ra >> 3) != 0 && (rb >> 3) != 0) {
    const FaceEdgeIds ea = m.face_edges[a], eb = m.face_edges[b];
    for (int x = 0; x < 3; ++x) {
      if (!((ra >> (3 + x)) & 1u)) continue;
      const Aabbf box_x = m.boxes[m.edge_feature(ea.e[x])];
      for (int y = 0; y < 3; ++y)
        if ((rb >> (3 + y)) & 1u && box_x.overlaps(m.boxes[m.edge_feature(eb.e[y])])) mask |= 1u << (6 + 3 * x + y);
    }
  }
  return mask != 0 && m.corners && faces_apart(m.corners[a], m.corners[b]) ? 0u : mask;
}

/// Bits 0-5 of an emission mask (vertex-face pairs) and bits 6-14 (edge-edge pairs).
constexpr unsigned kEmissionVfBits = 0x3fu, kEmissionEeBits = 0x7fc0u;

/// The feature pair of bit `bit` of an emission mask of (a, b) (emission_mask's bits): bit k < 3,
/// (vertex k of a, face b); 3 + k, (vertex k of b, face a); 6 + 3 x + y, (edge x of a, edge y of
/// b) as (smaller id, larger). Host and device.
struct EmittedPair {
  index_t first, second;
};
LWSCCD_HD inline EmittedPair emission_pair(const EmissionView& m, index_t a, index_t b, int bit) {
  if (bit < 3) return {m.faces[a].v[bit], m.face_feature(b)};
  if (bit < 6) return {m.faces[b].v[bit - 3], m.face_feature(a)};
  const index_t ex = m.edge_feature(m.face_edges[a].e[(bit - 6) / 3]), ey = m.edge_feature(m.face_edges[b].e[(bit - 6) % 3]);
  return ex < ey ? EmittedPair{ex, ey} : EmittedPair{ey, ex};
}

/// Calls on_vf(vertex id, face feature id) and on_ee(smaller edge feature id, larger) for each
/// pair of `mask` (emission_mask of (a, b)), by its bits in order (emission_pair): vertices of a,
/// then of b, then edges in (a's, b's) order. Host and device.
template <class OnVf, class OnEe>
LWSCCD_HD void decode_emission(const EmissionView& m, index_t a, index_t b, unsigned mask, OnVf&& on_vf, OnEe&& on_ee) {
  for (int bit = 0; bit < 15; ++bit) {
    if (!((mask >> bit) & 1u)) continue;
    const EmittedPair p = emission_pair(m, a, b, bit);
    if (bit < 6) on_vf(p.first, p.second);
    else on_ee(p.first, p.second);
  }
}

/// The kept feature pairs of the candidate pair (a, b): decode_emission of its emission_mask.
template <class OnVf, class OnEe>
LWSCCD_HD void emit_triangle_pair(const EmissionView& m, index_t a, index_t b, OnVf&& on_vf, OnEe&& on_ee) {
  decode_emission(m, a, b, emission_mask(m, a, b), on_vf, on_ee);
}

/// True when the orphan pair (first, second) (feature ids) is kept: its boxes overlap.
LWSCCD_HD inline bool orphan_kept(const EmissionView& m, index_t first, index_t second) {
  return m.boxes[first].overlaps(m.boxes[second]);
}

/// The representing faces of a mesh and the orphan pairs of that assignment, for one topology
/// (and body layout). Build once per mesh; emit_feature_pairs (CPU) and gpu::FeatureEmitter
/// (GPU) use it every step.
class RepresentativeTriangles {
 public:
  /// Assigns each vertex and edge to one incident face, balancing how many each face represents
  /// (Curtis et al.: about half a vertex and one and a half edges per face), and lists the
  /// orphans, without the pairs the layout does not consider (a feature's body is its
  /// representing face's). Throws InputError for a layout that does not fit the mesh.
  /// The mesh must outlive this object.
  explicit RepresentativeTriangles(const TriangleMesh& mesh, BodyLayout layout = {});

  /// Per face: the bits of EmissionView::represents.
  const std::vector<unsigned char>& represents() const { return represents_; }
  const std::vector<FaceEdgeIds>& face_edges() const { return face_edges_; }
  /// The face that represents vertex v (-1 for a vertex of no face), or edge e.
  index_t vertex_owner(index_t v) const { return vertex_owner_[v]; }
  index_t edge_owner(index_t e) const { return edge_owner_[e]; }
  /// The face that represents feature `id` (a face represents itself); -1 for an unused vertex.
  index_t owner_of_feature(index_t id) const;
  /// Non-incident pairs whose representing faces share a vertex (so no candidate triangle pair
  /// produces them), in the FeaturePairs id convention, sorted.
  const OrphanSets& orphans() const { return orphans_; }
  const TriangleMesh& mesh() const { return *mesh_; }
  const BodyLayout& layout() const { return layout_; }
  /// True when the layout considers the pair of features (ids): their representing faces' bodies.
  bool considers(index_t first, index_t second) const {
    return layout_.considers(owner_of_feature(first), owner_of_feature(second));
  }

  /// The view over this object's host arrays and the given boxes (one per feature id).
  EmissionView view(const Aabbf* boxes, const FaceCorners* corners = nullptr) const {
    return {mesh_->faces().data(), face_edges_.data(), mesh_->edges().data(), represents_.data(), boxes,
            mesh_->num_vertices(), mesh_->num_edges(), corners};
  }

 private:
  const TriangleMesh* mesh_;
  BodyLayout layout_;
  std::vector<unsigned char> represents_;
  std::vector<FaceEdgeIds> face_edges_;
  std::vector<index_t> vertex_owner_, edge_owner_;
  OrphanSets orphans_;
};

namespace detail {

/// A feature's box and id, packed with the others its face represents.
struct PackedFeature {
  Aabbf box;
  index_t id;  ///< feature id (a vertex's own, an edge's num_vertices + e)
};
/// A face's part of the CPU emission: its box, and where the features it represents lie in
/// PackedEmission::features (its vertices in faces[f].v order, then its edges in face_edges order),
/// with EmissionView::represents' bits.
struct PackedEmissionFace {
  Aabbf box;
  std::uint32_t first;
  std::uint32_t represents;
};
/// What the CPU emission reads per candidate, packed by face: a candidate's boxes lie in a few
/// cache lines instead of one each (pack_emission fills it from a step's feature boxes).
struct PackedEmission {
  std::vector<PackedEmissionFace> faces;
  std::vector<PackedFeature> features;
  index_t face_feature_base = 0;  ///< face f's feature id is face_feature_base + f
  const FaceCorners* corners = nullptr;  ///< per face, or null (EmissionView::corners)
  /// With corners, each face's summary (made once a step: every face is in many candidates).
  std::vector<FaceCornerSummary> corner_summaries;
};

}  // namespace detail

/// Feature pairs left in the lists the threads emitting them filled: the candidates' parts (each
/// a vf and an ee list), then the kept orphans' parts, in that order; their concatenation, per
/// kind, is the list emit_feature_pairs gives. Why: copying a step's pairs into one list costs
/// a pass over them, and on a first step the page faults of new memory (cloth-ball: 55 MB).
struct FeaturePairParts {
  using Pairs = std::vector<std::pair<index_t, index_t>>;
  std::vector<FeaturePairs> candidates;
  std::vector<Pairs> orphans_vf, orphans_ee;
  /// The emission's own scratch, kept between steps (its memory reused).
  detail::PackedEmission packed;

  /// The vertex-face (edge-edge) lists, in order.
  std::vector<const Pairs*> vf_lists() const { return lists_of(&FeaturePairs::vf, orphans_vf); }
  std::vector<const Pairs*> ee_lists() const { return lists_of(&FeaturePairs::ee, orphans_ee); }
  std::size_t vf_size() const { return size_of(vf_lists()); }
  std::size_t ee_size() const { return size_of(ee_lists()); }
  /// Both sequences, each in one list.
  FeaturePairs joined() const;

 private:
  std::vector<const Pairs*> lists_of(Pairs FeaturePairs::*kind, const std::vector<Pairs>& orphans) const {
    std::vector<const Pairs*> out;
    out.reserve(candidates.size() + orphans.size());
    for (const FeaturePairs& part : candidates) out.push_back(&(part.*kind));
    for (const Pairs& part : orphans) out.push_back(&part);
    return out;
  }
  static std::size_t size_of(const std::vector<const Pairs*>& lists) {
    std::size_t n = 0;
    for (const Pairs* list : lists) n += list->size();
    return n;
  }
};

/// One swept box per feature id (vertices, edges, faces) from the positions at t0 and t1, each
/// grown by `margin` (>= 0; a pipeline uses half its minimum separation, as for the BVH's leaves).
template <class P>
std::vector<Aabbf> feature_boxes(const TriangleMesh& mesh, const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1,
                                 double margin = 0);

/// Each face's corners (face_corners) from the positions at t0 and t1, on all cores: what the
/// emission's test of the faces' relative motion reads.
template <class P>
std::vector<FaceCorners> face_corners(const TriangleMesh& mesh, const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1);

/// The feature pairs of the candidate triangle pairs and of the orphans, each produced once and
/// kept when its feature boxes overlap, on all cores. Adjacent candidate pairs are skipped (the
/// orphans hold what they would give). Order: the candidates' pairs in candidate order, then the
/// kept orphans in order - not sorted (the GPU emitter gives the same lists in the same order).
/// With `corners` (one per face, face_corners), a candidate pair whose faces are apart by their
/// relative motion (faces_apart) gives none: none of its feature pairs can touch in the step. (The
/// orphans' faces share a vertex, so that test never parts them.) Throws InputError when `boxes`
/// or `corners` does not fit the mesh.
FeaturePairs emit_feature_pairs(const RepresentativeTriangles& rep, const std::vector<TrianglePair>& candidates,
                                const std::vector<Aabbf>& boxes, const std::vector<FaceCorners>* corners = nullptr);
/// The same for n candidates from `candidates`, with the orphans' pairs only when `with_orphans`
/// (a step split into parts lists them with one part).
FeaturePairs emit_feature_pairs(const RepresentativeTriangles& rep, const TrianglePair* candidates, std::size_t n,
                                const std::vector<Aabbf>& boxes, bool with_orphans,
                                const std::vector<FaceCorners>* corners = nullptr);
/// The same into `out` (its lists' memory reused), through `parts` (the per-thread lists), kept
/// for the next call: a caller that emits every step allocates nothing once warm.
void emit_feature_pairs_into(const RepresentativeTriangles& rep, const TrianglePair* candidates, std::size_t n,
                             const std::vector<Aabbf>& boxes, bool with_orphans, FeaturePairs& out,
                             FeaturePairParts& parts, const std::vector<FaceCorners>* corners = nullptr);
/// The feature pairs of candidates held in several lists, in their order (a work-stealing
/// traversal's threads' lists, cpu::traverse_in_lists), read where they lie, left in the lists
/// the threads emitting them filled (`out`'s memory reused): nothing is copied into one list.
/// cpu::test_feature_pairs reads them there; out.joined() is emit_feature_pairs's list.
void emit_feature_pairs_into(const RepresentativeTriangles& rep, const std::vector<std::vector<TrianglePair>>& candidate_lists,
                             const std::vector<Aabbf>& boxes, bool with_orphans, FeaturePairParts& out,
                             const std::vector<FaceCorners>* corners = nullptr);

/// The oracle: every non-incident vertex-face pair and every edge-edge pair without a common
/// vertex whose feature boxes overlap (and, with a layout, that rep.considers), sorted; vertices
/// of no face take no part. With `corners` (face_corners), a pair whose two representing faces
/// are apart by faces_apart is left out, as emit_feature_pairs leaves it out with them.
/// O(features^2): small meshes only.
FeaturePairs brute_force_feature_pairs(const RepresentativeTriangles& rep, const std::vector<Aabbf>& boxes,
                                       const std::vector<FaceCorners>* corners = nullptr);

/// The same set as brute_force_feature_pairs, by sorting the boxes on x and sweeping: for the
/// real scenes.
FeaturePairs sweep_feature_pairs(const RepresentativeTriangles& rep, const std::vector<Aabbf>& boxes,
                                 const std::vector<FaceCorners>* corners = nullptr);

}  // namespace lwsccd

#include "lwsccd/features/detail/representative_impl.hpp"
