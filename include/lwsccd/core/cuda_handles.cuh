// lwsccd — owners of CUDA events and streams: move-only, each destroys its handle with itself, so
// an object that holds several leaks none when its constructor throws half-way, and moves with
// its owner. Each converts to the raw handle, for the runtime calls that take one.
#pragma once

#include <cuda_runtime.h>

#include <utility>

#include "lwsccd/core/cuda_check.cuh"

namespace lwsccd::gpu {

/// A cudaEvent_t, created with the given flags (cudaEventDefault times; cudaEventDisableTiming
/// only orders), destroyed with the owner. Default-constructed: no event yet.
class CudaEvent {
 public:
  CudaEvent() = default;
  explicit CudaEvent(unsigned flags) { LWSCCD_CUDA_CHECK(cudaEventCreateWithFlags(&event_, flags)); }
  CudaEvent(CudaEvent&& other) noexcept : event_(std::exchange(other.event_, nullptr)) {}
  CudaEvent& operator=(CudaEvent&& other) noexcept {
    if (this != &other) {
      release();
      event_ = std::exchange(other.event_, nullptr);
    }
    return *this;
  }
  CudaEvent(const CudaEvent&) = delete;
  CudaEvent& operator=(const CudaEvent&) = delete;
  ~CudaEvent() { release(); }

  cudaEvent_t get() const { return event_; }
  operator cudaEvent_t() const { return event_; }  // NOLINT: used where the runtime takes the handle

 private:
  // (Not checked: a destructor does not throw; a failure shows in the next checked call.)
  void release() noexcept {
    if (event_) cudaEventDestroy(event_);
    event_ = nullptr;
  }
  cudaEvent_t event_ = nullptr;
};

/// A cudaStream_t of its own, created with the given flags (cudaStreamNonBlocking: not ordered
/// with the legacy default stream), destroyed with the owner. Default-constructed: no stream yet
/// (not the default stream: it converts to a null handle, which the runtime reads as that).
class CudaStream {
 public:
  CudaStream() = default;
  explicit CudaStream(unsigned flags) { LWSCCD_CUDA_CHECK(cudaStreamCreateWithFlags(&stream_, flags)); }
  CudaStream(CudaStream&& other) noexcept : stream_(std::exchange(other.stream_, nullptr)) {}
  CudaStream& operator=(CudaStream&& other) noexcept {
    if (this != &other) {
      release();
      stream_ = std::exchange(other.stream_, nullptr);
    }
    return *this;
  }
  CudaStream(const CudaStream&) = delete;
  CudaStream& operator=(const CudaStream&) = delete;
  ~CudaStream() { release(); }

  cudaStream_t get() const { return stream_; }
  operator cudaStream_t() const { return stream_; }  // NOLINT: used where the runtime takes the handle
  explicit operator bool() const { return stream_ != nullptr; }

 private:
  void release() noexcept {
    if (stream_) cudaStreamDestroy(stream_);
    stream_ = nullptr;
  }
  cudaStream_t stream_ = nullptr;
};

}  // namespace lwsccd::gpu
