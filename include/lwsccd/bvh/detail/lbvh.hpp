// lwsccd — the pieces of the LBVH build shared by the CPU backend and the CUDA kernels.
#pragma once

#include <cstdint>

#include "lwsccd/core/config.hpp"
#include "lwsccd/geometry/aabb.hpp"
#include "lwsccd/geometry/bv_traits.hpp"
#include "lwsccd/geometry/mesh.hpp"

namespace lwsccd {
struct LeafRange;
}

namespace lwsccd::detail {

LWSCCD_HD inline int count_leading_zeros64(std::uint64_t x) {
#if LWSCCD_IN_DEVICE_CODE
  return __clzll(static_cast<long long>(x));
#else
  return x == 0 ? 64 : __builtin_clzll(x);
#endif
}

LWSCCD_HD inline int count_leading_zeros32(std::uint32_t x) {
#if LWSCCD_IN_DEVICE_CODE
  return __clz(static_cast<int>(x));
#else
  return x == 0 ? 32 : __builtin_clz(x);
#endif
}

/// Length of the common prefix of sorted keys i and j (Karras's delta); equal codes fall back
/// to the positions, so every key is distinct; -1 outside [0, n).
LWSCCD_HD inline int common_prefix(const std::uint64_t* codes, index_t n, index_t i, index_t j) {
  if (j < 0 || j >= n) return -1;
  const std::uint64_t a = codes[i], b = codes[j];
  if (a != b) return count_leading_zeros64(a ^ b);
  return 64 + count_leading_zeros32(static_cast<std::uint32_t>(i ^ j));
}

struct RadixNode {
  index_t left, right;  ///< child node ids (internal 0..n-2, leaves n-1..2n-2)
  index_t first, last;  ///< covered sorted leaves
};

/// Internal node i of the binary radix tree over n >= 2 sorted keys (Karras 2012, Fig. 4).
LWSCCD_HD inline RadixNode radix_tree_node(const std::uint64_t* codes, index_t n, index_t i) {
  // Direction of the range: towards the neighbour sharing the longer prefix.
  const int d = common_prefix(codes, n, i, i + 1) - common_prefix(codes, n, i, i - 1) > 0 ? 1 : -1;
  const int delta_min = common_prefix(codes, n, i, i - d);
  // Upper bound on the range length, then binary search for the other end.
  index_t l_max = 2;
  while (common_prefix(codes, n, i, i + l_max * d) > delta_min) l_max *= 2;
  index_t l = 0;
  for (index_t t = l_max / 2; t >= 1; t /= 2)
    if (common_prefix(codes, n, i, i + (l + t) * d) > delta_min) l += t;
  const index_t j = i + l * d;
  // Split position: the last key that shares more than the node's prefix with key i.
  const int delta_node = common_prefix(codes, n, i, j);
  index_t s = 0;
  for (index_t div = 2;; div *= 2) {
    const index_t t = (l + div - 1) / div;
    if (common_prefix(codes, n, i, i + (s + t) * d) > delta_node) s += t;
    if (t <= 1) break;
  }
  const index_t gamma = i + s * d + (d < 0 ? d : 0);
  const index_t first = i < j ? i : j;
  const index_t last = i < j ? j : i;
  RadixNode node;
  node.left = first == gamma ? (n - 1) + gamma : gamma;
  node.right = last == gamma + 1 ? (n - 1) + gamma + 1 : gamma + 1;
  node.first = first;
  node.last = last;
  return node;
}

/// The centre of a triangle's swept AABB over the step (for Morton codes).
template <class P>
LWSCCD_HD Vec3<P> leaf_center(const Face& f, const Vec3<P>* x0, const Vec3<P>* x1) {
  Aabb<P> box = Aabb<P>::empty();
  for (int k = 0; k < 3; ++k) {
    box.expand(x0[f.v[k]]);
    box.expand(x1[f.v[k]]);
  }
  return box.center();
}

/// Leaf BV of a triangle over the step from its corners at t = 0 (`pts[0..2]`) and t = 1
/// (`pts[3..5]`), and the centre of its swept AABB (for Morton codes), expanded in leaf_center's
/// order.
template <class BV, class P>
LWSCCD_HD void leaf_volume_of_points(const Vec3<P> (&pts)[6], BV& bv, Vec3<P>& center,
                                     typename bv_traits<BV>::scalar_type margin = 0) {
  bv = bv_traits<BV>::fit(pts, 6);
  if (margin > 0) bv = bv_traits<BV>::inflate(bv, margin);  // proximity queries: see Bvh::set_leaf_margin
  Aabb<P> box = Aabb<P>::empty();
  for (int k = 0; k < 3; ++k) {
    box.expand(pts[k]);
    box.expand(pts[3 + k]);
  }
  center = box.center();
}

/// Leaf BV of a triangle over the step, and the centre of its swept AABB (for Morton codes).
template <class BV, class P>
LWSCCD_HD void leaf_volume(const Face& f, const Vec3<P>* x0, const Vec3<P>* x1, BV& bv, Vec3<P>& center,
                           typename bv_traits<BV>::scalar_type margin = 0) {
  const Vec3<P> pts[6] = {x0[f.v[0]], x0[f.v[1]], x0[f.v[2]], x1[f.v[0]], x1[f.v[1]], x1[f.v[2]]};
  leaf_volume_of_points(pts, bv, center, margin);
}

}  // namespace lwsccd::detail
