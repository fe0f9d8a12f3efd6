// lwsccd — Morton (Z-order) codes of points in a scene box: 30-bit (10 bits per axis) and
// 63-bit (21 bits per axis).
#pragma once

#include <cstdint>

#include "lwsccd/core/config.hpp"
#include "lwsccd/geometry/aabb.hpp"
#include "lwsccd/geometry/vec.hpp"

namespace lwsccd {

namespace detail {

/// Spreads the low 10 bits of v so that two zero bits follow each: ...9876543210 -> 9..8..7.. .
LWSCCD_HD constexpr std::uint32_t spread_bits_10(std::uint32_t v) {
  v &= 0x3ffu;
  v = (v | (v << 16)) & 0x030000ffu;
  v = (v | (v << 8)) & 0x0300f00fu;
  v = (v | (v << 4)) & 0x030c30c3u;
  v = (v | (v << 2)) & 0x09249249u;
  return v;
}

/// Spreads the low 21 bits of v the same way into 63 bits.
LWSCCD_HD constexpr std::uint64_t spread_bits_21(std::uint64_t v) {
  v &= 0x1fffffull;
  v = (v | (v << 32)) & 0x001f00000000ffffull;
  v = (v | (v << 16)) & 0x001f0000ff0000ffull;
  v = (v | (v << 8)) & 0x100f00f00f00f00full;
  v = (v | (v << 4)) & 0x10c30c30c30c30c3ull;
  v = (v | (v << 2)) & 0x1249249249249249ull;
  return v;
}

/// Grid cell of coordinate x in [lo, hi] on a grid of `cells` cells; clamped, 0 for a flat axis.
template <class T>
LWSCCD_HD std::uint32_t grid_cell(T x, T lo, T hi, std::uint32_t cells) {
  const T extent = hi - lo;
  if (!(extent > T(0))) return 0;
  T q = (x - lo) / extent * static_cast<T>(cells);
  if (!(q > T(0))) return 0;  // also maps NaN to cell 0
  if (q >= static_cast<T>(cells)) return cells - 1;
  return static_cast<std::uint32_t>(q);
}

}  // namespace detail

/// 30-bit Morton code of p within `scene` (x bits highest in each triple).
template <class T>
LWSCCD_HD std::uint32_t morton30(const Vec3<T>& p, const Aabb<T>& scene) {
  const std::uint32_t x = detail::grid_cell(p.x, scene.lo.x, scene.hi.x, 1024u);
  const std::uint32_t y = detail::grid_cell(p.y, scene.lo.y, scene.hi.y, 1024u);
  const std::uint32_t z = detail::grid_cell(p.z, scene.lo.z, scene.hi.z, 1024u);
  return (detail::spread_bits_10(x) << 2) | (detail::spread_bits_10(y) << 1) | detail::spread_bits_10(z);
}

/// 63-bit Morton code of p within `scene`.
template <class T>
LWSCCD_HD std::uint64_t morton63(const Vec3<T>& p, const Aabb<T>& scene) {
  constexpr std::uint32_t cells = 1u << 21;
  const std::uint64_t x = detail::grid_cell(p.x, scene.lo.x, scene.hi.x, cells);
  const std::uint64_t y = detail::grid_cell(p.y, scene.lo.y, scene.hi.y, cells);
  const std::uint64_t z = detail::grid_cell(p.z, scene.lo.z, scene.hi.z, cells);
  return (detail::spread_bits_21(x) << 2) | (detail::spread_bits_21(y) << 1) | detail::spread_bits_21(z);
}

}  // namespace lwsccd
