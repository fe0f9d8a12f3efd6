// lwsccd — the bounding-volume interface the rest of the library uses.
//
// Traversal, BVH and oracle code never name a BV type: they go through bv_traits<BV>, so a new
// volume (a k-DOP, a sphere) plugs in by specializing it. Every operation must be conservative:
// fit/merge/sweep never exclude a point they should contain, overlap never reports a false
// separation, also after rounding.
#pragma once

#include <cstdint>
#include <limits>
#include <type_traits>

#include "lwsccd/core/config.hpp"
#include "lwsccd/core/detail/rounding.hpp"
#include "lwsccd/core/error.hpp"
#include "lwsccd/geometry/aabb.hpp"
#include "lwsccd/geometry/obb.hpp"
#include "lwsccd/geometry/vec.hpp"

namespace lwsccd {

/// Specialize for a bounding-volume type. Required members (all LWSCCD_HD, static):
///   using scalar_type;
///   template <class U> BV fit(const Vec3<U>* points, int n);   // n >= 1
///   BV merge(const BV&, const BV&);
///   bool overlap(const BV&, const BV&);
///   scalar_type volume(const BV&);  scalar_type surface_area(const BV&);
///   BV inflate(const BV&, scalar_type margin);
///   Vec3<scalar_type> center(const BV&);
template <class BV>
struct bv_traits;  // no definition: an unknown BV fails is_bounding_volume below

/// A BV read from memory: `*p`. On the device an Aabbf at an 8-byte aligned address (every
/// allocation's boxes; 24 bytes each) is read in three 8-byte loads instead of six 4-byte ones
/// (the traversal reads two boxes per BVTT node pair).
template <class BV>
LWSCCD_HD inline BV load_bv(const BV* p) {
  return *p;
}
LWSCCD_HD inline Aabb<float> load_bv(const Aabb<float>* p) {
#ifdef __CUDA_ARCH__
  if ((reinterpret_cast<std::uintptr_t>(p) & 7u) == 0) {
    const float2* q = reinterpret_cast<const float2*>(p);
    const float2 a = __ldg(q), b = __ldg(q + 1), c = __ldg(q + 2);
    return {{a.x, a.y, b.x}, {b.y, c.x, c.y}};
  }
#endif
  return *p;
}

template <class T>
struct bv_traits<Aabb<T>> {
  using scalar_type = T;
  template <class U>
  LWSCCD_HD static Aabb<T> fit(const Vec3<U>* points, int n) {
    // The extremes in U, then each rounded once: rounding outward is monotone, so this is the box
    // that expanding by every point gives, with 6 roundings instead of 6 n (a leaf's 6 points:
    // 36 roundings, most of a CPU BVH build's time).
    Vec3<U> lo = points[0], hi = points[0];
    for (int i = 1; i < n; ++i) {
      lo = min(lo, points[i]);
      hi = max(hi, points[i]);
    }
    Aabb<T> box;
    box.lo = {detail::round_down<T>(lo.x), detail::round_down<T>(lo.y), detail::round_down<T>(lo.z)};
    box.hi = {detail::round_up<T>(hi.x), detail::round_up<T>(hi.y), detail::round_up<T>(hi.z)};
    return box;
  }
  LWSCCD_HD static Aabb<T> merge(const Aabb<T>& a, const Aabb<T>& b) {
    Aabb<T> r = a;
    r.expand(b);
    return r;
  }
  LWSCCD_HD static bool overlap(const Aabb<T>& a, const Aabb<T>& b) { return a.overlaps(b); }
  LWSCCD_HD static T volume(const Aabb<T>& a) { return a.volume(); }
  LWSCCD_HD static T surface_area(const Aabb<T>& a) { return a.surface_area(); }
  LWSCCD_HD static Aabb<T> inflate(const Aabb<T>& a, T margin) { return a.inflated(margin); }
  LWSCCD_HD static Vec3<T> center(const Aabb<T>& a) { return a.center(); }
};

template <class T>
struct bv_traits<Obb<T>> {
  using scalar_type = T;
  template <class U>
  LWSCCD_HD static Obb<T> fit(const Vec3<U>* points, int n) { return Obb<T>::fit(points, n); }
  LWSCCD_HD static Obb<T> merge(const Obb<T>& a, const Obb<T>& b) { return Obb<T>::merge(a, b); }
  LWSCCD_HD static bool overlap(const Obb<T>& a, const Obb<T>& b) { return Obb<T>::overlap(a, b); }
  LWSCCD_HD static T volume(const Obb<T>& a) { return a.volume(); }
  LWSCCD_HD static T surface_area(const Obb<T>& a) { return a.surface_area(); }
  LWSCCD_HD static Obb<T> inflate(const Obb<T>& a, T margin) { return a.inflated(margin); }
  LWSCCD_HD static Vec3<T> center(const Obb<T>& a) { return a.center; }
};

namespace detail {
// A margin to grow a BV by, in its scalar, rounded up (the grown BV still holds the whole margin).
// Throws InputError naming `who` unless finite and >= 0.
template <class BV>
typename bv_traits<BV>::scalar_type checked_margin(double margin, const char* who) {
  using S = typename bv_traits<BV>::scalar_type;
  if (!(margin >= 0) || !(margin <= static_cast<double>(std::numeric_limits<S>::max())))
    throw InputError(who, "margin", "must be finite and >= 0");
  return round_up<S>(margin);
}

template <class BV, class = void>
struct has_bv_traits : std::false_type {};
template <class BV>
struct has_bv_traits<BV, std::void_t<decltype(sizeof(bv_traits<BV>))>> : std::true_type {};

template <class BV, class = void>
struct bv_traits_complete : std::false_type {};
template <class BV>
struct bv_traits_complete<
    BV, std::void_t<typename bv_traits<BV>::scalar_type,
                    decltype(bv_traits<BV>::template fit<typename bv_traits<BV>::scalar_type>(
                        static_cast<const Vec3<typename bv_traits<BV>::scalar_type>*>(nullptr), 1)),
                    decltype(bv_traits<BV>::merge(std::declval<const BV&>(), std::declval<const BV&>())),
                    decltype(bv_traits<BV>::overlap(std::declval<const BV&>(), std::declval<const BV&>())),
                    decltype(bv_traits<BV>::volume(std::declval<const BV&>())),
                    decltype(bv_traits<BV>::surface_area(std::declval<const BV&>())),
                    decltype(bv_traits<BV>::center(std::declval<const BV&>()))>> : std::true_type {};
}  // namespace detail

/// True when BV has a complete bv_traits specialization.
template <class BV>
inline constexpr bool is_bounding_volume_v = detail::bv_traits_complete<BV>::value;

/// Compile-time contract check with a readable message; use at the top of BV-generic code.
template <class BV>
struct require_bounding_volume {
  static_assert(detail::has_bv_traits<BV>::value,
                "lwsccd: BV has no bv_traits<BV> specialization (see lwsccd/geometry/bv_traits.hpp)");
  static_assert(detail::bv_traits_complete<BV>::value,
                "lwsccd: bv_traits<BV> lacks a member: needs scalar_type, fit, merge, overlap, volume, "
                "surface_area, center (see lwsccd/geometry/bv_traits.hpp)");
  static constexpr bool value = true;
};

/// Bounding volume of a triangle's motion over the whole step: the convex hull of its six
/// endpoint positions contains every intermediate position under linear motion.
template <class BV, class U>
LWSCCD_HD BV swept_triangle_bv(const Vec3<U>& a0, const Vec3<U>& b0, const Vec3<U>& c0, const Vec3<U>& a1,
                               const Vec3<U>& b1, const Vec3<U>& c1) {
  const Vec3<U> pts[6] = {a0, b0, c0, a1, b1, c1};
  return bv_traits<BV>::fit(pts, 6);
}

}  // namespace lwsccd
