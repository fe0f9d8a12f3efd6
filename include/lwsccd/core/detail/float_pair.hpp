// lwsccd — pairs of floats ("double-word" numbers): a value hi + lo held in two floats, about 48
// bits of significand from FP32 arithmetic alone, for the few computations that need more than
// float on GPUs whose FP64 is scarce (the narrow phase's leaf proofs, NARROW_PHASE.md B17).
//
// The operations are Joldes, Muller and Popescu's (ACM TOMS 44(2), 2017): with u = 2^-24 and
// barring underflow, each result is the exact one times (1 + e):
//   pair_add (their Algorithm 6, AccurateDWPlusDW)  |e| <= 3u^2 / (1 - 4u)
//   pair_mul (Algorithm 12, DWTimesDW3, with FMA)   |e| <= 5u^2
//   pair_scale by a float (Algorithm 9, DWTimesFP3) |e| <= 2u^2
// so kFloatPairUnit (6u^2) bounds every one of them. Every float operation goes through the _rn
// intrinsics on the device (never contracted) and plain operations on the host (the library's
// target passes -ffp-contract=off), so both backends compute the same bits.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>

#include "lwsccd/core/config.hpp"
#include "lwsccd/core/detail/fp.hpp"

namespace lwsccd::detail {

/// hi + lo with |lo| <= ulp(hi) / 2 (a normalized double-word number).
struct FloatPair {
  float hi = 0.0f, lo = 0.0f;
};

/// The relative error every pair operation stays within, barring underflow: 6 u^2 (u = 2^-24).
inline constexpr float kFloatPairUnit = 6.0f / 281474976710656.0f;  // 6 * 2^-48

LWSCCD_HD inline float ffma(float a, float b, float c) {
#if LWSCCD_IN_DEVICE_CODE
  return __fmaf_rn(a, b, c);
#else
  return std::fma(a, b, c);
#endif
}

/// a + b exactly as s + e (Knuth's TwoSum: no condition on the operands).
LWSCCD_HD inline FloatPair two_sum(float a, float b) {
  const float s = fadd(a, b);
  const float bb = fsub(s, a);
  const float e = fadd(fsub(a, fsub(s, bb)), fsub(b, bb));
  return {s, e};
}
/// a + b exactly as s + e where |a| >= |b| (or a is 0) (Dekker's Fast2Sum).
LWSCCD_HD inline FloatPair fast_two_sum(float a, float b) {
  const float s = fadd(a, b);
  return {s, fsub(b, fsub(s, a))};
}

/// Algorithm 6 (AccurateDWPlusDW).
LWSCCD_HD inline FloatPair pair_add(const FloatPair& x, const FloatPair& y) {
  const FloatPair s = two_sum(x.hi, y.hi), t = two_sum(x.lo, y.lo);
  const FloatPair v = fast_two_sum(s.hi, fadd(s.lo, t.hi));
  return fast_two_sum(v.hi, fadd(t.lo, v.lo));
}
LWSCCD_HD inline FloatPair pair_neg(const FloatPair& x) { return {-x.hi, -x.lo}; }
LWSCCD_HD inline FloatPair pair_sub(const FloatPair& x, const FloatPair& y) { return pair_add(x, pair_neg(y)); }

/// Algorithm 12 (DWTimesDW3).
LWSCCD_HD inline FloatPair pair_mul(const FloatPair& x, const FloatPair& y) {
  const float ch = fmul(x.hi, y.hi);
  const float cl1 = ffma(x.hi, y.hi, -ch);
  const float tl1 = ffma(x.hi, y.lo, fmul(x.lo, y.lo));
  const float cl2 = ffma(x.lo, y.hi, tl1);
  return fast_two_sum(ch, fadd(cl1, cl2));
}

/// Algorithm 9 (DWTimesFP3): x times the float s.
LWSCCD_HD inline FloatPair pair_scale(const FloatPair& x, float s) {
  const float ch = fmul(x.hi, s);
  const float cl1 = ffma(x.hi, s, -ch);
  return fast_two_sum(ch, ffma(x.lo, s, cl1));
}

/// A double as a pair, without FP64 arithmetic: hi is x cut to float's 24 bits (toward zero, by
/// masking its low 29 significand bits), lo the rest (29 bits) rounded to float once, so that
/// |hi + lo - x| <= u |x - hi| < 2^-47 |x|. False (and nothing written) unless x is 0 or
/// 2^-60 <= |x| < 2^60, where both parts are normal floats and the cut and the scaling are exact.
LWSCCD_HD inline bool split_to_pair(double x, FloatPair& out) {
  std::uint64_t bits;
  std::memcpy(&bits, &x, sizeof bits);
  const int exponent = static_cast<int>((bits >> 52) & 0x7ffu) - 1023;
  if ((bits << 1) == 0) {  // +-0
    out = {0.0f, 0.0f};
    return true;
  }
  if (exponent < -60 || exponent >= 60) return false;
  constexpr std::uint64_t low_mask = (std::uint64_t(1) << 29) - 1;
  const std::uint64_t cut_bits = bits & ~low_mask;
  double cut;
  std::memcpy(&cut, &cut_bits, sizeof cut);
  const float hi = static_cast<float>(cut);  // exact: 24 significant bits, in float's range
  // The rest is (bits & low_mask) units of 2^(exponent - 52), with x's sign.
  const auto rest = static_cast<std::uint32_t>(bits & low_mask);
  const std::uint32_t scale_bits = static_cast<std::uint32_t>(exponent - 52 + 127) << 23;  // 2^(exponent - 52), normal
  float scale;
  std::memcpy(&scale, &scale_bits, sizeof scale);
  float lo = fmul(static_cast<float>(rest), scale);  // one rounding (rest to 24 bits); the scaling is exact
  if (bits >> 63) lo = -lo;
  out = fast_two_sum(hi, lo);  // |lo| < ulp(hi): normalize (exact)
  return true;
}
/// A float as a pair (exact).
LWSCCD_HD inline bool split_to_pair(float x, FloatPair& out) {
  out = {x, 0.0f};
  return x - x == 0.0f;
}

/// |hi| enlarged past |hi + lo| (|lo| <= 2^-24 |hi|): a float at least the pair's magnitude.
LWSCCD_HD inline float pair_magnitude_above(const FloatPair& x) { return fmul(std::fabs(x.hi), 1.0f + 0x1p-22f); }
/// A float of the pair's sign, no larger in magnitude than the pair: |hi| (1 - 2^-22) rounded
/// is below |hi| (1 - 2^-24) <= |hi + lo|.
LWSCCD_HD inline float pair_toward_zero(const FloatPair& x) { return fmul(x.hi, 1.0f - 0x1p-22f); }

}  // namespace lwsccd::detail
