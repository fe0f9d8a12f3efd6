// lwsccd-accuracy — what the program's parts share: the library's narrow phase, the names it
// uses, and the filter alone as a method (FilterOnly).
#pragma once

#include <algorithm>
#include <array>
#include <chrono>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "../bench_common.hpp"
#include "lwsccd/core/error.hpp"
#include "lwsccd/io/dataset.hpp"
#include "lwsccd/io/query_io.hpp"
#include "lwsccd/narrow_phase/ccd_filters.hpp"
#include "lwsccd/narrow_phase/ccd_query.hpp"
#include "lwsccd/narrow_phase/certified_ccd.hpp"
#include "lwsccd/narrow_phase/cubic_ccd.hpp"
#include "lwsccd/narrow_phase/inclusion_ccd.hpp"

#ifndef LWSCCD_BENCH_DATA_DIR
#define LWSCCD_BENCH_DATA_DIR "../shared/data"
#endif

namespace {

namespace fs = std::filesystem;
using lwsccd::CcdParams;
using lwsccd::CcdResult;
using lwsccd::EdgeEdgeQuery;
using lwsccd::InputError;
using lwsccd::Vec3d;
using lwsccd::VertexFaceQuery;
using Points = std::array<Vec3d, 8>;

/// The non-penetration filter alone as a method: "hit" means "may collide". Its toi (0) is only a
/// trivial lower bound. It is declared conservative because ccd_filters.hpp states that it culls
/// a pair only when it proves that the pair cannot touch.
struct FilterOnly {
  static constexpr const char* name = "filter-only";
  static constexpr bool conservative = true;
  template <class T>
  static CcdResult<T> vertex_face(const VertexFaceQuery<T>& q, const CcdParams<T>& p) {
    return lwsccd::non_penetration_filter(q, p) ? CcdResult<T>{true, T(0), false} : CcdResult<T>{};
  }
  template <class T>
  static CcdResult<T> edge_edge(const EdgeEdgeQuery<T>& q, const CcdParams<T>& p) {
    return lwsccd::non_penetration_filter(q, p) ? CcdResult<T>{true, T(0), false} : CcdResult<T>{};
  }
};
static_assert(lwsccd::require_ccd_method<FilterOnly>::value, "");
static_assert(lwsccd::require_ccd_method<lwsccd::CubicCcd>::value, "");
static_assert(lwsccd::require_ccd_method<lwsccd::InclusionCcd>::value, "");
static_assert(lwsccd::require_ccd_method<lwsccd::Filtered<lwsccd::InclusionCcd>>::value, "");

}  // namespace
