// lwsccd — orphan sets (Tang et al. 2008): culling adjacent triangle pairs without losing contacts.
//
// Triangle pairs that share a vertex (TrianglePair::adjacent) always overlap in any bounding
// volume, so testing their features would flood the narrow phase with false positives. They are
// skipped; the only feature pairs that this can lose are the "orphans": non-incident vertex-face
// and edge-edge pairs that no non-adjacent triangle pair of the mesh produces. Those are found
// once per topology and always tested.
#pragma once

#include <utility>
#include <vector>

#include "lwsccd/features/oracle.hpp"
#include "lwsccd/geometry/mesh.hpp"

namespace lwsccd {

/// Orphan feature pairs of a mesh, in the FeaturePairs id convention: vf = (vertex feature id,
/// face feature id), ee = (smaller edge feature id, larger). Both lists sorted and unique.
struct OrphanSets {
  std::vector<std::pair<index_t, index_t>> vf;
  std::vector<std::pair<index_t, index_t>> ee;
};

/// Every non-incident feature pair that only adjacent triangle pairs (sharing a vertex) produce:
/// (v, f) when f shares a vertex with every face incident to v (Algorithm FindVFOrphan), and
/// (e, e') when every face of e shares a vertex with every face of e' (FindEEOrphan). Depends on
/// the topology only: compute once per mesh. Linear in the size of the faces' vertex rings;
/// handles open, closed and non-manifold meshes, fans and isolated triangles.
OrphanSets find_orphan_sets(const TriangleMesh& mesh);

/// The feature pairs to test for the candidate triangle pairs `pairs`: feature_pairs of the
/// non-adjacent pairs only, plus every orphan pair; sorted and unique. For candidates from a
/// conservative broad phase over the whole mesh, this contains every feature pair of `pairs`
/// whose features' own bounding volumes overlap, so no contact is lost. (Orphans of bodies that
/// a BodyLayout excludes from self collision are included too, unless the sets were passed
/// through orphans_for_layout first.)
FeaturePairs culled_feature_pairs(const TriangleMesh& mesh, const std::vector<TrianglePair>& pairs,
                                  const OrphanSets& orphans);

/// The orphan pairs a scene with bodies needs: those whose two features lie in one body that
/// does not self-collide are dropped (a vertex or edge shared by several bodies counts as in
/// all of them, so its pairs stay). Validates the layout.
OrphanSets orphans_for_layout(const TriangleMesh& mesh, const OrphanSets& orphans, const BodyLayout& layout);

}  // namespace lwsccd

#include "lwsccd/features/detail/orphans_impl.hpp"
