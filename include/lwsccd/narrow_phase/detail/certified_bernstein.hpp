// lwsccd — the certified path's arithmetic on Bernstein coefficients: exact powers of two, the
// underflow slack, halving a piece (de Casteljau) and the sign tests on its coefficients.
// Part of certified_ccd.hpp: include <lwsccd/narrow_phase/certified_ccd.hpp>, not this file.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/core/detail/rounding.hpp"
#include "lwsccd/narrow_phase/certified_ccd.hpp"

namespace lwsccd::detail {

/// 2^-k for 0 <= k <= 120, built from its bits: exact, and no call (std::ldexp was a libm call on
/// the host, in the refinement's inner loop). x * exact_pow2_neg<T>(k) equals std::ldexp(x, -k)
/// wherever that does not underflow, which the refinement's dyadic times never do.
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE T exact_pow2_neg(int k) {
  static_assert(sizeof(T) == 8 || sizeof(T) == 4, "lwsccd: exact_pow2_neg is for float and double");
  T r;
  if constexpr (sizeof(T) == 8) {
    const std::uint64_t bits = static_cast<std::uint64_t>(1023 - k) << 52;
    std::memcpy(&r, &bits, sizeof r);
  } else {
    const std::uint32_t bits = static_cast<std::uint32_t>(127 - k) << 23;
    std::memcpy(&r, &bits, sizeof r);
  }
  return r;
}

/// underflow_slack's value, as the processor's multiplications give it: 64 denormals times f,
/// degree - 1 times, each product rounded to nearest even with gradual underflow.
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE T underflow_slack_by_multiplication(T f, int degree) {
  T s = T(64) * std::numeric_limits<T>::denorm_min();
  for (int i = 1; i < degree; ++i) s = fmul(s, f);
  return s;
}

#if !defined(__CUDA_ARCH__)
// The same products on the host without a floating-point multiplication on a denormal. Why: x86
// processors take a microcode assist for a multiplication with a denormal operand or result
// (measured on a Xeon: 93 ns against 1.4 ns), and the slack is a denormal times 1 + mag,
// degree - 1 times, in every screen and inside test (on the CPU most of the single-precision
// screen's time). Conversions and additions on denormals take no assist.

/// In float: each product is exact in double (two 24-bit significands, far from double's
/// underflow), and its conversion to float rounds it once, as the float multiplication does.
/// (The product passes through a volatile: else the compiler, seeing that, multiplies in float.)
inline float underflow_slack_without_assist(float f, int degree) {
  float s = 64.0f * std::numeric_limits<float>::denorm_min();
  for (int i = 1; i < degree; ++i) {
    volatile double product = static_cast<double>(s) * static_cast<double>(f);
    s = static_cast<float>(product);
  }
  return s;
}

#if (defined(__GNUC__) || defined(__clang__)) && defined(__SIZEOF_INT128__)
__extension__ typedef unsigned __int128 SlackWide;  // (a GCC/Clang extension: no -Wpedantic note)
inline int bit_length(std::uint64_t x) { return x ? 64 - __builtin_clzll(x) : 0; }
inline int bit_length(SlackWide x) {
  const auto high = static_cast<std::uint64_t>(x >> 64);
  return high ? 64 + bit_length(high) : bit_length(static_cast<std::uint64_t>(x));
}

/// In double, for finite f >= 1, in integers: the running value is m 2^j denormal units (m <=
/// 2^53 once rounded), each product m F 2^(j + e) (f = F 2^e, F the 53-bit significand) rounded
/// to the spacing at its size (one unit below the normal range, 2^(k - 52) units in
/// [2^k, 2^(k+1)) units above), to nearest even. Its bits are then j 2^52 + m: a denormal where
/// j = 0 and m < 2^52, else the exponent field j + 1 (a carry to m = 2^53 reads the same).
inline double underflow_slack_without_assist(double f, int degree) {
  if (!(f >= 1.0 && f <= std::numeric_limits<double>::max())) return underflow_slack_by_multiplication(f, degree);
  using Wide = SlackWide;
  std::uint64_t f_bits;
  std::memcpy(&f_bits, &f, sizeof f);
  const Wide significand = (f_bits & ((std::uint64_t(1) << 52) - 1)) | (std::uint64_t(1) << 52);
  const int e = static_cast<int>(f_bits >> 52) - 1023 - 52;  // f = significand 2^e
  constexpr std::uint64_t infinity_bits = std::uint64_t(0x7ff) << 52;
  Wide m = 64;
  int j = 0;
  for (int i = 1; i < degree; ++i) {
    const Wide product = m * significand;  // the value: product 2^t units
    const int t = j + e;
    const int k = bit_length(product) - 1 + t;  // 2^k <= value < 2^(k+1) units
    const int next_j = k > 52 ? k - 52 : 0;
    const int shift = next_j - t;
    if (shift <= 0) {
      m = product << -shift;  // exact
    } else {
      m = product >> shift;
      const Wide rest = product - (m << shift), half = Wide(1) << (shift - 1);
      if (rest > half || (rest == half && (m & 1u))) ++m;
    }
    j = next_j;
    if ((static_cast<Wide>(j) << 52) + m >= infinity_bits) return std::numeric_limits<double>::infinity();
  }
  const auto bits = static_cast<std::uint64_t>((static_cast<Wide>(j) << 52) + m);
  double s;
  std::memcpy(&s, &bits, sizeof s);
  return s;
}
#endif
#endif

/// Bound on what underflow can add to a degree-`d` product expression of values up to `mag`:
/// each operation loses at most a denormal, later multiplied by at most d - 1 factors. The same
/// value on the host and the device (on the host computed without an assist: see above).
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE T underflow_slack(T mag, int degree) {
  const T f = fadd(T(1), mag);
#if !defined(__CUDA_ARCH__) && ((defined(__GNUC__) || defined(__clang__)) && defined(__SIZEOF_INT128__))
  if constexpr (sizeof(T) == 4 || sizeof(T) == 8) return underflow_slack_without_assist(f, degree);
#elif !defined(__CUDA_ARCH__)
  if constexpr (sizeof(T) == 4) return underflow_slack_without_assist(f, degree);
#endif
  return underflow_slack_by_multiplication(f, degree);
}

/// The four Bernstein coefficients of the cubic on a dyadic interval and two bounds on their
/// error: `bound` covers rounding and the inputs' perturbation (what may be excluded), `exact`
/// rounding alone (what the query as given certainly does).
template <class T>
struct BernsteinPiece {
  T c[4];
  T bound, exact;
};

/// Halves a piece by de Casteljau at 1/2. Each average rounds once (|error| <= u max|c|, halving
/// is exact but for underflow); the innermost value goes through three: 3 u max|c| per halving.
template <class Policy, class T>
LWSCCD_HD LWSCCD_HOST_INLINE void bernstein_halves(const BernsteinPiece<T>& p, BernsteinPiece<T>& left, BernsteinPiece<T>& right) {
  const T h = T(0.5);
  const T m01 = fmul(fadd(p.c[0], p.c[1]), h), m12 = fmul(fadd(p.c[1], p.c[2]), h), m23 = fmul(fadd(p.c[2], p.c[3]), h);
  const T m012 = fmul(fadd(m01, m12), h), m123 = fmul(fadd(m12, m23), h);
  const T mid = fmul(fadd(m012, m123), h);
  T big = T(0);
  for (int i = 0; i < 4; ++i) big = std::fabs(p.c[i]) > big ? std::fabs(p.c[i]) : big;
  const T added = fmul(T(Policy::kSplitBound),
                       fadd(fmul(T(4) * unit_roundoff<T>(), big), T(4) * std::numeric_limits<T>::denorm_min()));
  const T bound = fadd(p.bound, added), exact = fadd(p.exact, added);
  left = {{p.c[0], m01, m012, mid}, bound, exact};
  right = {{mid, m123, m23, p.c[3]}, bound, exact};
}

/// -1, 0 or 1: the sign of x when |x| > bound, else 0.
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE int sign_beyond(T x, T bound) {
  return x > bound ? 1 : (x < -bound ? -1 : 0);
}

/// True when every cubic whose Bernstein coefficients lie within `bound` of c has exactly one root
/// in the interval: the end values have certain, opposite signs, and the coefficients change sign
/// once whatever the uncertain middle ones are (c1 certainly of c0's sign, or c2 of c3's), so by
/// Descartes' rule for the Bernstein basis there is at most one root, and an odd number.
template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE bool single_crossing(const T c[4], T bound) {
  const int first = sign_beyond(c[0], bound), last = sign_beyond(c[3], bound);
  if (first == 0 || last != -first) return false;
  return sign_beyond(c[1], bound) == first || sign_beyond(c[2], bound) == last;
}

/// True when both halves of the piece keep one sign beyond their perturbed bound: no perturbed
/// cubic has a root in it, so no inside test is needed there.
template <class Policy, class T>
LWSCCD_HD LWSCCD_HOST_INLINE bool halves_keep_sign(const BernsteinPiece<T>& p) {
  BernsteinPiece<T> left, right;
  bernstein_halves<Policy>(p, left, right);
  return same_sign_beyond(left.c, left.bound) && same_sign_beyond(right.c, right.bound);
}

template <class T>
LWSCCD_HD LWSCCD_HOST_INLINE bool all_within(const T c[4], T bound) {
  return std::fabs(c[0]) <= bound && std::fabs(c[1]) <= bound && std::fabs(c[2]) <= bound && std::fabs(c[3]) <= bound;
}

}  // namespace lwsccd::detail
