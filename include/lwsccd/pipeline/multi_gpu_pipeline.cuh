// lwsccd — a CCD step split over several GPUs with NCCL (gpu::MultiGpuPipeline). Needs NCCL
// (nccl.h, libnccl; the CUDA toolkit's or the nvidia-nccl wheel's): include <lwsccd/multi_gpu.cuh>
// and link NCCL (in lwsccd's build, the CMake target lwsccd::multi_gpu does both).
//
// Each GPU holds the whole mesh, its own BVH (built from the same positions, so the same tree)
// and a gpu::CcdPipeline that finds one share of the contacts (CcdPipeline::set_share): from the
// root, every count-th node pair of a cut of the BVTT made from the tree's topology; later steps
// from the share's own front. Between steps the shares are rebalanced by their measured time: the
// busiest GPU hands the tail of its front to the least busy (NCCL send / receive), a node pair
// being a part of the BVTT on its own. Rebuilds and restarts from the root are decided together
// (any GPU's wish is every GPU's), so the shares always partition the BVTT. After a step the
// statistics are exchanged (all-gather), the earliest time of impact reduced (all-reduce, min)
// and the contacts gathered to the first GPU (send / receive), where they are sorted once: the
// same sorted contacts as one GPU gives.
//
// Two ways to drive the GPUs, the two NCCL conventions: one process driving all of them (a device
// list: ncclCommInitAll, a host thread per GPU), or one process per GPU joining a communicator
// the caller made (ncclCommInitRank, the unique id shared by MPI, a file, torch.distributed):
// each process then holds one share, and rank 0's process gets the contacts.
#pragma once

#include <cub/device/device_merge.cuh>
#include <nccl.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <string>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

#include "lwsccd/pipeline/gpu_pipeline.cuh"

/// Checks an NCCL call: throws lwsccd::Error with the call, file, line and NCCL's message.
#define LWSCCD_NCCL_CHECK(call)                                                                                    \
  do {                                                                                                             \
    const ncclResult_t lwsccd_nccl_result_ = (call);                                                               \
    if (lwsccd_nccl_result_ != ncclSuccess)                                                                        \
      throw ::lwsccd::Error(std::string("NCCL error in ") + #call + " at " + __FILE__ + ":" + std::to_string(__LINE__) + \
                            ": " + ncclGetErrorString(lwsccd_nccl_result_));                                       \
  } while (0)

namespace lwsccd::gpu {

/// Knobs of the split step.
struct MultiGpuPolicy {
  /// Fronts are rebalanced after a step whose busiest GPU took this much longer than the least
  /// busy one: host time until its share's step was done, so a GPU that waited for the
  /// positions' broadcast takes less work.
  static constexpr double kImbalance = 0.02;
  /// Share of the estimated excess that moves: entries differ in work, so the moves approach the
  /// balance over a few steps instead of overshooting it.
  static constexpr double kMoveDamping = 0.5;
};

namespace detail {

// Restores the calling thread's current device when it goes (the pipeline's calls switch to
// their GPUs; the caller's choice stays its own).
class CurrentDeviceGuard {
 public:
  CurrentDeviceGuard() { LWSCCD_CUDA_CHECK(cudaGetDevice(&device_)); }
  ~CurrentDeviceGuard() { cudaSetDevice(device_); }
  CurrentDeviceGuard(const CurrentDeviceGuard&) = delete;
  CurrentDeviceGuard& operator=(const CurrentDeviceGuard&) = delete;

 private:
  int device_ = 0;
};

// One host thread per GPU of a process that drives several (each GPU's work waits on its own
// stream): run() hands every thread the same job with its rank and returns when all are done,
// rethrowing the first exception one of them threw. One rank runs on the caller's thread.
class DeviceWorkers {
 public:
  explicit DeviceWorkers(std::vector<int> devices) : devices_(std::move(devices)) {
    if (devices_.size() < 2) return;
    for (std::size_t r = 0; r < devices_.size(); ++r) threads_.emplace_back([this, r] { loop(r); });
  }
  ~DeviceWorkers() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    start_.notify_all();
    for (auto& t : threads_) t.join();
  }
  DeviceWorkers(const DeviceWorkers&) = delete;
  DeviceWorkers& operator=(const DeviceWorkers&) = delete;

  std::size_t size() const { return devices_.size(); }
  int device(std::size_t rank) const { return devices_[rank]; }

  void run(const std::function<void(std::size_t)>& job) {
    if (threads_.empty()) {
      CurrentDeviceGuard guard;
      LWSCCD_CUDA_CHECK(cudaSetDevice(devices_[0]));
      job(0);
      return;
    }
    std::unique_lock<std::mutex> lock(mutex_);
    job_ = &job;
    pending_ = threads_.size();
    error_ = nullptr;
    ++round_;
    start_.notify_all();
    done_.wait(lock, [this] { return pending_ == 0; });
    job_ = nullptr;
    if (error_) std::rethrow_exception(error_);
  }

 private:
  void loop(std::size_t rank) {
    std::uint64_t seen = 0;
    bool device_set = false;
    while (true) {
      const std::function<void(std::size_t)>* job = nullptr;
      {
        std::unique_lock<std::mutex> lock(mutex_);
        start_.wait(lock, [&] { return stop_ || round_ != seen; });
        if (stop_) return;
        seen = round_;
        job = job_;
      }
      std::exception_ptr error;
      try {
        if (!device_set) LWSCCD_CUDA_CHECK(cudaSetDevice(devices_[rank]));
        device_set = true;
        (*job)(rank);
      } catch (...) {
        error = std::current_exception();
      }
      std::lock_guard<std::mutex> lock(mutex_);
      if (error && !error_) error_ = error;
      if (--pending_ == 0) done_.notify_all();
    }
  }

  std::vector<int> devices_;
  std::vector<std::thread> threads_;
  std::mutex mutex_;
  std::condition_variable start_, done_;
  const std::function<void(std::size_t)>* job_ = nullptr;
  std::uint64_t round_ = 0;
  std::size_t pending_ = 0;
  bool stop_ = false;
  std::exception_ptr error_;
};

// A step's statistics as numbers, for the all-gather (and back).
constexpr int kPackedCounts = 8;
constexpr int kPackedFields = 24;
// Entries read by name (the rest are unpacked by unpack_stats).
constexpr int kPackedFront = 6, kPackedHitsVf = 10, kPackedRebuild = 21, kPackedRestart = 22, kPackedDone = 23;
constexpr int kPackedStats = kPackedFields + 2 * kPackedCounts;
inline void pack_counts(const NarrowPhaseCounts& c, double* out) {
  const std::size_t v[kPackedCounts] = {c.pairs, c.certified_hits, c.certified_misses, c.fallbacks, c.screened, c.single_misses,
                                        c.single_descents, c.float_pair_leaves};
  for (int k = 0; k < kPackedCounts; ++k) out[k] = static_cast<double>(v[k]);
}
inline NarrowPhaseCounts unpack_counts(const double* in) {
  auto n = [&](int k) { return static_cast<std::size_t>(in[k]); };
  NarrowPhaseCounts c;
  c.pairs = n(0), c.certified_hits = n(1), c.certified_misses = n(2), c.fallbacks = n(3), c.screened = n(4), c.single_misses = n(5);
  c.single_descents = n(6), c.float_pair_leaves = n(7);
  return c;
}
// Entries: the StepStats fields (front_size: the front the next step starts from), the share's
// wishes for the next step (rebuild, restart), the host time until its step was done (its positions
// placed, its step: what the balance evens out), then the certified counts.
inline void pack_stats(const StepStats& s, bool rebuild, bool restart, double done_ms, double* out) {
  const double v[kPackedFields] = {s.refit_ms, s.traverse_ms, s.features_ms, s.narrow_ms, s.total_ms, double(s.bvtt_nodes),
                        double(s.front_size), double(s.triangle_pairs), double(s.feature_pairs_vf), double(s.feature_pairs_ee),
                        double(s.hits_vf), double(s.hits_ee), double(s.gave_up), double(s.narrow_survivors),
                        double(s.narrow_warp_searches), double(s.peak_device_bytes), double(s.reruns),
                        double(s.traversal_relaunches), double(s.rebuilt), double(s.restarted_from_root), double(s.front_outgrown),
                        double(rebuild), double(restart), done_ms};
  std::copy(v, v + kPackedFields, out);
  pack_counts(s.narrow_vf, out + kPackedFields);
  pack_counts(s.narrow_ee, out + kPackedFields + kPackedCounts);
}
inline StepStats unpack_stats(const double* in) {
  auto n = [&](int k) { return static_cast<std::size_t>(in[k]); };
  StepStats s;
  s.refit_ms = in[0], s.traverse_ms = in[1], s.features_ms = in[2], s.narrow_ms = in[3], s.total_ms = in[4];
  s.bvtt_nodes = n(5), s.front_size = n(6), s.triangle_pairs = n(7), s.feature_pairs_vf = n(8), s.feature_pairs_ee = n(9);
  s.hits_vf = n(10), s.hits_ee = n(11), s.gave_up = n(12), s.narrow_survivors = n(13), s.narrow_warp_searches = n(14);
  s.peak_device_bytes = n(15), s.reruns = n(16), s.traversal_relaunches = n(17);
  s.rebuilt = in[18] != 0, s.restarted_from_root = in[19] != 0, s.front_outgrown = in[20] != 0;
  s.narrow_vf = unpack_counts(in + kPackedFields);
  s.narrow_ee = unpack_counts(in + kPackedFields + kPackedCounts);
  return s;
}

// Hits in (first, second) order, on the device (a merge's comparison).
struct HitPairLess {
  template <class Hit>
  LWSCCD_HD bool operator()(const Hit& a, const Hit& b) const {
    return a.first != b.first ? a.first < b.first : a.second < b.second;
  }
};

template <class T>
ncclDataType_t nccl_type() {
  static_assert(std::is_same<T, double>::value || std::is_same<T, float>::value, "lwsccd: positions and TOIs are float or double");
  return std::is_same<T, double>::value ? ncclDouble : ncclFloat;
}

}  // namespace detail

/// Where a split step's host time went, on the root's thread (ms): the positions placed
/// (uploaded, or broadcast: its transfer overlaps the step, whose wait then holds it), its share's
/// step (CcdPipeline::step_on_device), the statistics exchanged, the contacts gathered and
/// sorted, the next step agreed on (fronts moved).
struct MultiGpuTimes {
  double positions_ms = 0, share_step_ms = 0, exchange_ms = 0, gather_ms = 0, rebalance_ms = 0;
};

/// One step's contacts and statistics over every GPU: `stats` for the whole (stage times the
/// slowest GPU's, counts summed, peak_device_bytes the largest of the GPUs') and `devices` each
/// GPU's share (peak_device_bytes: the bytes that GPU holds for the pipeline after the step; its
/// buffers keep their largest size).
template <class T>
struct MultiGpuStepResult {
  NarrowPhaseResult<T> contacts;  ///< sorted by pair, as one GPU's (rank 0's process only, one process per GPU)
  StepStats stats;
  std::vector<StepStats> devices;  ///< per share, in rank order
  std::size_t moved_front_entries = 0;  ///< front entries this step's rebalancing moved between GPUs
  MultiGpuTimes times;
};

/// As gpu::CcdPipeline, with each step split over several GPUs (see the file's comment). Same
/// contacts and TOIs as one GPU, pair for pair. Steps do not stream: PipelineParams'
/// device_memory_budget and part_pairs must be 0 (each GPU holds the mesh and its BVH).
template <class BV = Aabbf, class Scheduler = LazyStealScheduler, class Method = CertifiedCcd, class T = double>
class MultiGpuPipeline {
 public:
  using Pipeline = CcdPipeline<BV, Scheduler, Method, T>;

  /// One process driving `devices` (CUDA device ordinals, distinct): a communicator over them
  /// (ncclCommInitAll) and a host thread each. The first device is the root: device positions are
  /// read there, device contacts left there.
  MultiGpuPipeline(std::shared_ptr<const TriangleMesh> mesh, BodyLayout layout, std::vector<int> devices, PipelineParams params = {})
      : workers_(checked_devices(devices)) {
    check_inputs(mesh, params);  // (before the communicator is made)
    const std::size_t n = devices.size();
    std::vector<ncclComm_t> comms(n);
    LWSCCD_NCCL_CHECK(ncclCommInitAll(comms.data(), static_cast<int>(n), devices.data()));
    ranks_.resize(n);
    for (std::size_t r = 0; r < n; ++r) {
      ranks_[r] = std::make_unique<Rank>();
      ranks_[r]->comm = comms[r];
      ranks_[r]->owns_comm = true;
    }
    share_count_ = n;
    first_rank_ = 0;
    make_pipelines(std::move(mesh), std::move(layout), params);
  }
  MultiGpuPipeline(std::shared_ptr<const TriangleMesh> mesh, std::vector<int> devices, PipelineParams params = {})
      : MultiGpuPipeline(std::move(mesh), BodyLayout{}, std::move(devices), params) {}

  /// One process per GPU: joins `comm` (made by the caller with ncclCommInitRank on this process's
  /// device; not destroyed here). Every process constructs and steps its pipeline in the same
  /// order; rank 0's steps return the contacts, the others' the statistics and earliest TOI.
  MultiGpuPipeline(std::shared_ptr<const TriangleMesh> mesh, BodyLayout layout, ncclComm_t comm, PipelineParams params = {})
      : workers_({comm_device(comm)}) {
    check_inputs(mesh, params);
    int rank = 0, count = 0;
    LWSCCD_NCCL_CHECK(ncclCommUserRank(comm, &rank));
    LWSCCD_NCCL_CHECK(ncclCommCount(comm, &count));
    ranks_.resize(1);
    ranks_[0] = std::make_unique<Rank>();
    ranks_[0]->comm = comm;
    share_count_ = static_cast<std::size_t>(count);
    first_rank_ = static_cast<std::size_t>(rank);
    make_pipelines(std::move(mesh), std::move(layout), params);
  }

  ~MultiGpuPipeline() {
    try {
      workers_.run([this](std::size_t r) {
        if (!ranks_[r]) return;
        const ncclComm_t comm = ranks_[r]->owns_comm && !aborted_ ? ranks_[r]->comm : nullptr;
        ranks_[r].reset();
        if (comm) ncclCommDestroy(comm);
      });
    } catch (...) {
    }
  }
  MultiGpuPipeline(const MultiGpuPipeline&) = delete;
  MultiGpuPipeline& operator=(const MultiGpuPipeline&) = delete;

  /// One step from host positions (each GPU uploads them). Synchronizes every GPU's stream.
  MultiGpuStepResult<T> step(const std::vector<Vec3d>& x0, const std::vector<Vec3d>& x1) { return from_host(x0, x1); }
  MultiGpuStepResult<T> step(const std::vector<Vec3f>& x0, const std::vector<Vec3f>& x1) { return from_host(x0, x1); }

  /// One step from positions in device memory on the root device (one process: the list's first
  /// device; one process per GPU: this process's device, every process passing its own copy).
  /// With one process they are broadcast to the other GPUs (ncclBroadcast). They are read in the
  /// default stream's order (written and synchronized before the call).
  MultiGpuStepResult<T> step_from_device(const Vec3d* x0, const Vec3d* x1) { return from_device(x0, x1); }
  MultiGpuStepResult<T> step_from_device(const Vec3f* x0, const Vec3f* x1) { return from_device(x0, x1); }

  /// As step_from_device, with the contacts left on the root device (sorted by pair, valid until
  /// the next step); `stats` as a MultiGpuStepResult's.
  DeviceStepResult<T> step_on_device(const Vec3d* x0, const Vec3d* x1) { return on_device(x0, x1); }
  DeviceStepResult<T> step_on_device(const Vec3f* x0, const Vec3f* x1) { return on_device(x0, x1); }

  /// The next step traverses from the root on every GPU (the shares dealt out afresh).
  void restart_from_root() {
    for (auto& k : ranks_) k->pipeline->restart_from_root();
  }

  /// Shares in all (GPUs over every process), and those this process drives.
  std::size_t num_shares() const { return share_count_; }
  std::size_t num_local_devices() const { return ranks_.size(); }
  int device(std::size_t local) const { return workers_.device(local); }
  const TriangleMesh& mesh() const { return ranks_[0]->pipeline->mesh(); }
  const PipelineParams& params() const { return ranks_[0]->pipeline->params(); }
  /// The last step's statistics per share (rank order), as in its MultiGpuStepResult.
  const std::vector<StepStats>& device_stats() const { return device_stats_; }
  /// The last step's host times on the root's thread, and the front entries its rebalancing moved.
  const MultiGpuTimes& last_times() const { return times_; }
  std::size_t last_moved_front_entries() const { return moved_; }

 private:
  struct Rank {
    ncclComm_t comm = nullptr;
    bool owns_comm = false;
    CudaStream stream, side;  ///< the share's work; the root's broadcast
    CudaEvent caller_done, broadcast_done;  ///< (made on the rank's GPU)
    bool broadcast_pending = false;
    std::unique_ptr<Pipeline> pipeline;
    DeviceBuffer<Vec3d> xd[2];  ///< positions uploaded or broadcast here
    DeviceBuffer<Vec3f> xf[2];
    DeviceStepResult<T> part;
    DeviceBuffer<double> exchange;  ///< the all-gather of every share's packed statistics
    DeviceBuffer<T> earliest;
    PinnedBuffer<double> host_exchange;
    PinnedBuffer<T> host_earliest;
    DeviceBuffer<FeatureHit<T>> gathered[2];  ///< the root's: every share's contacts
    DeviceBuffer<FeatureHit<T>> merged[2];    ///< and two shares' merged
    DeviceBuffer<unsigned char> merge_scratch;
    HitSorter<T> sorter;
  };

  static std::vector<int> checked_devices(const std::vector<int>& devices) {
    if (devices.empty()) throw InputError("gpu::MultiGpuPipeline", "devices", "is empty");
    int available = 0;
    LWSCCD_CUDA_CHECK(cudaGetDeviceCount(&available));
    for (std::size_t i = 0; i < devices.size(); ++i) {
      if (devices[i] < 0 || devices[i] >= available)
        throw InputError("gpu::MultiGpuPipeline", "devices",
                         "device " + std::to_string(devices[i]) + " is not one of the " + std::to_string(available) + " CUDA devices");
      for (std::size_t j = 0; j < i; ++j)
        if (devices[j] == devices[i])
          throw InputError("gpu::MultiGpuPipeline", "devices", "device " + std::to_string(devices[i]) + " is listed twice");
    }
    return devices;
  }
  static void check_inputs(const std::shared_ptr<const TriangleMesh>& mesh, const PipelineParams& params) {
    lwsccd::detail::checked_mesh(mesh, "gpu::MultiGpuPipeline");
    params.validate();
    if (params.device_memory_budget || params.part_pairs)
      throw InputError("gpu::MultiGpuPipeline", "params",
                       "a step split over GPUs does not stream: device_memory_budget and part_pairs must be 0");
  }
  static std::vector<int> comm_device(ncclComm_t comm) {
    int device = 0;
    LWSCCD_NCCL_CHECK(ncclCommCuDevice(comm, &device));
    return {device};
  }

  void make_pipelines(std::shared_ptr<const TriangleMesh> mesh, BodyLayout layout, const PipelineParams& params) {
    workers_.run([&](std::size_t r) {
      Rank& k = *ranks_[r];
      k.stream = CudaStream(cudaStreamNonBlocking);
      k.side = CudaStream(cudaStreamNonBlocking);
      k.caller_done = CudaEvent(cudaEventDisableTiming);
      k.broadcast_done = CudaEvent(cudaEventDisableTiming);
      k.pipeline = std::make_unique<Pipeline>(mesh, layout, params, k.stream);
      k.pipeline->set_share(first_rank_ + r, share_count_);
    });
  }

  template <class Q>
  MultiGpuStepResult<T> from_host(const std::vector<Vec3<Q>>& x0, const std::vector<Vec3<Q>>& x1) {
    const auto start = std::chrono::steady_clock::now();
    const std::size_t n = mesh().num_vertices();
    if (x0.size() != n || x1.size() != n)
      throw InputError("gpu::MultiGpuPipeline::step", "x0, x1",
                       "need " + std::to_string(n) + " positions each, got " + std::to_string(x0.size()) + " and " + std::to_string(x1.size()));
    MultiGpuStepResult<T> result;
    run_step(
        [&](Rank& k) {
          DeviceBuffer<Vec3<Q>>* x = positions<Q>(k);
          x[0].upload(x0, k.stream);
          x[1].upload(x1, k.stream);
          return std::pair<const Vec3<Q>*, const Vec3<Q>*>(x[0].data(), x[1].data());
        },
        result.stats, result.devices, result.moved_front_entries);
    return finished(std::move(result), start);
  }
  template <class Q>
  MultiGpuStepResult<T> from_device(const Vec3<Q>* x0, const Vec3<Q>* x1) {
    const auto start = std::chrono::steady_clock::now();
    MultiGpuStepResult<T> result;
    run_step([&](Rank& k) { return broadcast(k, x0, x1); }, result.stats, result.devices, result.moved_front_entries);
    return finished(std::move(result), start);
  }
  // A host step's end: the contacts downloaded, the host times, the call's time.
  MultiGpuStepResult<T> finished(MultiGpuStepResult<T>&& result, std::chrono::steady_clock::time_point start) {
    download(result.contacts);
    result.times = times_;
    result.stats.total_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return std::move(result);
  }
  template <class Q>
  DeviceStepResult<T> on_device(const Vec3<Q>* x0, const Vec3<Q>* x1) {
    const auto start = std::chrono::steady_clock::now();
    DeviceStepResult<T> result;
    std::vector<StepStats> devices;
    std::size_t moved = 0;
    run_step([&](Rank& k) { return broadcast(k, x0, x1); }, result.stats, devices, moved);
    result.contacts = gathered_;
    result.stats.total_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return result;
  }

  template <class Q>
  DeviceBuffer<Vec3<Q>>* positions(Rank& k) {
    if constexpr (std::is_same<Q, double>::value) {
      return k.xd;
    } else {
      return k.xf;
    }
  }

  // The root's device positions, broadcast from the root to the other GPUs of this process (one
  // process per GPU: every process has its own). The caller wrote them on the default stream: the
  // streams that read them wait for its work so far (no host wait). The root sends on a stream of
  // its own, so its step starts at once; its later NCCL calls wait for the broadcast
  // (broadcast_done), so one communicator's work stays in one order on every GPU.
  template <class Q>
  std::pair<const Vec3<Q>*, const Vec3<Q>*> broadcast(Rank& k, const Vec3<Q>* x0, const Vec3<Q>* x1) {
    const bool root = &k == ranks_[0].get();
    if (root) {
      LWSCCD_CUDA_CHECK(cudaEventRecord(k.caller_done, nullptr));
      LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(k.stream, k.caller_done, 0));
    }
    if (ranks_.size() == 1) return {x0, x1};
    const std::size_t n = mesh().num_vertices();
    DeviceBuffer<Vec3<Q>>* x = positions<Q>(k);
    // In place on the root (NCCL reads its buffer), into this GPU's copy elsewhere.
    Vec3<Q>* to[2] = {const_cast<Vec3<Q>*>(x0), const_cast<Vec3<Q>*>(x1)};
    cudaStream_t stream = k.stream;
    if (root) {
      stream = k.side;
      LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(stream, k.caller_done, 0));
    } else {
      for (int t = 0; t < 2; ++t) {
        x[t].resize_discard(n);
        to[t] = x[t].data();
      }
    }
    const auto use = nccl_use();
    LWSCCD_NCCL_CHECK(ncclGroupStart());
    for (int t = 0; t < 2; ++t)
      LWSCCD_NCCL_CHECK(ncclBroadcast(to[t], to[t], 3 * n, detail::nccl_type<Q>(), 0, k.comm, stream));
    LWSCCD_NCCL_CHECK(ncclGroupEnd());
    if (root) {
      LWSCCD_CUDA_CHECK(cudaEventRecord(k.broadcast_done, stream));
      k.broadcast_pending = true;
    }
    return {to[0], to[1]};
  }

  // Every share's step (run_share, on its GPU's thread), then the whole step's statistics.
  template <class Positions>
  void run_step(Positions&& place_positions, StepStats& stats, std::vector<StepStats>& devices, std::size_t& moved) {
    if (aborted_)
      throw Error("gpu::MultiGpuPipeline: an earlier step failed on one GPU and its communicator was aborted; make a new pipeline");
    const std::size_t shares = share_count_;
    workers_.run([&](std::size_t r) {
      try {
        run_share(place_positions, r, shares);
      } catch (...) {
        abort_communicators();
        throw;
      }
    });
    // Every rank holds the same exchange: read the first.
    combine(stats, devices, shares);
    gathered_.gave_up = stats.gave_up;  // (every share's, summed)
    gathered_.vf_counts = stats.narrow_vf;
    gathered_.ee_counts = stats.narrow_ee;
    moved = moved_;
    device_stats_ = devices;
  }

  // An error on one GPU alone (e.g. out of memory) would leave the others waiting in a collective
  // for it: this process's communicators are aborted, which ends their waits with errors (NCCL's
  // kernels watch for it), and the pipeline refuses further steps. (One process per GPU: the other
  // processes' waits end as any NCCL program's do, by their own watchdog or timeout.)
  void abort_communicators() {
    if (aborted_.exchange(true)) return;
    std::unique_lock<std::shared_mutex> lock(nccl_mutex_);  // (the calls under way end first)
    for (auto& k : ranks_)
      if (k && k->comm) ncclCommAbort(k->comm);
  }

  // Held while a thread makes NCCL calls (never while it waits for a GPU): once an abort has begun,
  // no thread calls NCCL on the aborted communicators.
  std::shared_lock<std::shared_mutex> nccl_use() {
    std::shared_lock<std::shared_mutex> lock(nccl_mutex_);
    if (aborted_) throw Error("gpu::MultiGpuPipeline: the step failed on another GPU; the communicators were aborted");
    return lock;
  }

  // One share's step: positions, its pipeline's step, the statistics all-gathered and the
  // earliest TOI all-reduced, the contacts gathered to the root and merged there, then the next
  // step agreed on (rebuild, restart, or the fronts rebalanced).
  template <class Positions>
  void run_share(Positions& place_positions, std::size_t r, std::size_t shares) {
    using clock = std::chrono::steady_clock;
    auto lap = [mark = clock::now()]() mutable {
      const auto now = clock::now();
      const double ms = std::chrono::duration<double, std::milli>(now - mark).count();
      mark = now;
      return ms;
    };
    MultiGpuTimes times;
    Rank& k = *ranks_[r];
    const auto x = place_positions(k);
    times.positions_ms = lap();
    k.part = k.pipeline->step_on_device(x.first, x.second, k.stream);
    times.share_step_ms = lap();
    if (k.broadcast_pending) {  // (the caller may overwrite its positions once the step returns)
      LWSCCD_CUDA_CHECK(cudaStreamWaitEvent(k.stream, k.broadcast_done, 0));
      k.broadcast_pending = false;
    }
    // Statistics and wishes of every share, everywhere.
    k.exchange.resize_discard(shares * detail::kPackedStats);
    k.host_exchange.ensure(shares * detail::kPackedStats);
    k.host_earliest.ensure(1);
    k.earliest.resize_discard(1);
    const std::size_t me = first_rank_ + r;
    double* mine = k.host_exchange.data() + me * detail::kPackedStats;
    StepStats own = k.part.stats;
    own.peak_device_bytes = k.pipeline->device_bytes() + wrapper_bytes(k);  // (memory_stats() counts the process's GPUs together)
    detail::pack_stats(own, k.pipeline->rebuild_due(), k.pipeline->wants_restart(), times.positions_ms + times.share_step_ms, mine);
    k.host_earliest[0] = k.part.contacts.earliest_toi;
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(k.exchange.data() + me * detail::kPackedStats, mine, detail::kPackedStats * sizeof(double),
                                      cudaMemcpyHostToDevice, k.stream));
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(k.earliest.data(), k.host_earliest.data(), sizeof(T), cudaMemcpyHostToDevice, k.stream));
    const auto use = nccl_use();
    LWSCCD_NCCL_CHECK(ncclGroupStart());
    LWSCCD_NCCL_CHECK(ncclAllGather(k.exchange.data() + me * detail::kPackedStats, k.exchange.data(), detail::kPackedStats,
                                    ncclDouble, k.comm, k.stream));
    LWSCCD_NCCL_CHECK(ncclAllReduce(k.earliest.data(), k.earliest.data(), 1, detail::nccl_type<T>(), ncclMin, k.comm, k.stream));
    LWSCCD_NCCL_CHECK(ncclGroupEnd());
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(k.host_exchange.data(), k.exchange.data(), shares * detail::kPackedStats * sizeof(double),
                                      cudaMemcpyDeviceToHost, k.stream));
    LWSCCD_CUDA_CHECK(cudaMemcpyAsync(k.host_earliest.data(), k.earliest.data(), sizeof(T), cudaMemcpyDeviceToHost, k.stream));
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(k.stream));
    times.exchange_ms = lap();
    gather_contacts(k, r);
    times.gather_ms = lap();
    agree_on_next_step(k, r);
    times.rebalance_ms = lap();
    if (r == 0) times_ = times;
  }

  // The whole step's statistics from the shares' (stage times the slowest GPU's, counts summed).
  void combine(StepStats& stats, std::vector<StepStats>& devices, std::size_t shares) const {
    const Rank& k = *ranks_[0];
    devices.resize(shares);
    for (std::size_t s = 0; s < shares; ++s) devices[s] = detail::unpack_stats(k.host_exchange.data() + s * detail::kPackedStats);
    stats = StepStats{};
    for (const StepStats& d : devices) {
      stats.refit_ms = std::max(stats.refit_ms, d.refit_ms);
      stats.traverse_ms = std::max(stats.traverse_ms, d.traverse_ms);
      stats.features_ms = std::max(stats.features_ms, d.features_ms);
      stats.narrow_ms = std::max(stats.narrow_ms, d.narrow_ms);
      stats.bvtt_nodes += d.bvtt_nodes;
      stats.front_size += d.front_size;
      stats.triangle_pairs += d.triangle_pairs;
      stats.feature_pairs_vf += d.feature_pairs_vf;
      stats.feature_pairs_ee += d.feature_pairs_ee;
      stats.hits_vf += d.hits_vf;
      stats.hits_ee += d.hits_ee;
      stats.gave_up += d.gave_up;
      stats.narrow_survivors += d.narrow_survivors;
      stats.narrow_warp_searches += d.narrow_warp_searches;
      add_counts(stats.narrow_vf, d.narrow_vf);
      add_counts(stats.narrow_ee, d.narrow_ee);
      stats.peak_device_bytes = std::max(stats.peak_device_bytes, d.peak_device_bytes);
      stats.reruns += d.reruns;
      stats.traversal_relaunches += d.traversal_relaunches;
      stats.rebuilt = stats.rebuilt || d.rebuilt;
      stats.restarted_from_root = stats.restarted_from_root || d.restarted_from_root;
      stats.front_outgrown = stats.front_outgrown || d.front_outgrown;
    }
  }

  // The shares' contacts to the root (rank 0), in rank order, sorted there once. Mode earliest
  // lists none.
  void gather_contacts(Rank& k, std::size_t r) {
    const std::size_t shares = share_count_, me = first_rank_ + r;
    const bool root = me == 0;
    const bool pairs = k.pipeline->params().mode != CcdMode::earliest;
    std::size_t total[2] = {0, 0};
    for (std::size_t s = 0; s < shares; ++s)
      for (int list = 0; list < 2; ++list)
        total[list] += pairs ? static_cast<std::size_t>(k.host_exchange[s * detail::kPackedStats + detail::kPackedHitsVf + list]) : 0;
    const FeatureHit<T>* own[2] = {k.part.contacts.vf, k.part.contacts.ee};
    const std::size_t own_count[2] = {pairs ? k.part.contacts.num_vf : 0, pairs ? k.part.contacts.num_ee : 0};
    if (root)
      for (int list = 0; list < 2; ++list) {
        k.gathered[list].resize_discard(std::max<std::size_t>(total[list], 1));
        if (own_count[list])
          LWSCCD_CUDA_CHECK(cudaMemcpyAsync(k.gathered[list].data(), own[list], own_count[list] * sizeof(FeatureHit<T>),
                                            cudaMemcpyDeviceToDevice, k.stream));
      }
    const auto use = nccl_use();
    LWSCCD_NCCL_CHECK(ncclGroupStart());
    for (int list = 0; list < 2; ++list) {
      if (root) {
        std::size_t at = own_count[list];
        for (std::size_t s = 1; s < shares; ++s) {
          const std::size_t n = static_cast<std::size_t>(k.host_exchange[s * detail::kPackedStats + detail::kPackedHitsVf + list]);
          if (pairs && n)
            LWSCCD_NCCL_CHECK(ncclRecv(k.gathered[list].data() + at, n * sizeof(FeatureHit<T>), ncclUint8, static_cast<int>(s), k.comm, k.stream));
          at += pairs ? n : 0;
        }
      } else if (own_count[list]) {
        LWSCCD_NCCL_CHECK(ncclSend(own[list], own_count[list] * sizeof(FeatureHit<T>), ncclUint8, 0, k.comm, k.stream));
      }
    }
    LWSCCD_NCCL_CHECK(ncclGroupEnd());
    if (root) {
      // Each share's hits are sorted: two shares merge in one pass, more are sorted again.
      const std::size_t id_limit = static_cast<std::size_t>(mesh().num_vertices()) + mesh().num_edges() + mesh().num_faces();
      for (int list = 0; list < 2; ++list) {
        if (shares > 2) {
          k.sorter.sort(k.gathered[list], total[list], id_limit, k.stream);
          continue;
        }
        const std::size_t first = own_count[list], second = total[list] - first;
        if (first == 0 || second == 0) continue;
        k.merged[list].resize_discard(total[list]);
        const FeatureHit<T>* a = k.gathered[list].data();
        std::size_t bytes = 0;
        LWSCCD_CUDA_CHECK(cub::DeviceMerge::MergeKeys(nullptr, bytes, a, static_cast<std::int64_t>(first), a + first,
                                                      static_cast<std::int64_t>(second), k.merged[list].data(),
                                                      detail::HitPairLess{}, k.stream));
        k.merge_scratch.resize_discard(std::max<std::size_t>(bytes, 1));
        LWSCCD_CUDA_CHECK(cub::DeviceMerge::MergeKeys(k.merge_scratch.data(), bytes, a, static_cast<std::int64_t>(first), a + first,
                                                      static_cast<std::int64_t>(second), k.merged[list].data(),
                                                      detail::HitPairLess{}, k.stream));
        std::swap(k.gathered[list], k.merged[list]);
      }
      DeviceContacts<T>& c = gathered_;
      c.vf = k.gathered[0].data();
      c.ee = k.gathered[1].data();
      c.num_vf = total[0];
      c.num_ee = total[1];
      c.earliest_toi = k.host_earliest[0];
    } else if (r == 0) {
      gathered_ = DeviceContacts<T>{};
      gathered_.earliest_toi = k.host_earliest[0];
    }
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(k.stream));
  }

  // The same decision on every rank from the same exchange: rebuild everywhere if one share's
  // tree decayed, restart everywhere if one wants to; else move front entries from the busiest
  // share to the least busy one.
  void agree_on_next_step(Rank& k, std::size_t r) {
    const std::size_t shares = share_count_, me = first_rank_ + r;
    bool rebuild = false, restart = false;
    std::size_t busiest = 0, idlest = 0;
    std::vector<double> busy(shares);
    std::vector<std::size_t> front(shares);
    for (std::size_t s = 0; s < shares; ++s) {
      const double* d = k.host_exchange.data() + s * detail::kPackedStats;
      rebuild = rebuild || d[detail::kPackedRebuild] != 0;
      restart = restart || d[detail::kPackedRestart] != 0;
      busy[s] = d[detail::kPackedDone];
      front[s] = static_cast<std::size_t>(d[detail::kPackedFront]);
      if (busy[s] > busy[busiest]) busiest = s;
      if (busy[s] < busy[idlest]) idlest = s;
    }
    std::size_t move = 0;
    if (rebuild) k.pipeline->rebuild_next();
    if (restart || rebuild) {
      k.pipeline->restart_from_root();
    } else if (busiest != idlest && busy[busiest] > (1 + MultiGpuPolicy::kImbalance) * busy[idlest]) {
      const double excess = (busy[busiest] - busy[idlest]) / (2 * busy[busiest]);
      move = static_cast<std::size_t>(MultiGpuPolicy::kMoveDamping * excess * static_cast<double>(front[busiest]));
    }
    if (r == 0) moved_ = move;
    if (move == 0 || (me != busiest && me != idlest)) return;
    Pipeline& p = *k.pipeline;
    const auto use = nccl_use();
    if (me == busiest) {
      const std::size_t keep = p.kept_front_size() - move;
      LWSCCD_NCCL_CHECK(ncclSend(p.kept_front() + keep, move * sizeof(NodePair), ncclUint8, static_cast<int>(idlest), k.comm, k.stream));
      p.resize_kept_front(keep, k.stream);
    } else {
      const std::size_t had = p.kept_front_size();
      p.resize_kept_front(had + move, k.stream);
      LWSCCD_NCCL_CHECK(ncclRecv(p.kept_front() + had, move * sizeof(NodePair), ncclUint8, static_cast<int>(busiest), k.comm, k.stream));
    }
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(k.stream));
  }

  // Device bytes a rank holds beside its pipeline.
  static std::size_t wrapper_bytes(const Rank& k) {
    return k.xd[0].capacity_bytes() + k.xd[1].capacity_bytes() + k.xf[0].capacity_bytes() + k.xf[1].capacity_bytes() +
           k.exchange.capacity_bytes() + k.earliest.capacity_bytes() + k.gathered[0].capacity_bytes() +
           k.gathered[1].capacity_bytes() + k.merged[0].capacity_bytes() + k.merged[1].capacity_bytes() +
           k.merge_scratch.capacity_bytes() + k.sorter.device_bytes();
  }

  void download(NarrowPhaseResult<T>& out) {
    const DeviceContacts<T>& c = gathered_;
    out.earliest_toi = c.earliest_toi;
    out.gave_up = c.gave_up;
    out.vf_counts = c.vf_counts;
    out.ee_counts = c.ee_counts;
    if (first_rank_ != 0) return;  // (one process per GPU: rank 0's process holds the contacts)
    Rank& k = *ranks_[0];
    detail::CurrentDeviceGuard guard;
    LWSCCD_CUDA_CHECK(cudaSetDevice(workers_.device(0)));
    out.vf.resize(c.num_vf);
    out.ee.resize(c.num_ee);
    if (c.num_vf) HostStaging<>::to_host(out.vf.data(), c.vf, c.num_vf * sizeof(FeatureHit<T>), k.stream);
    if (c.num_ee) HostStaging<>::to_host(out.ee.data(), c.ee, c.num_ee * sizeof(FeatureHit<T>), k.stream);
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(k.stream));
  }

  detail::DeviceWorkers workers_;
  std::vector<std::unique_ptr<Rank>> ranks_;  ///< each made and destroyed on its GPU's thread
  std::size_t share_count_ = 1, first_rank_ = 0;
  DeviceContacts<T> gathered_;
  std::vector<StepStats> device_stats_;
  std::size_t moved_ = 0;
  MultiGpuTimes times_;
  std::atomic<bool> aborted_{false};  ///< a step failed on one GPU: the communicators were aborted
  std::shared_mutex nccl_mutex_;       ///< NCCL calls (shared) against an abort (exclusive)
};

}  // namespace lwsccd::gpu
