// lwsccd — copies between pageable host memory (a caller's std::vector, a NumPy array) and device
// memory through a few page-locked chunks: the host copies one chunk (on several threads when it
// is large) while the copy engine moves the one before. A copy from pageable memory goes through
// the driver's own staging, one thread and one chunk at a time; this one keeps both the copy engine
// and the host's cores busy, and an upload returns before its last chunks have crossed.
//
// The chunks are shared by every copy of the process on a device (borrowed for one copy, each with
// the event of its last use): page-locking memory is slow (a new pipeline that locked its own
// 6 MB took ~3 ms longer over its first step), so it is done once per device and process.
#pragma once

#include <cuda_runtime.h>

#include <algorithm>
#include <cstddef>
#include <cstring>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

#include "lwsccd/core/cuda_check.cuh"
#include "lwsccd/core/cuda_handles.cuh"
#include "lwsccd/core/parallel.hpp"

namespace lwsccd::gpu {

/// Tuning of HostStaging (override by deriving and naming the knobs).
struct HostStagingPolicy {
  /// Bytes of a page-locked chunk at most; a copy uses up to kChunks of them at once, each the
  /// power of two that holds the copy, up to this (H200 host, the built-in 10 M scene's 240 MB of
  /// positions a step: 8 MiB chunks 7.1 ms over the stages, 2 MiB ones 14).
  static constexpr std::size_t kChunkBytes = std::size_t(8) << 20;
  static constexpr int kChunks = 3;
  /// Uploads of fewer bytes go straight from pageable memory: the driver's one-thread staging
  /// does as well up to a few MiB (H200 host: 2.2 MB pageable 0.155 ms, through page-locked
  /// memory 0.20; 240 MB 27 ms against 12 on eight threads).
  static constexpr std::size_t kDirectUploadBytes = std::size_t(4) << 20;
  /// Downloads of fewer bytes go straight to pageable memory. Larger ones cross to page-locked
  /// memory at the copy engine's speed (64 MiB in 1.24 ms, against 35 into pageable memory).
  static constexpr std::size_t kDirectDownloadBytes = std::size_t(64) << 10;
  /// Host copies of a chunk are split across threads in ranges of at least this many bytes.
  static constexpr std::size_t kThreadBytes = std::size_t(256) << 10;
};

namespace detail {

// A page-locked chunk (of `bytes`, or more) and the event recorded after its last copy (to or from the device): whoever
// borrows it next waits for that event before touching the memory.
struct StagingChunk {
  struct FreeHost {
    void operator()(unsigned char* p) const noexcept { cudaFreeHost(p); }  // (a destructor does not throw)
  };
  std::unique_ptr<unsigned char, FreeHost> memory;
  std::size_t bytes = 0;
  CudaEvent crossed{cudaEventDisableTiming};

  explicit StagingChunk(std::size_t n) : bytes(n) {
    void* p = nullptr;
    LWSCCD_CUDA_CHECK(cudaMallocHost(&p, n));
    memory.reset(static_cast<unsigned char*>(p));
  }
};

// The chunks not borrowed now, per device (an event belongs to the device it was made on), kept
// until the process ends.
class StagingChunkPool {
 public:
  std::unique_ptr<StagingChunk> take(std::size_t bytes) {
    int device = 0;
    LWSCCD_CUDA_CHECK(cudaGetDevice(&device));
    {
      std::lock_guard<std::mutex> lock(mutex_);
      std::vector<std::unique_ptr<StagingChunk>>& free = free_[device];
      for (std::size_t i = free.size(); i-- > 0;)
        if (free[i]->bytes >= bytes) {
          std::unique_ptr<StagingChunk> c = std::move(free[i]);
          free.erase(free.begin() + static_cast<std::ptrdiff_t>(i));
          return c;
        }
    }
    return std::make_unique<StagingChunk>(bytes);
  }
  void give(std::unique_ptr<StagingChunk> chunk) {
    int device = 0;
    if (cudaGetDevice(&device) != cudaSuccess) return;  // (the chunk is freed)
    std::lock_guard<std::mutex> lock(mutex_);
    free_[device].push_back(std::move(chunk));
  }
  // Destroyed at exit before the CUDA runtime's own teardown (which was registered earlier, by
  // the first CUDA call), so the chunks are freed (memory checkers see no leak); a copy is not
  // expected to run while the program exits.
  static StagingChunkPool& instance() {
    static StagingChunkPool pool;
    return pool;
  }

 private:
  std::mutex mutex_;
  std::map<int, std::vector<std::unique_ptr<StagingChunk>>> free_;
};

// kChunks chunks borrowed for one copy, given back (with their events) when it ends.
template <class Policy>
class BorrowedChunks {
 public:
  explicit BorrowedChunks(std::size_t bytes) {
    // Chunks of a power of two bytes (from a page up): a small copy locks no more than it needs,
    // and the pool holds few sizes.
    std::size_t per_chunk = 4096;
    while (per_chunk < bytes && per_chunk < Policy::kChunkBytes) per_chunk *= 2;
    per_chunk = std::min(per_chunk, Policy::kChunkBytes);
    const std::size_t count = std::min<std::size_t>(Policy::kChunks, (bytes + per_chunk - 1) / per_chunk);
    for (std::size_t k = 0; k < count; ++k) chunks_.push_back(StagingChunkPool::instance().take(per_chunk));
    chunk_bytes_ = per_chunk;
  }
  ~BorrowedChunks() {
    for (auto& c : chunks_) StagingChunkPool::instance().give(std::move(c));
  }
  BorrowedChunks(const BorrowedChunks&) = delete;
  BorrowedChunks& operator=(const BorrowedChunks&) = delete;

  StagingChunk& operator[](std::size_t k) { return *chunks_[k % chunks_.size()]; }
  std::size_t size() const { return chunks_.size(); }
  std::size_t chunk_bytes() const { return chunk_bytes_; }

 private:
  std::vector<std::unique_ptr<StagingChunk>> chunks_;
  std::size_t chunk_bytes_ = 0;
};

}  // namespace detail

/// Copies through the process's page-locked chunks (detail::StagingChunkPool). Stateless: any
/// number of owners and threads may copy at once (each copy borrows chunks of its own).
template <class Policy = HostStagingPolicy>
class HostStaging {
 public:
  static_assert(Policy::kChunks >= 2, "lwsccd: HostStagingPolicy::kChunks must be at least 2 (one copied while one crosses)");
  static_assert(Policy::kChunkBytes >= 4096, "lwsccd: HostStagingPolicy::kChunkBytes must be at least a page");

  /// Enqueues the copy of `bytes` from pageable `host` to `device` on `stream`. Returns once
  /// `host` has been read (it may change afterwards); the last chunks may still be crossing, in
  /// `stream`'s order.
  static void to_device(void* device, const void* host, std::size_t bytes, cudaStream_t stream) {
    if (bytes == 0) return;
    if (bytes < Policy::kDirectUploadBytes) {
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(device, host, bytes, cudaMemcpyHostToDevice, stream));
      return;
    }
    detail::BorrowedChunks<Policy> chunks(bytes);
    const auto* from = static_cast<const unsigned char*>(host);
    auto* to = static_cast<unsigned char*>(device);
    const std::size_t step = chunks.chunk_bytes();
    for (std::size_t k = 0, offset = 0; offset < bytes; ++k, offset += step) {
      const std::size_t n = std::min(step, bytes - offset);
      detail::StagingChunk& c = chunks[k];
      LWSCCD_CUDA_CHECK(cudaEventSynchronize(c.crossed));  // its last copy has left it
      host_copy(c.memory.get(), from + offset, n);
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(to + offset, c.memory.get(), n, cudaMemcpyHostToDevice, stream));
      LWSCCD_CUDA_CHECK(cudaEventRecord(c.crossed, stream));
    }
  }

  /// Copies `bytes` from `device` to pageable `host` in `stream`'s order and waits for them: the
  /// copy engine fills the next chunks while the host empties this one.
  static void to_host(void* host, const void* device, std::size_t bytes, cudaStream_t stream) {
    if (bytes == 0) return;
    if (bytes < Policy::kDirectDownloadBytes) {
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(host, device, bytes, cudaMemcpyDeviceToHost, stream));
      LWSCCD_CUDA_CHECK(cudaStreamSynchronize(stream));
      return;
    }
    detail::BorrowedChunks<Policy> chunks(bytes);
    const auto* from = static_cast<const unsigned char*>(device);
    auto* to = static_cast<unsigned char*>(host);
    const std::size_t step = chunks.chunk_bytes();
    const std::size_t count = (bytes + step - 1) / step;
    auto enqueue = [&](std::size_t k) {
      detail::StagingChunk& c = chunks[k];
      const std::size_t offset = k * step;
      LWSCCD_CUDA_CHECK(cudaEventSynchronize(c.crossed));  // (its last borrower's copy)
      LWSCCD_CUDA_CHECK(cudaMemcpyAsync(c.memory.get(), from + offset, std::min(step, bytes - offset),
                                        cudaMemcpyDeviceToHost, stream));
      LWSCCD_CUDA_CHECK(cudaEventRecord(c.crossed, stream));
    };
    for (std::size_t k = 0; k < std::min(count, chunks.size()); ++k) enqueue(k);
    for (std::size_t k = 0; k < count; ++k) {
      detail::StagingChunk& c = chunks[k];
      LWSCCD_CUDA_CHECK(cudaEventSynchronize(c.crossed));
      const std::size_t offset = k * step;
      host_copy(to + offset, c.memory.get(), std::min(step, bytes - offset));
      if (k + chunks.size() < count) enqueue(k + chunks.size());
    }
  }

 private:
  // memcpy, split across the CPU backend's threads when the chunk is large.
  static void host_copy(void* to, const void* from, std::size_t n) {
    if (n < 2 * Policy::kThreadBytes) {
      std::memcpy(to, from, n);
      return;
    }
    lwsccd::detail::parallel_ranges(n, Policy::kThreadBytes, [&](std::size_t begin, std::size_t end) {
      std::memcpy(static_cast<unsigned char*>(to) + begin, static_cast<const unsigned char*>(from) + begin, end - begin);
    });
  }
};

}  // namespace lwsccd::gpu
