// lwsccd — bounding volume test tree (BVTT) traversal tasks: self collision inside one BVH and
// collision between two BVHs (dissertation Algorithm 2.1), with front tracking.
#pragma once

#include <cstdint>
#include <vector>

#include "lwsccd/bvh/bvh.hpp"
#include "lwsccd/core/config.hpp"
#include "lwsccd/features/oracle.hpp"
#include "lwsccd/geometry/mesh.hpp"
#include "lwsccd/traversal/traversal_task.hpp"

namespace lwsccd {

/// A BVTT node: a pair of BVH nodes. For self collision a == b means "the self-collision of
/// node a" (expanded into its children's self collisions and their mutual pair).
struct NodePair {
  index_t a, b;
};

namespace detail {

/// The BVTT descent rule shared by the tasks: split the larger volume (by surface area) of a
/// pair that overlaps and is not two leaves; a leaf cannot be split.
/// `box_a`, `box_b`: the two nodes' volumes, as the caller read them.
LWSCCD_EXEC_CHECK_DISABLE
template <class BV, class Out>
LWSCCD_HD void descend_larger(const BvhView<BV>& ta, const BvhView<BV>& tb, const NodePair& p, const BV& box_a, const BV& box_b,
                              Out& out) {
  const bool leaf_a = ta.is_leaf(p.a), leaf_b = tb.is_leaf(p.b);
  const bool split_b = leaf_a || (!leaf_b && bv_traits<BV>::surface_area(box_b) > bv_traits<BV>::surface_area(box_a));
  if (split_b) {
    out.push_item(NodePair{p.a, tb.left[p.b]});
    out.push_item(NodePair{p.a, tb.right[p.b]});
  } else {
    out.push_item(NodePair{ta.left[p.a], p.b});
    out.push_item(NodePair{ta.right[p.a], p.b});
  }
}

}  // namespace detail

/// node_body value of a BVH node whose faces belong to more than one body.
constexpr index_t kMixedBodies = -1;

/// Which leaf pairs are reported: faces' bodies and which bodies self-collide (device-friendly
/// raw arrays; null = one self-colliding body). Mirrors BodyLayout.
struct LeafFilter {
  const index_t* face_body = nullptr;
  const unsigned char* body_self_collides = nullptr;
  const Face* faces = nullptr;  ///< for the adjacency flag
  bool skip_adjacent = false;   ///< leave triangles sharing a vertex to the orphan sets
  /// Per BVH node: the one body of all its faces, or kMixedBodies (node_bodies()). With it, a
  /// node pair inside one body that does not self-collide is dropped whole, not descended to
  /// its leaves: a rigid ball costs the traversal nothing. Null: leaves are filtered one by one.
  const index_t* node_body = nullptr;

  LWSCCD_HD bool prunes(index_t node_a, index_t node_b) const {
    if (!node_body || !body_self_collides) return false;
    const index_t body = node_body[node_a];
    return body != kMixedBodies && body == node_body[node_b] && !body_self_collides[body];
  }

  LWSCCD_HD bool considers(index_t f, index_t g) const {
    if (!face_body) return true;
    const index_t bf = face_body[f], bg = face_body[g];
    return bf != bg || !body_self_collides || body_self_collides[bf];
  }
  LWSCCD_HD bool adjacent(index_t f, index_t g) const {
    const Face& x = faces[f];
    const Face& y = faces[g];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        if (x.v[i] == y.v[j]) return true;
    return false;
  }
};

/// Self collision of one BVH: every pair of distinct triangles whose leaf BVs overlap, once.
/// Seeds: {root, root} for a fresh traversal, or a recorded front.
template <class BV>
struct SelfCollisionTask {
  using item_type = NodePair;
  using result_type = TrianglePair;
  static constexpr int kMaxChildren = 3;
  static constexpr int kMaxResults = 1;

  BvhView<BV> bvh;
  LeafFilter filter;

  LWSCCD_EXEC_CHECK_DISABLE
  template <class Out>
  LWSCCD_HD void process(const NodePair& p, Out& out) const {
    // Never reports anything, now or after a refit (bodies are fixed): off the front for good.
    if (filter.prunes(p.a, p.b)) return;
    if (p.a == p.b) {
      if (bvh.is_leaf(p.a)) return;
      const index_t l = bvh.left[p.a], r = bvh.right[p.a];
      out.push_item(NodePair{l, l});
      out.push_item(NodePair{r, r});
      out.push_item(NodePair{l, r});
      return;
    }
    const BV box_a = load_bv(bvh.bvs + p.a), box_b = load_bv(bvh.bvs + p.b);
    if (!bv_traits<BV>::overlap(box_a, box_b)) {
      out.push_front(p);
      return;
    }
    if (bvh.is_leaf(p.a) && bvh.is_leaf(p.b)) {
      out.push_front(p);
      emit_leaf_pair(bvh.primitive(p.a), bvh.primitive(p.b), out);
      return;
    }
    detail::descend_larger(bvh, bvh, p, box_a, box_b, out);
  }

  LWSCCD_EXEC_CHECK_DISABLE
  template <class Out>
  LWSCCD_HD void emit_leaf_pair(index_t f, index_t g, Out& out) const {
    if (!filter.considers(f, g)) return;
    const bool adjacent = filter.faces ? filter.adjacent(f, g) : false;
    if (adjacent && filter.skip_adjacent) return;
    out.push_result(f < g ? TrianglePair{f, g, adjacent} : TrianglePair{g, f, adjacent});
  }
};

namespace detail {
/// A node's body from its leaf range: `changes[k]` counts the body changes between consecutive
/// sorted leaves up to leaf k, so the range holds one body exactly when the count does not move.
LWSCCD_HD inline index_t node_body_of(const LeafRange& range, const index_t* changes, const index_t* leaf_primitive,
                                      const index_t* face_body) {
  return changes[range.last] == changes[range.first] ? face_body[leaf_primitive[range.first]] : kMixedBodies;
}
}  // namespace detail

/// LeafFilter::node_body for a BVH (host side; the GPU pipeline computes it on the device).
/// Depends on the tree's topology only: recompute after a build, not after a refit.
template <class BV>
std::vector<index_t> node_bodies(const BvhView<BV>& bvh, const std::vector<index_t>& face_body) {
  const index_t n = bvh.num_leaves;
  std::vector<index_t> changes(static_cast<std::size_t>(n), 0), out(static_cast<std::size_t>(bvh.num_nodes()));
  for (index_t k = 1; k < n; ++k)
    changes[k] = changes[k - 1] + (face_body[bvh.leaf_primitive[k]] != face_body[bvh.leaf_primitive[k - 1]]);
  for (index_t node = 0; node < bvh.num_nodes(); ++node)
    out[node] = detail::node_body_of(bvh.ranges[node], changes.data(), bvh.leaf_primitive, face_body.data());
  return out;
}

/// When to restart from the root instead of the recorded front (Tang et al. 2010, 2.3.3): the
/// front only deepens as pairs separate, so once it has grown past `growth_limit` times its size
/// right after the last restart, the next traversal starts from the root again. A BVH rebuild
/// (a new generation) always restarts.
struct FrontPolicy {
  double growth_limit = 1.5;
};

/// Keeps a traversal's front between steps and decides where the next traversal starts. `Front`:
/// the list the front is kept in (std::vector<NodePair>, or cpu::ListsOf<NodePair>: the lists a
/// work-stealing traversal's threads wrote it in), with size(), empty(), clear() and swap().
template <class Front>
class BasicFrontTracker {
 public:
  explicit BasicFrontTracker(FrontPolicy policy = {}) : policy_(policy) {}

  /// Seeds for the next traversal of a BVH of the given generation.
  const Front& seeds(std::uint64_t bvh_generation) {
    if (bvh_generation != generation_ || front_.empty() || reset_next_) {
      generation_ = bvh_generation;
      restarted_ = true;
      root_seed_ = {NodePair{0, 0}};
      return root_seed_;
    }
    restarted_ = false;
    return front_;
  }
  /// Records the front the traversal just produced.
  void update(Front front) {
    front_ = std::move(front);
    recorded();
  }
  /// The same, taking `front`'s memory: `front` receives the previous front's (a traversal that
  /// writes its next front there allocates nothing).
  void exchange(Front& front) {
    front_.swap(front);
    recorded();
  }
  bool last_was_restart() const { return restarted_; }
  std::size_t size() const { return front_.size(); }
  void reset() { front_.clear(); }
  /// The next seeds() returns the root, whatever the front (the caller knows the front is stale).
  void restart_next() { reset_next_ = true; }

 private:
  void recorded() {
    if (restarted_) size_at_restart_ = front_.size();
    reset_next_ = static_cast<double>(front_.size()) > policy_.growth_limit * static_cast<double>(size_at_restart_);
  }

  FrontPolicy policy_;
  Front front_, root_seed_;
  std::uint64_t generation_ = ~std::uint64_t(0);
  std::size_t size_at_restart_ = 0;
  bool restarted_ = true, reset_next_ = false;
};

/// The front kept in one list.
using FrontTracker = BasicFrontTracker<std::vector<NodePair>>;

/// Collision between two BVHs (two bodies with their own trees): pairs (triangle of A, triangle
/// of B) whose leaf BVs overlap. Results are (a, b) with a from A and b from B (not re-ordered).
template <class BV>
struct InterCollisionTask {
  using item_type = NodePair;
  using result_type = TrianglePair;
  static constexpr int kMaxChildren = 2;
  static constexpr int kMaxResults = 1;

  BvhView<BV> a_tree, b_tree;

  LWSCCD_EXEC_CHECK_DISABLE
  template <class Out>
  LWSCCD_HD void process(const NodePair& p, Out& out) const {
    const BV box_a = load_bv(a_tree.bvs + p.a), box_b = load_bv(b_tree.bvs + p.b);
    if (!bv_traits<BV>::overlap(box_a, box_b)) {
      out.push_front(p);
      return;
    }
    if (a_tree.is_leaf(p.a) && b_tree.is_leaf(p.b)) {
      out.push_front(p);
      out.push_result(TrianglePair{a_tree.primitive(p.a), b_tree.primitive(p.b), false});
      return;
    }
    detail::descend_larger(a_tree, b_tree, p, box_a, box_b, out);
  }
};

}  // namespace lwsccd
