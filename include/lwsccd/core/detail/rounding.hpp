// lwsccd — directed rounding helpers that keep bounding volumes conservative.
#pragma once

#include <cmath>
#include <limits>

#include "lwsccd/core/config.hpp"

namespace lwsccd::detail {

/// Unit roundoff of T (half the machine epsilon).
template <class T>
LWSCCD_HD constexpr T unit_roundoff() {
  return std::numeric_limits<T>::epsilon() / T(2);
}

/// The largest T not greater than x (x converted from a possibly wider type).
template <class T, class U>
LWSCCD_HD T round_down(U x) {
  T r = static_cast<T>(x);
  if (static_cast<U>(r) > x) r = std::nextafter(r, -std::numeric_limits<T>::infinity());
  return r;
}

/// The smallest T not less than x.
template <class T, class U>
LWSCCD_HD T round_up(U x) {
  T r = static_cast<T>(x);
  if (static_cast<U>(r) < x) r = std::nextafter(r, std::numeric_limits<T>::infinity());
  return r;
}

/// The wider of two floating-point types.
template <class A, class B>
using wider_t = decltype(A(0) + B(0));

}  // namespace lwsccd::detail
