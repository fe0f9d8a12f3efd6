// lwsccd — owning device memory (RAII) with library-wide accounting of bytes in use and peak.
#pragma once

#include <cuda_runtime.h>

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "lwsccd/core/error.hpp"
#include "lwsccd/geometry/mesh.hpp"  // index_t

#include "lwsccd/core/cuda_check.cuh"

namespace lwsccd::gpu {

/// Bytes of device memory held by lwsccd objects now, and the most held at once; `cached`: blocks
/// the objects gave back, kept by the process for the next ones (gpu::release_cached_memory());
/// `reserved`: the process's shared slabs' memory that no object holds (small blocks are cut from
/// slabs of 32 MiB, one cudaMalloc for many: their room not cut yet and the pieces given back).
struct MemoryStats {
  std::size_t in_use = 0;
  std::size_t peak = 0;
  std::size_t cached = 0;
  std::size_t reserved = 0;
  /// cudaMalloc calls lwsccd has made in this process (a block from the cache or cut from a slab
  /// makes none): what a first step on new memory pays for, ~60-100 us each.
  std::size_t allocations = 0;
};

namespace detail {
inline std::atomic<std::size_t>& bytes_in_use() {
  static std::atomic<std::size_t> v{0};
  return v;
}
inline std::atomic<std::size_t>& bytes_peak() {
  static std::atomic<std::size_t> v{0};
  return v;
}
inline std::atomic<std::size_t>& bytes_budget() {
  static std::atomic<std::size_t> v{~std::size_t(0)};
  return v;
}
inline std::atomic<std::size_t>& bytes_cached() {
  static std::atomic<std::size_t> v{0};
  return v;
}
inline std::atomic<std::size_t>& bytes_reserved() {
  static std::atomic<std::size_t> v{0};
  return v;
}
inline std::atomic<std::size_t>& allocation_calls() {
  static std::atomic<std::size_t> v{0};
  return v;
}
inline std::atomic<bool>& caching_enabled() {
  static std::atomic<bool> v{true};
  return v;
}
inline void account_alloc(std::size_t bytes) {
  const std::size_t now = bytes_in_use().fetch_add(bytes) + bytes;
  std::size_t peak = bytes_peak().load();
  while (now > peak && !bytes_peak().compare_exchange_weak(peak, now)) {
  }
}
inline void account_free(std::size_t bytes) { bytes_in_use().fetch_sub(bytes); }

// The process's cache of device blocks that lwsccd objects gave back, per device, so that a
// pipeline made after others starts with their memory and a buffer that grows does not pay
// cudaFree's device-wide wait. Stream-safe without knowing the streams: a given-back block may
// still be read by work enqueued before; it serves a request only after a device-wide
// synchronisation that came after it was given back (one cudaDeviceSynchronize makes every block
// given back until then reusable; cudaFree waited as much for each block). A block serves only a
// request of its exact size (a pipeline on the same scene asks for the same sizes), so what
// objects hold stays what they asked for, byte for byte (the budget's accounting). Freed when the
// process ends, on gpu::release_cached_memory(), when cudaMalloc fails, and where a memory budget
// needs their room.
//
// A new block of at most a quarter of the device's next slab is cut from a slab (one cudaMalloc
// for many) instead of a cudaMalloc of its own. Why: cudaMalloc costs ~60-100 us a call whatever
// the size (H200, 1 MiB to 1 GiB), and a pipeline's first step on new memory makes dozens of
// requests, each on the step's path. A device's slabs double while it holds them (kSlabBytes,
// then twice that, up to kMaxSlabBytes), so a first step of a larger scene makes a few calls,
// not one per buffer. A new piece is cut where a held slab has room (the first by address); a
// slab is opened only for a block none has room for, so the room not cut is at most the newest
// slab plus less than half of each older one. Slab memory no object holds (room not cut yet,
// pieces given back) is `reserved`, outside a memory budget's count (under a budget no new slab
// is made); pieces given back serve requests of their size as any cached block; a slab is freed
// (release_all) once none of its pieces is held.
class DevicePool {
 public:
  struct Block {
    void* ptr = nullptr;
    std::size_t bytes = 0;
  };
  static constexpr std::size_t kSlabBytes = std::size_t(32) << 20;      ///< a device's first slab
  static constexpr std::size_t kMaxSlabBytes = std::size_t(256) << 20;  ///< the slabs' growth stops here
  static constexpr std::size_t kCutShare = 4;  ///< blocks up to 1 / kCutShare of the next slab are cut
  static constexpr std::size_t kCarveAlign = 256;  // (cudaMalloc's alignment)

  // Destroyed at exit before the CUDA runtime's own teardown: its constructor makes a CUDA call
  // first, which registers that teardown earlier (so the blocks are freed; memory checkers see no
  // leak).
  static DevicePool& instance() {
    static DevicePool pool;
    return pool;
  }
  static bool alive() { return alive_flag().load(); }

  // A block of `bytes` on the current device.
  Block allocate(std::size_t bytes) {
    const std::size_t size = bytes;
    int device = 0;
    LWSCCD_CUDA_CHECK(cudaGetDevice(&device));
    // A block given back since the last wait needs one (for all of them). The wait is made without
    // the lock: another thread driving another GPU (gpu::MultiGpuPipeline) may have to allocate
    // before this device's work (a collective waiting for that GPU) can end.
    for (int attempt = 0; attempt < 2; ++attempt) {
      std::uint64_t releases = 0;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        PerDevice& d = of(device);
        auto range = d.blocks.equal_range(size);
        if (range.first == range.second) break;
        auto safe = range.first;
        while (safe != range.second && safe->second.released > d.synced) ++safe;
        if (safe != range.second) {
          Block b{safe->second.ptr, size};
          d.blocks.erase(safe);
          if (Slab* slab = slab_of(d, b.ptr)) ++slab->pieces_held, bytes_reserved().fetch_sub(size);
          else bytes_cached().fetch_sub(size);
          return b;
        }
        releases = d.releases;
      }
      if (attempt == 1) break;
      LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
      std::lock_guard<std::mutex> lock(mutex_);
      PerDevice& d = of(device);
      d.synced = std::max(d.synced, releases);  // (what was given back before the wait)
    }
    // (Under a memory budget only from a slab's room already held: no new slab.)
    if (caching_enabled().load()) {
      if (void* piece = carve(device, size, bytes_budget().load() == ~std::size_t(0))) return {piece, size};
    }
    return {new_memory(device, size), size};
  }

  // Takes back a block of `device` (never throws: called from destructors). A slab's piece is
  // always cached (it cannot be freed alone; release_all frees its slab).
  void give_back(void* ptr, std::size_t bytes, int device) noexcept {
    bool free_now = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      PerDevice& d = of_existing(device);
      Slab* slab = slab_of(d, ptr);
      if (slab) --slab->pieces_held;
      if (!slab && !caching_enabled().load()) {
        free_now = true;
      } else {
        try {
          d.blocks.emplace(bytes, Cached{ptr, ++d.releases});
          (slab ? bytes_reserved() : bytes_cached()).fetch_add(bytes);
        } catch (...) {
          free_now = !slab;  // (no room to remember it; a slab's piece is lost until its slab is freed)
        }
      }
    }
    if (free_now) cudaFree(ptr);  // (its device-wide wait without the lock: see allocate)
  }

  // Frees every cached block of `device` (-1: of every device) after a device-wide wait.
  void release_all(int device = -1) {
    std::lock_guard<std::mutex> lock(mutex_);
    int current = 0;
    LWSCCD_CUDA_CHECK(cudaGetDevice(&current));
    for (std::size_t k = 0; k < devices_.size(); ++k) {
      if ((device >= 0 && static_cast<int>(k) != device) || (devices_[k].blocks.empty() && devices_[k].slabs.empty())) continue;
      LWSCCD_CUDA_CHECK(cudaSetDevice(static_cast<int>(k)));
      LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
      PerDevice& d = devices_[k];
      // Every cached block goes, but the pieces of a slab that still has pieces held: they stay
      // cached (they cannot be freed alone); a slab with none held goes whole.
      for (auto it = d.blocks.begin(); it != d.blocks.end();) {
        const Slab* slab = slab_of(d, it->second.ptr);
        if (slab && slab->pieces_held > 0) {
          ++it;
          continue;
        }
        if (!slab) LWSCCD_CUDA_CHECK(cudaFree(it->second.ptr));
        (slab ? bytes_reserved() : bytes_cached()).fetch_sub(it->first);
        it = d.blocks.erase(it);
      }
      d.synced = d.releases;
      for (auto it = d.slabs.begin(); it != d.slabs.end();) {
        if (it->second.pieces_held > 0) {
          ++it;
          continue;
        }
        LWSCCD_CUDA_CHECK(cudaFree(it->first));
        bytes_reserved().fetch_sub(it->second.bytes - it->second.used);
        it = d.slabs.erase(it);
      }
    }
    LWSCCD_CUDA_CHECK(cudaSetDevice(current));
  }

  DevicePool(const DevicePool&) = delete;
  DevicePool& operator=(const DevicePool&) = delete;

 private:
  struct Cached {
    void* ptr;
    std::uint64_t released;  ///< the device's count of blocks given back, when this one was
  };
  struct Slab {
    std::size_t bytes = 0;        ///< its size
    std::size_t used = 0;         ///< bytes cut from its start
    std::size_t pieces_held = 0;  ///< pieces held by objects (not in the cache)
  };
  struct PerDevice {
    std::multimap<std::size_t, Cached> blocks;
    std::uint64_t releases = 0;  ///< blocks given back so far
    std::uint64_t synced = 0;    ///< of those, the ones given back before the last wait
    std::map<char*, Slab> slabs;  ///< by base address
    // The size of the slab it would open next: doubled for each slab it holds, at most kMaxSlabBytes.
    std::size_t next_slab_bytes() const {
      std::size_t bytes = kSlabBytes;
      for (std::size_t k = 0; k < slabs.size() && bytes < kMaxSlabBytes; ++k) bytes *= 2;
      return bytes;
    }
  };

  // A new cudaMalloc of `size` bytes on the current device (the cache's blocks freed first where
  // it fails, then once more).
  void* new_memory(int device, std::size_t size) {
    void* ptr = nullptr;
    allocation_calls().fetch_add(1);
    cudaError_t e = cudaMalloc(&ptr, size);
    if (e == cudaErrorMemoryAllocation) {
      (void)cudaGetLastError();
      release_all(device);
      allocation_calls().fetch_add(1);
      e = cudaMalloc(&ptr, size);
    }
    LWSCCD_CUDA_CHECK(e);
    return ptr;
  }
  // A piece of `size` bytes cut from a slab of the device with room; where none has, from a new
  // slab if `may_open`; null where the block is too large to be cut (more than a kCutShare-th of
  // the next slab) or no slab may be opened.
  void* carve(int device, std::size_t size, bool may_open) {
    const std::size_t cut = (size + kCarveAlign - 1) / kCarveAlign * kCarveAlign;
    std::size_t slab_bytes = 0;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      PerDevice& d = of(device);
      slab_bytes = d.next_slab_bytes();
      if (cut > slab_bytes / kCutShare) return nullptr;
      for (auto& [base, slab] : d.slabs)
        if (slab.used + cut <= slab.bytes) return cut_from(base, slab, cut);
    }
    if (!may_open) return nullptr;
    char* base = static_cast<char*>(new_memory(device, slab_bytes));
    std::lock_guard<std::mutex> lock(mutex_);
    PerDevice& d = of(device);
    Slab& slab = d.slabs[base];
    slab.bytes = slab_bytes;
    bytes_reserved().fetch_add(slab_bytes);
    return cut_from(base, slab, cut);
  }
  static void* cut_from(char* base, Slab& slab, std::size_t cut) {
    void* piece = base + slab.used;
    slab.used += cut;
    ++slab.pieces_held;
    bytes_reserved().fetch_sub(cut);
    return piece;
  }
  // The slab holding ptr, or null.
  static Slab* slab_of(PerDevice& d, const void* ptr) {
    if (d.slabs.empty()) return nullptr;
    auto it = d.slabs.upper_bound(static_cast<char*>(const_cast<void*>(ptr)));
    if (it == d.slabs.begin()) return nullptr;
    --it;
    const char* p = static_cast<const char*>(ptr);
    return p < it->first + it->second.bytes ? &it->second : nullptr;
  }
  DevicePool() {
    int device = 0;
    (void)cudaGetDevice(&device);  // (initializes the runtime; a failure shows at the first allocation)
    alive_flag().store(true);
  }
  ~DevicePool() {
    alive_flag().store(false);
    for (auto& d : devices_) {  // (errors ignored: the process is ending)
      for (auto& [size, c] : d.blocks)
        if (!slab_of(d, c.ptr)) cudaFree(c.ptr);
      for (auto& [base, slab] : d.slabs) cudaFree(base);
    }
  }
  static std::atomic<bool>& alive_flag() {
    static std::atomic<bool> v{false};
    return v;
  }
  PerDevice& of(int device) {
    if (static_cast<std::size_t>(device) >= devices_.size()) devices_.resize(static_cast<std::size_t>(device) + 1);
    return devices_[static_cast<std::size_t>(device)];
  }
  // A device that allocated before (no allocation: give_back never throws).
  PerDevice& of_existing(int device) { return devices_[static_cast<std::size_t>(device)]; }

  std::mutex mutex_;
  std::vector<PerDevice> devices_;
};

// Refuses an allocation that would take the library past the budget (before any allocation).
// Cached blocks count as held: where they stand in the way they are freed first.
inline void check_budget(std::size_t bytes) {
  const std::size_t budget = bytes_budget().load();
  auto exceeds = [&] {
    const std::size_t held = bytes_in_use().load() + bytes_cached().load();
    return bytes > budget || held > budget - bytes;
  };
  if (!exceeds()) return;
  // The current device's cached blocks only: freeing another's would wait for that GPU, whose work
  // may wait for this thread (a collective of gpu::MultiGpuPipeline).
  int device = 0;
  LWSCCD_CUDA_CHECK(cudaGetDevice(&device));
  if (bytes_cached().load() > 0 || bytes_reserved().load() > 0) DevicePool::instance().release_all(device);
  if (!exceeds()) return;
  const std::size_t in_use = bytes_in_use().load();
  throw Error("lwsccd: device memory budget exceeded: an allocation of " + std::to_string(bytes) + " bytes with " +
              std::to_string(in_use) + " in use would pass the budget of " + std::to_string(budget) +
              " bytes (gpu::set_memory_budget)");
}
}  // namespace detail

inline MemoryStats memory_stats() {
  return {detail::bytes_in_use().load(), detail::bytes_peak().load(), detail::bytes_cached().load(),
          detail::bytes_reserved().load(), detail::allocation_calls().load()};
}
/// Caps the device memory all lwsccd objects may hold together, the process's cached blocks
/// included (the current device's are freed first where they stand in the way; another device's
/// only by release_cached_memory(), which waits for that device); an allocation past it throws
/// lwsccd::Error (nothing is allocated then). Default: no cap. Under a cap no new slab is made
/// (small blocks come only from slabs already held, whose free memory is not counted:
/// memory_stats().reserved).
inline void set_memory_budget(std::size_t bytes) { detail::bytes_budget().store(bytes); }
inline std::size_t memory_budget() { return detail::bytes_budget().load(); }
/// Restarts the peak at the current use (for measuring one phase).
inline void reset_peak_memory() { detail::bytes_peak().store(detail::bytes_in_use().load()); }
/// Frees the device blocks lwsccd objects gave back and the process kept for later ones (after a
/// device-wide synchronisation), on every device: for a program that is done with lwsccd for now.
inline void release_cached_memory() {
  if (detail::bytes_cached().load() > 0 || detail::bytes_reserved().load() > 0) detail::DevicePool::instance().release_all();
}
/// Whether blocks lwsccd objects give back are kept for later ones (default: true). Off, they are
/// freed at once (cudaFree, as a program that shares the device tightly may prefer); turning it
/// off does not free what is cached (release_cached_memory()).
inline void set_memory_caching(bool enabled) { detail::caching_enabled().store(enabled); }

/// A typed device array. Growing discards the contents (callers refill what they grow).
template <class T>
class DeviceBuffer {
 public:
  DeviceBuffer() = default;
  explicit DeviceBuffer(std::size_t n) { resize_discard(n); }
  ~DeviceBuffer() { release(); }
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  DeviceBuffer(DeviceBuffer&& o) noexcept
      : ptr_(o.ptr_), size_(o.size_), capacity_(o.capacity_), bytes_(o.bytes_), device_(o.device_) {
    o.ptr_ = nullptr;
    o.size_ = o.capacity_ = o.bytes_ = 0;
  }
  DeviceBuffer& operator=(DeviceBuffer&& o) noexcept {
    if (this != &o) {
      release();
      ptr_ = o.ptr_;
      size_ = o.size_;
      capacity_ = o.capacity_;
      bytes_ = o.bytes_;
      device_ = o.device_;
      o.ptr_ = nullptr;
      o.size_ = o.capacity_ = o.bytes_ = 0;
    }
    return *this;
  }

  /// Sets the size to n, reallocating (contents lost) only when n exceeds the capacity. The
  /// block comes from the process's cache where it holds one of the size (detail::DevicePool).
  void resize_discard(std::size_t n) {
    if (n > capacity_) {
      release();
      detail::check_budget(n * sizeof(T));
      const detail::DevicePool::Block block = detail::DevicePool::instance().allocate(n * sizeof(T));
      LWSCCD_CUDA_CHECK(cudaGetDevice(&device_));
      ptr_ = static_cast<T*>(block.ptr);
      bytes_ = block.bytes;
      capacity_ = block.bytes / sizeof(T);
      detail::account_alloc(bytes_);
    }
    size_ = n;
  }
  void upload(const T* host, std::size_t n, cudaStream_t stream = nullptr) {
    resize_discard(n);
    if (n) LWSCCD_CUDA_CHECK(cudaMemcpyAsync(ptr_, host, n * sizeof(T), cudaMemcpyHostToDevice, stream));
  }
  void upload(const std::vector<T>& host, cudaStream_t stream = nullptr) { upload(host.data(), host.size(), stream); }
  /// Synchronous copy to the host (waits for `stream`).
  std::vector<T> download(cudaStream_t stream = nullptr) const {
    std::vector<T> out(size_);
    if (size_) {
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(out.data(), ptr_, size_ * sizeof(T), cudaMemcpyDeviceToHost, stream));
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
    }
    return out;
  }

  /// Sets the size to n keeping the first size() elements: reallocates (to grow_to elements, at
  /// least n) only when n exceeds the capacity, copying them over on `stream`.
  void resize_keep(std::size_t n, std::size_t grow_to = 0, cudaStream_t stream = nullptr) {
    if (n > capacity_) {
      DeviceBuffer bigger(std::max(n, grow_to));
      if (size_) LWSCCD_CUDA_CHECK(cudaMemcpyAsync(bigger.ptr_, ptr_, size_ * sizeof(T), cudaMemcpyDeviceToDevice, stream));
      std::swap(ptr_, bigger.ptr_);
      std::swap(capacity_, bigger.capacity_);
      std::swap(bytes_, bigger.bytes_);
      std::swap(device_, bigger.device_);
    }
    size_ = n;
  }
  /// Synchronous copy of the first n elements to the host (waits for `stream`).
  std::vector<T> download_prefix(std::size_t n, cudaStream_t stream = nullptr) const {
    std::vector<T> out(n);
    if (n) {
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(out.data(), ptr_, n * sizeof(T), cudaMemcpyDeviceToHost, stream));
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
    }
    return out;
  }

  T* data() { return ptr_; }
  const T* data() const { return ptr_; }
  std::size_t size() const { return size_; }
  std::size_t capacity_bytes() const { return bytes_; }

 private:
  void release() noexcept {
    if (ptr_) {
      // Never throws from a destructor; after the pool's end (a static object destroyed later)
      // straight to cudaFree, whose failure here would mean a dead context.
      if (detail::DevicePool::alive()) detail::DevicePool::instance().give_back(ptr_, bytes_, device_);
      else cudaFree(ptr_);
      detail::account_free(bytes_);
    }
    ptr_ = nullptr;
    size_ = capacity_ = bytes_ = 0;
  }

  T* ptr_ = nullptr;
  std::size_t size_ = 0;
  std::size_t capacity_ = 0;
  std::size_t bytes_ = 0;  ///< the block's size (capacity_ elements)
  int device_ = 0;
};


/// Page-locked host memory (RAII): the target of asynchronous copies of counts, read after a sync.
template <class T>
class PinnedBuffer {
 public:
  PinnedBuffer() = default;
  explicit PinnedBuffer(std::size_t n) : size_(n) {
    void* p = nullptr;
    LWSCCD_CUDA_CHECK(cudaMallocHost(&p, n * sizeof(T)));
    ptr_ = static_cast<T*>(p);
    for (std::size_t i = 0; i < n; ++i) ptr_[i] = T{};
  }
  ~PinnedBuffer() {
    if (ptr_) cudaFreeHost(ptr_);  // never throws from a destructor
  }
  PinnedBuffer(const PinnedBuffer&) = delete;
  PinnedBuffer& operator=(const PinnedBuffer&) = delete;
  PinnedBuffer(PinnedBuffer&& o) noexcept : ptr_(o.ptr_), size_(o.size_) { o.ptr_ = nullptr, o.size_ = 0; }
  PinnedBuffer& operator=(PinnedBuffer&& o) noexcept {
    std::swap(ptr_, o.ptr_);
    std::swap(size_, o.size_);
    return *this;
  }
  /// Allocates (zeroed) when it holds fewer than n elements. Owners allocate on first use, so that
  /// constructing them needs no CUDA device (a program may build one and fall back to the CPU).
  void ensure(std::size_t n) {
    if (size_ < n) *this = PinnedBuffer(n);
  }
  T* data() { return ptr_; }
  const T* data() const { return ptr_; }
  T& operator[](std::size_t i) { return ptr_[i]; }
  const T& operator[](std::size_t i) const { return ptr_[i]; }
  std::size_t size() const { return size_; }

 private:
  T* ptr_ = nullptr;
  std::size_t size_ = 0;
};

/// The length of a device list that is known only on the device (written by an earlier kernel:
/// no host round trip), bounded by the room its buffer has. `word` null: the length is `room`.
/// Packed words hold two 32-bit counts (FeatureEmitter: vertex-face high, edge-edge low).
struct DeviceCount {
  enum class Part : unsigned char { whole, high, low };
  const unsigned long long* word = nullptr;
  Part part = Part::whole;
  std::size_t room = 0;

  /// A length known on the host.
  static DeviceCount known(std::size_t n) { return {nullptr, Part::whole, n}; }
  __device__ std::size_t get() const {
    if (!word) return room;
    unsigned long long v = *word;
    if (part == Part::high) v >>= 32;
    else if (part == Part::low) v &= 0xffffffffull;
    return v < room ? static_cast<std::size_t>(v) : room;
  }
};

/// A device list of candidate feature pairs and its length (known on the host, or left on the
/// device by an earlier stage such as gpu::FeatureEmitter).
struct PairList {
  const std::pair<index_t, index_t>* pairs = nullptr;
  DeviceCount count;
};

}  // namespace lwsccd::gpu
