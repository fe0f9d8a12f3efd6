// lwsccd — elemental CCD queries (vertex-face, edge-edge), parameters and results.
//
// Every point moves linearly over the step's normalised time [0, 1]. A method (CubicCcd,
// InclusionCcd, ...) is a policy type with
//   template <class T> LWSCCD_HD static CcdResult<T> vertex_face(const VertexFaceQuery<T>&, const CcdParams<T>&);
//   template <class T> LWSCCD_HD static CcdResult<T> edge_edge(const EdgeEdgeQuery<T>&, const CcdParams<T>&);
//   static constexpr const char* name;  static constexpr bool conservative;
#pragma once

#include <type_traits>

#include "lwsccd/core/config.hpp"
#include "lwsccd/geometry/vec.hpp"

namespace lwsccd {

/// Vertex p against triangle (a, b, c); positions at t = 0 and t = 1 (the order of the
/// dataset's query files: p0 a0 b0 c0 p1 a1 b1 c1).
template <class T>
struct VertexFaceQuery {
  Vec3<T> p0, a0, b0, c0, p1, a1, b1, c1;
  /// The eight points in file order (the members are consecutive).
  LWSCCD_HD const Vec3<T>* points() const { return &p0; }
  template <class U>
  LWSCCD_HD VertexFaceQuery<U> cast() const {
    return {p0.template cast<U>(), a0.template cast<U>(), b0.template cast<U>(), c0.template cast<U>(),
            p1.template cast<U>(), a1.template cast<U>(), b1.template cast<U>(), c1.template cast<U>()};
  }
};

/// Edge (a, b) against edge (c, d); positions at t = 0 and t = 1 (dataset order: a0 b0 c0 d0 a1 b1 c1 d1).
template <class T>
struct EdgeEdgeQuery {
  Vec3<T> a0, b0, c0, d0, a1, b1, c1, d1;
  /// The eight points in file order (the members are consecutive).
  LWSCCD_HD const Vec3<T>* points() const { return &a0; }
  template <class U>
  LWSCCD_HD EdgeEdgeQuery<U> cast() const {
    return {a0.template cast<U>(), b0.template cast<U>(), c0.template cast<U>(), d0.template cast<U>(),
            a1.template cast<U>(), b1.template cast<U>(), c1.template cast<U>(), d1.template cast<U>()};
  }
};

/// What a narrow phase is asked for.
///  - contacts: every colliding pair with its time of impact (a lower bound within `tolerance`);
///  - earliest: only the earliest time of impact over all pairs (what a line search needs);
///  - set:      which pairs collide, each with some lower bound of its time of impact, unrefined.
enum class CcdMode : unsigned char { contacts, earliest, set };

/// The FP32-to-FP64 throughput ratio from which the pipelines prove contacts' leaves in pairs of
/// floats (CcdParams::leaves_in_float_pairs): the GPU's own ratio or the one planned for
/// (PipelineParams::fp64_ratio). There a tail's ~250 FP64 operations cost more than the pairs'
/// ~1,000 FP32 ones; an H100's or H200's ratio is 2, an RTX's or L40's 32 to 64.
inline constexpr int kFloatPairLeavesMinFp64Ratio = 8;

/// Run-time parameters of the elemental tests.
template <class T>
struct CcdParams {
  T min_separation = T(0);  ///< report pairs that come closer than this (InclusionCcd; 0 = contact)
  T tolerance = T(1e-6);    ///< time resolution of the reported time of impact
  int max_iterations = 16384;  ///< InclusionCcd: boxes examined before answering "collision" (bounded time)
  CcdMode mode = CcdMode::contacts;  ///< per query, only `set` changes anything: the TOI need not be refined
  /// Contacts at or after this time may be ignored (reported as "no collision"); earlier ones
  /// never are. Batches in mode `earliest` lower it to the best time already found.
  T time_limit = T(1);
  /// No contact happens before this time (a caller's proof, e.g. CertifiedCcd's exclusions):
  /// the inclusion search drops boxes that end before it. The reported TOI stays a lower bound.
  T time_from = T(0);
  /// CertifiedCcd: prove each contact's time-of-impact leaf in pairs of floats before double
  /// (docs/NARROW_PHASE.md, B17). The answers are the same either way; the contacts' tails then
  /// take no FP64, which pays on GPUs whose FP64 runs at a small share of FP32 (RTX, L40), and
  /// costs a little where FP64 is plentiful. gpu::NarrowPhase turns it on itself on such a GPU
  /// (or where planned for one: PipelineParams::fp64_ratio).
  bool leaves_in_float_pairs = false;
};

/// The answer to one query. `toi` is in [0, 1] when `hit`; conservative methods guarantee that
/// no contact happens before `toi` (a lower bound of the true time of impact).
template <class T>
struct CcdResult {
  bool hit = false;
  T toi = T(1);
  bool gave_up = false;  ///< InclusionCcd: answered "hit" because the iteration or box budget ran out
};

namespace detail {
// One detector per member of the method contract, so that a missing one is named on its own.
template <class M, class = void>
struct method_has_name : std::false_type {};
template <class M>
struct method_has_name<M, std::void_t<decltype(M::name)>> : std::true_type {};
template <class M, class = void>
struct method_has_conservative : std::false_type {};
template <class M>
struct method_has_conservative<M, std::void_t<decltype(M::conservative)>> : std::true_type {};
template <class M, class = void>
struct method_has_vertex_face : std::false_type {};
template <class M>
struct method_has_vertex_face<M, std::void_t<decltype(M::template vertex_face<float>(
                                     std::declval<const VertexFaceQuery<float>&>(), std::declval<const CcdParams<float>&>()))>>
    : std::true_type {};
template <class M, class = void>
struct method_has_edge_edge : std::false_type {};
template <class M>
struct method_has_edge_edge<M, std::void_t<decltype(M::template edge_edge<float>(
                                   std::declval<const EdgeEdgeQuery<float>&>(), std::declval<const CcdParams<float>&>()))>>
    : std::true_type {};
template <class M>
struct is_ccd_method : std::bool_constant<method_has_name<M>::value && method_has_conservative<M>::value &&
                                          method_has_vertex_face<M>::value && method_has_edge_edge<M>::value> {};
}  // namespace detail

/// Compile-time contract of a narrow-phase method (lwsccd/narrow_phase/ccd_query.hpp): one
/// static_assert per member, each naming what is missing.
template <class M>
struct require_ccd_method {
  static_assert(detail::method_has_name<M>::value, "lwsccd: a CCD method needs static constexpr const char* name");
  static_assert(detail::method_has_conservative<M>::value,
                "lwsccd: a CCD method needs static constexpr bool conservative (true: never misses a contact)");
  static_assert(detail::method_has_vertex_face<M>::value,
                "lwsccd: a CCD method needs static vertex_face<T>(const VertexFaceQuery<T>&, const CcdParams<T>&) "
                "returning CcdResult<T>");
  static_assert(detail::method_has_edge_edge<M>::value,
                "lwsccd: a CCD method needs static edge_edge<T>(const EdgeEdgeQuery<T>&, const CcdParams<T>&) "
                "returning CcdResult<T>");
  static constexpr bool value = true;
};

}  // namespace lwsccd
