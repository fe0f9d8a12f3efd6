// lwsccd — definitions for narrow_phase.cuh: the kernels, a file per concern (narrow_lists.cuh,
// certified_kernels.cuh, inclusion_kernels.cuh, hit_sort.cuh), then NarrowPhase's host loops.
#pragma once

#include <cooperative_groups.h>
#include <cooperative_groups/reduce.h>
#include <cooperative_groups/scan.h>

#include <cstring>

#include "lwsccd/narrow_phase/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.cuh"

// In the order they were written in (each uses only what comes before it).
#include "lwsccd/narrow_phase/detail/narrow_lists.cuh"
#include "lwsccd/narrow_phase/detail/certified_kernels.cuh"
#include "lwsccd/narrow_phase/detail/inclusion_kernels.cuh"
#include "lwsccd/narrow_phase/detail/hit_sort.cuh"

namespace lwsccd::gpu {

template <class Method, class T, class Policy>
void NarrowPhase<Method, T, Policy>::ensure_streams() {
  if (start_) return;
  start_ = CudaEvent(cudaEventDisableTiming);
  joined_ = CudaEvent(cudaEventDisableTiming);
  int device = 0;
  LWSCCD_CUDA_CHECK(cudaGetDevice(&device));
  LWSCCD_CUDA_CHECK(cudaDeviceGetAttribute(&sms_, cudaDevAttrMultiProcessorCount, device));
  sms_ = std::max(1, sms_);
  LWSCCD_CUDA_CHECK(cudaDeviceGetAttribute(&fp64_ratio_, cudaDevAttrSingleToDoublePrecisionPerfRatio, device));
  overlap_launches_ = Policy::kOverlapLaunches && lwsccd::detail::device_overlaps_launches(device);
  control_.resize_discard(detail::kNarrowControlWords);
  for (auto& l : lists_) {
    l.host_counters = PinnedBuffer<unsigned long long>(detail::kNarrowCounters);
    l.counters.resize_discard(detail::kNarrowCounters);
    l.stream = CudaStream(cudaStreamNonBlocking);
    l.done = CudaEvent(cudaEventDisableTiming);
    l.early_stream = CudaStream(cudaStreamNonBlocking);
    l.early_listed = CudaEvent(cudaEventDisableTiming);
    l.early_done = CudaEvent(cudaEventDisableTiming);
  }
}

// Blocks of a grid-stride kernel over a list with room for `room` items (0: nothing to launch).
template <class Method, class T, class Policy>
unsigned NarrowPhase<Method, T, Policy>::grid_for(std::size_t room, int block, int per_sm) const {
  const std::size_t wanted = (room + static_cast<std::size_t>(block) - 1) / static_cast<std::size_t>(block);
  return static_cast<unsigned>(std::min<std::size_t>(wanted, static_cast<std::size_t>(sms_) * static_cast<std::size_t>(per_sm)));
}

template <class Method, class T, class Policy>
template <class P>
void NarrowPhase<Method, T, Policy>::enqueue_positions(const DeviceMeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                                       cudaStream_t stream) {
  ensure_streams();  // (sms_ for the grid)
  if constexpr (kSingleFirst) {
    const std::size_t vertices = static_cast<std::size_t>(mesh.num_vertices);
    single_.resize_discard(std::max<std::size_t>(vertices, 1));
    const unsigned blocks = grid_for(vertices, 256, 8);
    if (blocks > 0) {
      detail::single_vertices_kernel<P><<<blocks, 256, 0, stream>>>(x0, x1, vertices, single_.data());
      LWSCCD_CUDA_CHECK_LAUNCH();
    }
  }
  positions_ahead_[0] = x0;
  positions_ahead_[1] = x1;
}

template <class Method, class T, class Policy>
template <class P>
void NarrowPhase<Method, T, Policy>::enqueue_positions_widened(const DeviceMeshFeatures& mesh, const Vec3<float>* f0,
                                                               const Vec3<float>* f1, Vec3<P>* x0, Vec3<P>* x1,
                                                               cudaStream_t stream) {
  ensure_streams();  // (sms_ for the grid)
  const std::size_t vertices = static_cast<std::size_t>(mesh.num_vertices);
  SingleVertex* out = nullptr;
  if constexpr (kSingleFirst) {
    single_.resize_discard(std::max<std::size_t>(vertices, 1));
    out = single_.data();
  }
  const unsigned blocks = grid_for(vertices, 256, 8);
  if (blocks > 0) {
    detail::widened_vertices_kernel<P><<<blocks, 256, 0, stream>>>(f0, f1, vertices, x0, x1, out);
    LWSCCD_CUDA_CHECK_LAUNCH();
  }
  positions_ahead_[0] = x0;
  positions_ahead_[1] = x1;
}

// `stream` waits for both lists' work so far; the lists then wait for `stream`.
template <class Method, class T, class Policy>
void NarrowPhase<Method, T, Policy>::join_lists(cudaStream_t stream) {
  for (auto& l : lists_) {
    LWSCCD_CUDA_CHECK(cudaEventRecord(l.done, l.stream));
    LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(stream, l.done, 0));
  }
}

template <class Method, class T, class Policy>
template <class P>
void NarrowPhase<Method, T, Policy>::enqueue(const DeviceMeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1, PairList vf,
                                             PairList ee, const CcdParams<T>& params, cudaStream_t stream) {
  ensure_streams();
  stream_ = stream;
  id_limit_ = mesh.num_features();
  const MeshFeatures view = mesh.view();
  const PairList inputs[2] = {vf, ee};
  // The single-precision passes' positions, once for every window and the count below (unless
  // enqueue_positions made them).
  const bool ahead = positions_ahead_[0] == static_cast<const void*>(x0) && positions_ahead_[1] == static_cast<const void*>(x1);
  if (!ahead) enqueue_positions(mesh, x0, x1, stream);
  drop_positions_ahead();
  // A first run has no rooms learned yet: it counts the screen's survivors first (one more
  // screen and one synchronisation of `stream`), so that its lists fit and it runs once.
  if constexpr (kTwoPass && Policy::kCountFirstRun) {
    if (!rooms_learned_) {
      rooms_learned_ = true;
      count_survivors(view, x0, x1, vf, ee, params, stream);
    }
  }
  for (int k = 0; k < 2; ++k) {
    List& l = lists_[k];
    const std::size_t room = inputs[k].count.room;
    // Hits and survivors of a run are at most its input: room for the initial capacity, or for
    // the input where that is less (grown before the launch, so an input that grew since the last
    // run costs no rerun below it); larger only where an earlier run needed more.
    const std::size_t least = std::max<std::size_t>(std::min(initial_capacity_, room), 1);
    l.hit_room = std::max(l.hit_room, least);
    l.work_room = std::max(l.work_room, least);
    if (!kTwoPass) l.work_room = std::max(l.work_room, room);  // one-pass methods test the input itself
    l.hits.resize_discard(l.hit_room);
    if (kTwoPass) l.survivors.resize_discard(l.work_room);
    // The lists of the refinement in double: FP32 first with the filter, only what single
    // precision leaves reaches them, so their room is learned from that count (kKeptSlots);
    // otherwise they may get every survivor.
    l.refine_room = refine_room_learned(params.mode) ? std::max(l.refine_room, least) : l.work_room;
    l.early_room = early_search_room(l, params.mode);
    if (l.early_room > 0) l.early.resize_discard(l.early_room);
    if (kCertified) {
      l.undecided.resize_discard(l.refine_room);
      l.deferred.resize_discard(l.refine_room);
      // (Any list may hand searches on: planned for a GPU with little FP64, a thread each takes
      // every deferred list, however short.)
      if (Policy::kHandOnDoubleSearches) l.handed.resize_discard(l.refine_room);
      if (Policy::kRefineFilter && params.mode != CcdMode::set) {  // mode set does not run the filter
        // (FP32 first: the double filter's lists hold only what single precision leaves.)
        const std::size_t filter_percent = kSingleFirst ? Policy::kDoubleAfterSingleRoomPercent : Policy::kFilterRoomPercent;
        const std::size_t deep_percent = kSingleFirst ? Policy::kDoubleAfterSingleRoomPercent : Policy::kDeepRoomPercent;
        l.interval_room = std::max(l.interval_room, std::max<std::size_t>(l.work_room / 100 * filter_percent, 1));
        l.intervals.resize_discard(l.interval_room);
        l.listed.resize_discard((l.refine_room + 31) / 32);
        if (kSingleFirst) l.double_kept.resize_discard(l.refine_room);
        // (The four kernels' lists, whether this run takes them or one thread a pair; none for the
        // block form, whose lists stay in shared memory.)
        if (kSingleFirst && !Policy::kSingleFilterInBlocks) {
          l.single_interval_room =
              std::max(l.single_interval_room, std::max<std::size_t>(l.work_room / 100 * Policy::kFilterRoomPercent, 1));
          l.single_intervals.resize_discard(l.single_interval_room);
          l.single_failed.resize_discard((l.work_room + 31) / 32);
          if (single_second_round(params.mode)) {
            l.single_expanded.resize_discard(l.single_interval_room);
            l.single_deep_room = std::max(l.single_deep_room, std::max<std::size_t>(l.work_room / 100 * Policy::kDeepRoomPercent, 1));
            l.single_deep.resize_discard(l.single_deep_room);
          }
        }
        if (second_round(params.mode)) {
          l.expanded.resize_discard(l.interval_room);
          l.deep_room = std::max(l.deep_room, std::max<std::size_t>(l.work_room / 100 * deep_percent, 1));
          l.deep.resize_discard(l.deep_room);
        }
      }
    }
    if (lwsccd::detail::inclusion_search_of<FullTest>::value) l.open.resize_discard(kCertified ? l.refine_room : l.work_room);
  }
  // Mode earliest with CertifiedCcd: growing time windows (CertifiedPolicy::kEarliestFirst), each
  // screening and refining the pairs and running the fallback up to the window's end; a window
  // after one that holds a contact is skipped on the device (as the CPU backend stops there).
  // Other modes and methods: one window, the caller's.
  const bool windows = kCertified && params.mode == CcdMode::earliest;
  unsigned long long* control = control_.data();
  for (int round = 0;; ++round) {
    CcdParams<T> limited = params;
    if (fp64_ratio() >= Policy::kFloatPairLeavesMinFp64Ratio) limited.leaves_in_float_pairs = true;
    if constexpr (kCertified)
      if (windows) limited.time_limit = Method::earliest_window(round, params.time_limit);
    detail::window_begin_kernel<><<<1, 1, 0, stream>>>(control, lists_[0].counters.data(), lists_[1].counters.data(),
                                                     vf.count, ee.count, round == 0);
    LWSCCD_CUDA_CHECK_LAUNCH();
    LWSCCD_CUDA_CHECK(cudaEventRecord(start_, stream));
    for (auto& l : lists_) LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(l.stream, start_, 0));
    // The longer list's launches lead (its chain is usually the step's longest).
    const int first = ee.count.room > vf.count.room ? 1 : 0;
    Launches launches[2];
    enqueue_first_pass<P, true>(view, x0, x1, vf, limited, lists_[0], launches[0]);
    enqueue_first_pass<P, false>(view, x0, x1, ee, limited, lists_[1], launches[1]);
    issue_in_turn(launches, first);
    const unsigned long long* limit = nullptr;
    if (kCertified && params.mode == CcdMode::earliest) {
      // The fallback need not look past the best certified time of either list (as the CPU does).
      join_lists(stream);
      detail::fallback_limit_kernel<><<<1, 1, 0, stream>>>(control, lists_[0].counters.data(), lists_[1].counters.data(),
                                                          detail::time_bits(limited.time_limit));
      LWSCCD_CUDA_CHECK_LAUNCH();
      LWSCCD_CUDA_CHECK(cudaEventRecord(start_, stream));
      for (auto& l : lists_) LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(l.stream, start_, 0));
      limit = control + detail::kFallbackLimitBits;
    }
    enqueue_full_test<P, true>(view, x0, x1, vf, limited, limit, lists_[0], launches[0]);
    enqueue_full_test<P, false>(view, x0, x1, ee, limited, limit, lists_[1], launches[1]);
    issue_in_turn(launches, first);
    join_lists(stream);
    if (!windows || !(limited.time_limit < params.time_limit)) break;
  }
  earliest_only_ = params.mode == CcdMode::earliest;
  // The hits' sort, enqueued before their count reaches the host (the last run's count + a
  // quarter): a round trip between the run and its sort idled the GPU for its ~14 launches a list.
  if (!earliest_only_) {
    for (auto& l : lists_) {
      l.sorter.sort_ahead(l.hits, l.counters.data() + detail::kHits, l.sort_span, id_limit_, l.stream,
                          l.counters.data() + detail::kHitSortOverflow, overlap_launches_);
    }
    join_lists(stream);
  }
  for (auto& l : lists_)
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(l.host_counters.data(), l.counters.data(), detail::kNarrowCounters * sizeof(unsigned long long),
                                      cudaMemcpyDeviceToHost, stream));
}

// The first run's sizing: the screen alone over both lists (its survivors only counted: no room
// for them yet), then their rooms from the counts, and the hits' room from a share of them (most
// survivors are no contact: cloth-ball's 2.31 M survivors hold 114 K contacts). The screen then
// runs again in the run proper. Mode earliest counts over the whole time limit, which holds every
// window's survivors.
template <class Method, class T, class Policy>
template <class P>
void NarrowPhase<Method, T, Policy>::count_survivors(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                                     const PairList& vf, const PairList& ee, const CcdParams<T>& params,
                                                     cudaStream_t stream) {
  if constexpr (kTwoPass) {
    unsigned long long* control = control_.data();
    detail::window_begin_kernel<><<<1, 1, 0, stream>>>(control, lists_[0].counters.data(), lists_[1].counters.data(), vf.count,
                                                     ee.count, true);
    LWSCCD_CUDA_CHECK_LAUNCH();
    LWSCCD_CUDA_CHECK(cudaEventRecord(start_, stream));
    const PairList inputs[2] = {vf, ee};
    for (int k = 0; k < 2; ++k) {
      List& l = lists_[k];
      LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(l.stream, start_, 0));
      const unsigned blocks = grid_for(inputs[k].count.room, Policy::kBlock, Policy::kGridBlocksPerSm);
      if (blocks == 0) continue;
      if (k == 0)
        detail::screen_kernel<Method, true, Policy::kBlock, T, P><<<blocks, Policy::kBlock, 0, l.stream>>>(
            mesh, x0, x1, single_.data(), inputs[k], params, control, nullptr, 0, l.counters.data());
      else
        detail::screen_kernel<Method, false, Policy::kBlock, T, P><<<blocks, Policy::kBlock, 0, l.stream>>>(
            mesh, x0, x1, single_.data(), inputs[k], params, control, nullptr, 0, l.counters.data());
      LWSCCD_CUDA_CHECK_LAUNCH();
    }
    join_lists(stream);
    for (auto& l : lists_)
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(l.host_counters.data(), l.counters.data(), detail::kNarrowCounters * sizeof(unsigned long long),
                                        cudaMemcpyDeviceToHost, stream));
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
    for (auto& l : lists_) {
      const unsigned long long survivors = l.host_counters.data()[detail::kSurvivors];
      l.work_room = std::max(l.work_room, detail::grown_room(survivors));
      l.hit_room = std::max(l.hit_room, detail::grown_room(survivors / Policy::kFirstRunHitsPerSurvivors));
      l.refine_room = std::max(l.refine_room, detail::grown_room(survivors / Policy::kFirstRunRefinePerSurvivors));
    }
  }
}

// Pass 1 on the list's stream: two-pass methods' cheap first step on every pair (survivors
// appended); CertifiedCcd's refinement of the survivors (hits and undecided queries appended).
// Its launches are recorded in `out` in their order, a kernel (with the memset before it) or the
// early searches' fork each, for enqueue() to issue in turn with the other list's.
template <class Method, class T, class Policy>
template <class P, bool kVertexFace>
void NarrowPhase<Method, T, Policy>::enqueue_first_pass(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                                        const PairList& in, const CcdParams<T>& params, List& list,
                                                        Launches& out) {
  List* const lp = &list;
  if constexpr (kTwoPass) {
    const unsigned blocks = grid_for(in.count.room, Policy::kBlock, Policy::kGridBlocksPerSm);
    if (blocks == 0) return;
    record(out, lp, [=](List& l) {
      chain(detail::screen_kernel<Method, kVertexFace, Policy::kBlock, T, P>, blocks, Policy::kBlock, l.stream,
          mesh, x0, x1, single_.data(), in, params, control_.data(), l.survivors.data(), l.work_room, l.counters.data());
    });
  }
  if constexpr (kCertified) {
    const List& l = list;
    const std::size_t room = std::min(l.work_room, in.count.room);
    // Mode set tries hits on the way down (from level 0), which the filter leaves to the whole
    // search: there the levels-to-kRefineDeferLevel kernel decides more at once.
    // The pairs the double refinement takes: the survivors, or (FP32 first) those the
    // single-precision filter leaves.
    const Pair* kept = l.survivors.data();
    int kept_counter = detail::kSurvivors;
    // The deferred pairs: a warp each when they are few (the long searches' latency is the
    // list's), else a thread each; each kernel returns at once where the other one's case holds.
    // A warp each only on a GPU with FP64 to spare (kHandedWarpsMaxFp64Ratio): every lane of a
    // warp's search repeats its FP64 instructions.
    const std::size_t warp_below =
        fp64_ratio() <= Policy::kHandedWarpsMaxFp64Ratio ? static_cast<std::size_t>(Policy::kRefineWarpBelow) : 0;
    // kHandOnDoubleSearches: the thread kernels list the searches in double they hand on in `handed`
    // (room for every deferred entry, allocated with the list).
    constexpr bool kHand = Policy::kHandOnDoubleSearches;
    unsigned* handed = kHand ? list.handed.data() : nullptr;
    // FP32 first: the contacts the single-precision filter sends whole are searched by the double
    // filter's kernel, beside its pairs (filter_kernel), where a thread each takes them. Planned
    // from the list's last run (whether it sent more than the warps take); the device decides
    // which entries that kernel searched and refine_deferred_kernel skips, so a plan that misses
    // costs only time. A list whose whole searches go to warps keeps the filter's kernel alone.
    bool whole_in_filter = false;
    whole_beside_filter_above_ = static_cast<std::size_t>(-1);
    // FP32 first: the pairs coplanar over the whole step in float searched early (refine_early_kernel;
    // early_search_room says where).
    const bool early = l.early_room > 0;
    if (Policy::kRefineFilter && params.mode != CcdMode::set) {
      if constexpr (kSingleFirst) {
        const unsigned single_blocks = grid_for(l.single_interval_room, Policy::kBlock, Policy::kGridBlocksPerSm);
        const bool one_thread = single_filter_on_one_thread(l);
        const bool in_blocks = !one_thread && Policy::kSingleFilterInBlocks;
        const bool listed = !one_thread && !in_blocks;  // the four kernels
        const bool single_deeper = listed && single_second_round(params.mode);
        record(out, lp, [=](List& l) {
          if (in_blocks) {
            if constexpr (Policy::kSingleFilterInBlocks)  // (not instantiated otherwise: any kBlock then)
              chain(detail::single_block_filter_kernel<Method, kVertexFace, Policy::kBlock, Policy::kSingleBlockMinBlocksPerSm,
                                                         Policy::kSingleBlockPiecesPerPair, T, Policy::kSingleInsideWhole>,
                    grid_for(room, Policy::kBlock, Policy::kGridBlocksPerSm), Policy::kBlock, l.stream,
                      mesh, single_.data(), l.survivors.data(), l.work_room, params, control_.data(), l.counters.data(),
                      l.double_kept.data(), l.refine_room, l.deferred.data(), l.early.data(), l.early_room);
          } else if (one_thread)
            chain(detail::single_route_kernel<Method, kVertexFace, T, Policy::kSingleInsideWhole>,
                  grid_for(room, Policy::kBlock, Policy::kGridBlocksPerSm), Policy::kBlock, l.stream,
                    mesh, single_.data(), l.survivors.data(), l.work_room, params, control_.data(), l.counters.data(),
                    l.double_kept.data(), l.refine_room, l.deferred.data(), l.early.data(), l.early_room);
          else
            chain(detail::single_filter_kernel<Method, kVertexFace, T>,
                  grid_for(room, Policy::kBlock, Policy::kGridBlocksPerSm), Policy::kBlock, l.stream,
                    mesh, single_.data(), l.survivors.data(), l.work_room, params, control_.data(), l.counters.data(),
                    l.single_intervals.data(), l.single_interval_room, l.double_kept.data(), l.refine_room, l.early.data(),
                    l.early_room);
        });
        if (early) {  // the early searches, beside the rest of the chain (joined before the undecided are settled)
          record(out, lp, [=](List& l) {
            LWSCCD_CUDA_CHECK(cudaEventRecord(l.early_listed, l.stream));
            LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(l.early_stream, l.early_listed, 0));
            // (A warp for each of the last run's searches: a block more than needed holds SM room
            // the chain's kernels wait for. More searches this run wait for a warp's ticket.)
            detail::refine_early_kernel<Method, kVertexFace, T, P><<<grid_for(early_search_warps(l) * 32, Policy::kBlock, 1), Policy::kBlock,
                                                                     0, l.early_stream>>>(
                    mesh, x0, x1, l.early.data(), l.early_room, params, control_.data(), l.counters.data(), l.hits.data(), l.hit_room,
                    l.undecided.data());
            LWSCCD_CUDA_CHECK_LAUNCH();
            LWSCCD_CUDA_CHECK(cudaEventRecord(l.early_done, l.early_stream));
          });
        }
        if (listed) {
          record(out, lp, [=](List& l) {
            LWSCCD_CUDA_CHECK(cudaMemsetAsync(l.single_failed.data(), 0, l.single_failed.size() * sizeof(unsigned), l.stream));
            chain(detail::single_inside_kernel<Method, kVertexFace, T, Policy::kSingleInsideWhole>, single_blocks, Policy::kBlock, l.stream,
                mesh, single_.data(), l.survivors.data(), l.refine_room, control_.data(), l.counters.data(), detail::kSingleIntervals,
                l.single_intervals.data(), l.single_interval_room, l.single_failed.data(), l.double_kept.data(), l.deferred.data(),
                single_deeper ? l.single_expanded.data() : nullptr);
          });
        }
        if (single_deeper) {
          record(out, lp, [=](List& l) {
            chain(detail::single_expand_kernel<Method, kVertexFace, T>, single_blocks, Policy::kBlock, l.stream,
                mesh, single_.data(), l.survivors.data(), params, control_.data(), l.counters.data(), l.single_expanded.data(),
                l.single_deep.data(), l.single_deep_room, l.single_failed.data(), l.double_kept.data(), l.refine_room);
          });
          record(out, lp, [=](List& l) {
            chain(detail::single_inside_kernel<Method, kVertexFace, T, Policy::kSingleInsideWhole>,
                  grid_for(l.single_deep_room, Policy::kBlock, Policy::kGridBlocksPerSm), Policy::kBlock, l.stream,
                    mesh, single_.data(), l.survivors.data(), l.refine_room, control_.data(), l.counters.data(),
                    detail::kSingleDeepIntervals, l.single_deep.data(), l.single_deep_room, l.single_failed.data(),
                    l.double_kept.data(), l.deferred.data(), nullptr);
          });
        }
        kept = l.double_kept.data();
        kept_counter = detail::kDoubleKept;
        whole_in_filter = Policy::kWholeBesideFilter && list.sent_whole > warp_below;
        if (whole_in_filter) whole_beside_filter_above_ = warp_below;
      }
      const unsigned interval_blocks = grid_for(l.interval_room, Policy::kBlock, Policy::kGridBlocksPerSm);
      const bool deeper = second_round(params.mode);
      record(out, lp, [=](List& l) {
        const auto launch = [&](auto kernel) {
          chain(kernel, grid_for(room, Policy::kBlock, Policy::kGridBlocksPerSm), Policy::kBlock, l.stream,
              mesh, x0, x1, kept, kept_counter, l.refine_room, params, control_.data(), l.counters.data(), l.intervals.data(),
              l.interval_room, l.hits.data(), l.hit_room, l.undecided.data(), l.deferred.data(), warp_below, handed,
              l.listed.data(), l.listed.size());
        };
        if (whole_in_filter) launch(detail::filter_kernel<Method, kVertexFace, true, kHand, T, P>);
        else launch(detail::filter_kernel<Method, kVertexFace, false, kHand, T, P>);
      });
      record(out, lp, [=](List& l) {
        chain(detail::filter_inside_kernel<Method, kVertexFace, T, P>, interval_blocks, Policy::kBlock, l.stream,
            mesh, x0, x1, kept, params, control_.data(), l.counters.data(), detail::kIntervals, l.intervals.data(),
            l.interval_room, l.listed.data(), l.deferred.data(), deeper ? l.expanded.data() : nullptr);
      });
      if (deeper) {
        record(out, lp, [=](List& l) {
          chain(detail::filter_expand_kernel<Method, kVertexFace, T, P>, interval_blocks, Policy::kBlock, l.stream,
              mesh, x0, x1, kept, params, control_.data(), l.counters.data(), l.expanded.data(), l.deep.data(),
              l.deep_room, l.listed.data(), l.deferred.data());
        });
        record(out, lp, [=](List& l) {
          chain(detail::filter_inside_kernel<Method, kVertexFace, T, P>,
                grid_for(l.deep_room, Policy::kBlock, Policy::kGridBlocksPerSm), Policy::kBlock, l.stream,
                  mesh, x0, x1, kept, params, control_.data(), l.counters.data(), detail::kDeepIntervals,
                  l.deep.data(), l.deep_room, l.listed.data(), l.deferred.data(), nullptr);
        });
      }
    } else {
      record(out, lp, [=](List& l) {
        chain(detail::refine_kernel<Method, kVertexFace, Policy::kRefineDeferLevel, Policy::kBlock, Policy::kRefineMinBlocks, T, P>,
              grid_for(room, Policy::kBlock, Policy::kGridBlocksPerSm), Policy::kBlock, l.stream,
                mesh, x0, x1, single_.data(), l.survivors.data(), l.work_room, params, control_.data(), l.counters.data(), l.hits.data(),
                l.hit_room, l.undecided.data(), l.deferred.data());
      });
    }
    record(out, lp, [=](List& l) {
      chain(detail::refine_deferred_kernel<Method, kVertexFace, kHand, T, P>, grid_for(room, Policy::kBlock, 8), Policy::kBlock, l.stream,
          mesh, x0, x1, kept, l.refine_room, l.deferred.data(), params, control_.data(), l.counters.data(), l.hits.data(),
          l.hit_room, l.undecided.data(), warp_below, handed, whole_in_filter);
    });
    if (handed) {  // a warp or a thread each, by their number (one of the two kernels returns at once)
      const std::size_t warp_limit = fp64_ratio() <= Policy::kHandedWarpsMaxFp64Ratio
                                         ? static_cast<std::size_t>(sms_) * static_cast<std::size_t>(Policy::kHandedWarpsPerSm)
                                         : 0;
      handed_warp_limit_ = warp_limit;
      auto launch_handed = [=, &out](auto kernel) {
        record(out, lp, [=](List& l) {
          chain(kernel, grid_for(l.handed.size() * 32, Policy::kBlock, 8), Policy::kBlock, l.stream,  // (a warp per entry at most)
              mesh, x0, x1, kept, l.deferred.data(), handed, params, control_.data(), l.counters.data(), l.hits.data(), l.hit_room,
              l.undecided.data(), warp_below, warp_limit);
        });
      };
      launch_handed(detail::refine_handed_kernel<Method, kVertexFace, true, T, P>);
      launch_handed(detail::refine_handed_kernel<Method, kVertexFace, false, T, P>);
    }
    if (warp_below > 0) {
      const std::size_t warp_room = std::min(room, warp_below);
      record(out, lp, [=](List& l) {
        chain(detail::refine_deferred_warp_kernel<Method, kVertexFace, T, P>,
              static_cast<unsigned>((warp_room * 32 + Policy::kBlock - 1) / Policy::kBlock), Policy::kBlock, l.stream,
                mesh, x0, x1, kept, l.refine_room, l.deferred.data(), params, control_.data(), l.counters.data(), l.hits.data(),
                l.hit_room, l.undecided.data(), warp_below);
      });
    }
    // Before mode earliest's fallback limit: a settled hit lowers it as the CPU's certified hits do.
    record(out, lp, [=](List& l) {
      if (early) LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(l.stream, l.early_done, 0));
      chain(detail::settle_undecided_kernel<Method, kVertexFace, T, P>, grid_for(room, Policy::kBlock, 1), Policy::kBlock, l.stream,
          mesh, x0, x1, params, control_.data(), l.counters.data(), l.hits.data(), l.hit_room, l.undecided.data(), l.refine_room);
    });
  }
}

// The full test on the list's stream, of CertifiedCcd's undecided queries, of the first pass's
// survivors, or (one-pass methods) of the input: hits appended after the list's earlier ones.
// Its launches are recorded in `out`, as the first pass's.
template <class Method, class T, class Policy>
template <class P, bool kVertexFace>
void NarrowPhase<Method, T, Policy>::enqueue_full_test(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1,
                                                       const PairList& in, const CcdParams<T>& params,
                                                       const unsigned long long* limit, List& list, Launches& out) {
  List* const lp = &list;
  auto launch = [&](const auto* items, DeviceCount count) {
    using Item = std::remove_cv_t<std::remove_pointer_t<std::decay_t<decltype(items)>>>;
    count.room = std::min(count.room, in.count.room);
    if (count.room == 0) return;
    if constexpr (lwsccd::detail::inclusion_search_of<FullTest>::value) {
      // A thread per query for a few rounds, then a warp per query still open. CertifiedCcd's
      // undecided pairs are few (none on most steps): grids for the last run's numbers, not for
      // the list's room (a grid of the room's thousands of blocks with nothing to do took ~4 us).
      const std::size_t thread_room = fallback_room(count.room, list.fallback_seen, Policy::kBlock);
      const std::size_t warp_room = fallback_room(count.room, list.open_seen, Policy::kSearchWarpsPerBlock);
      record(out, lp, [=](List& l) {
        chain(detail::inclusion_thread_kernel<FullTest, kVertexFace, T, P, Policy::kThreadRounds, Policy::kThreadBoxes, Item>,
              grid_for(thread_room, Policy::kBlock, Policy::kGridBlocksPerSm), Policy::kBlock, l.stream, mesh, x0, x1, items, count,
              params, control_.data(), limit, l.counters.data(), l.hits.data(), l.hit_room, l.open.data(),
              static_cast<std::size_t>(Policy::kWarpSearchDirect));
      });
      record(out, lp, [=](List& l) {
        constexpr int kWarps = Policy::kSearchWarpsPerBlock;
        chain(detail::inclusion_warp_kernel<FullTest, kVertexFace, T, P, kWarps, Item>,
              grid_for(warp_room, kWarps, Policy::kGridBlocksPerSm), 32 * kWarps, l.stream, mesh, x0, x1, items,
              static_cast<const unsigned*>(l.open.data()), params, control_.data(), limit, l.counters.data(), l.hits.data(),
              l.hit_room);
      });
    } else {
      record(out, lp, [=](List& l) {
        chain(detail::ccd_pairs_kernel<FullTest, kVertexFace, T, P, Item>,
              grid_for(count.room, Policy::kBlock, Policy::kGridBlocksPerSm), Policy::kBlock, l.stream, mesh, x0, x1, items, count,
              params, control_.data(), limit, l.counters.data(), l.hits.data(), l.hit_room);
      });
    }
  };
  const List& l = list;
  const unsigned long long* counters = l.counters.data();
  if constexpr (kCertified) launch(l.undecided.data(), DeviceCount{counters + detail::kUndecided, DeviceCount::Part::whole, l.refine_room});
  else if constexpr (kTwoPass) launch(l.survivors.data(), DeviceCount{counters + detail::kSurvivors, DeviceCount::Part::whole, l.work_room});
  else launch(in.pairs, in.count);
}

// Records `launch` (a kernel of `list` with the memset before it, or the early searches' fork) in
// `out`: run later, then checked.
template <class Method, class T, class Policy>
template <class Launch>
void NarrowPhase<Method, T, Policy>::record(Launches& out, List* list, Launch launch) {
  out.push_back([list, launch] {
    launch(*list);
    LWSCCD_CUDA_CHECK_LAUNCH();
  });
}

// Issues two lists' recorded launches in turn, one of each (`first` leads): each list's stay in
// their order on its stream, and neither stream waits for the host to launch the other list's
// whole chain (cloth-funnel, H200: the edge-edge list's first kernel started ~125 us after the
// vertex-face one's, the host launching all of those in between).
template <class Method, class T, class Policy>
void NarrowPhase<Method, T, Policy>::issue_in_turn(Launches (&launches)[2], int first) {
  const std::size_t n = std::max(launches[0].size(), launches[1].size());
  for (std::size_t i = 0; i < n; ++i)
    for (int k : {first, 1 - first})
      if (i < launches[k].size()) launches[k][i]();
  launches[0].clear();
  launches[1].clear();
}

template <class Method, class T, class Policy>
bool NarrowPhase<Method, T, Policy>::collect() {
  bool complete = true;
  for (auto& l : lists_) {
    const unsigned long long* c = l.host_counters.data();
    const unsigned long long kept = std::max(c[detail::kSurvivors], c[detail::kSurvivorsPeak]);
    unsigned long long hits = c[detail::kHits];
    if (kTwoPass && kept > l.work_room) {
      // The run tested only the survivors that fitted: as many hits again per survivor for the
      // rest, so that their room does not cost a second rerun (cloth-ball's first step did).
      hits = std::max(hits, static_cast<unsigned long long>(static_cast<double>(hits) * static_cast<double>(kept) /
                                                            static_cast<double>(l.work_room)));
      l.work_room = detail::grown_room(kept);
      complete = false;
    }
    if (hits > l.hit_room) {
      l.hit_room = detail::grown_room(hits);
      complete = false;
    }
    // FP32 first: pairs single precision left that found no slot in the double filter's list.
    const unsigned long long slots = std::max(c[detail::kKeptSlots], c[detail::kKeptSlotsPeak]);
    if (slots > l.refine_room) {
      l.refine_room = detail::grown_room(slots);
      complete = false;
    }
    // The filter's intervals that did not fit went to the whole search (same answers): more room
    // for the next run, no rerun.
    if (c[detail::kIntervals] > l.interval_room) l.interval_room = detail::grown_room(c[detail::kIntervals]);
    if (c[detail::kDeepIntervals] > l.deep_room) l.deep_room = detail::grown_room(c[detail::kDeepIntervals]);
    if (c[detail::kSingleIntervals] > l.single_interval_room) l.single_interval_room = detail::grown_room(c[detail::kSingleIntervals]);
    if (c[detail::kSingleDeepIntervals] > l.single_deep_room) l.single_deep_room = detail::grown_room(c[detail::kSingleDeepIntervals]);
  }
  if (!complete) {
    ++reruns_;
    return false;
  }
  gave_up_ = 0;
  earliest_ = T(1);
  for (auto& l : lists_) {
    const unsigned long long* c = l.host_counters.data();
    const auto pairs = static_cast<std::size_t>(c[detail::kPairs]);
    l.count = static_cast<std::size_t>(c[detail::kHits]);
    l.num_full = static_cast<std::size_t>(kCertified ? c[detail::kUndecided] - c[detail::kSettled] : kTwoPass ? c[detail::kSurvivors] : pairs);
    l.warp_searches = static_cast<std::size_t>(c[detail::kOpen]);
    l.whole_searches = static_cast<std::size_t>(c[detail::kDeferred]);
    l.handed_searches = static_cast<std::size_t>(c[detail::kHandedToWarps]);
    // (As the two kernels decide on the device: a warp each up to the limit.)
    l.handed_in_warps = l.handed_searches <= handed_warp_limit_ ? l.handed_searches : 0;
    // (As filter_kernel decides on the device: whole_searched_early.)
    l.sent_whole = kCertified ? static_cast<std::size_t>(c[detail::kSingleWhole]) : 0;
    l.whole_beside_filter = l.sent_whole > whole_beside_filter_above_ ? l.sent_whole : 0;
    l.early_searches = kCertified ? static_cast<std::size_t>(std::min<unsigned long long>(c[detail::kEarlySearches], l.early_room)) : 0;
    if (kCertified) {
      l.early_candidates = static_cast<std::size_t>(c[detail::kEarlyCandidates]);
      l.survivors_seen = static_cast<std::size_t>(c[detail::kSurvivors]);
      l.fallback_seen = static_cast<std::size_t>(c[detail::kUndecided]);
      l.open_seen = static_cast<std::size_t>(c[detail::kOpen]);
    }
    l.counts = {};
    l.counts.pairs = pairs;
    l.counts.screened = kCertified ? static_cast<std::size_t>(c[detail::kSurvivors] + c[detail::kSeparated]) : 0;
    // Single precision's misses: at once (screen, filter without intervals), and every pair whose
    // listed intervals were all outside in float.
    l.counts.single_misses =
        kCertified ? static_cast<std::size_t>(c[detail::kSingleMisses] + c[detail::kSeparated] + c[detail::kSingleListed] -
                                              c[detail::kSingleFailed] + c[detail::kSingleSearchMisses])
                   : 0;
    l.counts.single_descents = kCertified ? static_cast<std::size_t>(c[detail::kSingleDescents]) : 0;
    l.counts.float_pair_leaves = kCertified ? static_cast<std::size_t>(c[detail::kFloatPairLeaves]) : 0;
    l.counts.certified_hits = static_cast<std::size_t>(c[detail::kCertifiedHits]);
    // As the CPU backend counts (NarrowPhaseCounts): a method without the certified path answers
    // every pair by its own test, its quick rejections included, so every pair is a fallback.
    l.counts.fallbacks = kCertified ? l.num_full : pairs;
    l.counts.certified_misses = kCertified ? pairs - l.counts.certified_hits - l.num_full : 0;
    gave_up_ += static_cast<std::size_t>(c[detail::kGaveUp]);
    const T list_min = static_cast<T>(detail::time_of_bits(c[detail::kEarliestBits]));
    earliest_ = list_min < earliest_ ? list_min : earliest_;
  }
  // The hits in (first, second) order, on the device: they were appended in any order. The two
  // lists sort at once, each on its stream; the run's stream waits for both.
  // A sort enqueued with the run (sort_ahead, from the last run's count) is used where it covered
  // the count; otherwise the hits are sorted now.
  if (!earliest_only_) {
    for (auto& l : lists_) {
      if (!l.sorter.take_ahead(l.hits, l.count, l.host_counters.data()[detail::kHitSortOverflow]))
        l.sorter.sort(l.hits, l.count, id_limit_, l.stream);
      l.sort_span = HitSorter<T>::span_after(l.count);
    }
    join_lists(stream_);
  } else {
    for (auto& l : lists_) l.sorter.take_ahead(l.hits, 0);
  }
  return true;
}

template <class T>
void HitSorter<T>::radix_sort(const FeatureHit<T>* hits, std::size_t n, int id_bits, cudaStream_t stream,
                              const unsigned long long* device_count) {
  keys_.resize_discard(n);
  sorted_keys_.resize_discard(n);
  detail::hit_keys_kernel<<<static_cast<unsigned>((n + 255) / 256), 256, 0, stream>>>(hits, n, id_bits, keys_.data(), device_count);
  LWSCCD_CUDA_CHECK_LAUNCH();
  std::size_t bytes = 0;
  LWSCCD_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, bytes, keys_.data(), sorted_keys_.data(), hits, sorted_.data(),
                                                    static_cast<std::int64_t>(n), 0, 2 * id_bits, stream));
  scratch_.resize_discard(std::max({bytes, scratch_.size(), std::size_t(1)}));
  LWSCCD_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(scratch_.data(), bytes, keys_.data(), sorted_keys_.data(), hits, sorted_.data(),
                                                    static_cast<std::int64_t>(n), 0, 2 * id_bits, stream));
}

template <class T>
void HitSorter<T>::sort(DeviceBuffer<FeatureHit<T>>& hits, std::size_t n, std::size_t id_limit, cudaStream_t stream) {
  if (n < 2) return;
  sorted_.resize_discard(std::max(n, hits.size()));
  // Only the bits the ids use are sorted: horse-gallop's 50 K features take 32 of the 64, which
  // halves the radix passes (a sort of a few dozen hits took ~24 us per list on an H100).
  const int id_bits = detail::id_bits_below(id_limit);
  if (n <= static_cast<std::size_t>(detail::kSmallHitSort)) {
    detail::small_hit_sort_kernel<T, detail::kSmallHitSort>
        <<<1, detail::kSmallHitSort, 0, stream>>>(hits.data(), static_cast<int>(n), id_bits, sorted_.data());
    LWSCCD_CUDA_CHECK_LAUNCH();
  } else {
    radix_sort(hits.data(), n, id_bits, stream, nullptr);
  }
  std::swap(hits, sorted_);  // (only the handles: the sort wrote `sorted_`, which is now `hits`)
}

template <class T>
void HitSorter<T>::bucket_sort(const FeatureHit<T>* hits, const unsigned long long* device_count, std::size_t span,
                               std::size_t id_limit, int id_bits, cudaStream_t stream, unsigned long long* overflow,
                               bool overlap) {
  // Buckets: a power of two, at least twice the span (a couple of hits a bucket where the first
  // ids spread), at most one first id each; memory and scan in proportion to the span, not to
  // the mesh.
  int bucket_bits = 1;
  while (bucket_bits < id_bits && (std::size_t(1) << bucket_bits) < 2 * span) ++bucket_bits;
  const int shift = id_bits - bucket_bits;
  const std::size_t buckets = ((std::max<std::size_t>(id_limit, 1) - 1) >> shift) + 1;
  if (bucket_count_.size() < buckets + 1) {
    bucket_count_.resize_discard(buckets + 1);
    LWSCCD_CUDA_CHECK(cudaMemsetAsync(bucket_count_.data(), 0, bucket_count_.size() * sizeof(unsigned), stream));
  }
  // The scan's tiles: their sums (a word of another generation is stale; cleared when they grow,
  // as a new buffer's words could hold anything) and the ticket (zero between sorts).
  const std::size_t tiles = (buckets + 1 + detail::kBucketScanTile - 1) / detail::kBucketScanTile;
  if (tile_sums_.size() < tiles) {
    tile_sums_.resize_discard(tiles);
    LWSCCD_CUDA_CHECK(cudaMemsetAsync(tile_sums_.data(), 0, tile_sums_.size() * sizeof(unsigned long long), stream));
  }
  if (tile_ticket_.size() == 0) {
    tile_ticket_.resize_discard(1);
    LWSCCD_CUDA_CHECK(cudaMemsetAsync(tile_ticket_.data(), 0, sizeof(unsigned), stream));
  }
  if (++scan_generation_ == 0) {  // (wrapped: every old word could match again)
    LWSCCD_CUDA_CHECK(cudaMemsetAsync(tile_sums_.data(), 0, tile_sums_.size() * sizeof(unsigned long long), stream));
    scan_generation_ = 1;
  }
  bucket_start_.resize_discard(buckets + 1);
  keys_.resize_discard(span);
  order_.resize_discard(span);
  const unsigned blocks = static_cast<unsigned>((span + 255) / 256);
  using lwsccd::detail::launch_after_previous;
  launch_after_previous(overlap, detail::bucket_count_kernel<T>, blocks, 256, stream, hits, span, device_count, shift,
                        bucket_count_.data(), overflow);
  // (bucket_count_[buckets] is zero: the scan's last word is the count.)
  launch_after_previous(overlap, detail::bucket_scan_kernel<>, static_cast<unsigned>(tiles),
                        static_cast<unsigned>(detail::kBucketScanThreads), stream, static_cast<const unsigned*>(bucket_count_.data()),
                        buckets + 1, bucket_start_.data(), tile_sums_.data(), tile_ticket_.data(), scan_generation_);
  launch_after_previous(overlap, detail::bucket_place_kernel<T>, blocks, 256, stream, hits, span, device_count, shift, id_bits,
                        bucket_count_.data(), static_cast<const unsigned*>(bucket_start_.data()), keys_.data(), order_.data(),
                        tile_ticket_.data());
  launch_after_previous(overlap, detail::bucket_rank_kernel<T>, blocks, 256, stream, hits, span, device_count, shift, id_bits,
                        static_cast<const unsigned*>(bucket_start_.data()), static_cast<const unsigned long long*>(keys_.data()),
                        static_cast<const unsigned*>(order_.data()), sorted_.data());
}

template <class T>
void HitSorter<T>::sort_ahead(const DeviceBuffer<FeatureHit<T>>& hits, const unsigned long long* device_count, std::size_t span,
                              std::size_t id_limit, cudaStream_t stream, unsigned long long* overflow, bool overlap_launches) {
  ahead_ = 0;
  ahead_bucketed_ = false;
  span = std::min(span, hits.size());
  if (span < 2) return;
  sorted_.resize_discard(std::max(span, hits.size()));
  const int id_bits = detail::id_bits_below(id_limit);
  if (span <= static_cast<std::size_t>(detail::kSmallHitSort)) {
    lwsccd::detail::launch_after_previous(overlap_launches, detail::small_hit_sort_kernel<T, detail::kSmallHitSort>, 1,
                                          static_cast<unsigned>(detail::kSmallHitSort), stream, hits.data(), static_cast<int>(span),
                                          id_bits, sorted_.data(), device_count);
  } else if (overflow && !ahead_by_radix_ && span < (std::size_t(1) << 31)) {
    bucket_sort(hits.data(), device_count, span, id_limit, id_bits, stream, overflow, overlap_launches);
    ahead_bucketed_ = true;
  } else {
    radix_sort(hits.data(), span, id_bits, stream, device_count);
  }
  ahead_ = span;
}

template <class T>
bool HitSorter<T>::take_ahead(DeviceBuffer<FeatureHit<T>>& hits, std::size_t n, unsigned long long overflow) {
  const std::size_t ahead = ahead_;
  const bool bucketed = ahead_bucketed_;
  ahead_ = 0;
  ahead_bucketed_ = false;
  if (bucketed && overflow != 0) ahead_by_radix_ = true;
  if (n < 2) return true;  // (nothing to order)
  if (ahead < n || (bucketed && overflow != 0)) return false;
  std::swap(hits, sorted_);  // (slots past n: by radix the others after the hits; by buckets stale)
  return true;
}

template <class Method, class T, class Policy>
NarrowPhaseResult<T> NarrowPhase<Method, T, Policy>::download(cudaStream_t stream) const {
  NarrowPhaseResult<T> r;
  download_into(r, stream);
  return r;
}

template <class Method, class T, class Policy>
template <class StagingPolicy>
void NarrowPhase<Method, T, Policy>::download_into(NarrowPhaseResult<T>& r, cudaStream_t stream) const {
  if (joined_ && stream != stream_) {  // the sort was enqueued on the run's stream
    LWSCCD_CUDA_CHECK(cudaEventRecord(joined_, stream_));
    LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(stream, joined_, 0));
  }
  r.vf.resize(earliest_only_ ? 0 : lists_[0].count);
  r.ee.resize(earliest_only_ ? 0 : lists_[1].count);
  HostStaging<StagingPolicy>::to_host(r.vf.data(), lists_[0].hits.data(), r.vf.size() * sizeof(FeatureHit<T>), stream);
  HostStaging<StagingPolicy>::to_host(r.ee.data(), lists_[1].hits.data(), r.ee.size() * sizeof(FeatureHit<T>), stream);
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));  // (also with no hits: the stream's work is done on return)
  r.earliest_toi = earliest_;
  r.gave_up = gave_up_;
  r.vf_counts = lists_[0].counts;
  r.ee_counts = lists_[1].counts;
}

}  // namespace lwsccd::gpu
