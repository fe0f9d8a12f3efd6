// lwsccd — floating-point operations that round the same way on the host and the device.
//
// nvcc contracts a*b+c into one fused multiply-add wherever it can (also across inlined
// functions); the host does not. Code whose results must be bit-identical on both backends (the
// OBB fit, merge and overlap, whose values decide candidate pairs and, through the eigenvectors
// of nearly isotropic point sets, can otherwise amplify a last-bit difference into a different
// box) is written with these helpers: on the device they are the _rn intrinsics, which are never
// contracted; on the host, plain operations (the library's CMake target passes
// -ffp-contract=off to GCC and Clang so that the host never contracts either).
#pragma once

#include "lwsccd/core/config.hpp"
#include "lwsccd/geometry/vec.hpp"

namespace lwsccd::detail {

LWSCCD_HD inline float fmul(float a, float b) {
#if LWSCCD_IN_DEVICE_CODE
  return __fmul_rn(a, b);
#else
  return a * b;
#endif
}
LWSCCD_HD inline double fmul(double a, double b) {
#if LWSCCD_IN_DEVICE_CODE
  return __dmul_rn(a, b);
#else
  return a * b;
#endif
}
LWSCCD_HD inline float fadd(float a, float b) {
#if LWSCCD_IN_DEVICE_CODE
  return __fadd_rn(a, b);
#else
  return a + b;
#endif
}
LWSCCD_HD inline double fadd(double a, double b) {
#if LWSCCD_IN_DEVICE_CODE
  return __dadd_rn(a, b);
#else
  return a + b;
#endif
}
LWSCCD_HD inline float fsub(float a, float b) {
#if LWSCCD_IN_DEVICE_CODE
  return __fsub_rn(a, b);
#else
  return a - b;
#endif
}
LWSCCD_HD inline double fsub(double a, double b) {
#if LWSCCD_IN_DEVICE_CODE
  return __dsub_rn(a, b);
#else
  return a - b;
#endif
}

// long double: host-side references (tests, exact checks); no device version exists.
inline long double fmul(long double a, long double b) { return a * b; }
inline long double fadd(long double a, long double b) { return a + b; }
inline long double fsub(long double a, long double b) { return a - b; }

/// False for NaN and infinities (a value that is not finite decides nothing).
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE bool finite_value(T x) {
  return x - x == T(0);
}

template <class T> LWSCCD_HD Vec3<T> vadd(const Vec3<T>& a, const Vec3<T>& b) { return {fadd(a.x, b.x), fadd(a.y, b.y), fadd(a.z, b.z)}; }
template <class T> LWSCCD_HD Vec3<T> vsub(const Vec3<T>& a, const Vec3<T>& b) { return {fsub(a.x, b.x), fsub(a.y, b.y), fsub(a.z, b.z)}; }
template <class T> LWSCCD_HD Vec3<T> vscale(const Vec3<T>& a, T s) { return {fmul(a.x, s), fmul(a.y, s), fmul(a.z, s)}; }
/// a + b * s, rounded twice.
template <class T> LWSCCD_HD Vec3<T> vadd_scaled(const Vec3<T>& a, const Vec3<T>& b, T s) { return vadd(a, vscale(b, s)); }
template <class T> LWSCCD_HD T vdot(const Vec3<T>& a, const Vec3<T>& b) {
  return fadd(fadd(fmul(a.x, b.x), fmul(a.y, b.y)), fmul(a.z, b.z));
}
/// |a| . |b| (componentwise absolute values): the magnitude that bounds dot's rounding error.
template <class T> LWSCCD_HD T vabs_dot(const Vec3<T>& a, const Vec3<T>& b) {
  return fadd(fadd(fmul(std::fabs(a.x), std::fabs(b.x)), fmul(std::fabs(a.y), std::fabs(b.y))), fmul(std::fabs(a.z), std::fabs(b.z)));
}
template <class T> LWSCCD_HD Vec3<T> vcross(const Vec3<T>& a, const Vec3<T>& b) {
  return {fsub(fmul(a.y, b.z), fmul(a.z, b.y)), fsub(fmul(a.z, b.x), fmul(a.x, b.z)), fsub(fmul(a.x, b.y), fmul(a.y, b.x))};
}
template <class T> LWSCCD_HD T vnorm(const Vec3<T>& a) { return std::sqrt(vdot(a, a)); }
/// Comparisons spelled out (no fmax/fmin: what they return for NaN differs between libraries).
template <class T> LWSCCD_HD T fmax_of(T a, T b) { return a > b ? a : b; }
template <class T> LWSCCD_HD T fmin_of(T a, T b) { return a < b ? a : b; }
/// x clamped to [0, 1] (NaN to 0).
template <class T> LWSCCD_HD T unit_clamp(T x) { return x > T(0) ? (x < T(1) ? x : T(1)) : T(0); }

}  // namespace lwsccd::detail
