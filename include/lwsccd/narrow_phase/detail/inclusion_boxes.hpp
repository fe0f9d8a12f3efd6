// lwsccd — the inclusion search's boxes: dyadic boxes of (t, u, v), their order keys (the whole box
// in two words, time first) and the conversions between them.
// Part of inclusion_ccd.hpp: include <lwsccd/narrow_phase/inclusion_ccd.hpp>, not this file.
#pragma once

#include <cassert>
#include <cmath>
#include <cstdint>
#include <limits>
#include <type_traits>
#include "lwsccd/core/detail/fp.hpp"
#include "lwsccd/core/detail/rounding.hpp"
#include "lwsccd/narrow_phase/ccd_filters.hpp"
#include "lwsccd/narrow_phase/ccd_query.hpp"
#include "lwsccd/narrow_phase/inclusion_ccd.hpp"

namespace lwsccd::detail {

/// A dyadic box: dimension i spans [idx_i, idx_i + 1] * 2^-level_i.
struct DyadicBox {
  std::uint32_t idx[3];
  std::uint8_t level[3];
  std::uint8_t accepted;  ///< passed the contact test in a round that could not report it yet
};

// Earliest time of a box as an integer on the finest grid, for ordering.
LWSCCD_HD inline std::uint64_t box_time_key(const DyadicBox& b) {
  return static_cast<std::uint64_t>(b.idx[0]) << (40 - b.level[0]);
}
// The search's order: earlier first; at equal times the smaller (deeper) box first, so that
// ties dive; then any fixed order, so that the order is total (two distinct boxes are never
// tied) and "the k earliest boxes" is the same set however they are stored. As two words compared
// in turn: [time key (40 bits) | 127 - level sum | level t | level u] and [u index | v index |
// accepted mark] (levels are at most 31, InclusionSetup::max_level; equal time keys and t levels
// mean equal t indices, and the level sum then fixes the v level). The mark orders a box only
// against itself marked, which no store holds at once. The key is the whole box (box_of_key): the
// GPU's warp search keeps its live boxes as keys, ranked and merged by two word compares (by fields
// the ranking alone cost it ~22 K of a round's ~35 K cycles).
struct BoxOrderKey {
  std::uint64_t high, low;
};
constexpr int kMaxBoxLevel = 31;  ///< a box index has 31 bits (InclusionSetup::max_level's cap)
LWSCCD_HD inline BoxOrderKey box_order_key(const DyadicBox& b) {
  assert(b.level[0] <= kMaxBoxLevel && b.level[1] <= kMaxBoxLevel && b.level[2] <= kMaxBoxLevel);
  const std::uint64_t level_sum = static_cast<std::uint64_t>(b.level[0]) + b.level[1] + b.level[2];
  return {box_time_key(b) << 17 | (127u - level_sum) << 10 | static_cast<std::uint64_t>(b.level[0]) << 5 | b.level[1],
          static_cast<std::uint64_t>(b.idx[1]) << 33 | static_cast<std::uint64_t>(b.idx[2]) << 1 | (b.accepted ? 1u : 0u)};
}
LWSCCD_HD inline DyadicBox box_of_key(const BoxOrderKey& k) {
  const unsigned level_t = static_cast<unsigned>(k.high >> 5) & 31u, level_u = static_cast<unsigned>(k.high) & 31u;
  const unsigned level_sum = 127u - (static_cast<unsigned>(k.high >> 10) & 127u);
  DyadicBox b;
  b.idx[0] = static_cast<std::uint32_t>((k.high >> 17) >> (40u - level_t));
  b.idx[1] = static_cast<std::uint32_t>(k.low >> 33);
  b.idx[2] = static_cast<std::uint32_t>(k.low >> 1) & 0x7fffffffu;
  b.level[0] = static_cast<std::uint8_t>(level_t);
  b.level[1] = static_cast<std::uint8_t>(level_u);
  b.level[2] = static_cast<std::uint8_t>(level_sum - level_t - level_u);
  b.accepted = static_cast<std::uint8_t>(k.low & 1u);
  return b;
}
LWSCCD_HD inline bool key_before(const BoxOrderKey& a, const BoxOrderKey& b) {
  return a.high < b.high || (a.high == b.high && a.low < b.low);
}
// A stored box's time key and mark, as a box or as its key (InclusionSearch holds either).
LWSCCD_HD inline std::uint64_t box_time_key(const BoxOrderKey& k) { return k.high >> 17; }
LWSCCD_HD inline bool is_accepted(const DyadicBox& b) { return b.accepted != 0; }
LWSCCD_HD inline bool is_accepted(const BoxOrderKey& k) { return (k.low & 1u) != 0; }
LWSCCD_HD inline void whole_domain(DyadicBox& b) { b = DyadicBox{{0, 0, 0}, {0, 0, 0}, 0}; }
LWSCCD_HD inline void whole_domain(BoxOrderKey& k) { k = box_order_key(DyadicBox{{0, 0, 0}, {0, 0, 0}, 0}); }
LWSCCD_HD inline bool box_before(const DyadicBox& a, const DyadicBox& b) { return key_before(box_order_key(a), box_order_key(b)); }

}  // namespace lwsccd::detail
