// The GPU narrow phase against the CPU backend, pair for pair (and TOI bit for bit).
#include <catch2/catch.hpp>

#include <algorithm>
#include <array>
#include <cstring>
#include <initializer_list>
#include <random>

#include "lwsccd/io/dataset.hpp"
#include "lwsccd/narrow_phase/certified_ccd.hpp"
#include "lwsccd/narrow_phase/cubic_ccd.hpp"
#include "lwsccd/narrow_phase/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.cuh"
#include "contact_compare.hpp"
#include "scene_fixtures.hpp"
#include "test_support.hpp"

using namespace lwsccd;

namespace {

// The certified filters' interval lists with almost no room (single precision's, and one entry
// for the double filter's): their pairs go to the whole search.
// (The single-precision filter in its four kernels, whose lists these are.)
struct TinyFilterRoom : gpu::NarrowPhasePolicy {
  static constexpr int kFilterRoomPercent = 1;
  static constexpr int kDoubleAfterSingleRoomPercent = 0;
  static constexpr int kSingleFilterOneThreadPerSm = 0;
  static constexpr bool kSingleFilterInBlocks = false;
};
struct TinyDeepRoom : gpu::NarrowPhasePolicy {
  static constexpr int kDeepRoomPercent = 1;
  static constexpr int kDoubleAfterSingleRoomPercent = 0;
  static constexpr int kSingleFilterOneThreadPerSm = 0;
  static constexpr bool kSingleFilterInBlocks = false;
};
// The single-precision filter as a thread a pair listing its intervals and a thread an interval
// testing them (four kernels), in one kernel with a block's pairs in shared memory, and on one
// thread a pair, whatever the lists' lengths (the default plans the last two from them).
struct SingleFilterInFourKernels : gpu::NarrowPhasePolicy {
  static constexpr int kSingleFilterOneThreadPerSm = 0;
  static constexpr bool kSingleFilterInBlocks = false;
};
struct SingleFilterInBlocks : gpu::NarrowPhasePolicy {
  static constexpr int kSingleFilterOneThreadPerSm = 0;
  static constexpr bool kSingleFilterInBlocks = true;
};
// The block form with no room for the second round's pieces: every pair that has some is routed
// on its thread.
struct SingleFilterInBlocksNoPieceRoom : SingleFilterInBlocks {
  static constexpr int kSingleBlockPiecesPerPair = 0;
};
// The block form from rooms of the initial capacity (no count before a first run).
struct SingleFilterInBlocksFromCapacity : SingleFilterInBlocks {
  static constexpr bool kCountFirstRun = false;
};
struct SingleFilterOnOneThread : gpu::NarrowPhasePolicy {
  static constexpr int kSingleFilterOneThreadPerSm = 1 << 20;
};
// The certified path in double alone (no single-precision pass).
struct DoubleOnlyCertified : CertifiedPolicy {
  static constexpr bool kSingleFirst = false;
};
struct FirstRoundOnly : gpu::NarrowPhasePolicy {
  static constexpr bool kFilterSecondRound = false;
};
// Deferred lists of any length searched a thread per pair, whose searches in double are handed to
// a warp each, to a thread each in a kernel of their own, or (NoneHanded) stay on their thread.
struct HandedToWarps : gpu::NarrowPhasePolicy {
  static constexpr int kRefineWarpBelow = 0;
};
struct HandedToThreads : gpu::NarrowPhasePolicy {
  static constexpr int kRefineWarpBelow = 0;
  static constexpr int kHandedWarpsPerSm = 0;
};
// As on a GPU with little FP64 (any GPU's FP32-to-FP64 ratio is above 1): a thread each.
struct HandedAsWithLittleFp64 : gpu::NarrowPhasePolicy {
  static constexpr int kRefineWarpBelow = 0;
  static constexpr int kHandedWarpsMaxFp64Ratio = 1;
};
struct NoneHanded : gpu::NarrowPhasePolicy {
  static constexpr int kRefineWarpBelow = 0;
  static constexpr bool kHandOnDoubleSearches = false;
};
// A first run that does not count its survivors first: it starts from the initial capacity and
// grows where that overflowed.
struct GrowFromCapacity : gpu::NarrowPhasePolicy {
  static constexpr bool kCountFirstRun = false;
};

// Every kernel launched plainly, one after the other on its stream (no programmatic dependent
// launch, whatever the device).
struct PlainLaunches : gpu::NarrowPhasePolicy {
  static constexpr bool kOverlapLaunches = false;
};

// Returns the GPU's whole refinements (NarrowPhase::whole_searches).
template <class Method, class T, class Policy = gpu::NarrowPhasePolicy>
std::size_t compare_backends(const TriangleMesh& mesh, const std::vector<Vec3d>& x0, const std::vector<Vec3d>& x1,
                             const FeaturePairs& pairs, std::size_t capacity, CcdMode mode = CcdMode::contacts,
                             std::size_t* reruns = nullptr, std::size_t* handed = nullptr, int fp64_ratio = 0,
                             std::size_t* handed_in_warps = nullptr, std::size_t* device_bytes = nullptr) {
  gpu::DeviceMeshFeatures features(mesh);
  gpu::DeviceStep<double> step(mesh, x0, x1);
  gpu::DeviceBuffer<std::pair<index_t, index_t>> vf, ee;
  vf.upload(pairs.vf);
  ee.upload(pairs.ee);
  gpu::NarrowPhase<Method, T, Policy> narrow(capacity);
  narrow.plan_for_fp64_ratio(fp64_ratio);
  CcdParams<T> params;
  params.mode = mode;
  narrow.run(features, step.x0.data(), step.x1.data(), vf.data(), vf.size(), ee.data(), ee.size(), params);
  // (The CPU asked for the leaves in pairs of floats where the GPU's plan takes them: the same
  // answers either way, and then the same counts of them too.)
  CcdParams<T> cpu_params = params;
  cpu_params.leaves_in_float_pairs = narrow.fp64_ratio() >= kFloatPairLeavesMinFp64Ratio;
  const auto cpu_result = cpu::test_feature_pairs<Method, T>(mesh, x0, x1, pairs, cpu_params);
  const auto gpu_result = narrow.download();
  lwsccd_test::require_same_contacts(gpu_result, cpu_result);
  // An output with less room than the hits it needed ran again with more (and lost nothing),
  // unless the run counted its survivors first and sized its lists from them.
  const bool counted_first = Policy::kCountFirstRun && gpu::NarrowPhase<Method, T, Policy>::kTwoPass;
  if (!counted_first && mode != CcdMode::earliest && std::max(cpu_result.vf.size(), cpu_result.ee.size()) > capacity)
    REQUIRE(narrow.reruns() > 0);
  if (reruns) *reruns = narrow.reruns();
  if (handed) *handed = narrow.handed_searches();
  if (handed_in_warps) *handed_in_warps = narrow.handed_searches_in_warps();
  if (device_bytes) *device_bytes = narrow.device_bytes();
  if (lwsccd::detail::certified_of<Method>::value) {
    lwsccd_test::require_same_counts(gpu_result.vf_counts, cpu_result.vf_counts);
    lwsccd_test::require_same_counts(gpu_result.ee_counts, cpu_result.ee_counts);
    REQUIRE(gpu_result.vf_counts.float_pair_leaves == cpu_result.vf_counts.float_pair_leaves);
    REQUIRE(gpu_result.ee_counts.float_pair_leaves == cpu_result.ee_counts.float_pair_leaves);
    if (!cpu_params.leaves_in_float_pairs) REQUIRE(gpu_result.ee_counts.float_pair_leaves + gpu_result.vf_counts.float_pair_leaves == 0);
    if (fp64_ratio >= kFloatPairLeavesMinFp64Ratio)
      std::printf("  planned for FP64 at 1/%d: %zu + %zu contacts' leaves proved in pairs of floats, of %zu + %zu tails\n",
                  fp64_ratio, gpu_result.vf_counts.float_pair_leaves, gpu_result.ee_counts.float_pair_leaves,
                  gpu_result.vf_counts.single_descents, gpu_result.ee_counts.single_descents);
  }
  const char* mode_name = mode == CcdMode::earliest ? "earliest" : mode == CcdMode::set ? "set" : "contacts";
  std::printf("  %s/%s/%s: %zu vf + %zu ee pairs -> %zu + %zu hits, earliest TOI %.9g; certified hits %zu + %zu, "
              "fallbacks %zu + %zu\n", Method::name, sizeof(T) == 4 ? "float" : "double", mode_name, pairs.vf.size(),
              pairs.ee.size(), cpu_result.vf.size(), cpu_result.ee.size(), double(cpu_result.earliest_toi),
              cpu_result.vf_counts.certified_hits, cpu_result.ee_counts.certified_hits, cpu_result.vf_counts.fallbacks,
              cpu_result.ee_counts.fallbacks);
  return narrow.whole_searches();
}

}  // namespace

TEST_CASE("GPU narrow phase equals the CPU backend on a folded cloth, with a growing output", "[gpu][narrow]") {
  const auto m = lwsccd_test::folded_cloth(40, 4);
  const auto pairs = brute_force_pairs(m.mesh, swept_triangle_bvs<Aabbd>(m.mesh, m.x0, m.x1));
  const FeaturePairs fp = feature_pairs(m.mesh, pairs);
  // A one-hit output forces reruns with more room (a first run that does not count first).
  compare_backends<Filtered<InclusionCcd>, double, GrowFromCapacity>(m.mesh, m.x0, m.x1, fp, 1);
  compare_backends<Filtered<InclusionCcd>, float, GrowFromCapacity>(m.mesh, m.x0, m.x1, fp, 3);
  compare_backends<CubicCcd, double>(m.mesh, m.x0, m.x1, fp, 1 << 16);
  compare_backends<CubicCcd, float>(m.mesh, m.x0, m.x1, fp, 1 << 16);
  for (CcdMode mode : {CcdMode::contacts, CcdMode::earliest, CcdMode::set}) {
    compare_backends<CertifiedCcd, double, GrowFromCapacity>(m.mesh, m.x0, m.x1, fp, 1, mode);
    compare_backends<CertifiedCcd, float, GrowFromCapacity>(m.mesh, m.x0, m.x1, fp, 3, mode);
    // The default first run counts its survivors first: from the same one-item capacity it
    // runs once (the hits' room: an eighth of the survivors, more than this cloth's contacts).
    std::size_t reruns = 1;
    compare_backends<CertifiedCcd, double>(m.mesh, m.x0, m.x1, fp, 1, mode, &reruns);
    CHECK(reruns == 0);
    // The single-precision filter in either form: the same answers and counts.
    std::size_t four_kernels_bytes = 0, in_blocks_bytes = 0;
    compare_backends<CertifiedCcd, double, SingleFilterInFourKernels>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode, nullptr, nullptr, 0,
                                                                      nullptr, &four_kernels_bytes);
    compare_backends<CertifiedCcd, float, SingleFilterInFourKernels>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode);
    compare_backends<CertifiedCcd, double, SingleFilterOnOneThread>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode);
    compare_backends<CertifiedCcd, float, SingleFilterOnOneThread>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode);
    compare_backends<CertifiedCcd, double, SingleFilterInBlocks>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode, nullptr, nullptr, 0, nullptr,
                                                                 &in_blocks_bytes);
    // The block form's lists stay in shared memory: it holds none of the four kernels' (mode set
    // runs no filter, so holds none either way).
    if (mode == CcdMode::set) CHECK(in_blocks_bytes == four_kernels_bytes);
    else CHECK(in_blocks_bytes < four_kernels_bytes);
    compare_backends<CertifiedCcd, float, SingleFilterInBlocks>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode);
    compare_backends<CertifiedCcd, double, SingleFilterInBlocksNoPieceRoom>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode);
  }
  // Intervals that do not fit the filter's list: those pairs are searched whole, same answers.
  compare_backends<CertifiedCcd, double, TinyFilterRoom>(m.mesh, m.x0, m.x1, fp, 1 << 16);
  compare_backends<CertifiedCcd, float, TinyFilterRoom>(m.mesh, m.x0, m.x1, fp, 1 << 16, CcdMode::earliest);
  // The same for the second round's list (mode contacts: the only one that runs it).
  compare_backends<CertifiedCcd, double, TinyDeepRoom>(m.mesh, m.x0, m.x1, fp, 1 << 16);
  compare_backends<CertifiedCcd, float, TinyDeepRoom>(m.mesh, m.x0, m.x1, fp, 1 << 16);
}

TEST_CASE("GPU narrow phase: launches overlapped where the device can, and plain launches, give the CPU's answers",
          "[gpu][narrow]") {
  int device = 0, major = 0;
  REQUIRE(cudaGetDevice(&device) == cudaSuccess);
  REQUIRE(cudaDeviceGetAttribute(&major, cudaDevAttrComputeCapabilityMajor, device) == cudaSuccess);
  const auto m = lwsccd_test::folded_cloth(40, 4);
  const FeaturePairs fp = feature_pairs(m.mesh, brute_force_pairs(m.mesh, swept_triangle_bvs<Aabbd>(m.mesh, m.x0, m.x1)));
  // How a narrow phase launched its kernels: known from its first run on.
  const auto overlapped = [&](auto&& narrow) {
    gpu::DeviceMeshFeatures features(m.mesh);
    gpu::DeviceStep<double> step(m.mesh, m.x0, m.x1);
    gpu::DeviceBuffer<std::pair<index_t, index_t>> vf, ee;
    vf.upload(fp.vf);
    ee.upload(fp.ee);
    CHECK_FALSE(narrow.overlaps_launches());
    narrow.run(features, step.x0.data(), step.x1.data(), vf.data(), vf.size(), ee.data(), ee.size(), CcdParams<double>{});
    return narrow.overlaps_launches();
  };
  CHECK(overlapped(gpu::NarrowPhase<CertifiedCcd, double>(1 << 16)) == (major >= 9));
  CHECK_FALSE(overlapped(gpu::NarrowPhase<CertifiedCcd, double, PlainLaunches>(1 << 16)));
  for (CcdMode mode : {CcdMode::contacts, CcdMode::earliest, CcdMode::set}) {
    compare_backends<CertifiedCcd, double, PlainLaunches>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode);
    compare_backends<CertifiedCcd, float, PlainLaunches>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode);
  }
}

TEST_CASE("GPU narrow phase: the filter's second round leaves fewer pairs to the whole search", "[gpu][narrow]") {
  // A folded cloth: on the CPU (CertifiedFilter::decides) 6,733 of its 30,504 screened pairs
  // are left to the whole search by the first round, 1,806 by both. The double path alone, whose
  // filter sees every screened pair (with FP32 first the single passes and the search in float
  // leave it almost none).
  using Method = CertifiedCcdT<Filtered<InclusionCcd>, DoubleOnlyCertified>;
  const auto m = lwsccd_test::folded_cloth(40, 4);
  const auto pairs = brute_force_pairs(m.mesh, swept_triangle_bvs<Aabbd>(m.mesh, m.x0, m.x1));
  const FeaturePairs fp = feature_pairs(m.mesh, pairs);
  const std::size_t both = compare_backends<Method, double>(m.mesh, m.x0, m.x1, fp, 1 << 16);
  const std::size_t first = compare_backends<Method, double, FirstRoundOnly>(m.mesh, m.x0, m.x1, fp, 1 << 16);
  std::printf("  whole refinements: %zu with the second round, %zu with the first only\n", both, first);
  CHECK(both < first);
}

TEST_CASE("GPU narrow phase: searches in double handed from a thread to a warp each give the same answers", "[gpu][narrow]") {
  // The double path alone searches every deferred pair in double, so its thread hands each on;
  // with FP32 first only the pairs single precision leaves undecided are.
  using DoubleOnly = CertifiedCcdT<Filtered<InclusionCcd>, DoubleOnlyCertified>;
  const auto m = lwsccd_test::folded_cloth(40, 4);
  const auto pairs = brute_force_pairs(m.mesh, swept_triangle_bvs<Aabbd>(m.mesh, m.x0, m.x1));
  const FeaturePairs fp = feature_pairs(m.mesh, pairs);
  for (CcdMode mode : {CcdMode::contacts, CcdMode::earliest, CcdMode::set}) {
    INFO("mode " << int(mode));
    std::size_t handed = 0, none = 1;
    const std::size_t whole = compare_backends<DoubleOnly, double, HandedToWarps>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode, nullptr, &handed);
    const std::size_t whole_on_threads =
        compare_backends<DoubleOnly, double, NoneHanded>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode, nullptr, &none);
    std::printf("  whole searches %zu, handed to warps %zu\n", whole, handed);
    CHECK(whole == whole_on_threads);
    CHECK(handed > 0);
    CHECK(handed <= whole);
    CHECK(none == 0);
    std::size_t to_threads = 0;
    compare_backends<DoubleOnly, double, HandedToThreads>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode, nullptr, &to_threads);
    CHECK(to_threads == handed);
    compare_backends<CertifiedCcd, float, HandedToThreads>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode);
    compare_backends<DoubleOnly, double, HandedAsWithLittleFp64>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode);
    // Planned as for a GPU whose FP32 runs 64 times its FP64 (PipelineParams::fp64_ratio): the same
    // answers, every handed search a thread each; planned for 1 (as an H100 or H200 is): a warp each
    // in a list that hands on at most kHandedWarpsPerSm per SM (all of them where both lists together do).
    std::size_t planned_64 = 0, in_warps_64 = 1, planned_1 = 0, in_warps_1 = 0;
    compare_backends<DoubleOnly, double, HandedToWarps>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode, nullptr, &planned_64, 64, &in_warps_64);
    compare_backends<DoubleOnly, double, HandedToWarps>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode, nullptr, &planned_1, 1, &in_warps_1);
    CHECK(planned_64 == handed);
    CHECK(in_warps_64 == 0);
    CHECK(planned_1 == handed);
    int sms = 0;
    LWSCCD_CUDA_CHECK(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, 0));
    const auto warp_limit = static_cast<std::size_t>(sms) * static_cast<std::size_t>(HandedToWarps::kHandedWarpsPerSm);
    std::printf("  planned for FP64 at 1/64: %zu handed, %zu a warp each; at 1/1: %zu a warp each (limit %zu a list)\n",
                planned_64, in_warps_64, in_warps_1, warp_limit);
    CHECK(in_warps_1 <= handed);
    if (handed <= warp_limit) CHECK(in_warps_1 == handed);
    compare_backends<DoubleOnly, float, HandedToWarps>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode);
    compare_backends<CertifiedCcd, double, HandedToWarps>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode);
    compare_backends<CertifiedCcd, float, HandedToWarps>(m.mesh, m.x0, m.x1, fp, 1 << 16, mode);
  }
}

// Runs CertifiedCcd twice on the same pairs (the second run planned from the first), planned for
// `fp64_ratio`, each run's answers and counts against the CPU's; calls after_run(narrow, run)
// after each run and returns the CPU's result.
template <class Policy, class T, class AfterRun>
auto runs_against_cpu(const lwsccd_test::MovingMesh& m, const FeaturePairs& fp, CcdMode mode, int fp64_ratio, AfterRun after_run) {
  gpu::DeviceMeshFeatures features(m.mesh);
  gpu::DeviceStep<double> step(m.mesh, m.x0, m.x1);
  gpu::DeviceBuffer<std::pair<index_t, index_t>> vf, ee;
  vf.upload(fp.vf);
  ee.upload(fp.ee);
  gpu::NarrowPhase<CertifiedCcd, T, Policy> narrow(1 << 16);
  narrow.plan_for_fp64_ratio(fp64_ratio);
  CcdParams<T> params;
  params.mode = mode;
  CcdParams<T> cpu_params = params;
  cpu_params.leaves_in_float_pairs = narrow.fp64_ratio() >= kFloatPairLeavesMinFp64Ratio;
  const auto cpu_result = cpu::test_feature_pairs<CertifiedCcd, T>(m.mesh, m.x0, m.x1, fp, cpu_params);
  for (int run = 0; run < 2; ++run) {
    narrow.run(features, step.x0.data(), step.x1.data(), vf.data(), vf.size(), ee.data(), ee.size(), params);
    const auto gpu_result = narrow.download();
    lwsccd_test::require_same_contacts(gpu_result, cpu_result);
    lwsccd_test::require_same_counts(gpu_result.vf_counts, cpu_result.vf_counts);
    lwsccd_test::require_same_counts(gpu_result.ee_counts, cpu_result.ee_counts);
    REQUIRE(gpu_result.ee_counts.float_pair_leaves == cpu_result.ee_counts.float_pair_leaves);
    REQUIRE(gpu_result.vf_counts.float_pair_leaves == cpu_result.vf_counts.float_pair_leaves);
    after_run(narrow, run);
  }
  return cpu_result;
}

// Returns {whole searches, those beside the double filter} of the second of two runs (the first
// has no last run to plan from: none beside it).
template <class Policy, class T>
std::pair<std::size_t, std::size_t> whole_beside_filter_runs(const lwsccd_test::MovingMesh& m, const FeaturePairs& fp, CcdMode mode,
                                                             int fp64_ratio) {
  std::pair<std::size_t, std::size_t> searches;
  runs_against_cpu<Policy, T>(m, fp, mode, fp64_ratio, [&](const auto& narrow, int run) {
    if (run == 0) CHECK(narrow.whole_searches_beside_filter() == 0);
    searches = {narrow.whole_searches(), narrow.whole_searches_beside_filter()};
  });
  return searches;
}

struct WholeAfterFilter : gpu::NarrowPhasePolicy {
  static constexpr bool kWholeBesideFilter = false;
};

TEST_CASE("GPU narrow phase: contacts sent whole, searched beside the double filter, give the same answers", "[gpu][narrow]") {
  // FP32 first sends a pair with an interval inside in float (a contact) straight to the whole
  // search; filter_kernel searches those beside its own pairs, a thread each, where the list's
  // whole searches do not all go to warps (planned from the list's last run). Planned for FP64
  // at 1/64 they never do (a thread each always); at 1/1 only where a list holds more than
  // kRefineWarpBelow.
  const auto m = lwsccd_test::folded_cloth(40, 4);
  const auto pairs = brute_force_pairs(m.mesh, swept_triangle_bvs<Aabbd>(m.mesh, m.x0, m.x1));
  const FeaturePairs fp = feature_pairs(m.mesh, pairs);
  for (CcdMode mode : {CcdMode::contacts, CcdMode::earliest, CcdMode::set}) {
    INFO("mode " << int(mode));
    for (int ratio : {64, 1}) {
      const auto [whole, beside] = whole_beside_filter_runs<gpu::NarrowPhasePolicy, double>(m, fp, mode, ratio);
      std::printf("  planned for FP64 at 1/%d, mode %d: %zu whole searches, %zu of them beside the double filter\n", ratio,
                  int(mode), whole, beside);
      CHECK(beside <= whole);
      if (mode == CcdMode::set) CHECK(beside == 0);  // (no filter)
      if (ratio == 1) CHECK((beside == 0 || beside > static_cast<std::size_t>(gpu::NarrowPhasePolicy::kRefineWarpBelow)));
      if (ratio == 64 && mode == CcdMode::contacts) CHECK(beside > 0);
    }
  }
  // Float inputs; the searches in double run there too (not handed on); the knob off.
  CHECK(whole_beside_filter_runs<gpu::NarrowPhasePolicy, float>(m, fp, CcdMode::contacts, 64).second > 0);
  CHECK(whole_beside_filter_runs<NoneHanded, double>(m, fp, CcdMode::contacts, 64).second > 0);
  CHECK(whole_beside_filter_runs<WholeAfterFilter, double>(m, fp, CcdMode::contacts, 64).second == 0);
}

// Returns the early searches of each of two runs (NarrowPhase::early_searches).
template <class Policy, class T>
std::array<std::size_t, 2> early_search_runs(const lwsccd_test::MovingMesh& m, const FeaturePairs& fp, CcdMode mode,
                                             int fp64_ratio = 0) {
  std::array<std::size_t, 2> early = {0, 0};
  const auto cpu_result = runs_against_cpu<Policy, T>(m, fp, mode, fp64_ratio,
                                                      [&](const auto& narrow, int run) { early[run] = narrow.early_searches(); });
  std::printf("  %s/%s: %zu + %zu hits, %zu + %zu undecided for the fallback, %zu and %zu early searches\n",
              sizeof(T) == 4 ? "float" : "double", mode == CcdMode::earliest ? "earliest" : "contacts", cpu_result.vf.size(),
              cpu_result.ee.size(), cpu_result.vf_counts.fallbacks, cpu_result.ee_counts.fallbacks, early[0], early[1]);
  return early;
}

struct NoEarlySearches : gpu::NarrowPhasePolicy {
  static constexpr int kEarlyCoplanarSearches = 0;
};
struct ThreeEarlySearches : gpu::NarrowPhasePolicy {
  static constexpr int kEarlyCoplanarSearches = 3;
};

TEST_CASE("GPU narrow phase: pairs coplanar over the whole step in float, searched early, give the same answers", "[gpu][narrow]") {
  // A seam of duplicated vertices ~1e-6 apart, sliding in the sheets' plane: the pairs of edges
  // and of vertices and faces along it keep their cubic within float's bound over the whole step
  // and are not outside there in float (145 pairs), so the single-precision filter sends them to
  // the early searches (a warp each, on a stream of their own).
  const auto m = lwsccd_test::seam_sheets(8, 7);
  const FeaturePairs fp = feature_pairs(m.mesh, brute_force_pairs(m.mesh, swept_triangle_bvs<Aabbd>(m.mesh, m.x0, m.x1)));
  for (CcdMode mode : {CcdMode::contacts, CcdMode::earliest}) {
    INFO("mode " << int(mode));
    const auto early = early_search_runs<gpu::NarrowPhasePolicy, double>(m, fp, mode);
    CHECK(early[0] > 6);
    CHECK(early[1] == early[0]);  // (planned from the first run: as many)
    // Without them: the same answers and counts.
    CHECK(early_search_runs<NoEarlySearches, double>(m, fp, mode) == std::array<std::size_t, 2>{0, 0});
    // Room for three a list: a first run takes three a list early and the rest through the double
    // filter; a run after one with more than that plans none (the same answers and counts).
    CHECK(early_search_runs<ThreeEarlySearches, double>(m, fp, mode) == std::array<std::size_t, 2>{6, 0});
    // Planned for a GPU with little FP64 the searches in double run a thread each: none early.
    CHECK(early_search_runs<gpu::NarrowPhasePolicy, double>(m, fp, mode, 64) == std::array<std::size_t, 2>{0, 0});
    CHECK(early_search_runs<gpu::NarrowPhasePolicy, float>(m, fp, mode)[1] > 0);
  }
  // The folded cloth has no such pairs: nothing early, the same answers (its second run plans no
  // early searches at all).
  const auto cloth = lwsccd_test::folded_cloth(40, 4);
  const FeaturePairs cloth_pairs =
      feature_pairs(cloth.mesh, brute_force_pairs(cloth.mesh, swept_triangle_bvs<Aabbd>(cloth.mesh, cloth.x0, cloth.x1)));
  CHECK(early_search_runs<gpu::NarrowPhasePolicy, double>(cloth, cloth_pairs, CcdMode::contacts) == std::array<std::size_t, 2>{0, 0});
}

TEST_CASE("GPU narrow phase: a short list planned for FP64 at 1/64 hands its searches in double on", "[gpu][narrow]") {
  // Planned for a GPU with little FP64 every deferred list goes to a thread each and hands its
  // searches in double on, however short: a list with room for fewer entries than
  // kRefineWarpBelow still needs room for them (it once had none there).
  using DoubleOnly = CertifiedCcdT<Filtered<InclusionCcd>, DoubleOnlyCertified>;
  const auto m = lwsccd_test::folded_cloth(40, 4);
  const auto pairs = brute_force_pairs(m.mesh, swept_triangle_bvs<Aabbd>(m.mesh, m.x0, m.x1));
  const FeaturePairs all = feature_pairs(m.mesh, pairs);
  // The cloth's contacts, which every one reach a whole search: at most 300 of each kind.
  const auto contacts = cpu::test_feature_pairs<DoubleOnly, double>(m.mesh, m.x0, m.x1, all, CcdParams<double>{});
  FeaturePairs few;
  for (const auto& h : contacts.vf)
    if (few.vf.size() < 300) few.vf.push_back({h.first, h.second});
  for (const auto& h : contacts.ee)
    if (few.ee.size() < 300) few.ee.push_back({h.first, h.second});
  REQUIRE(few.vf.size() + few.ee.size() > 0);
  std::size_t handed = 0, in_warps = 1;
  // (A capacity below kRefineWarpBelow: the lists' room is the input's, 300 pairs each.)
  compare_backends<DoubleOnly, double>(m.mesh, m.x0, m.x1, few, 256, CcdMode::contacts, nullptr, &handed, 64, &in_warps);
  std::printf("  %zu + %zu pairs planned for FP64 at 1/64: %zu searches in double handed on, %zu a warp each\n", few.vf.size(),
              few.ee.size(), handed, in_warps);
  CHECK(handed > 0);
  CHECK(in_warps == 0);
  compare_backends<CertifiedCcd, double>(m.mesh, m.x0, m.x1, few, 256, CcdMode::contacts, nullptr, nullptr, 64);
  compare_backends<CertifiedCcd, float>(m.mesh, m.x0, m.x1, few, 256, CcdMode::earliest, nullptr, nullptr, 64);
}

TEST_CASE("GPU hit sort: by (first, second) over only the bits the feature ids take", "[gpu][narrow]") {
  // Limits at and around powers of two (the key packs first above second by the ids' bit width),
  // ids up to the largest below the limit, duplicates of first, n = 0, 1 (left as they are), and
  // n on both sides of the one-block sort's limit (256).
  std::mt19937 rng(7);
  for (const std::size_t limit : {std::size_t(1), std::size_t(2), std::size_t(3), std::size_t(1) << 16, (std::size_t(1) << 16) + 1,
                                  std::size_t(50021), std::size_t(1) << 31})
    for (const std::size_t n : {std::size_t(0), std::size_t(1), std::size_t(2), std::size_t(255), std::size_t(256),
                                  std::size_t(257), std::size_t(777), std::size_t(20000)}) {
      INFO("limit " << limit << ", n " << n);
      std::uniform_int_distribution<std::size_t> id(0, limit - 1), few(0, std::min<std::size_t>(limit - 1, 9));
      std::vector<FeatureHit<double>> hits(n);
      for (std::size_t i = 0; i < n; ++i)
        hits[i] = {static_cast<index_t>(i % 3 ? id(rng) : few(rng)), static_cast<index_t>(i % 5 ? id(rng) : limit - 1),
                   static_cast<double>(i)};
      gpu::DeviceBuffer<FeatureHit<double>> d;
      d.upload(hits);
      gpu::HitSorter<double> sorter;
      sorter.sort(d, n, limit);
      LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
      const std::vector<FeatureHit<double>> got = d.download_prefix(n);
      std::vector<FeatureHit<double>> expected = hits;
      std::stable_sort(expected.begin(), expected.end());  // CUB's radix sort is stable too
      REQUIRE(got.size() == n);
      for (std::size_t i = 0; i < n; ++i) {
        REQUIRE(got[i].first == expected[i].first);
        REQUIRE(got[i].second == expected[i].second);
        REQUIRE(got[i].toi == expected[i].toi);
      }
    }
}

TEST_CASE("GPU hit sort ahead: enqueued before the count reaches the host, used only where it covered it", "[gpu][narrow]") {
  // A buffer whose slots past the count hold other hits (a run's room past its hits): the sort
  // ahead of `span` slots must order the first n (stably) and put nothing of the rest before
  // them; where the span is short of n it must say so and leave the buffer as it was. By radix
  // (no overflow word) and by buckets (with one): a bucket past detail::kBucketRankMax hits must
  // be counted there and the sort declined, and the sorter then sorts ahead by radix.
  std::mt19937 rng(11);
  for (const bool buckets : {false, true})
    for (const std::size_t limit : {std::size_t(3), std::size_t(1) << 16, std::size_t(50021), std::size_t(1) << 31})
      for (const std::size_t n : {std::size_t(0), std::size_t(1), std::size_t(2), std::size_t(200), std::size_t(256),
                                  std::size_t(300), std::size_t(20000)})
        for (const std::size_t span : {n, n + 7, n > 0 ? n - 1 : 0, std::size_t(256), 2 * n + 3}) {
          INFO("buckets " << buckets << ", limit " << limit << ", n " << n << ", span " << span);
          const std::size_t size = std::max(span, n) + 5;
          std::uniform_int_distribution<std::size_t> id(0, limit - 1);
          std::vector<FeatureHit<double>> hits(size);
          for (std::size_t i = 0; i < size; ++i)
            hits[i] = {static_cast<index_t>(i % 4 ? id(rng) : 0), static_cast<index_t>(id(rng)), static_cast<double>(i)};
          gpu::DeviceBuffer<FeatureHit<double>> d;
          d.upload(hits);
          gpu::DeviceBuffer<unsigned long long> count, overflow;
          count.upload(std::vector<unsigned long long>{n});
          overflow.upload(std::vector<unsigned long long>{0});
          gpu::HitSorter<double> sorter;
          sorter.sort_ahead(d, count.data(), span, limit, nullptr, buckets ? overflow.data() : nullptr);
          LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
          const unsigned long long overflowed = overflow.download()[0];
          // Hits with first id 0 (a quarter of them) share a bucket: past its limit with n 20000.
          const bool bucketed = buckets && std::min(span, size) > static_cast<std::size_t>(gpu::detail::kSmallHitSort);
          const std::size_t in_first_bucket = static_cast<std::size_t>(
              std::count_if(hits.begin(), hits.begin() + static_cast<std::ptrdiff_t>(std::min(n, span)),
                            [&](const FeatureHit<double>& h) { return h.first == 0; }));
          if (!bucketed) REQUIRE(overflowed == 0);
          if (bucketed && in_first_bucket > gpu::detail::kBucketRankMax) REQUIRE(overflowed > 0);
          const bool covered = sorter.take_ahead(d, n, overflowed);
          REQUIRE(covered == (n < 2 || (span >= n && overflowed == 0)));
          CHECK(sorter.ahead_by_radix() == (overflowed > 0));
          std::vector<FeatureHit<double>> expected(hits.begin(), hits.begin() + static_cast<std::ptrdiff_t>(n));
          if (covered) std::stable_sort(expected.begin(), expected.end());
          const std::vector<FeatureHit<double>> got = d.download_prefix(n);
          for (std::size_t i = 0; i < n; ++i) {
            REQUIRE(got[i].first == expected[i].first);
            REQUIRE(got[i].second == expected[i].second);
            REQUIRE(got[i].toi == expected[i].toi);
          }
          CHECK(!sorter.take_ahead(d, std::max<std::size_t>(n, 2)));  // (taken once only)
          if (overflowed == 0) continue;
          // Declined once, by radix from then on: the same hits sorted ahead again are covered.
          d.upload(hits);
          sorter.sort_ahead(d, count.data(), span, limit, nullptr, overflow.data());
          LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
          REQUIRE(sorter.take_ahead(d, n, 0) == (span >= n));
        }
}

TEST_CASE("GPU hit sort ahead by buckets: spread and crowded first ids, run after run", "[gpu][narrow]") {
  // One sorter many times (its bucket counts and its scan's ticket must return to zero after each
  // sort, its scan's tile sums of earlier sorts be passed over), with first ids spread (a bucket
  // or two each), in runs (consecutive ids, as contacts of one region), and up to kBucketRankMax
  // in one bucket: every sort covered and stable. Half the sorts (of both lengths) overlap their
  // launches where the device can (as the narrow phase's).
  std::mt19937 rng(5);
  gpu::HitSorter<double> sorter;
  gpu::DeviceBuffer<unsigned long long> count, overflow;
  overflow.upload(std::vector<unsigned long long>{0});
  for (int round = 0; round < 12; ++round) {
    const std::size_t limit = round % 3 == 0 ? std::size_t(300000) : round % 3 == 1 ? std::size_t(4099) : std::size_t(1) << 20;
    const std::size_t n = round % 2 ? 70000 : 1000 + 37 * static_cast<std::size_t>(round);
    INFO("round " << round << ", limit " << limit << ", n " << n);
    std::uniform_int_distribution<std::size_t> id(0, limit - 1);
    std::vector<FeatureHit<double>> hits(n);
    const index_t crowded = static_cast<index_t>(id(rng));
    for (std::size_t i = 0; i < n; ++i) {
      index_t first = static_cast<index_t>(id(rng));
      if (round % 4 == 1) first = static_cast<index_t>((i / 3) % limit);                  // runs of ids
      if (i < gpu::detail::kBucketRankMax / 2) first = crowded;                          // one crowded id
      hits[i] = {first, static_cast<index_t>(i % 7 ? id(rng) : 1), static_cast<double>(i)};
    }
    gpu::DeviceBuffer<FeatureHit<double>> d;
    d.upload(hits);
    count.upload(std::vector<unsigned long long>{n});
    const bool overlap = round % 4 < 2 && lwsccd::detail::device_overlaps_launches(0);
    sorter.sort_ahead(d, count.data(), gpu::HitSorter<double>::span_after(n), limit, nullptr, overflow.data(), overlap);
    LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
    const unsigned long long overflowed = overflow.download()[0];
    if (limit >= n) REQUIRE(overflowed == 0);  // (a dense id range: buckets of one or two ids)
    REQUIRE(sorter.take_ahead(d, n, overflowed) == (overflowed == 0));
    if (overflowed) {
      overflow.upload(std::vector<unsigned long long>{0});
      continue;
    }
    std::stable_sort(hits.begin(), hits.end());
    const std::vector<FeatureHit<double>> got = d.download_prefix(n);
    for (std::size_t i = 0; i < n; ++i) {
      REQUIRE(got[i].first == hits[i].first);
      REQUIRE(got[i].second == hits[i].second);
      REQUIRE(got[i].toi == hits[i].toi);
    }
  }
}

// The folded cloth's feature pairs, all of them and every k-th, on the device, for a narrow phase
// run after run.
struct RunAfterRun {
  lwsccd_test::MovingMesh m = lwsccd_test::folded_cloth(40, 4);
  FeaturePairs all, few;
  gpu::DeviceMeshFeatures features{m.mesh};
  gpu::DeviceStep<double> step{m.mesh, m.x0, m.x1};
  explicit RunAfterRun(std::size_t every) {
    all = feature_pairs(m.mesh, brute_force_pairs(m.mesh, swept_triangle_bvs<Aabbd>(m.mesh, m.x0, m.x1)));
    for (std::size_t i = 0; i < all.vf.size(); i += every) few.vf.push_back(all.vf[i]);
    for (std::size_t i = 0; i < all.ee.size(); i += every) few.ee.push_back(all.ee[i]);
  }
  // Runs `narrow` on each of `runs` in turn: every run's contacts (more than `least`) must be the
  // CPU backend's.
  template <class Policy>
  void require_cpu_contacts(gpu::NarrowPhase<CertifiedCcd, double, Policy>& narrow, std::initializer_list<const FeaturePairs*> runs,
                            const CcdParams<double>& params, std::size_t least) const {
    for (const FeaturePairs* fp : runs) {
      gpu::DeviceBuffer<std::pair<index_t, index_t>> vf, ee;
      vf.upload(fp->vf);
      ee.upload(fp->ee);
      narrow.run(features, step.x0.data(), step.x1.data(), vf.data(), vf.size(), ee.data(), ee.size(), params);
      const auto expected = cpu::test_feature_pairs<CertifiedCcd, double>(m.mesh, m.x0, m.x1, *fp, params);
      REQUIRE(expected.vf.size() + expected.ee.size() > least);
      lwsccd_test::require_same_contacts(narrow.download(), expected);
    }
  }
};

TEST_CASE("GPU narrow phase run after run: hits sorted ahead where the last count covers them, else after", "[gpu][narrow]") {
  // The same object on the folded cloth's pairs, then a few of them (fewer hits: the sort ahead
  // covers them), then all again (more hits than the span learned from the few: sorted after the
  // count comes back), then once more (covered): each run's contacts are the CPU backend's.
  const RunAfterRun r(7);
  for (CcdMode mode : {CcdMode::contacts, CcdMode::set}) {
    gpu::NarrowPhase<CertifiedCcd, double> narrow(1 << 16);
    CcdParams<double> params;
    params.mode = mode;
    r.require_cpu_contacts(narrow, {&r.all, &r.all, &r.few, &r.all, &r.all}, params, 2);
  }
}

TEST_CASE("GPU single-precision filter in blocks from a small capacity: a block's pairs sent on together, past the room too",
          "[gpu][narrow]") {
  // The block form (its pairs' sends take their places a block at a time) in a narrow phase whose
  // first run starts from rooms of 16 (no count first): its lists overflow, the double filter's
  // among them (the sends past its room take no place, and the run is repeated with more room),
  // then a few of the pairs, then all again. Every run's contacts are the CPU backend's.
  const RunAfterRun r(11);
  gpu::NarrowPhase<CertifiedCcd, double, SingleFilterInBlocksFromCapacity> narrow(16);
  r.require_cpu_contacts(narrow, {&r.all, &r.few, &r.all}, CcdParams<double>{}, 16);
  CHECK(narrow.reruns() > 0);  // (the rooms of 16 did overflow)
}

TEST_CASE("GPU narrow phase equals the CPU backend on the real scenes' candidate pairs", "[gpu][narrow][data]") {
  if (!lwsccd_test::have_data()) {
    WARN("SKIPPED: shared data not found at " << lwsccd_test::data_dir());
    return;
  }
  for (const char* name : {"cloth-funnel", "armadillo-rollers", "cloth-ball"}) {
    INFO(name);
    const Scene scene = load_scene(lwsccd_test::data_dir() + "/scenes/" + name);
    const FeaturePairs fp{scene.truth.vf, scene.truth.ee};
    std::printf("%s\n", name);
    compare_backends<Filtered<InclusionCcd>, double>(*scene.step.mesh, scene.step.x0, scene.step.x1, fp, 1 << 10);
    compare_backends<Filtered<InclusionCcd>, float>(*scene.step.mesh, scene.step.x0, scene.step.x1, fp, 1 << 10);
    compare_backends<CubicCcd, double>(*scene.step.mesh, scene.step.x0, scene.step.x1, fp, 1 << 10);
    for (CcdMode mode : {CcdMode::contacts, CcdMode::earliest, CcdMode::set}) {
      compare_backends<CertifiedCcd, double>(*scene.step.mesh, scene.step.x0, scene.step.x1, fp, 1 << 10, mode);
      compare_backends<CertifiedCcd, float>(*scene.step.mesh, scene.step.x0, scene.step.x1, fp, 1 << 10, mode);
    }
  }
}
