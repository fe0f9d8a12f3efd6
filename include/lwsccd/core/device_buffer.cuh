// lwsccd — owning device memory (RAII) with library-wide accounting of bytes in use and peak.
#pragma once

#include <cuda_runtime.h>

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "lwsccd/core/error.hpp"
#include "lwsccd/geometry/mesh.hpp"  // index_t

#include "lwsccd/core/cuda_check.cuh"

namespace lwsccd::gpu {

/// Bytes of device memory held by lwsccd objects now, and the most held at once.
struct MemoryStats {
  std::size_t in_use = 0;
  std::size_t peak = 0;
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
// Refuses an allocation that would take the library past the budget (before cudaMalloc).
inline void check_budget(std::size_t bytes) {
  const std::size_t in_use = bytes_in_use().load(), budget = bytes_budget().load();
  if (bytes > budget || in_use > budget - bytes)
    throw Error("lwsccd: device memory budget exceeded: an allocation of " + std::to_string(bytes) + " bytes with " +
                std::to_string(in_use) + " in use would pass the budget of " + std::to_string(budget) +
                " bytes (gpu::set_memory_budget)");
}
inline void account_alloc(std::size_t bytes) {
  const std::size_t now = bytes_in_use().fetch_add(bytes) + bytes;
  std::size_t peak = bytes_peak().load();
  while (now > peak && !bytes_peak().compare_exchange_weak(peak, now)) {
  }
}
inline void account_free(std::size_t bytes) { bytes_in_use().fetch_sub(bytes); }
}  // namespace detail

inline MemoryStats memory_stats() { return {detail::bytes_in_use().load(), detail::bytes_peak().load()}; }
/// Caps the device memory all lwsccd objects may hold together; an allocation past it throws
/// lwsccd::Error (nothing is allocated then). Default: no cap.
inline void set_memory_budget(std::size_t bytes) { detail::bytes_budget().store(bytes); }
inline std::size_t memory_budget() { return detail::bytes_budget().load(); }
/// Restarts the peak at the current use (for measuring one phase).
inline void reset_peak_memory() { detail::bytes_peak().store(detail::bytes_in_use().load()); }

/// A typed device array. Growing discards the contents (callers refill what they grow).
template <class T>
class DeviceBuffer {
 public:
  DeviceBuffer() = default;
  explicit DeviceBuffer(std::size_t n) { resize_discard(n); }
  ~DeviceBuffer() { release(); }
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  DeviceBuffer(DeviceBuffer&& o) noexcept : ptr_(o.ptr_), size_(o.size_), capacity_(o.capacity_) {
    o.ptr_ = nullptr;
    o.size_ = o.capacity_ = 0;
  }
  DeviceBuffer& operator=(DeviceBuffer&& o) noexcept {
    if (this != &o) {
      release();
      ptr_ = o.ptr_;
      size_ = o.size_;
      capacity_ = o.capacity_;
      o.ptr_ = nullptr;
      o.size_ = o.capacity_ = 0;
    }
    return *this;
  }

  /// Sets the size to n, reallocating (contents lost) only when n exceeds the capacity.
  void resize_discard(std::size_t n) {
    if (n > capacity_) {
      release();
      detail::check_budget(n * sizeof(T));
      LWSCCD_CUDA_CHECK(cudaMalloc(&ptr_, n * sizeof(T)));
      capacity_ = n;
      detail::account_alloc(capacity_ * sizeof(T));
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
  std::size_t capacity_bytes() const { return capacity_ * sizeof(T); }

 private:
  void release() noexcept {
    if (ptr_) {
      cudaFree(ptr_);  // never throws from a destructor; a failure here means a dead context
      detail::account_free(capacity_ * sizeof(T));
    }
    ptr_ = nullptr;
    size_ = capacity_ = 0;
  }

  T* ptr_ = nullptr;
  std::size_t size_ = 0;
  std::size_t capacity_ = 0;
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
