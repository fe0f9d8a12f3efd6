// lwsccd — casting rays against a triangle BVH as a traversal task: the lazy-stealing scheduler
// (and every other) reused for ray tracing, written only against the public task interface.
//
// Items are (ray, BVH node) pairs. Closest hit: each ray keeps its best hit in a 64-bit word
// (t's float bits, which order like t for t >= 0, above the triangle id) lowered with an atomic
// minimum, and nodes the ray enters only beyond its best hit are pruned. Any hit (shadow rays):
// the first hit sets the ray's word and the others stop. Both give the same answer in every
// scheduler (the minimum does not depend on the order).
#pragma once

#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "lwsccd/bvh/bvh.hpp"
#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/traversal/traversal_task.hpp"

namespace lwsccd {

struct Ray {
  Vec3f origin, direction;
  float t_max;
};

struct RayNode {
  index_t ray, node;
};

/// No hit: the largest key.
constexpr std::uint64_t kNoHit = ~std::uint64_t(0);

LWSCCD_HD inline std::uint64_t hit_key(float t, index_t triangle) {
  std::uint32_t bits;
  memcpy(&bits, &t, sizeof bits);
  return (static_cast<std::uint64_t>(bits) << 32) | static_cast<std::uint32_t>(triangle);
}
LWSCCD_HD inline float hit_t(std::uint64_t key) {
  const std::uint32_t bits = static_cast<std::uint32_t>(key >> 32);
  float t;
  memcpy(&t, &bits, sizeof t);
  return t;
}
LWSCCD_HD inline index_t hit_triangle(std::uint64_t key) { return static_cast<index_t>(key & 0xffffffffu); }

namespace detail {

LWSCCD_HD inline std::uint64_t atomic_load_u64(const std::uint64_t* p) {
#if LWSCCD_IN_DEVICE_CODE
  return *reinterpret_cast<const volatile unsigned long long*>(p);
#else
  return __atomic_load_n(p, __ATOMIC_RELAXED);
#endif
}

LWSCCD_HD inline void atomic_min_u64(std::uint64_t* p, std::uint64_t value) {
#if LWSCCD_IN_DEVICE_CODE
  atomicMin(reinterpret_cast<unsigned long long*>(p), static_cast<unsigned long long>(value));
#else
  std::uint64_t current = __atomic_load_n(p, __ATOMIC_RELAXED);
  while (value < current && !__atomic_compare_exchange_n(p, &current, value, true, __ATOMIC_RELAXED, __ATOMIC_RELAXED)) {
  }
#endif
}

/// Entry distance of the ray into the box, or +inf when it misses it within [0, t_max]. The slab
/// distances are widened by a few ulps (Ize 2013) so that rounding never culls a box the ray
/// touches: the traversal then finds exactly the hits a test of every triangle finds.
LWSCCD_HD inline float ray_box_entry(const Ray& r, const Vec3f& inv, const Aabbf& b, float t_max) {
  float t0 = 0.0f, t1 = t_max;
  for (int a = 0; a < 3; ++a) {
    float near_t = fmul(fsub(b.lo[a], r.origin[a]), inv[a]), far_t = fmul(fsub(b.hi[a], r.origin[a]), inv[a]);
    if (near_t > far_t) {
      const float tmp = near_t;
      near_t = far_t;
      far_t = tmp;
    }
    // NaN from 0 * inf (ray in the slab's plane) keeps the bounds unchanged.
    t0 = near_t > t0 ? near_t : t0;
    t1 = far_t < t1 ? far_t : t1;
  }
  constexpr float kWiden = 8.0f * std::numeric_limits<float>::epsilon();
  return t0 * (1.0f - kWiden) <= t1 * (1.0f + kWiden) ? t0 * (1.0f - kWiden) : std::numeric_limits<float>::infinity();
}

/// 1 / direction, componentwise (IEEE division: the same bits on host and device).
LWSCCD_HD inline Vec3f inverse_direction(const Vec3f& d) { return {1.0f / d.x, 1.0f / d.y, 1.0f / d.z}; }

/// Moller-Trumbore: distance along the ray to triangle (a, b, c), or +inf. Rounded the same way
/// on host and device (detail/fp.hpp), so every scheduler reports the same bits.
LWSCCD_HD inline float ray_triangle(const Ray& r, const Vec3f& a, const Vec3f& b, const Vec3f& c) {
  const Vec3f e1 = vsub(b, a), e2 = vsub(c, a);
  const Vec3f p = vcross(r.direction, e2);
  const float det = vdot(e1, p);
  if (det == 0.0f) return std::numeric_limits<float>::infinity();
  const float inv_det = 1.0f / det;
  const Vec3f s = vsub(r.origin, a);
  const float u = fmul(vdot(s, p), inv_det);
  if (u < 0.0f || u > 1.0f) return std::numeric_limits<float>::infinity();
  const Vec3f q = vcross(s, e1);
  const float v = fmul(vdot(r.direction, q), inv_det);
  if (v < 0.0f || fadd(u, v) > 1.0f) return std::numeric_limits<float>::infinity();
  const float t = fmul(vdot(e2, q), inv_det);
  return t > 0.0f && t <= r.t_max ? t : std::numeric_limits<float>::infinity();
}

/// One ray's walk down a BVH from `node`, whose box it enters within its best hit so far (`hit`,
/// lowered as it finds closer ones): near child first, the far one on a local stack of kStack
/// nodes with their entry distances, so a pending node beyond a closer hit found since is dropped
/// without a box test. After `budget` visited nodes, or when a far child finds the stack full, it
/// stops and hands every node it still had to visit to `spill` (at most kStack + 2), for other
/// threads to take. Any hit: it stops at the first one. The same nodes are pruned as in
/// RayCastTask (entry distance beyond the best hit), so the closest hit is the same.
template <int kStack, class Spill>
LWSCCD_HD void walk_ray(const BvhView<Aabbf>& bvh, const Face* faces, const Vec3f* positions, const Ray& r, const Vec3f& inv,
                        index_t node, std::uint64_t& hit, bool any_hit, int budget, Spill& spill) {
  static_assert(kStack >= 1, "lwsccd: walk_ray needs a stack of at least one node");
  index_t pending[kStack];
  float pending_entry[kStack];
  int top = 0;
  float limit = hit == kNoHit ? r.t_max : hit_t(hit);
  auto spill_stack = [&] {  // the pending nodes the ray still enters, to other threads
    while (top > 0)
      if (pending_entry[--top] <= limit) spill(pending[top]);
  };
  for (int visits = 0;; ++visits) {
    if (visits == budget) {  // out of budget: the node and the stack go to other threads
      spill(node);
      spill_stack();
      return;
    }
    if (bvh.is_leaf(node)) {
      const index_t tri = bvh.primitive(node);
      const Face f = faces[tri];
      const float t = ray_triangle(r, positions[f.v[0]], positions[f.v[1]], positions[f.v[2]]);
      if (t <= limit) {
        const std::uint64_t key = hit_key(t, tri);
        if (key < hit) hit = key;
        limit = hit_t(hit);
        if (any_hit) return;
      }
    } else {
      const index_t a = bvh.left[node], b = bvh.right[node];
      const float entry_a = ray_box_entry(r, inv, bvh.bvs[a], limit), entry_b = ray_box_entry(r, inv, bvh.bvs[b], limit);
      const bool enters_a = entry_a <= limit, enters_b = entry_b <= limit;
      if (enters_a && enters_b) {
        const bool a_first = entry_a <= entry_b;
        const index_t near = a_first ? a : b, far = a_first ? b : a;
        if (top == kStack) {  // no room for the far child: hand everything over
          spill(far);
          spill(near);
          spill_stack();
          return;
        }
        pending[top] = far;
        pending_entry[top] = a_first ? entry_b : entry_a;
        ++top;
        node = near;
        continue;
      }
      if (enters_a || enters_b) {
        node = enters_a ? a : b;
        continue;
      }
    }
    // Back to the nearest pending node the ray still enters within its best hit.
    while (top > 0 && !(pending_entry[top - 1] <= limit)) --top;
    if (top == 0) return;
    node = pending[--top];
  }
}

}  // namespace detail

/// Rays against a BVH of AABBs over the triangles at t0 (x0). Seeds: {ray, root} per ray.
struct RayCastTask {
  using item_type = RayNode;
  using result_type = RayNode;  ///< unused: hits go to `best`
  static constexpr int kMaxChildren = 2;
  static constexpr int kMaxResults = 1;

  BvhView<Aabbf> bvh;
  const Face* faces;
  const Vec3f* positions;
  const Ray* rays;
  std::uint64_t* best;  ///< per ray, kNoHit before the traversal
  bool any_hit = false;
  /// Optional, per ray: detail::inverse_direction of its direction (inverse_directions() makes
  /// them), so that each of its items does not divide three times again; the same hits.
  const Vec3f* inverse = nullptr;

  /// What an item starts from: its ray, the ray's best hit so far and the distance it limits,
  /// the inverse direction; false when the item ends at once (any hit found, or its node's box
  /// not entered within the limit).
  struct ItemStart {
    Ray r;
    std::uint64_t current;
    float limit;
    Vec3f inv;
  };
  LWSCCD_HD bool start(const RayNode& item, ItemStart& s) const {
    s.r = rays[item.ray];
    s.current = detail::atomic_load_u64(&best[item.ray]);
    if (any_hit && s.current != kNoHit) return false;
    s.limit = s.current == kNoHit ? s.r.t_max : hit_t(s.current);
    s.inv = inverse ? inverse[item.ray] : detail::inverse_direction(s.r.direction);
    return detail::ray_box_entry(s.r, s.inv, bvh.bvs[item.node], s.limit) <= s.limit;
  }

  LWSCCD_EXEC_CHECK_DISABLE
  template <class Out>
  LWSCCD_HD void process(const RayNode& item, Out& out) const {
    ItemStart s;
    if (!start(item, s)) return;
    const Ray& r = s.r;
    const float limit = s.limit;
    if (bvh.is_leaf(item.node)) {
      const index_t tri = bvh.primitive(item.node);
      const Face f = faces[tri];
      const float t = detail::ray_triangle(r, positions[f.v[0]], positions[f.v[1]], positions[f.v[2]]);
      if (t <= limit) detail::atomic_min_u64(&best[item.ray], hit_key(t, tri));
      return;
    }
    out.push_item(RayNode{item.ray, bvh.left[item.node]});
    out.push_item(RayNode{item.ray, bvh.right[item.node]});
  }
};

/// RayCastTask with items that each walk a ray `visit_budget` nodes down the BVH (detail::walk_ray:
/// near child first, a local stack of StackSize nodes) before handing the nodes still to visit
/// back as items, instead of one node per item. The scheduler's cost (a round, a scan, shared
/// memory, steals) is then paid per walk, not per node; the budget bounds how long one thread
/// holds a ray, so long rays are still split among threads. Budget 0 (or less): no bound (a whole
/// ray per item, unless its stack fills). The same closest hits as RayCastTask, in every scheduler.
///
/// kMaxChildren is StackSize + 2 (16 by default): a scheduler's policy needs room for that many
/// children per thread and round - gpu::RayWalkLazySteal (<lwsccd/traverse.cuh>) has it; a policy
/// with too little says so in its static_asserts. The defaults (a stack of 14, walks of 64, that
/// policy) were the fastest of the variants lwsccd-bench-rays --walks weighs on an H100
/// (docs/RAYTRACING.md).
template <int StackSize = 14>
struct RayWalkTask : RayCastTask {
  static_assert(StackSize >= 1, "lwsccd: RayWalkTask needs a stack of at least one node (StackSize >= 1)");
  static constexpr int kStackSize = StackSize;
  static constexpr int kMaxChildren = StackSize + 2;
  int visit_budget = 64;  ///< nodes one item visits before it hands the rest back (0 or less: no bound)

  LWSCCD_EXEC_CHECK_DISABLE
  template <class Out>
  LWSCCD_HD void process(const RayNode& item, Out& out) const {
    ItemStart s;
    if (!start(item, s)) return;
    Spill<Out> spill{out, item.ray};
    std::uint64_t hit = s.current;
    detail::walk_ray<StackSize>(bvh, faces, positions, s.r, s.inv, item.node, hit, any_hit,
                                visit_budget > 0 ? visit_budget : -1, spill);
    if (hit < s.current) detail::atomic_min_u64(&best[item.ray], hit);
  }

 private:
  template <class Out>
  struct Spill {
    Out& out;
    index_t ray;
    LWSCCD_EXEC_CHECK_DISABLE
    LWSCCD_HD void operator()(index_t node) { out.push_item(RayNode{ray, node}); }
  };
};

/// The inverse directions of `rays`, for RayCastTask::inverse.
inline std::vector<Vec3f> inverse_directions(const std::vector<Ray>& rays) {
  std::vector<Vec3f> out(rays.size());
  for (std::size_t i = 0; i < rays.size(); ++i) out[i] = detail::inverse_direction(rays[i].direction);
  return out;
}

}  // namespace lwsccd
