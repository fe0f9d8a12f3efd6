// lwsccd — owning device memory (RAII) with library-wide accounting of bytes in use and peak.
#pragma once

#include <cuda_runtime.h>

#include <atomic>
#include <cstddef>
#include <string>
#include <vector>

#include "lwsccd/error.hpp"

#include "lwsccd/cuda_check.cuh"

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

}  // namespace lwsccd::gpu
