// lwsccd — oriented bounding box: covariance fit (Gottschalk et al. 1996) and separating-axis test.
//
// Semantics: the box is the slab intersection { p : |axis[i] . (p - center)| <= half[i], i = 0..2 }
// of the *stored* (rounded) values. Fitting pads every extent by a rigorous bound on the rounding
// of the projections, so each fitted point lies in that set. The stored axes are orthonormal only
// up to rounding; merge and overlap treat each extent as half[i] + kSlack * (sum of half) which
// covers that deviation, so neither can exclude a point of the set.
#pragma once

#include <cmath>
#include <limits>

#include "lwsccd/core/config.hpp"
#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/core/detail/rounding.hpp"
#include "lwsccd/geometry/aabb.hpp"
#include "lwsccd/geometry/detail/sym_eigen3.hpp"
#include "lwsccd/geometry/vec.hpp"

namespace lwsccd {

template <class T>
struct Obb {
  using scalar_type = T;
  Vec3<T> center;
  Vec3<T> axis[3];  ///< orthonormal up to rounding, right-handed
  Vec3<T> half;     ///< half extents along axis[0..2]

  /// Relative slack covering the non-orthonormality of the rounded axes (a few units of
  /// roundoff, taken generously).
  static constexpr T kSlack = T(64) * std::numeric_limits<T>::epsilon();

  /// Extent along axis i used by merge and overlap (conservative, see the file comment).
  LWSCCD_HD T safe_half(int i) const {
    return detail::fadd(half[i], detail::fmul(kSlack, detail::fadd(detail::fadd(half.x, half.y), half.z)));
  }

  LWSCCD_HD T volume() const { return T(8) * half.x * half.y * half.z; }
  LWSCCD_HD T surface_area() const { return T(8) * (half.x * half.y + half.y * half.z + half.z * half.x); }

  /// True when p is inside the box up to the rounding of this test (a point of the set is never
  /// reported outside).
  template <class U>
  LWSCCD_HD bool contains(const Vec3<U>& p) const;

  /// The box grown by `margin` along every axis, rounded outward.
  LWSCCD_HD Obb inflated(T margin) const {
    Obb r = *this;
    LWSCCD_UNROLL for (int i = 0; i < 3; ++i)
      r.half[i] = std::nextafter(half[i] + margin, std::numeric_limits<T>::infinity());
    return r;
  }

  /// The eight corners c +- h0 a0 +- h1 a1 +- h2 a2 (rounded; for display and refitting parents).
  LWSCCD_HD void corners(Vec3<T> out[8]) const {
    LWSCCD_UNROLL for (int k = 0; k < 8; ++k) {
      const T s0 = (k & 1) ? T(1) : T(-1), s1 = (k & 2) ? T(1) : T(-1), s2 = (k & 4) ? T(1) : T(-1);
      out[k] = detail::vadd_scaled(detail::vadd_scaled(detail::vadd_scaled(center, axis[0], s0 * half.x), axis[1], s1 * half.y),
                                   axis[2], s2 * half.z);
    }
  }

  /// Fits a box to n points by the covariance method; the points may be wider than T.
  template <class U>
  LWSCCD_HD static Obb fit(const Vec3<U>* points, int n);
  /// A box that encloses both a and b: axes from the covariance of their 16 corners, extents
  /// from the children's support functions (not from rounded corners).
  LWSCCD_HD static Obb merge(const Obb& a, const Obb& b);
  /// Separating-axis test over the 15 candidate axes. Never reports a false separation.
  /// fit, merge and overlap round identically on the host and the device (detail/fp.hpp).
  LWSCCD_HD static bool overlap(const Obb& a, const Obb& b);
};

using Obbf = Obb<float>;
using Obbd = Obb<double>;

}  // namespace lwsccd

#include "lwsccd/geometry/detail/obb_impl.hpp"
