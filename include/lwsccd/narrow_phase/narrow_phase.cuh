// lwsccd — the narrow phase on the GPU: a thread per candidate feature pair, hits appended on the
// device into an output that grows as needed (nothing is dropped), no host round trip inside a run.
#pragma once

#include <cub/device/device_radix_sort.cuh>

#include <algorithm>
#include <functional>
#include <utility>
#include <vector>

#include "lwsccd/bvh/bvh.cuh"
#include "lwsccd/core/cuda_handles.cuh"
#include "lwsccd/core/device_buffer.cuh"
#include "lwsccd/core/error.hpp"
#include "lwsccd/core/host_staging.cuh"
#include "lwsccd/core/launch.cuh"
#include "lwsccd/narrow_phase/ccd_filters.hpp"
#include "lwsccd/narrow_phase/certified_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.hpp"

namespace lwsccd::gpu {

/// Faces and edges on the device, for turning feature ids into query points.
struct DeviceMeshFeatures {
  DeviceBuffer<Face> faces;
  DeviceBuffer<Edge> edges;
  index_t num_vertices = 0, num_edges = 0;

  DeviceMeshFeatures() = default;
  explicit DeviceMeshFeatures(const TriangleMesh& mesh, cudaStream_t stream = nullptr)
      : num_vertices(mesh.num_vertices()), num_edges(mesh.num_edges()) {
    faces.upload(mesh.faces(), stream);
    edges.upload(mesh.edges(), stream);
  }
  MeshFeatures view() const { return {faces.data(), edges.data(), num_vertices, num_edges}; }
  /// Vertices, edges and faces together: every feature id is below this.
  std::size_t num_features() const { return static_cast<std::size_t>(num_vertices) + num_edges + faces.size(); }
};

/// Knobs of the GPU narrow phase.
struct NarrowPhasePolicy {
  static constexpr int kBlock = 128;               ///< threads per block, a thread per query
  static constexpr int kThreadRounds = 6;   ///< InclusionCcd: rounds of the one-thread attempt per query
  static constexpr int kThreadBoxes = 64;   ///< InclusionCcd: live boxes the one-thread attempt may keep
  static constexpr int kSearchWarpsPerBlock = 2;   ///< InclusionCcd's searches left open: a warp per query (~11 KiB of shared memory each)
  /// InclusionCcd: a list of at most this many queries skips the one-thread attempt (its warp
  /// searches run at once; CertifiedCcd's few fallbacks); 0 always makes the attempt.
  static constexpr int kWarpSearchDirect = 1024;
  /// CertifiedCcd: refinements that would halve intervals this deep (width 2^-level) go to a
  /// second kernel, so that the long searches of contacts do not hold up warps of quick misses.
  /// On an H100 levels 3 and 4 were fastest (cloth-ball narrow 3.3 ms against 3.5 at level 8,
  /// built-in 100K 1.05 against 1.5; docs/BENCHMARKS.md).
  static constexpr int kRefineDeferLevel = 4;
  /// CertifiedCcd: at most this many deferred refinements run a warp each (inside tests by
  /// subtrees: the long coplanar searches' latency ~5x shorter), more a thread each; 0: always a thread.
  static constexpr int kRefineWarpBelow = 1024;
  /// CertifiedCcd, a deferred list longer than kRefineWarpBelow (a thread per pair): the searches in
  /// double of the pairs single precision leaves undecided are handed from their thread to a kernel
  /// of their own (listed for it), a warp each (inside tests by subtrees, the next search by a ticket) or a
  /// thread each by the two knobs below, so that one long search no longer holds up the thread
  /// kernel (the same answers). False: they run on their thread.
  static constexpr bool kHandOnDoubleSearches = true;
  /// CertifiedCcd FP32 first: the contacts the single-precision filter sends whole are searched by
  /// the double filter's kernel beside its few, long pairs, where the list's last run sent more
  /// than kRefineWarpBelow (the SMs' warp slots the two kernels left idle one after the other are
  /// shared; NVIDIA H200, cloth-ball narrow 0.83 -> 0.81 ms). The same answers; false: after it.
  static constexpr bool kWholeBesideFilter = true;
  /// CertifiedCcd FP32 first: a pair whose cubic stays within float's bound over the whole step
  /// (motion coplanar all along: cloth-funnel's seams sliding in the cloth's plane) and whose
  /// inside test there is not outside in float is searched whole by a warp of its own, on a stream
  /// of the list's own, as soon as the single-precision filter's first kernel has listed it. Those
  /// searches were the longest of their list and ran last, after the double filter's kernels. The
  /// same answers; 0: none. Planned from the list's last run: early searches only where it had
  /// such pairs, at most this many (a few long searches; more would cost a warp's lanes each, as
  /// kHandedWarpsPerSm says, and go through the double filter as before) and at least one in
  /// kEarlyCoplanarPerSurvivors of the pairs its screen passed (a long list's chain outlasts them
  /// anyway, and the stream's fork and join cost it ~0.01 ms), and only where the searches in
  /// double run a warp each (kHandedWarpsMaxFp64Ratio).
  static constexpr int kEarlyCoplanarSearches = 256;
  static constexpr int kEarlyCoplanarPerSurvivors = 256;
  /// A list's kernels (the screen through the fallback's and the hits' sort, all but a sort by
  /// radix, the rare path after a crowded bucket) are launched to overlap the end of the one
  /// before them (programmatic dependent launch, compute capability 9.0 and later; elsewhere
  /// plain launches): a kernel's blocks are set up while the last one's finish and wait on the
  /// device for it, instead of the stream draining between the two (NVIDIA H200:
  /// armadillo-rollers narrow 0.516 -> 0.494 ms, the other shared scenes within their spread). The same answers; false: plain launches. Every
  /// kernel NarrowPhase::chain launches starts with detail::start_after_previous_grids.
  static constexpr bool kOverlapLaunches = true;
  /// At most this many handed searches per SM run a warp each; more run a thread each (in a kernel
  /// of their own, still apart from the short ones): a warp's search costs ~30 lanes' work, which
  /// pays where a few long searches set the time (cloth-ball: 3.4 K edge-edge, 201 of them
  /// coplanar ones that end undecided), not where thousands of them do (the built-in scene's
  /// degenerate motion). 0: always a thread each.
  static constexpr int kHandedWarpsPerSm = 32;
  /// Searches in double run a warp each (the handed ones, and a deferred list of at most
  /// kRefineWarpBelow pairs) only on GPUs whose FP32 throughput is at most this many times their
  /// FP64 one (cudaDevAttrSingleToDoublePrecisionPerfRatio: 2 on an H100 or H200, 32-64 on the RTX
  /// and L40 classes): every lane of a warp's search repeats its FP64 instructions, which a GPU
  /// with little FP64 pays for; there they run a thread each.
  static constexpr int kHandedWarpsMaxFp64Ratio = 2;
  /// CertifiedCcd: contacts' leaves proved in pairs of floats first (CcdParams::leaves_in_float_pairs,
  /// the same answers) on GPUs whose FP32 throughput is at least this many times their FP64 one
  /// (as planned: plan_for_fp64_ratio), whatever the caller's CcdParams say.
  static constexpr int kFloatPairLeavesMinFp64Ratio = lwsccd::kFloatPairLeavesMinFp64Ratio;
  /// CertifiedCcd's refinement kernel: blocks per SM it must fit (__launch_bounds__), which caps
  /// its registers per thread. 1: no cap (255 registers); on an H100 caps of 3 and 4 blocks
  /// spilled and made the narrow phase 1.3x and 2.9x slower on cloth-ball.
  static constexpr int kRefineMinBlocks = 1;
  /// CertifiedCcd's refinement starts with its filter (CertifiedFilter): a thread per pair prunes
  /// the cubic's pieces to the first inside-test level, then a thread per listed interval runs the
  /// inside test, so the costliest step no longer diverges; the pairs it cannot exclude are
  /// searched whole. Same answers as without (false, and always in mode set: refine_kernel's
  /// levels, then the rest). H100, cloth-ball narrow phase, mode contacts: 2.34-2.53 -> 1.66-2.09 ms.
  static constexpr bool kRefineFilter = true;
  /// The filter's list of intervals starts with room for this percentage of the screened pairs'
  /// room (~1.03 intervals per listed pair on the scenes); pairs whose intervals do not fit are
  /// searched whole (same answers) and the room grows for the next run.
  static constexpr int kFilterRoomPercent = 100;
  /// The filter's second round: an interval whose inside test is unknown is split as the search
  /// would split it, down to the next inside-test level (CertifiedFilter::expand), and those
  /// intervals are tested a thread each too; only pairs with an interval not certainly outside
  /// there are searched whole (on cloth-ball 301 K edge-edge pairs -> 105 K, 95 K of them contacts).
  /// Mode contacts only: in mode earliest the short windows leave it little, and its two launches
  /// per window cost more (H100: cloth-ball narrow, contacts 1.89 -> 1.28 ms, earliest 0.43 -> 0.45).
  static constexpr bool kFilterSecondRound = true;
  /// Its list's starting room, as a percentage of the screened pairs' room (grown like the first's).
  static constexpr int kDeepRoomPercent = 100;
  /// FP32 first: the double filter sees only the pairs single precision leaves (cloth-ball ~6% of
  /// the screened pairs, the other shared scenes less), so its two interval lists start with room
  /// for this percentage of the screened pairs' room instead of the two above (grown like them:
  /// intervals that do not fit are searched whole, and the next run has room for them).
  static constexpr int kDoubleAfterSingleRoomPercent = 12;
  /// FP32 first: a pair with an interval certainly inside in float (a contact, nearly always)
  /// goes from the single-precision filter straight to the whole search, past the double filter,
  /// which would only pass it on (same answers: the filter decides only what the search decides
  /// alike; the double screen still runs first). Only pairs the float filter fails take the
  /// double filter's kernels.
  static constexpr bool kSingleInsideWhole = true;
  /// FP32 first: a list whose last run's screen passed fewer pairs than this many per SM runs the
  /// single-precision filter's two rounds on one thread a pair (single_route_kernel, the pair's
  /// float query gathered once), instead of a thread a pair listing its intervals and a thread an
  /// interval testing them (four kernels). Its pairs have about one interval each (cloth-ball:
  /// 1.04 in the first round, half of them tested again below), so one thread keeps most lanes
  /// busy; but in a long edge-edge list the four kernels' denser inside tests win (NVIDIA H200,
  /// the float filter's kernels in a trace of the steady step: cloth-ball's edge-edge list 207 us
  /// in four kernels against 230 on one thread, armadillo-rollers' 94 against 116; cloth-ball's
  /// vertex-face list 97 against 69, cloth-funnel's two lists 23 and 25 against 8 and 11). The
  /// block form (kSingleFilterInBlocks) on the short lists too was slower on them (cloth-funnel,
  /// horse-gallop and the built-in 100 K scene, NVIDIA H100); from 768 pairs per SM on (1024 before)
  /// it takes cloth-ball's vertex-face list (~119 K pairs), not armadillo-rollers' (~67 K): cloth-ball's
  /// narrow phase 0.493-0.494 -> 0.475-0.481 ms (NVIDIA H100). The same answers and counts either
  /// way; 0: never on one thread.
  static constexpr int kSingleFilterOneThreadPerSm = 768;
  /// FP32 first: a list that does not run the single-precision filter on one thread a pair runs
  /// it in one kernel whose blocks keep their pairs' float queries and intervals in shared memory
  /// (single_block_filter_kernel: a thread a pair lists, a thread an interval tests, a thread an
  /// unknown interval lists its pieces, a thread a piece tests, between the block's barriers),
  /// instead of four kernels that gather each pair's query from global memory again in each
  /// (cloth-ball's narrow phase 0.68 -> 0.63 ms on an NVIDIA H100, the others unchanged).
  /// The same answers and counts; false: the four kernels.
  static constexpr bool kSingleFilterInBlocks = true;
  /// The block form's room for the second round's pieces, per pair of the block (cloth-ball: 0.5
  /// a pair); a pair whose pieces do not fit is routed on its thread (route_single), the same answer.
  static constexpr int kSingleBlockPiecesPerPair = 4;
  /// The block form's blocks per SM (__launch_bounds__): 5 caps it at 96 registers (153 without),
  /// so that 5 of its blocks of 128 fit an SM beside their shared memory (23 KB a block) and hide
  /// each other's barriers and loads.
  static constexpr int kSingleBlockMinBlocksPerSm = 5;
  /// Kernels whose input length is read on the device loop over it (grid-stride) in a grid of
  /// this many blocks per SM (or fewer, where the input's room is smaller).
  static constexpr int kGridBlocksPerSm = 16;
  /// A first run counts its screen's survivors before it runs (no rerun for want of room) and
  /// gives the hits room for one in this many of them. Since the screen tests the features'
  /// relative motion (B14) a survivor is often a contact (cloth-ball 1 in 5, the built-in scene's
  /// vertex-face list 1 in 2), and a survivor gives at most one hit. A run with more hits grows
  /// the room and runs again. False: a first run starts from the initial capacity and grows where
  /// it overflowed (a run again).
  static constexpr bool kCountFirstRun = true;
  static constexpr int kFirstRunHitsPerSurvivors = 1;
  /// FP32 first: a first run gives the refinement in double's lists (the pairs single precision
  /// leaves, and the contacts it sends to the whole search) room for one in this many survivors
  /// (what they take: cloth-ball ~21%, the built-in scene's vertex-face list ~47%; a survivor
  /// takes at most one slot); more is learned from a run's count (a run again).
  static constexpr int kFirstRunRefinePerSurvivors = 1;
};

/// Sorts device hits by (first, second), the order of the CPU backend's results (CUB radix sort
/// on a 64-bit key; ahead of the count, by buckets of first ids where it can). Owns its scratch
/// (reused; it only grows).
template <class T>
class HitSorter {
 public:
  /// Sorts the first n hits of `hits` by (first, second) on `stream`; every id is below
  /// `id_limit` (the mesh's feature count: only the bits that takes are sorted). The sorted hits
  /// end up in `hits` by an exchange of buffers (the old one becomes this sorter's scratch), so
  /// `hits` keeps at least its size.
  void sort(DeviceBuffer<FeatureHit<T>>& hits, std::size_t n, std::size_t id_limit, cudaStream_t stream = nullptr);
  /// Enqueues the sort of the first `span` slots of `hits` (at most its size) while their count
  /// is still on the device only (`device_count`: slots from it on sort after the hits), so that
  /// no host round trip sits between a run's last kernel and its sort. take_ahead() then says
  /// whether that sort covered the count.
  /// With `overflow` (a device word, zero, that the caller reads back with its run's counts) the
  /// hits are sorted by buckets of first ids (detail::bucket_rank_kernel: four launches, no
  /// radix passes); a bucket of more than detail::kBucketRankMax hits adds to *overflow, and the
  /// caller passes the word to take_ahead(), which then declines the sort (sort() them). From
  /// then on this sorter sorts ahead by radix (a scene whose contacts crowd a few features keeps
  /// crowding them). Without `overflow`: by radix. With `overlap_launches` (a device of compute
  /// capability 9.0 or later: detail::device_overlaps_launches) the sort's kernels (the one-block
  /// sort's and the bucket sort's; a sort by radix launches plainly) are launched to overlap the
  /// end of the kernel before them on `stream` (detail::launch_after_previous); the same order.
  void sort_ahead(const DeviceBuffer<FeatureHit<T>>& hits, const unsigned long long* device_count, std::size_t span,
                  std::size_t id_limit, cudaStream_t stream = nullptr, unsigned long long* overflow = nullptr,
                  bool overlap_launches = false);
  /// Once the stream of the last sort_ahead() has been synchronized and the count `n` is known:
  /// true when that sort covered it, the sorted hits then in `hits` (buffers exchanged as by
  /// sort()); false when it did not (`hits` unchanged: sort() them). `overflow`: the value of the
  /// word given to sort_ahead() (not zero: a bucket was too full, the sort is declined). Forgets
  /// the sort ahead.
  bool take_ahead(DeviceBuffer<FeatureHit<T>>& hits, std::size_t n, unsigned long long overflow = 0);
  /// The span to sort ahead in a run that follows one with `n` hits: a quarter more, so that a
  /// count that grows a little from run to run stays covered.
  static std::size_t span_after(std::size_t n) { return n + n / 4 + 32; }
  /// Whether sort_ahead() sorts by radix whatever it is given (after a bucket overflowed).
  bool ahead_by_radix() const { return ahead_by_radix_; }
  std::size_t device_bytes() const {
    return sorted_.capacity_bytes() + keys_.capacity_bytes() + sorted_keys_.capacity_bytes() + scratch_.capacity_bytes() +
           bucket_count_.capacity_bytes() + bucket_start_.capacity_bytes() + order_.capacity_bytes() + tile_sums_.capacity_bytes() +
           tile_ticket_.capacity_bytes();
  }

 private:
  void radix_sort(const FeatureHit<T>* hits, std::size_t n, int id_bits, cudaStream_t stream, const unsigned long long* device_count);
  void bucket_sort(const FeatureHit<T>* hits, const unsigned long long* device_count, std::size_t span, std::size_t id_limit,
                   int id_bits, cudaStream_t stream, unsigned long long* overflow, bool overlap);
  std::size_t ahead_ = 0;  ///< slots the last sort_ahead() sorted (0: none pending)
  bool ahead_bucketed_ = false;  ///< the last sort_ahead() sorted by buckets
  bool ahead_by_radix_ = false;  ///< a bucket overflowed once: sort ahead by radix from then on
  DeviceBuffer<FeatureHit<T>> sorted_;
  DeviceBuffer<unsigned long long> keys_, sorted_keys_;
  DeviceBuffer<unsigned char> scratch_;
  DeviceBuffer<unsigned> bucket_count_;  ///< per bucket, zero between sorts (cleared when it grows)
  DeviceBuffer<unsigned> bucket_start_, order_;
  DeviceBuffer<unsigned long long> tile_sums_;  ///< the bucket scan's tile sums, this sort's generation high (detail::bucket_scan_kernel)
  DeviceBuffer<unsigned> tile_ticket_;          ///< the bucket scan's ticket, zero between sorts
  unsigned scan_generation_ = 0;                ///< the last bucket scan's (never 0 in a scan)
};

/// Runs a CCD method over device lists of candidate pairs, in the mode params.mode (as
/// cpu::test_feature_pairs, with the same answers). CertifiedCcd classifies every pair in the
/// first pass, a thread per pair (its hits are stored at once), and runs its fallback only on the
/// undecided ones. Other methods with a quick_reject (the conservative inclusion method, filtered
/// methods) run their cheap first step on every pair, then the full test on the survivors. The
/// inclusion method's full test runs a thread per query for a few rounds, then a warp per query
/// still open.
///
/// No host round trip inside a run: every list is appended on the device (an atomic counter per
/// list, warp-aggregated) into buffers sized from earlier runs, every kernel reads its input's
/// length on the device (grid-stride loops), and mode earliest's windows are all enqueued, each
/// skipped on the device once an earlier one holds a contact. The host reads the counters once at
/// the end (collect()); where a list outgrew its buffer the run is enqueued again with room for it,
/// so nothing is lost. Owns its buffers (reused; they only grow).
template <class Method, class T, class Policy = NarrowPhasePolicy>
class NarrowPhase {
 public:
  static_assert(require_ccd_method<Method>::value, "");
  static_assert(!Policy::kSingleFilterInBlocks || (Policy::kBlock >= 32 && Policy::kBlock < 256),
                "lwsccd: NarrowPhasePolicy::kSingleFilterInBlocks numbers a block's pairs in a byte: kBlock must be "
                "32..255 (or set kSingleFilterInBlocks = false)");
  static_assert(Policy::kSingleBlockPiecesPerPair >= 0, "lwsccd: NarrowPhasePolicy::kSingleBlockPiecesPerPair must be >= 0");
  static_assert(Policy::kSingleBlockMinBlocksPerSm >= 1, "lwsccd: NarrowPhasePolicy::kSingleBlockMinBlocksPerSm must be >= 1");
  using Pair = std::pair<index_t, index_t>;

  /// Output buffers start with room for `initial_capacity` pairs, or for the input's room where
  /// that is less (a list never holds more than its input: a streamed step's small parts keep
  /// small buffers), and grow (with a rerun) whenever a run needed more (tests force tiny values).
  explicit NarrowPhase(std::size_t initial_capacity = 1 << 16)
      : initial_capacity_(std::max<std::size_t>(initial_capacity, 1)) {}

  /// Tests `num_vf` vertex-face and `num_ee` edge-edge pairs (device arrays of id pairs) and waits
  /// for the answer (enqueue, then collect until complete). The hits stay on the device until
  /// download().
  template <class P>
  void run(const DeviceMeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1, const Pair* vf, std::size_t num_vf,
           const Pair* ee, std::size_t num_ee, const CcdParams<T>& params, cudaStream_t stream = nullptr) {
    run(mesh, x0, x1, PairList{vf, DeviceCount::known(num_vf)}, PairList{ee, DeviceCount::known(num_ee)}, params, stream);
  }
  template <class P>
  void run(const DeviceMeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1, PairList vf, PairList ee,
           const CcdParams<T>& params, cudaStream_t stream = nullptr) {
    do {
      enqueue(mesh, x0, x1, vf, ee, params, stream);
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
    } while (!collect());
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
  }

  /// Enqueues a run on `stream` without waiting (the two lists run on streams of their own,
  /// ordered after `stream`'s earlier work; `stream` waits for them). The inputs must stay valid
  /// until collect() returns true.
  template <class P>
  void enqueue(const DeviceMeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1, PairList vf, PairList ee,
               const CcdParams<T>& params, cudaStream_t stream = nullptr);

  /// What enqueue does first from the positions alone (FP32 first: the vertices rounded to float
  /// for the single-precision passes; nothing for other methods), enqueued ahead on `stream`, e.g.
  /// a second stream while the traversal runs. The next enqueue on the same x0, x1 (unchanged)
  /// skips it; its stream must wait for this one's work.
  template <class P>
  void enqueue_positions(const DeviceMeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1, cudaStream_t stream = nullptr);
  /// enqueue_positions of float positions f0, f1 widened to P, with the widening itself: x0, x1
  /// (num_vertices points each) filled with f0, f1 widened (exactly) by the same kernel. Why:
  /// float input then costs no launch more than double input (a launch a step's side work holds
  /// back the traversal's where the refit is short: docs/PIPELINE.md).
  template <class P>
  void enqueue_positions_widened(const DeviceMeshFeatures& mesh, const Vec3<float>* f0, const Vec3<float>* f1, Vec3<P>* x0,
                                 Vec3<P>* x1, cudaStream_t stream = nullptr);
  /// Forgets an enqueue_positions that no enqueue has used (the positions may have changed since).
  void drop_positions_ahead() { positions_ahead_[0] = positions_ahead_[1] = nullptr; }

  /// After `stream` (the last enqueue's) has been synchronized: reads the run's counters. Returns
  /// false when an output outgrew its buffer (now grown: enqueue the same run again); true when
  /// the run is complete, in which case the hits' sort by (first, second) is enqueued on `stream`.
  bool collect();

  NarrowPhase(const NarrowPhase&) = delete;
  NarrowPhase& operator=(const NarrowPhase&) = delete;
  /// Movable (its streams, events and buffers move with it); the moved-from one may only be
  /// destroyed or assigned to.
  NarrowPhase(NarrowPhase&&) = default;
  NarrowPhase& operator=(NarrowPhase&&) = default;

  /// The method that runs on the first pass's survivors: CertifiedCcd's fallback, or Method.
  using FullTest = typename lwsccd::detail::full_test_of<Method>::type;
  static constexpr bool kCertified = lwsccd::detail::certified_of<Method>::value;
  static constexpr bool kTwoPass = kCertified || lwsccd::detail::has_quick_reject<Method>::value;
  /// CertifiedCcd decides in single precision first: its filter runs in float before the double one.
  static constexpr bool kSingleFirst = lwsccd::detail::single_first_of<Method>::value;

  // Results of the last collected run:
  std::size_t num_vf_hits() const { return lists_[0].count; }
  std::size_t num_ee_hits() const { return lists_[1].count; }
  /// Pairs of the last run left for the full test by the first pass (all pairs for one-pass methods).
  std::size_t survivors() const { return lists_[0].num_full + lists_[1].num_full; }
  /// Queries of the last run that the one-thread attempt left to a warp search (InclusionCcd).
  std::size_t warp_searches() const { return lists_[0].warp_searches + lists_[1].warp_searches; }
  /// CertifiedCcd: refinements the first pass's filter could not decide, searched whole (all of
  /// them without the filter), in the last run (mode earliest: its last window).
  std::size_t whole_searches() const { return lists_[0].whole_searches + lists_[1].whole_searches; }
  /// CertifiedCcd: of those, searches in double that a thread handed on to a warp or a thread each
  /// (NarrowPhasePolicy::kHandOnDoubleSearches), in the last run.
  std::size_t handed_searches() const { return lists_[0].handed_searches + lists_[1].handed_searches; }
  /// Of those, the ones the last run searched a warp each (the rest: a thread each).
  std::size_t handed_searches_in_warps() const { return lists_[0].handed_in_warps + lists_[1].handed_in_warps; }
  /// CertifiedCcd FP32 first: of the whole searches, those of the contacts the single-precision
  /// filter sent whole that the double filter's kernel ran beside its own pairs, a thread each, in
  /// the last run (none where a list's whole searches all went to warps).
  std::size_t whole_searches_beside_filter() const { return lists_[0].whole_beside_filter + lists_[1].whole_beside_filter; }
  /// CertifiedCcd FP32 first: pairs coplanar over the whole step in float searched early, a warp
  /// each (NarrowPhasePolicy::kEarlyCoplanarSearches), in the last run (mode earliest: its last window).
  std::size_t early_searches() const { return lists_[0].early_searches + lists_[1].early_searches; }
  /// Whether a list's kernels (all but a sort by radix) are launched to overlap the kernel before them
  /// (NarrowPhasePolicy::kOverlapLaunches on a device of compute capability 9.0 or later),
  /// decided on the device of the first run: false before it.
  bool overlaps_launches() const { return overlap_launches_; }
  /// Plans the following runs as for a GPU whose FP32 runs `ratio` times faster than its FP64 (0:
  /// this device's own, cudaDevAttrSingleToDoublePrecisionPerfRatio): past
  /// kHandedWarpsMaxFp64Ratio the searches in double run a thread each. The answers do not change
  /// (PipelineParams::fp64_ratio: measuring on one GPU the path another takes). From
  /// kFloatPairLeavesMinFp64Ratio on, contacts' leaves are proved in pairs of floats first.
  void plan_for_fp64_ratio(int ratio) {
    if (ratio < 0) throw InputError("gpu::NarrowPhase::plan_for_fp64_ratio", "ratio", "must be >= 0 (0: the device's own)");
    planned_fp64_ratio_ = ratio;
  }
  /// The FP32:FP64 ratio the runs plan for (the device's until the first run, unless planned).
  int fp64_ratio() const { return planned_fp64_ratio_ > 0 ? planned_fp64_ratio_ : fp64_ratio_; }
  T earliest_toi() const { return earliest_; }
  std::size_t gave_up() const { return gave_up_; }
  /// Runs enqueued again because an output outgrew its buffer, since construction.
  std::size_t reruns() const { return reruns_; }
  /// How the last run answered each list's pairs (vertex-face, edge-edge).
  NarrowPhaseCounts counts(int list) const { return lists_[list].counts; }
  /// Copies the hits to the host, sorted by (first, second) like the CPU backend's.
  NarrowPhaseResult<T> download(cudaStream_t stream = nullptr) const;
  /// The same into `result`, whose lists' memory is reused (a caller that keeps one result pays
  /// no page faults for it), through page-locked chunks (HostStaging).
  template <class StagingPolicy = HostStagingPolicy>
  void download_into(NarrowPhaseResult<T>& result, cudaStream_t stream = nullptr) const;
  /// The hits of the last collected run on the device (sorted once `stream` reaches them).
  const FeatureHit<T>* vf_hits() const { return lists_[0].hits.data(); }
  const FeatureHit<T>* ee_hits() const { return lists_[1].hits.data(); }
  /// Of device_bytes(), the hits' lists and their sorting.
  std::size_t hit_bytes() const {
    std::size_t bytes = 0;
    for (const auto& l : lists_) bytes += l.hits.capacity_bytes() + l.sorter.device_bytes();
    return bytes;
  }
  std::size_t device_bytes() const {
    std::size_t bytes = control_.capacity_bytes() + single_.capacity_bytes();
    for (const auto& l : lists_)
      bytes += l.hits.capacity_bytes() + l.sorter.device_bytes() + l.survivors.capacity_bytes() + l.undecided.capacity_bytes() +
               l.counters.capacity_bytes() + l.deferred.capacity_bytes() + l.open.capacity_bytes() + l.intervals.capacity_bytes() +
               l.listed.capacity_bytes() + l.expanded.capacity_bytes() + l.deep.capacity_bytes() +
               l.double_kept.capacity_bytes() + l.single_intervals.capacity_bytes() + l.single_failed.capacity_bytes() +
               l.single_expanded.capacity_bytes() + l.single_deep.capacity_bytes() + l.handed.capacity_bytes() +
               l.early.capacity_bytes();
    return bytes;
  }

 private:
  // One list's buffers (vertex-face or edge-edge) and its stream.
  struct List {
    DeviceBuffer<FeatureHit<T>> hits;
    HitSorter<T> sorter;                         ///< the ordering by (first, second)
    DeviceBuffer<Pair> survivors;                ///< pairs the first pass keeps
    DeviceBuffer<FeatureHit<T>> undecided;       ///< CertifiedCcd: left to the fallback, with the time excluded before
    DeviceBuffer<unsigned> deferred, open;       ///< indices: refinements deferred, searches left to a warp
    DeviceBuffer<unsigned> handed;               ///< the deferred entries whose search in double a thread handed on
    DeviceBuffer<unsigned long long> intervals;  ///< CertifiedCcd's filter: intervals to test for inside (detail::filter_item)
    DeviceBuffer<unsigned long long> expanded;   ///< the filter's second round: intervals to split further (room: interval_room)
    DeviceBuffer<unsigned long long> deep;       ///< the second round's intervals to test for inside
    DeviceBuffer<unsigned> listed;               ///< the filter: a bit per pair, set once it is deferred
    DeviceBuffer<Pair> double_kept;              ///< FP32 first: screened pairs single precision leaves to the double filter
    DeviceBuffer<unsigned long long> single_intervals;  ///< the single-precision filter's intervals (detail::filter_item)
    DeviceBuffer<unsigned> single_failed;        ///< a bit per pair, set once it goes to the double filter
    DeviceBuffer<unsigned long long> single_expanded;  ///< its second round: intervals to split further (room: single_interval_room)
    DeviceBuffer<unsigned long long> single_deep;      ///< the second round's intervals to test for inside
    DeviceBuffer<Pair> early;                    ///< FP32 first: pairs coplanar over the whole step in float, searched early
    DeviceBuffer<unsigned long long> counters;   ///< detail::NarrowCounter words
    PinnedBuffer<unsigned long long> host_counters;
    std::size_t hit_room = 0, work_room = 0;     ///< room of hits; of survivors
    std::size_t refine_room = 0;                 ///< room of double_kept, deferred, undecided and open (CertifiedCcd)
    std::size_t interval_room = 0, deep_room = 0;  ///< room of the filter's intervals, of its second round's
    std::size_t single_interval_room = 0, single_deep_room = 0;  ///< room of the single-precision filter's intervals, of its second round's
    NarrowPhaseCounts counts;
    std::size_t count = 0, num_full = 0, warp_searches = 0, whole_searches = 0, handed_searches = 0, handed_in_warps = 0,
                whole_beside_filter = 0;
    std::size_t sent_whole = 0;  ///< the last run's: contacts the single-precision filter sent whole (plans the next)
    std::size_t early_room = 0;      ///< the last enqueue's room of `early` (0: no early searches)
    std::size_t early_searches = 0;  ///< the last run's early searches
    /// The last run's pairs coplanar over the whole step in float and not outside there (plans
    /// the next run's early searches: none where it had none); unknown before a first run.
    std::size_t early_candidates = kUnknownCandidates;
    std::size_t survivors_seen = 0;  ///< the last run's pairs its screen passed (plans the early searches)
    /// CertifiedCcd: the last run's undecided pairs, and those of them its fallback searched a warp
    /// each (plan the fallback's grids); unknown before a first run.
    std::size_t fallback_seen = kUnknownCandidates, open_seen = kUnknownCandidates;
    std::size_t sort_span = 0;                   ///< hits the next run sorts before its count reaches the host (0: none)
    CudaStream stream;
    CudaEvent done;
    CudaStream early_stream;               ///< the early searches' (refine_early_kernel)
    CudaEvent early_listed, early_done;    ///< its start after the single-precision filter's first kernel; its end
  };

  void ensure_streams();
  void join_lists(cudaStream_t stream);
  /// Whether the filter's second round runs (NarrowPhasePolicy::kFilterSecondRound).
  static constexpr bool second_round(CcdMode mode) { return Policy::kRefineFilter && Policy::kFilterSecondRound && mode == CcdMode::contacts; }
  // Whether the refinement's lists (refine_room) hold only what single precision leaves, their
  // room learned from its count: FP32 first with the filter (any other path refines every survivor).
  static constexpr bool refine_room_learned(CcdMode mode) { return kSingleFirst && Policy::kRefineFilter && mode != CcdMode::set; }
  // Room of a list's early searches: where the single-precision filter runs, the searches in
  // double run a warp each, and the list's last run had pairs for them, at most
  // kEarlyCoplanarSearches and a share of its survivors (kEarlyCoplanarPerSurvivors), or there
  // was no run yet; 0: none this run (such pairs take the double filter's route, and are counted
  // for the next run's plan).
  std::size_t early_search_room(const List& l, CcdMode mode) const {
    constexpr auto most = static_cast<std::size_t>(Policy::kEarlyCoplanarSearches);
    const bool planned =
        l.early_candidates == kUnknownCandidates ||
        (l.early_candidates > 0 && l.early_candidates <= most &&
         l.early_candidates * static_cast<std::size_t>(Policy::kEarlyCoplanarPerSurvivors) >= l.survivors_seen);
    if constexpr (kSingleFirst)
      if (Policy::kRefineFilter && mode != CcdMode::set && fp64_ratio() <= Policy::kHandedWarpsMaxFp64Ratio && planned) return most;
    return 0;
  }
  // The warps of a list's early searches: one for each of the last run's pairs (a warp takes the
  // next by a ticket), the room's worth before a first run.
  std::size_t early_search_warps(const List& l) const {
    return l.early_candidates == kUnknownCandidates ? l.early_room : std::max<std::size_t>(std::min(l.early_candidates, l.early_room), 1);
  }
  static constexpr std::size_t kUnknownCandidates = static_cast<std::size_t>(-1);
  // The items a fallback kernel's grid is sized for (grid_for), of a list whose room is `room`:
  // CertifiedCcd's, the last run's `seen` and a quarter more, at least a block of `per_block` items
  // per SM (a grid-stride loop takes any more); other methods', and before a first run, the room.
  std::size_t fallback_room(std::size_t room, std::size_t seen, int per_block) const {
    if (!kCertified || seen == kUnknownCandidates) return room;
    const std::size_t planned = std::max(seen + seen / 4, static_cast<std::size_t>(sms_) * static_cast<std::size_t>(per_block));
    return std::min(room, planned);
  }
  // Whether this run's single-precision filter runs on one thread a pair (kSingleFilterOneThreadPerSm):
  // planned from the last run's survivors, before a first run from their room (its count).
  bool single_filter_on_one_thread(const List& l) const {
    const std::size_t survivors = l.survivors_seen > 0 ? l.survivors_seen : l.work_room;
    return survivors < static_cast<std::size_t>(sms_) * static_cast<std::size_t>(Policy::kSingleFilterOneThreadPerSm);
  }
  // The single-precision filter's second round (CertifiedPolicy::kSingleSecondRound) runs wherever
  // its first does, as on the CPU (CertifiedFilter::decides_single).
  static constexpr bool single_second_round(CcdMode mode) {
    if constexpr (kSingleFirst) return Policy::kRefineFilter && mode != CcdMode::set && Method::policy_type::kSingleSecondRound;
    else return false;
  }
  template <class P>
  void count_survivors(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1, const PairList& vf, const PairList& ee,
                       const CcdParams<T>& params, cudaStream_t stream);
  // A list's launches in their order, recorded to be issued in turn with the other list's.
  using Launches = std::vector<std::function<void()>>;
  template <class P, bool kVertexFace>
  void enqueue_first_pass(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1, const PairList& in,
                          const CcdParams<T>& params, List& list, Launches& out);
  template <class P, bool kVertexFace>
  void enqueue_full_test(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1, const PairList& in,
                         const CcdParams<T>& params, const unsigned long long* limit, List& list, Launches& out);
  template <class Launch>
  static void record(Launches& out, List* list, Launch launch);
  /// One kernel of a list's first pass on `stream`, overlapping the one before it where
  /// overlap_launches_ (Policy::kOverlapLaunches on a device that can); the kernel waits for the
  /// earlier work on the device (detail::start_after_previous_grids).
  template <class... Params, class... Args>
  void chain(void (*kernel)(Params...), unsigned grid, unsigned block, cudaStream_t stream, Args&&... args) const {
    lwsccd::detail::launch_after_previous(overlap_launches_, kernel, grid, block, stream, std::forward<Args>(args)...);
  }
  void issue_in_turn(Launches (&launches)[2], int first);
  unsigned grid_for(std::size_t room, int block, int per_sm) const;

  std::size_t initial_capacity_;
  List lists_[2];  ///< vertex-face, edge-edge
  CudaEvent start_, joined_;
  cudaStream_t stream_ = nullptr;  ///< the last enqueue's
  std::size_t id_limit_ = 0;       ///< the last enqueue's mesh: its feature count (ids are below it)
  DeviceBuffer<unsigned long long> control_;  ///< detail::NarrowControl words
  DeviceBuffer<SingleVertex> single_;         ///< FP32 first: the vertices rounded to float, for the single-precision passes
  const void* positions_ahead_[2] = {nullptr, nullptr};  ///< the x0, x1 of enqueue_positions (until the next enqueue)
  std::size_t gave_up_ = 0, reruns_ = 0;
  T earliest_ = T(1);
  int sms_ = 1;
  int fp64_ratio_ = 2;  ///< the device's FP32 to FP64 throughput ratio
  bool overlap_launches_ = false;  ///< chain's launches overlap (set with the streams)
  int planned_fp64_ratio_ = 0;  ///< plan_for_fp64_ratio (0: the device's)
  std::size_t handed_warp_limit_ = 0;  ///< the last run's: at most this many handed searches went to warps
  /// The last run's: the contacts sent whole were searched beside the double filter where more
  /// than this many (none: the largest size_t).
  std::size_t whole_beside_filter_above_ = static_cast<std::size_t>(-1);
  bool earliest_only_ = false;  ///< the last run was in mode earliest: download() gives no pairs
  bool rooms_learned_ = false;  ///< a run has sized the lists (count_survivors on the first)
};

}  // namespace lwsccd::gpu

#include "lwsccd/narrow_phase/detail/narrow_phase_kernels.cuh"
