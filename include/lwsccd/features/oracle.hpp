// lwsccd — the CPU oracle: brute-force candidate triangle pairs and their feature pairs.
//
// Deliberately simple (every pair of triangles is tested) so that it can be trusted; every
// faster broad phase in the library is checked against it. sweep_and_prune_pairs gives the same
// set for AABBs in O(n log n + k) for the larger real scenes.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "lwsccd/geometry/bv_traits.hpp"
#include "lwsccd/geometry/mesh.hpp"
#include "lwsccd/geometry/vec.hpp"

namespace lwsccd {

/// A candidate pair of triangles, a < b.
struct TrianglePair {
  index_t a, b;
  bool adjacent;  ///< the triangles share a vertex (their adjacent features are culled)
  /// Explicit and zeroed, so that a copy of a pair never carries uninitialised bytes (what
  /// compute-sanitizer's initcheck flags in every download of the traversal's results).
  unsigned char padding[3] = {0, 0, 0};
  friend bool operator==(const TrianglePair& x, const TrianglePair& y) {
    return x.a == y.a && x.b == y.b && x.adjacent == y.adjacent;
  }
  friend bool operator<(const TrianglePair& x, const TrianglePair& y) {
    return x.a != y.a ? x.a < y.a : x.b < y.b;
  }
};

/// Which triangle pairs are considered: self pairs inside a body only if that body
/// self-collides, pairs across bodies always. Empty vectors mean one self-colliding body.
struct BodyLayout {
  std::vector<index_t> face_body;        ///< body id of each face, or empty
  std::vector<bool> body_self_collides;  ///< per body id, or empty (all self-collide)

  bool considers(index_t f, index_t g) const {
    if (face_body.empty()) return true;
    const index_t bf = face_body[f], bg = face_body[g];
    if (bf != bg) return true;
    return body_self_collides.empty() || body_self_collides[bf];
  }
  /// Throws InputError when face_body does not match the mesh or names an unknown body.
  void validate(const TriangleMesh& mesh) const;
};

/// Bounding volume of each triangle's motion from x0 to x1.
template <class BV, class U>
std::vector<BV> swept_triangle_bvs(const TriangleMesh& mesh, const std::vector<Vec3<U>>& x0,
                                   const std::vector<Vec3<U>>& x1);

/// All pairs of distinct triangles whose BVs overlap, sorted by (a, b); O(n^2) on all cores.
template <class BV>
std::vector<TrianglePair> brute_force_pairs(const TriangleMesh& mesh, const std::vector<BV>& bvs,
                                            const BodyLayout& layout = {});

/// The same set as brute_force_pairs for AABBs, by sorting on x and sweeping.
template <class T>
std::vector<TrianglePair> sweep_and_prune_pairs(const TriangleMesh& mesh, const std::vector<Aabb<T>>& bvs,
                                                const BodyLayout& layout = {});

/// Vertex-face and edge-edge feature pairs, in the dataset's feature-id convention
/// (TriangleMesh::vertex_feature_id, edge_feature_id, face_feature_id). ee pairs have first < second.
struct FeaturePairs {
  std::vector<std::pair<index_t, index_t>> vf;
  std::vector<std::pair<index_t, index_t>> ee;
};

/// The 6 VF and 9 EE pairs of every triangle pair, without features that share a vertex (a
/// vertex of the face, edges with a common endpoint), de-duplicated and sorted.
FeaturePairs feature_pairs(const TriangleMesh& mesh, const std::vector<TrianglePair>& pairs);

}  // namespace lwsccd

#include "lwsccd/features/detail/oracle_impl.hpp"
