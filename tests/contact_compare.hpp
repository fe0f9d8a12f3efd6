// Comparing two sets of contacts pair for pair and TOI bit for bit (GPU against CPU).
#pragma once

#include <catch2/catch.hpp>

#include <cstring>

#include "lwsccd/narrow_phase/narrow_phase.hpp"

namespace lwsccd_test {

template <class T>
void require_same_hits(const std::vector<lwsccd::FeatureHit<T>>& gpu, const std::vector<lwsccd::FeatureHit<T>>& cpu) {
  REQUIRE(gpu.size() == cpu.size());
  for (std::size_t i = 0; i < gpu.size(); ++i) {
    REQUIRE(gpu[i].first == cpu[i].first);
    REQUIRE(gpu[i].second == cpu[i].second);
    REQUIRE(std::memcmp(&gpu[i].toi, &cpu[i].toi, sizeof(T)) == 0);
  }
}

template <class T>
void require_same_contacts(const lwsccd::NarrowPhaseResult<T>& gpu, const lwsccd::NarrowPhaseResult<T>& cpu) {
  require_same_hits(gpu.vf, cpu.vf);
  require_same_hits(gpu.ee, cpu.ee);
  REQUIRE(gpu.earliest_toi == cpu.earliest_toi);
  REQUIRE(gpu.gave_up == cpu.gave_up);
}

/// The certified path's counts (certified hits and misses, fallbacks, screened pairs, FP32 misses) of two backends.
inline void require_same_counts(const lwsccd::NarrowPhaseCounts& a, const lwsccd::NarrowPhaseCounts& b) {
  REQUIRE(a.pairs == b.pairs);
  REQUIRE(a.certified_hits == b.certified_hits);
  REQUIRE(a.certified_misses == b.certified_misses);
  REQUIRE(a.fallbacks == b.fallbacks);
  REQUIRE(a.screened == b.screened);
  REQUIRE(a.single_misses == b.single_misses);
  REQUIRE(a.single_descents == b.single_descents);
}

}  // namespace lwsccd_test
