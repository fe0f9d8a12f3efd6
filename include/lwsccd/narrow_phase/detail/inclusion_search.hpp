// lwsccd — the inclusion search itself: InclusionSearch (boxes in time order, rounds of a batch,
// the front settled), a bounded first attempt (inclusion_try) and the whole search (inclusion_solve).
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
#include "lwsccd/narrow_phase/detail/inclusion_tests.hpp"

namespace lwsccd::detail {

/// The search over boxes, in rounds: take the (up to) kBatch earliest boxes, examine them all
/// (apart, so that a warp's lanes can do it together), then apply the verdicts in time order. A
/// box that passes is the contact when every earlier box of its round was excluded (then no
/// contact can come before it: everything earlier is excluded); otherwise it goes back, marked,
/// and the earlier boxes' halves are looked at first. The live boxes are kept sorted (by
/// box_before, a total order), the round's new boxes merged in: one thread does it in turn here,
/// a warp does it in parallel on the GPU (narrow_phase/detail/inclusion_kernels.cuh), with the same sets, rounds and
/// answers.
///
/// Bounded memory: when more than kMaxBoxes boxes are live after a round, only the earliest
/// three quarters are kept and the earliest dropped time is remembered. Once every box before that
/// time is excluded, the search restarts from the whole domain with the times before it cut off
/// (they are excluded already): a full store costs time, not the false "hit at the current time"
/// that giving up would answer (seen on a sliver triangle in cloth-ball, where that hit was at
/// t = 0).
///
/// kStore (at most kMaxBoxes) is the room this instance has: a search that would keep more live
/// boxes than that stops with `overflow` set, so that a small first attempt (a GPU thread with
/// little memory) can hand the query over to a full one, which then gives the same answer.
/// Item: how a live box is stored, as a DyadicBox or as its BoxOrderKey (the GPU's warp search,
/// which ranks and merges them itself; apply() is for DyadicBox).
template <class Policy, class T, int kStore = Policy::kMaxBoxes, class Item = DyadicBox>
struct InclusionSearch {
  static_assert(Policy::kMaxBoxes >= 2, "lwsccd: InclusionCcd policy: kMaxBoxes must be at least 2");
  static_assert(Policy::kBatch >= 1 && Policy::kBatch <= 32, "lwsccd: InclusionCcd policy: kBatch must be in [1, 32]");
  static_assert(kStore >= 1 && kStore <= Policy::kMaxBoxes, "lwsccd: InclusionSearch: kStore must be in [1, kMaxBoxes]");
  static constexpr int kBatch = Policy::kBatch;
  static constexpr int kCapacity = Policy::kMaxBoxes;
  static constexpr int kKeep = kCapacity - kCapacity / 4;  ///< kept when more than kCapacity are live
  static constexpr int kFresh = 2 * kBatch;                ///< new boxes of a round, at most
  static constexpr int kRoom = kStore + kFresh;
  bool overflow = false;  ///< more live boxes than kStore: this instance cannot go on
  static constexpr std::uint64_t kNone = ~std::uint64_t(0);
  enum class Round : std::uint8_t { examine, no_contact, gave_up };

  Item items[2][kRoom];  ///< live boxes, sorted: items[current][head, head + size)
  int current = 0, head = 0, size = 0, batch_size = 0, examined = 0;
  std::uint64_t floor_key = 0, evicted_key = kNone;
  T t_floor = T(0);

  LWSCCD_HD const Item* batch() const { return items[current] + head - batch_size; }
  LWSCCD_HD const Item* live() const { return items[current] + head; }

  LWSCCD_HD void restart_whole() {
    current = head = 0;
    size = 1;
    whole_domain(items[0][0]);
  }
  LWSCCD_HD void start() {
    restart_whole();
    batch_size = examined = 0;
    floor_key = 0;
    evicted_key = kNone;
    t_floor = T(0);
  }
  /// A box's earliest time not cut off (a time key is exact in T: T's rounding of idx0 is scaled
  /// by a power of two either way).
  template <class Box>
  LWSCCD_HD T time_of(const Box& b) const {
    const std::uint64_t key = box_time_key(b);
    return key < floor_key ? t_floor : std::ldexp(static_cast<T>(key), -40);
  }
  /// Takes the next round's boxes (restarting past dropped boxes when needed). On gave_up,
  /// `result` holds the conservative answer.
  LWSCCD_HD Round next_round(int max_iterations, CcdResult<T>& result) {
    if (!settle_front(result)) return result.hit ? Round::gave_up : Round::no_contact;
    int k = 0, unexamined = 0;
    while (in_batch(k)) unexamined += is_accepted(items[current][head + k]) ? 0 : 1, ++k;
    return take_batch(k, unexamined, max_iterations, result);
  }
  /// next_round in three steps, for a warp that finds the batch with one ballot: settle_front
  /// restarts past dropped boxes where needed (false: no round; `result` holds a hit when the
  /// search gave up, else none); in_batch(i): whether live box i joins the batch (the batch is a
  /// prefix of the live boxes); take_batch: takes the first k, `unexamined` of them not yet accepted.
  LWSCCD_HD bool settle_front(CcdResult<T>& result) {
    result = {};
    while (size == 0 || (evicted_key != kNone && box_time_key(items[current][head]) >= evicted_key)) {
      if (evicted_key == kNone) return false;  // everything excluded
      // No time excluded since the last restart: the store is too small for this query.
      if (evicted_key == floor_key) {
        result = {true, t_floor, true};
        return false;
      }
      floor_key = evicted_key;
      t_floor = std::ldexp(static_cast<T>(floor_key), -40);  // a box's time: exact in T
      evicted_key = kNone;
      restart_whole();
    }
    return true;
  }
  LWSCCD_HD bool in_batch(int i) const {
    return i < kBatch && i < size && (evicted_key == kNone || box_time_key(items[current][head + i]) < evicted_key);
  }
  LWSCCD_HD Round take_batch(int k, int unexamined, int max_iterations, CcdResult<T>& result) {
    const Item* first = items[current] + head;
    batch_size = k;
    head += k;
    size -= k;
    if (examined >= max_iterations) {
      result = {true, time_of(first[0]), true};  // the earliest time not excluded
      return Round::gave_up;
    }
    examined += unexamined;
    return Round::examine;
  }
  /// Whether the verdicts answer the query: the first accepted box of the round, if no box
  /// before it was split. Returns its index, or -1.
  LWSCCD_HD static int answer_index(const BoxVerdict* verdicts, int n) {
    for (int i = 0; i < n; ++i) {
      if (verdicts[i] == BoxVerdict::accepted) return i;
      if (verdicts[i] != BoxVerdict::excluded) return -1;
    }
    return -1;
  }
  /// The new boxes a verdict gives (0 to 2): the two halves of a split box, or an accepted box
  /// marked; without those that cannot matter (beyond u + v = 1 for vertex-face, before the cut,
  /// or at or after a dropped time: searched again after the restart).
  LWSCCD_HD int fresh_boxes(const DyadicBox& box, BoxVerdict verdict, bool vf, DyadicBox out[2]) const {
    int n = 0;
    auto keep = [&](const DyadicBox& b) {
      if ((static_cast<std::uint64_t>(b.idx[0]) + 1) << (40 - b.level[0]) <= floor_key) return;  // before the cut
      if (evicted_key != kNone && box_time_key(b) >= evicted_key) return;
      out[n++] = b;
    };
    if (verdict == BoxVerdict::excluded) return 0;
    if (verdict == BoxVerdict::accepted) {
      DyadicBox marked = box;
      marked.accepted = 1;
      keep(marked);
      return n;
    }
    const int split = static_cast<int>(verdict) - static_cast<int>(BoxVerdict::split_t);
    for (int half = 0; half < 2; ++half) {
      DyadicBox child = box;
      child.idx[split] = box.idx[split] * 2 + static_cast<std::uint32_t>(half);
      child.level[split] = static_cast<std::uint8_t>(box.level[split] + 1);
      if (vf) {  // vertex-face: drop boxes entirely beyond u + v = 1 (exact integer test)
        const std::uint64_t ulo = static_cast<std::uint64_t>(child.idx[1]) << (40 - child.level[1]);
        const std::uint64_t vlo = static_cast<std::uint64_t>(child.idx[2]) << (40 - child.level[2]);
        if (ulo + vlo > (std::uint64_t(1) << 40)) continue;
      }
      keep(child);
    }
    return n;
  }
  /// One thread's round end: the answer, or the new boxes merged into the live ones (kept to the
  /// earliest kKeep when more than kCapacity). True when `result` is the answer.
  LWSCCD_HD bool apply(const BoxVerdict* verdicts, bool vf, CcdResult<T>& result) {
    const DyadicBox* round = batch();
    const int answer = answer_index(verdicts, batch_size);
    if (answer >= 0) {
      result = {true, time_of(round[answer]), false};
      return true;
    }
    DyadicBox fresh[kFresh];
    int nf = 0;
    for (int i = 0; i < batch_size; ++i) nf += fresh_boxes(round[i], verdicts[i], vf, fresh + nf);
    for (int i = 1; i < nf; ++i)  // insertion sort: at most 2 kBatch boxes
      for (int j = i; j > 0 && box_before(fresh[j], fresh[j - 1]); --j) {
        const DyadicBox x = fresh[j];
        fresh[j] = fresh[j - 1];
        fresh[j - 1] = x;
      }
    const DyadicBox* a = live();
    DyadicBox* out = items[1 - current];
    const int total = size + nf, limit = total > kCapacity ? kKeep : total;
    int i = 0, j = 0;
    for (int o = 0; o <= limit && o < total; ++o) {
      const bool take_a = j == nf || (i < size && box_before(a[i], fresh[j]));
      const DyadicBox& next = take_a ? a[i++] : fresh[j++];
      if (o < limit) {
        out[o] = next;
      } else {  // the earliest dropped box
        const std::uint64_t dropped = box_time_key(next);
        evicted_key = dropped < evicted_key ? dropped : evicted_key;
      }
    }
    current = 1 - current;
    head = 0;
    size = limit;
    overflow = limit > kStore;
    return false;
  }
};

/// The search in one thread, for at most `max_rounds` rounds and kStore live boxes: false when
/// it stopped before the answer (then a full search must answer: the GPU's warp search).
template <class Policy, int kStore, class Q, class T>
LWSCCD_HD bool inclusion_try(const Q& q, const CcdParams<T>& params, int max_rounds, CcdResult<T>& result) {
  result = {};
  const InclusionSetup<T> setup = inclusion_setup(q, params);
  if (setup.separated) return true;
  InclusionSearch<Policy, T, kStore> search;
  search.start();
  BoxVerdict verdicts[Policy::kBatch];
  for (int round = 0; round < max_rounds; ++round) {
    const auto next = search.next_round(params.max_iterations, result);
    if (next == InclusionSearch<Policy, T, kStore>::Round::no_contact) {
      result = {};
      return true;
    }
    if (next == InclusionSearch<Policy, T, kStore>::Round::gave_up) return true;
    for (int i = 0; i < search.batch_size; ++i)
      verdicts[i] = examine_box(q, setup, search.batch()[i], search.floor_key, search.t_floor);
    if (search.apply(verdicts, setup.vf, result)) return true;
    if (search.overflow) return false;
  }
  return false;
}

/// The whole search in one thread (the CPU).
template <class Policy, class Q, class T>
LWSCCD_HD CcdResult<T> inclusion_solve(const Q& q, const CcdParams<T>& params) {
  CcdResult<T> result;
  inclusion_try<Policy, Policy::kMaxBoxes>(q, params, std::numeric_limits<int>::max(), result);
  return result;
}

}  // namespace lwsccd::detail
