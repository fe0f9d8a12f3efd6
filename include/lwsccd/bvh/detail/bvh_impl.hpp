// lwsccd — definitions for bvh.hpp (host side).
#pragma once

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>

#include "lwsccd/bvh/bvh.hpp"
#include "lwsccd/bvh/detail/lbvh.hpp"
#include "lwsccd/core/error.hpp"
#include "lwsccd/core/parallel.hpp"
#include "lwsccd/geometry/morton.hpp"

namespace lwsccd {

namespace detail {

// Host-only long double helpers (plain arrays, so that no device code is instantiated for
// long double under nvcc).
struct ExactBox {
  long double lo[3], hi[3];
  long double volume() const {
    long double v = 1;
    for (int i = 0; i < 3; ++i) v *= hi[i] > lo[i] ? hi[i] - lo[i] : 0;
    return v;
  }
};

// An AABB around any BV, for the overlap statistic (exact for AABBs, from corners for OBBs).
template <class T>
ExactBox enclosing_box(const Aabb<T>& b) {
  return {{b.lo.x, b.lo.y, b.lo.z}, {b.hi.x, b.hi.y, b.hi.z}};
}
template <class T>
void obb_corner(const Obb<T>& b, int k, bool safe, long double out[3]) {
  for (int a = 0; a < 3; ++a) out[a] = b.center[a];
  for (int i = 0; i < 3; ++i) {
    const long double h = safe ? static_cast<long double>(b.safe_half(i)) : static_cast<long double>(b.half[i]);
    for (int a = 0; a < 3; ++a) out[a] += ((k >> i) & 1 ? 1 : -1) * h * b.axis[i][a];
  }
}
template <class T>
ExactBox enclosing_box(const Obb<T>& b) {
  ExactBox box{{HUGE_VALL, HUGE_VALL, HUGE_VALL}, {-HUGE_VALL, -HUGE_VALL, -HUGE_VALL}};
  for (int k = 0; k < 8; ++k) {
    long double c[3];
    obb_corner(b, k, false, c);
    for (int a = 0; a < 3; ++a) {
      box.lo[a] = std::min(box.lo[a], c[a]);
      box.hi[a] = std::max(box.hi[a], c[a]);
    }
  }
  return box;
}

// Does `outer` contain point p, evaluated in long double without slack?
template <class T>
bool contains_exactly(const Aabb<T>& outer, const long double p[3]) {
  for (int a = 0; a < 3; ++a)
    if (p[a] < outer.lo[a] || p[a] > outer.hi[a]) return false;
  return true;
}
template <class T>
bool contains_exactly(const Obb<T>& outer, const long double p[3]) {
  for (int i = 0; i < 3; ++i) {
    long double s = 0;
    for (int a = 0; a < 3; ++a) s += static_cast<long double>(outer.axis[i][a]) * (p[a] - outer.center[a]);
    if (std::fabs(s) > static_cast<long double>(outer.half[i])) return false;
  }
  return true;
}
template <class BV, class U>
bool contains_point_exactly(const BV& outer, const Vec3<U>& p) {
  const long double q[3] = {p.x, p.y, p.z};
  return contains_exactly(outer, q);
}

// Does `outer` enclose `inner`? AABBs: exactly; OBBs: the corners of inner's conservative extents.
template <class T>
bool encloses(const Aabb<T>& outer, const Aabb<T>& inner) {
  return contains_point_exactly(outer, inner.lo) && contains_point_exactly(outer, inner.hi);
}
template <class T>
bool encloses(const Obb<T>& outer, const Obb<T>& inner) {
  for (int k = 0; k < 8; ++k) {
    long double c[3];
    obb_corner(inner, k, true, c);
    if (!contains_exactly(outer, c)) return false;
  }
  return true;
}

inline long double intersection_volume(const ExactBox& a, const ExactBox& b) {
  long double v = 1;
  for (int i = 0; i < 3; ++i) {
    const long double lo = std::max(a.lo[i], b.lo[i]), hi = std::min(a.hi[i], b.hi[i]);
    if (hi <= lo) return 0;
    v *= hi - lo;
  }
  return v;
}

template <class P>
void check_step_positions(index_t num_vertices, const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1,
                          const char* who) {
  for (const auto* x : {&x0, &x1}) {
    const char* name = x == &x0 ? "x0" : "x1";
    if (x->size() != static_cast<std::size_t>(num_vertices))
      throw InputError(who, name, "has " + std::to_string(x->size()) + " positions, the mesh has " +
                                      std::to_string(num_vertices) + " vertices");
    for (std::size_t v = 0; v < x->size(); ++v)
      if (!is_finite((*x)[v]))
        throw InputError(who, std::string(name) + " vertex " + std::to_string(v), "coordinate is NaN or infinite");
  }
}

}  // namespace detail

namespace detail {
/// BvhQuality::sah_cost alone, on all cores: the internal nodes' surface areas summed in fixed
/// blocks, then the blocks' sums in order (the same value whatever the thread count).
template <class BV>
double sah_cost(const BvhView<BV>& bvh) {
  const index_t n = bvh.num_leaves;
  if (n < 2) return 0.0;
  const double root_area = static_cast<double>(bv_traits<BV>::surface_area(bvh.bvs[0]));
  if (!(root_area > 0)) return 0.0;
  constexpr std::size_t kBlock = 4096;
  const auto internal = static_cast<std::size_t>(n - 1);
  std::vector<double> block_sums((internal + kBlock - 1) / kBlock, 0.0);
  parallel_ranges(block_sums.size(), 1, [&](std::size_t first, std::size_t last) {
    for (std::size_t b = first; b < last; ++b)
      for (std::size_t i = b * kBlock; i < std::min(internal, (b + 1) * kBlock); ++i)
        block_sums[b] += static_cast<double>(bv_traits<BV>::surface_area(bvh.bvs[i])) / root_area;
  });
  double cost = 0;
  for (const double s : block_sums) cost += s;
  return cost;
}
}  // namespace detail

template <class BV>
BvhQuality measure_quality(const BvhView<BV>& bvh) {
  BvhQuality q;
  const index_t n = bvh.num_leaves;
  if (n == 0) return q;
  const double root_area = static_cast<double>(bv_traits<BV>::surface_area(bvh.bvs[0]));
  const double root_volume = static_cast<double>(bv_traits<BV>::volume(bvh.bvs[0]));
  const auto root_box = detail::enclosing_box(bvh.bvs[0]);
  const long double root_box_volume = root_box.volume();
  for (index_t i = 0; i + 1 < n; ++i) {
    q.sah_cost += root_area > 0 ? static_cast<double>(bv_traits<BV>::surface_area(bvh.bvs[i])) / root_area : 0.0;
    q.volume_sum += root_volume > 0 ? static_cast<double>(bv_traits<BV>::volume(bvh.bvs[i])) / root_volume : 0.0;
    const long double inter =
        detail::intersection_volume(detail::enclosing_box(bvh.bvs[bvh.left[i]]), detail::enclosing_box(bvh.bvs[bvh.right[i]]));
    q.sibling_overlap += root_box_volume > 0 ? static_cast<double>(inter / root_box_volume) : 0.0;
  }
  // Depths: parents precede children in no fixed order, so walk from the root.
  std::vector<std::pair<index_t, int>> stack{{0, 0}};
  double depth_sum = 0;
  while (!stack.empty()) {
    const auto [node, depth] = stack.back();
    stack.pop_back();
    if (bvh.is_leaf(node)) {
      q.max_depth = std::max(q.max_depth, depth);
      depth_sum += depth;
    } else {
      stack.push_back({bvh.left[node], depth + 1});
      stack.push_back({bvh.right[node], depth + 1});
    }
  }
  q.mean_leaf_depth = depth_sum / n;
  return q;
}

template <class BV, class P>
std::string check_bvh_invariants(const BvhView<BV>& bvh, const std::vector<Face>& faces,
                                 const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1) {
  const index_t n = bvh.num_leaves;
  if (n != static_cast<index_t>(faces.size()))
    return "num_leaves " + std::to_string(n) + " != face count " + std::to_string(faces.size());
  if (n == 0) return "";
  const index_t nodes = bvh.num_nodes();
  if (bvh.parent[0] != -1) return "root has a parent";
  std::vector<int> visits(static_cast<std::size_t>(nodes), 0);
  std::vector<index_t> stack{0};
  while (!stack.empty()) {
    const index_t node = stack.back();
    stack.pop_back();
    if (node < 0 || node >= nodes) return "child id " + std::to_string(node) + " out of range";
    if (++visits[node] > 1) return "node " + std::to_string(node) + " reached twice";
    if (bvh.is_leaf(node)) {
      const index_t k = bvh.leaf_index(node);
      if (bvh.ranges[node].first != k || bvh.ranges[node].last != k) return "leaf " + std::to_string(k) + " has a wrong range";
      continue;
    }
    const index_t l = bvh.left[node], r = bvh.right[node];
    if (l < 0 || l >= nodes || r < 0 || r >= nodes) return "node " + std::to_string(node) + " has a child out of range";
    if (bvh.parent[l] != node || bvh.parent[r] != node)
      return "node " + std::to_string(node) + ": a child's parent link does not point back";
    const LeafRange rl = bvh.ranges[l], rr = bvh.ranges[r], rn = bvh.ranges[node];
    if (rn.first != rl.first || rn.last != rr.last || rl.last + 1 != rr.first)
      return "node " + std::to_string(node) + ": leaf range is not the concatenation of its children's";
    if (!detail::encloses(bvh.bvs[node], bvh.bvs[l]) || !detail::encloses(bvh.bvs[node], bvh.bvs[r]))
      return "node " + std::to_string(node) + ": BV does not enclose a child's BV";
    stack.push_back(l);
    stack.push_back(r);
  }
  for (index_t node = 0; node < nodes; ++node)
    if (visits[node] != 1) return "node " + std::to_string(node) + " not reached from the root";
  std::vector<char> seen(static_cast<std::size_t>(n), 0);
  for (index_t k = 0; k < n; ++k) {
    const index_t f = bvh.leaf_primitive[k];
    if (f < 0 || f >= n || seen[f]++) return "leaf_primitive is not a permutation (leaf " + std::to_string(k) + ")";
    const BV& bv = bvh.bvs[bvh.leaf_node(k)];
    for (int c = 0; c < 3; ++c)
      if (!detail::contains_point_exactly(bv, x0[faces[f].v[c]]) || !detail::contains_point_exactly(bv, x1[faces[f].v[c]]))
        return "leaf " + std::to_string(k) + " (triangle " + std::to_string(f) + ") does not enclose its motion";
  }
  return "";
}

namespace cpu {

template <class BV>
template <class P>
void Bvh<BV>::build(const TriangleMesh& mesh, const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1) {
  detail::check_step_positions(mesh.num_vertices(), x0, x1, "cpu::Bvh::build");
  num_vertices_ = mesh.num_vertices();
  faces_ = mesh.faces();
  build_tree(x0, x1);
}

template <class BV>
template <class P>
void Bvh<BV>::build_tree(const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1) {
  const auto n = static_cast<index_t>(faces_.size());
  const auto size = static_cast<std::size_t>(n);
  std::vector<Vec3<P>> centers(size);
  // The centres and their box in fixed blocks, the blocks' boxes merged in order (exact either way).
  constexpr std::size_t kBlock = 4096;
  std::vector<Aabb<P>> block_boxes((size + kBlock - 1) / kBlock, Aabb<P>::empty());
  detail::parallel_ranges(block_boxes.size(), 1, [&](std::size_t first, std::size_t last) {
    for (std::size_t b = first; b < last; ++b)
      for (std::size_t f = b * kBlock; f < std::min(size, (b + 1) * kBlock); ++f) {
        centers[f] = detail::leaf_center(faces_[f], x0.data(), x1.data());
        block_boxes[b].expand(centers[f]);
      }
  });
  Aabb<P> scene = Aabb<P>::empty();
  for (const Aabb<P>& box : block_boxes) scene.expand(box);
  // Sorted by (code, triangle): the order of a stable sort by code, as CUB's radix sort gives on the GPU.
  std::vector<std::pair<std::uint64_t, index_t>> keyed(size);
  detail::parallel_ranges(size, detail::grain_for(size), [&](std::size_t begin, std::size_t end) {
    for (std::size_t f = begin; f < end; ++f) keyed[f] = {morton63(centers[f], scene), static_cast<index_t>(f)};
  });
  detail::parallel_sort(keyed.begin(), keyed.end());

  // Every entry of the node arrays is written below (a rebuild of the same mesh resizes nothing).
  BvhNodes<BV>& t = nodes_;
  t.num_leaves = n;
  const auto nodes = static_cast<std::size_t>(2 * n - 1);
  t.leaf_primitive.resize(size);
  t.leaf_codes.resize(size);
  t.bvs.resize(nodes);
  t.left.resize(size - 1);
  t.right.resize(size - 1);
  t.parent.resize(nodes);
  t.ranges.resize(nodes);
  t.parent[0] = -1;
  detail::parallel_ranges(size, detail::grain_for(size), [&](std::size_t begin, std::size_t end) {
    for (std::size_t k = begin; k < end; ++k) {
      t.leaf_codes[k] = keyed[k].first, t.leaf_primitive[k] = keyed[k].second;
      t.ranges[size - 1 + k] = {static_cast<index_t>(k), static_cast<index_t>(k)};
    }
  });
  // Each node is made from the codes alone (Karras's radix tree), and each child has one parent.
  detail::parallel_ranges(size - 1, detail::grain_for(size), [&](std::size_t begin, std::size_t end) {
    for (auto i = static_cast<index_t>(begin); i < static_cast<index_t>(end); ++i) {
      const detail::RadixNode node = detail::radix_tree_node(t.leaf_codes.data(), n, i);
      t.left[i] = node.left;
      t.right[i] = node.right;
      t.ranges[i] = {node.first, node.last};
      t.parent[node.left] = i;
      t.parent[node.right] = i;
    }
  });
  arrivals_.resize(size > 0 ? size - 1 : 0);
  fit_bottom_up(x0, x1);
  ++generation_;
  cost_at_build_ = detail::sah_cost(view());
}

template <class BV>
template <class P>
void Bvh<BV>::fit_bottom_up(const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1) {
  BvhNodes<BV>& t = nodes_;
  const index_t n = t.num_leaves;
  // The GPU's bottom-up pass on all cores: a node is fitted by the second child to arrive, always
  // as merge(left, right), so both backends compute the same values in the same order. The
  // arrival counters are left at zero for the next pass.
  std::atomic<unsigned char>* arrived = arrivals_.data();
  detail::parallel_ranges(static_cast<std::size_t>(n), detail::grain_for(static_cast<std::size_t>(n)),
                          [&](std::size_t begin, std::size_t end) {
    for (auto k = static_cast<index_t>(begin); k < static_cast<index_t>(end); ++k) {
      Vec3<P> unused_center;
      detail::leaf_volume(faces_[t.leaf_primitive[k]], x0.data(), x1.data(), t.bvs[n - 1 + k], unused_center, leaf_margin_);
      for (index_t p = t.parent[n - 1 + k]; p != -1; p = t.parent[p]) {
        // The first to arrive leaves; the second (which sees the first's writes) fits the node.
        if (arrived[p].fetch_add(1, std::memory_order_acq_rel) == 0) break;
        arrived[p].store(0, std::memory_order_relaxed);
        t.bvs[p] = bv_traits<BV>::merge(t.bvs[t.left[p]], t.bvs[t.right[p]]);
      }
    }
  });
}

template <class BV>
template <class P>
void Bvh<BV>::refit(const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1) {
  if (nodes_.num_leaves == 0) throw Error("cpu::Bvh::refit: the BVH has not been built");
  detail::check_step_positions(num_vertices_, x0, x1, "cpu::Bvh::refit");
  fit_bottom_up(x0, x1);
}

template <class BV>
template <class P>
bool Bvh<BV>::refit_or_rebuild(const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1,
                               const RebuildPolicy& policy) {
  refit(x0, x1);
  if (!policy.should_rebuild(detail::sah_cost(view()), cost_at_build_)) return false;
  build_tree(x0, x1);
  return true;
}

}  // namespace cpu

}  // namespace lwsccd
