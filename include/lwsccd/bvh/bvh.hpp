// lwsccd — linear BVH (LBVH) over the triangles of a step: node layout, device-agnostic view,
// quality metrics, rebuild policy, and the CPU backend's build and refit.
//
// Build: leaf BVs bound each triangle's motion over the whole step; Morton codes (63-bit) of the
// centres of the triangles' swept AABBs, stably sorted; Karras's binary radix tree (2012);
// bottom-up fit. Ties between equal codes are broken by sorted position, as Karras proposes, and
// the stable sort keeps triangle order among equal codes, so the CPU and GPU builds produce the
// same tree for the same input. Morton codes come from AABB centres (exact min/max arithmetic)
// even for OBB trees, so that rounding differences between host and device cannot change the
// topology.
//
// Node numbering: internal nodes 0 .. n-2, leaves n-1 .. 2n-2 (leaf k = node n-1+k, k in sorted
// order). The root is node 0 for every n >= 1 (a single triangle is a leaf root).
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "lwsccd/core/config.hpp"
#include "lwsccd/geometry/bv_traits.hpp"
#include "lwsccd/geometry/mesh.hpp"
#include "lwsccd/geometry/vec.hpp"

namespace lwsccd {

/// The sorted leaves a node covers: [first, last] in Morton order.
struct LeafRange {
  index_t first, last;
};

/// Read-only, trivially copyable view of a BVH, valid on the side (host or device) whose memory
/// it points into. Traversal code is written against this view only.
template <class BV>
struct BvhView {
  using bv_type = BV;
  index_t num_leaves = 0;
  const BV* bvs = nullptr;                   ///< 2n-1 nodes
  const index_t* left = nullptr;             ///< n-1 internal nodes: left child node
  const index_t* right = nullptr;            ///< n-1 internal nodes: right child node
  const index_t* parent = nullptr;           ///< 2n-1 nodes: parent node, -1 for the root
  const LeafRange* ranges = nullptr;         ///< 2n-1 nodes
  const index_t* leaf_primitive = nullptr;   ///< n leaves: triangle id of sorted leaf k

  LWSCCD_HD index_t num_nodes() const { return num_leaves > 0 ? 2 * num_leaves - 1 : 0; }
  LWSCCD_HD static constexpr index_t root() { return 0; }
  LWSCCD_HD bool is_leaf(index_t node) const { return node >= num_leaves - 1; }
  LWSCCD_HD index_t leaf_index(index_t node) const { return node - (num_leaves - 1); }
  LWSCCD_HD index_t leaf_node(index_t k) const { return num_leaves - 1 + k; }
  LWSCCD_HD index_t primitive(index_t leaf_node_id) const { return leaf_primitive[leaf_index(leaf_node_id)]; }
};

/// Host copy of every array of a BVH (the CPU backend's storage, and what a GPU BVH downloads to
/// for comparison).
template <class BV>
struct BvhNodes {
  index_t num_leaves = 0;
  std::vector<BV> bvs;
  std::vector<index_t> left, right, parent;
  std::vector<LeafRange> ranges;
  std::vector<index_t> leaf_primitive;
  std::vector<std::uint64_t> leaf_codes;  ///< sorted Morton codes

  BvhView<BV> view() const {
    return {num_leaves, bvs.data(), left.data(), right.data(), parent.data(), ranges.data(), leaf_primitive.data()};
  }
};

/// Quality of a BVH: the SAH-like cost used by the rebuild policy, and shape statistics.
struct BvhQuality {
  double sah_cost = 0;           ///< sum over internal nodes of surface area / root surface area
  double volume_sum = 0;         ///< sum of internal node volumes / root volume
  double sibling_overlap = 0;    ///< sum of sibling AABB-intersection volumes / root volume
  int max_depth = 0;             ///< edges from the root to the deepest leaf
  double mean_leaf_depth = 0;
};

/// Refit while the cost stays within `factor` times the cost of the last build; rebuild
/// otherwise. A rebuild changes the tree's generation (fronts kept by traversals then reset).
struct RebuildPolicy {
  double factor = 1.5;
  bool should_rebuild(double cost_now, double cost_at_build) const { return cost_now > factor * cost_at_build; }
};

/// Computes BvhQuality on the host (O(n)).
template <class BV>
BvhQuality measure_quality(const BvhView<BV>& bvh);

/// Checks every structural invariant of a host BVH: each leaf reached once from the root,
/// parent/child links, leaf ranges, every internal BV enclosing its children's BVs and every leaf
/// BV enclosing its triangle at t0 and t1 (hence its whole motion), checked in long double.
/// Returns a description of the first violation, or "" when there is none.
template <class BV, class P>
std::string check_bvh_invariants(const BvhView<BV>& bvh, const std::vector<Face>& faces,
                                 const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1);

namespace detail {
/// The per-node arrival counters of the CPU's parallel bottom-up fit, zero between fits. Scratch:
/// a copy is a zeroed array of the same size.
class ArrivalCounters {
 public:
  ArrivalCounters() = default;
  ArrivalCounters(const ArrivalCounters& other) { resize(other.size_); }
  ArrivalCounters& operator=(const ArrivalCounters& other) {
    if (this != &other) resize(other.size_);
    return *this;
  }
  ArrivalCounters(ArrivalCounters&&) noexcept = default;
  ArrivalCounters& operator=(ArrivalCounters&&) noexcept = default;
  void resize(std::size_t n) {
    counters_.reset(n ? new std::atomic<unsigned char>[n]() : nullptr);  // value-initialised: zero
    size_ = n;
  }
  std::atomic<unsigned char>* data() { return counters_.get(); }

 private:
  std::unique_ptr<std::atomic<unsigned char>[]> counters_;
  std::size_t size_ = 0;
};
}  // namespace detail

namespace cpu {

/// A BVH on the CPU backend. Position type P (float/double) may differ from the BV's scalar.
template <class BV>
class Bvh {
 public:
  static_assert(require_bounding_volume<BV>::value, "");

  Bvh() = default;
  /// Builds over mesh with positions x0 -> x1. Throws InputError for NaN/inf positions or a
  /// position count that differs from the mesh's.
  template <class P>
  Bvh(const TriangleMesh& mesh, const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1) {
    build(mesh, x0, x1);
  }

  template <class P>
  void build(const TriangleMesh& mesh, const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1);
  /// Recomputes every BV for new positions on the same topology (leaf order kept).
  template <class P>
  void refit(const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1);
  /// refit, then rebuild if the policy says the tree has decayed; returns true on a rebuild.
  template <class P>
  bool refit_or_rebuild(const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1, const RebuildPolicy& policy = {});

  /// Grows every leaf by `margin` on every side (rounded outward) from the next build or refit
  /// on: two leaves then overlap whenever their triangles come within 2 * margin, so proximity
  /// queries (a minimum separation d) use d / 2. Throws InputError unless finite and >= 0.
  void set_leaf_margin(double margin) { leaf_margin_ = detail::checked_margin<BV>(margin, "cpu::Bvh::set_leaf_margin"); }
  double leaf_margin() const { return leaf_margin_; }

  BvhView<BV> view() const { return nodes_.view(); }
  const BvhNodes<BV>& nodes() const { return nodes_; }
  /// Incremented by every build: fronts recorded against another generation are stale.
  std::uint64_t generation() const { return generation_; }
  double cost_at_build() const { return cost_at_build_; }

 private:
  template <class P>
  void build_tree(const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1);
  template <class P>
  void fit_bottom_up(const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1);

  index_t num_vertices_ = 0;
  std::vector<Face> faces_;
  BvhNodes<BV> nodes_;
  std::uint64_t generation_ = 0;
  double cost_at_build_ = 0;
  typename bv_traits<BV>::scalar_type leaf_margin_ = 0;
  detail::ArrivalCounters arrivals_;
};

}  // namespace cpu

}  // namespace lwsccd

#include "lwsccd/bvh/detail/bvh_impl.hpp"
