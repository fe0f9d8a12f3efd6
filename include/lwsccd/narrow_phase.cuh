// lwsccd — the narrow phase on the GPU: one thread per candidate feature pair, hits compacted
// with CUB into an output that grows as needed (nothing is dropped), earliest TOI by reduction.
#pragma once

#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_reduce.cuh>
#include <cub/device/device_select.cuh>

#include <algorithm>
#include <utility>

#include "lwsccd/bvh.cuh"
#include "lwsccd/ccd_filters.hpp"
#include "lwsccd/certified_ccd.hpp"
#include "lwsccd/device_buffer.cuh"
#include "lwsccd/narrow_phase.hpp"

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
};

/// Knobs of the GPU narrow phase.
struct NarrowPhasePolicy {
  static constexpr int kBlock = 128;               ///< threads per block, a thread per query
  static constexpr int kThreadRounds = 6;   ///< InclusionCcd: rounds of the one-thread attempt per query
  static constexpr int kThreadBoxes = 64;   ///< InclusionCcd: live boxes the one-thread attempt may keep
  static constexpr int kSearchWarpsPerBlock = 2;   ///< InclusionCcd's searches left open: a warp per query (~12 KiB of shared memory each)
  /// CertifiedCcd: refinements that would halve intervals this deep (width 2^-level) go to a
  /// second kernel, so that the long searches of contacts do not hold up warps of quick misses.
  /// On an H100 levels 3 and 4 were fastest (cloth-ball narrow 3.3 ms against 3.5 at level 8,
  /// built-in 100K 1.05 against 1.5; docs/BENCHMARKS.md).
  static constexpr int kRefineDeferLevel = 4;
  /// CertifiedCcd's refinement kernel: blocks per SM it must fit (__launch_bounds__), which caps
  /// its registers per thread. 1: no cap (255 registers); on an H100 caps of 3 and 4 blocks
  /// spilled and made the narrow phase 1.3x and 2.9x slower on cloth-ball.
  static constexpr int kRefineMinBlocks = 1;
};

/// Runs a CCD method over device lists of candidate pairs, in the mode params.mode (as
/// cpu::test_feature_pairs, with the same answers). CertifiedCcd classifies every pair in the
/// first pass, a thread per pair (its hits are stored at once), and runs its fallback only on the
/// undecided ones. Other methods with a quick_reject (the conservative inclusion method, filtered
/// methods) run their cheap first step on every pair, then the full test on the compacted
/// survivors. The inclusion method's full test runs a thread per query for a few rounds, then a
/// warp per query still open. Owns its scratch and output buffers (reused; they only grow).
template <class Method, class T, class Policy = NarrowPhasePolicy>
class NarrowPhase {
 public:
  static_assert(require_ccd_method<Method>::value, "");
  using Pair = std::pair<index_t, index_t>;

  /// Pairs are processed in chunks of `chunk_pairs`; the output starts at `initial_capacity`
  /// hits and doubles whenever a chunk might not fit (tests force tiny values).
  explicit NarrowPhase(std::size_t chunk_pairs = std::size_t(1) << 22, std::size_t initial_capacity = 1 << 16)
      : chunk_(std::max<std::size_t>(chunk_pairs, 1)), initial_capacity_(std::max<std::size_t>(initial_capacity, 1)) {}

  /// Tests `num_vf` vertex-face and `num_ee` edge-edge pairs (device arrays of id pairs). The
  /// two lists run on streams of their own, overlapping; `stream` is ordered before and after
  /// them. Synchronizes once per chunk (to size the outputs); the hits stay on the device until
  /// download().
  template <class P>
  void run(const DeviceMeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1, const Pair* vf, std::size_t num_vf,
           const Pair* ee, std::size_t num_ee, const CcdParams<T>& params, cudaStream_t stream = nullptr);

  NarrowPhase(const NarrowPhase&) = delete;
  NarrowPhase& operator=(const NarrowPhase&) = delete;
  ~NarrowPhase() {
    for (auto& l : lists_) {
      if (l.host_counts) cudaFreeHost(l.host_counts);
      if (l.stream) cudaStreamDestroy(l.stream);
      if (l.done) cudaEventDestroy(l.done);
    }
    if (start_) cudaEventDestroy(start_);
  }

  /// The method that runs on the first pass's survivors: CertifiedCcd's fallback, or Method.
  using FullTest = typename lwsccd::detail::full_test_of<Method>::type;
  static constexpr bool kCertified = lwsccd::detail::certified_of<Method>::value;
  static constexpr bool kTwoPass = kCertified || lwsccd::detail::has_quick_reject<Method>::value;

  std::size_t num_vf_hits() const { return lists_[0].count; }
  /// Pairs of the last run left for the full test by the first pass (all pairs for one-pass methods).
  std::size_t survivors() const { return lists_[0].num_survivors + lists_[1].num_survivors; }
  /// Queries of the last run that the one-thread attempt left to a warp search (InclusionCcd).
  std::size_t warp_searches() const { return lists_[0].warp_searches + lists_[1].warp_searches; }
  std::size_t num_ee_hits() const { return lists_[1].count; }
  T earliest_toi() const { return earliest_; }
  std::size_t gave_up() const { return gave_up_; }
  /// How the last run answered each list's pairs (vertex-face, edge-edge).
  NarrowPhaseCounts counts(int list) const { return lists_[list].counts; }
  /// Copies the hits to the host (run() left them sorted on the device, like the CPU backend's).
  NarrowPhaseResult<T> download(cudaStream_t stream = nullptr) const;
  std::size_t device_bytes() const {
    std::size_t bytes = toi_.capacity_bytes() + reduce_scratch_.capacity_bytes();
    for (const auto& l : lists_)
      bytes += l.hits.capacity_bytes() + l.staged.capacity_bytes() + l.flags.capacity_bytes() + l.scratch.capacity_bytes() +
               l.hit_flags.capacity_bytes() +
               l.survivors.capacity_bytes() + l.undecided.capacity_bytes() + l.counters.capacity_bytes() + l.pending.capacity_bytes() +
               l.pending_index.capacity_bytes() + l.sorted.capacity_bytes() + l.keys.capacity_bytes() + l.sorted_keys.capacity_bytes();
    return bytes;
  }

 private:
  // One list's buffers (vertex-face or edge-edge) and its stream.
  struct List {
    DeviceBuffer<FeatureHit<T>> hits, staged, sorted;  ///< sorted: run()'s final ordering by (first, second)
    DeviceBuffer<unsigned long long> keys, sorted_keys;
    DeviceBuffer<unsigned char> flags, scratch;
    DeviceBuffer<unsigned long long> survivors;  ///< pairs left after Method::quick_reject, as 64-bit words
    DeviceBuffer<FeatureHit<T>> undecided;  ///< CertifiedCcd: pairs left to the fallback, with the time excluded before
    DeviceBuffer<unsigned long long> counters;   ///< [0]: selected, [1]: gave up, [2]: left to warp searches, [3]: certified hits
    DeviceBuffer<unsigned char> hit_flags;       ///< CertifiedCcd's first pass: certified hits
    NarrowPhaseCounts counts;
    DeviceBuffer<unsigned char> pending;         ///< per query: left open by the one-thread attempt (or refinement deferred)
    DeviceBuffer<unsigned> pending_index;
    std::size_t count = 0, num_survivors = 0, tested = 0, warp_searches = 0;
    std::size_t refined = 0, num_undecided = 0;  ///< CertifiedCcd: screened pairs refined, left undecided
    unsigned long long* host_counts = nullptr;   ///< pinned copies of counters
    const Pair* to_test = nullptr;  ///< survivors, or the input pairs for one-pass methods
    cudaStream_t stream = nullptr;
    cudaEvent_t done = nullptr;
  };

  void ensure_streams();
  template <class P, bool kVertexFace>
  void screen(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1, const Pair* pairs, std::size_t n,
              const CcdParams<T>& params, List& list);
  void compact_screened(List& list);
  template <class P, bool kVertexFace>
  std::size_t refine_chunk(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1, const CcdParams<T>& params,
                           List& list);
  void collect_refined(List& list, std::size_t m);
  template <class In, class Out>
  void select_flagged(List& list, In in, const unsigned char* flags, Out out, unsigned long long* count, std::size_t n);
  template <class P, bool kVertexFace>
  void launch_chunk(const MeshFeatures& mesh, const Vec3<P>* x0, const Vec3<P>* x1, const CcdParams<T>& params, List& list,
                    std::size_t begin, std::size_t m);
  void grow_hits(List& list, std::size_t room);
  void sort_hits(List& list, cudaStream_t stream);
  T list_minimum(const List& list, cudaStream_t stream);

  std::size_t chunk_, initial_capacity_;
  List lists_[2];  ///< vertex-face, edge-edge
  cudaEvent_t start_ = nullptr;
  DeviceBuffer<T> toi_;
  DeviceBuffer<unsigned char> reduce_scratch_;
  std::size_t gave_up_ = 0;
  T earliest_ = T(1);
  int deferred_grid_ = 1;        ///< blocks of the deferred refinement kernel (a grid-stride loop)
  bool earliest_only_ = false;  ///< the last run was in mode earliest: download() gives no pairs
};

}  // namespace lwsccd::gpu

#include "lwsccd/detail/narrow_phase_kernels.cuh"
