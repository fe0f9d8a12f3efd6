// The geometry core run inside kernels, compared with the same code run on the host.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cstring>
#include <random>
#include <type_traits>
#include <utility>
#include <vector>

#include "lwsccd/core/cuda_check.cuh"
#include "lwsccd/core/cuda_handles.cuh"
#include "lwsccd/core/device_buffer.cuh"
#include "lwsccd/geometry/bv_traits.hpp"
#include "lwsccd/geometry/morton.hpp"

using namespace lwsccd;

namespace {

template <class T>
class DeviceBuffer {  // minimal RAII for the test
 public:
  explicit DeviceBuffer(std::size_t n) : n_(n) { LWSCCD_CUDA_CHECK(cudaMalloc(&ptr_, sizeof(T) * (n ? n : 1))); }
  explicit DeviceBuffer(const std::vector<T>& host) : DeviceBuffer(host.size()) {
    LWSCCD_CUDA_CHECK(cudaMemcpy(ptr_, host.data(), sizeof(T) * n_, cudaMemcpyHostToDevice));
  }
  ~DeviceBuffer() { cudaFree(ptr_); }
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  T* get() const { return ptr_; }
  std::vector<T> to_host() const {
    std::vector<T> out(n_);
    LWSCCD_CUDA_CHECK(cudaMemcpy(out.data(), ptr_, sizeof(T) * n_, cudaMemcpyDeviceToHost));
    return out;
  }

 private:
  T* ptr_ = nullptr;
  std::size_t n_;
};

template <class BV>
__global__ void fit_swept_kernel(const Vec3d* p0, const Vec3d* p1, int n, BV* out) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) out[i] = swept_triangle_bv<BV>(p0[3 * i], p0[3 * i + 1], p0[3 * i + 2], p1[3 * i], p1[3 * i + 1], p1[3 * i + 2]);
}

template <class BV>
__global__ void overlap_kernel(const BV* bvs, int n, int* out) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) out[i] = i + 1 < n && bv_traits<BV>::overlap(bvs[i], bvs[i + 1]) ? 1 : 0;  // every element written
}

__global__ void morton_kernel(const Vec3f* pts, int n, Aabbf scene, std::uint32_t* m30, std::uint64_t* m63) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) {
    m30[i] = morton30(pts[i], scene);
    m63[i] = morton63(pts[i], scene);
  }
}

struct Triangles {
  std::vector<Vec3d> p0, p1;
};

Triangles random_triangles(int n) {
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> u(-1, 1);
  Triangles t;
  for (int i = 0; i < n; ++i) {
    const Vec3d c{u(rng) * 10, u(rng) * 10, u(rng) * 10};
    for (int k = 0; k < 3; ++k) {
      const Vec3d p = c + Vec3d{u(rng), u(rng), u(rng)};
      t.p0.push_back(p);
      t.p1.push_back(p + Vec3d{u(rng), u(rng), u(rng)} * 0.5);
    }
    if (i % 9 == 0) t.p0[3 * i + 2] = t.p0[3 * i + 1];  // degenerate at t0
  }
  return t;
}

}  // namespace

TEMPLATE_TEST_CASE("GPU swept AABBs equal the host's bit for bit, overlaps too", "[gpu][aabb]", float, double) {
  using BV = Aabb<TestType>;
  const int n = 4000;
  const Triangles t = random_triangles(n);
  DeviceBuffer<Vec3d> d0(t.p0), d1(t.p1);
  DeviceBuffer<BV> dbv(n);
  DeviceBuffer<int> dov(n);
  fit_swept_kernel<BV><<<(n + 127) / 128, 128>>>(d0.get(), d1.get(), n, dbv.get());
  LWSCCD_CUDA_CHECK_LAUNCH();
  overlap_kernel<BV><<<(n + 127) / 128, 128>>>(dbv.get(), n, dov.get());
  LWSCCD_CUDA_CHECK_LAUNCH();
  LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
  const auto gpu = dbv.to_host();
  const auto ov = dov.to_host();
  int overlaps = 0;
  for (int i = 0; i < n; ++i) {
    const BV host = swept_triangle_bv<BV>(t.p0[3 * i], t.p0[3 * i + 1], t.p0[3 * i + 2], t.p1[3 * i], t.p1[3 * i + 1],
                                          t.p1[3 * i + 2]);
    REQUIRE(gpu[i].lo == host.lo);
    REQUIRE(gpu[i].hi == host.hi);
    if (i + 1 < n) {
      REQUIRE(ov[i] == (bv_traits<BV>::overlap(gpu[i], gpu[i + 1]) ? 1 : 0));
      overlaps += ov[i];
    }
  }
  CHECK(overlaps > 10);
}

TEMPLATE_TEST_CASE("GPU swept OBBs contain every endpoint and overlap like the host", "[gpu][obb]", float, double) {
  using BV = Obb<TestType>;
  const int n = 4000;
  const Triangles t = random_triangles(n);
  DeviceBuffer<Vec3d> d0(t.p0), d1(t.p1);
  DeviceBuffer<BV> dbv(n);
  DeviceBuffer<int> dov(n);
  fit_swept_kernel<BV><<<(n + 127) / 128, 128>>>(d0.get(), d1.get(), n, dbv.get());
  LWSCCD_CUDA_CHECK_LAUNCH();
  overlap_kernel<BV><<<(n + 127) / 128, 128>>>(dbv.get(), n, dov.get());
  LWSCCD_CUDA_CHECK_LAUNCH();
  LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
  const auto gpu = dbv.to_host();
  const auto ov = dov.to_host();
  for (int i = 0; i < n; ++i) {
    // Host and device round alike (detail/fp.hpp): the same bits; and containment, checked here
    // in long double without slack.
    const BV host = swept_triangle_bv<BV>(t.p0[3 * i], t.p0[3 * i + 1], t.p0[3 * i + 2], t.p1[3 * i], t.p1[3 * i + 1],
                                          t.p1[3 * i + 2]);
    REQUIRE(std::memcmp(&host, &gpu[i], sizeof(BV)) == 0);
    for (const Vec3d* p : {&t.p0[3 * i], &t.p0[3 * i + 1], &t.p0[3 * i + 2], &t.p1[3 * i], &t.p1[3 * i + 1], &t.p1[3 * i + 2]}) {
      for (int a = 0; a < 3; ++a) {
        long double s = 0;
        for (int c = 0; c < 3; ++c) s += (long double)gpu[i].axis[a][c] * ((long double)(*p)[c] - (long double)gpu[i].center[c]);
        REQUIRE(std::fabs(s) <= (long double)gpu[i].half[a]);
      }
    }
    if (i + 1 < n) REQUIRE(ov[i] == (bv_traits<BV>::overlap(gpu[i], gpu[i + 1]) ? 1 : 0));
  }
}

TEST_CASE("GPU Morton codes equal the host's", "[gpu][morton]") {
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<float> u(-3, 3);
  const int n = 10000;
  std::vector<Vec3f> pts(n);
  for (auto& p : pts) p = {u(rng), u(rng), u(rng)};
  const Aabbf scene{{-2, -2, -2}, {2, 2.5f, 2}};
  DeviceBuffer<Vec3f> dp(pts);
  DeviceBuffer<std::uint32_t> d30(n);
  DeviceBuffer<std::uint64_t> d63(n);
  morton_kernel<<<(n + 255) / 256, 256>>>(dp.get(), n, scene, d30.get(), d63.get());
  LWSCCD_CUDA_CHECK_LAUNCH();
  LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
  const auto m30 = d30.to_host();
  const auto m63 = d63.to_host();
  for (int i = 0; i < n; ++i) {
    REQUIRE(m30[i] == morton30(pts[i], scene));
    REQUIRE(m63[i] == morton63(pts[i], scene));
  }
}

// The owners of CUDA events and streams (core/cuda_handles.cuh): move-only, the handle moves.
static_assert(!std::is_copy_constructible_v<gpu::CudaEvent> && std::is_nothrow_move_constructible_v<gpu::CudaEvent> &&
                  std::is_nothrow_move_assignable_v<gpu::CudaEvent>,
              "CudaEvent: move-only");
static_assert(!std::is_copy_constructible_v<gpu::CudaStream> && std::is_nothrow_move_constructible_v<gpu::CudaStream> &&
                  std::is_nothrow_move_assignable_v<gpu::CudaStream>,
              "CudaStream: move-only");

TEST_CASE("CudaEvent and CudaStream own their handle: moved, it stays valid; the source is empty", "[gpu][handles]") {
  gpu::CudaStream stream(cudaStreamNonBlocking);
  gpu::CudaEvent event(cudaEventDisableTiming);
  REQUIRE(stream.get() != nullptr);
  REQUIRE(event.get() != nullptr);
  const cudaStream_t raw_stream = stream;
  const cudaEvent_t raw_event = event;
  gpu::CudaStream moved_stream(std::move(stream));
  gpu::CudaEvent moved_event;
  moved_event = std::move(event);
  CHECK(stream.get() == nullptr);
  CHECK(!stream);
  CHECK(event.get() == nullptr);
  REQUIRE(moved_stream.get() == raw_stream);
  REQUIRE(moved_event.get() == raw_event);
  // The moved handles work: an event recorded on the stream completes.
  LWSCCD_CUDA_CHECK(cudaEventRecord(moved_event, moved_stream));
  LWSCCD_CUDA_CHECK(cudaEventSynchronize(moved_event));
  CHECK(cudaEventQuery(moved_event) == cudaSuccess);
  // Move-assigning over a live owner releases its old handle (no leak; the new one works).
  moved_event = gpu::CudaEvent(cudaEventDisableTiming);
  LWSCCD_CUDA_CHECK(cudaEventRecord(moved_event, moved_stream));
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(moved_stream));
}

namespace {
// Spins for about `ns` nanoseconds of the GPU's clock, then fills `out` with `value`: a writer
// that is still running when the host has long given its buffer back.
__global__ void late_fill_kernel(unsigned* out, std::size_t n, unsigned value, unsigned long long ns) {
  if (threadIdx.x == 0 && blockIdx.x == 0) {
    unsigned long long start = 0, now = 0;
    asm volatile("mov.u64 %0, %%globaltimer;" : "=l"(start));
    do {
      asm volatile("mov.u64 %0, %%globaltimer;" : "=l"(now));
    } while (now - start < ns);
  }
  __syncthreads();
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += gridDim.x * blockDim.x) out[i] = value;
}
}  // namespace

TEST_CASE("Small device blocks are cut from shared slabs: their own memory, exact accounting, slabs freed once no piece is held",
          "[gpu][pool]") {
  gpu::set_memory_caching(true);
  gpu::release_cached_memory();
  REQUIRE(gpu::memory_stats().cached == 0);
  REQUIRE(gpu::memory_stats().reserved == 0);  // (no object of the process holds a piece here)
  const std::size_t in_use = gpu::memory_stats().in_use;
  constexpr std::size_t kSlab = gpu::detail::DevicePool::kSlabBytes;
  // Odd sizes below the limit, the last ones large enough to need a second slab.
  std::vector<std::size_t> sizes{1, 255, 257, 4099, 100'003, 1'000'001, 7'000'013, 7'500'007, 7'900'001, 8'000'009, 7'000'001};
  for (std::size_t& n : sizes) n = std::min(n, kSlab / gpu::detail::DevicePool::kCutShare);
  std::size_t total = 0;
  for (const std::size_t n : sizes) total += n;
  {
    std::vector<gpu::DeviceBuffer<unsigned char>> buffers;
    for (const std::size_t n : sizes) buffers.emplace_back(n);
    CHECK(gpu::memory_stats().in_use == in_use + total);  // what was asked for, byte for byte
    CHECK(gpu::memory_stats().reserved > 0);
    CHECK(gpu::memory_stats().reserved < 3 * kSlab - total);  // two slabs at most (32 and 64 MiB), the pieces cut from them
    for (std::size_t k = 0; k < buffers.size(); ++k) {
      CHECK(reinterpret_cast<std::uintptr_t>(buffers[k].data()) % 256 == 0);
      CHECK(buffers[k].capacity_bytes() == sizes[k]);
    }
    // Each piece its own memory: filled with its own byte, read back whole.
    for (std::size_t k = 0; k < buffers.size(); ++k)
      LWSCCD_CUDA_CHECK(cudaMemset(buffers[k].data(), static_cast<int>(k + 1), sizes[k]));
    std::size_t wrong = 0;
    for (std::size_t k = 0; k < buffers.size(); ++k) {
      const std::vector<unsigned char> host = buffers[k].download();
      wrong += static_cast<std::size_t>(std::count_if(host.begin(), host.end(), [&](unsigned char c) { return c != k + 1; }));
    }
    CHECK(wrong == 0);
    // A piece given back serves the next request of its size (meanwhile slab memory no object holds).
    const unsigned char* third = buffers[2].data();
    const std::size_t room = gpu::memory_stats().reserved;
    buffers[2] = gpu::DeviceBuffer<unsigned char>();
    CHECK(gpu::memory_stats().cached == 0);
    CHECK(gpu::memory_stats().reserved == room + sizes[2]);
    gpu::DeviceBuffer<unsigned char> again(sizes[2]);
    CHECK(again.data() == third);
    CHECK(gpu::memory_stats().reserved == room);
    // Released while other pieces are held: a held slab's pieces given back stay (they cannot be freed alone).
    buffers[0] = gpu::DeviceBuffer<unsigned char>();
    gpu::release_cached_memory();
    CHECK(gpu::memory_stats().reserved == room + sizes[0]);
    gpu::DeviceBuffer<unsigned char> first_again(sizes[0]);
    CHECK(gpu::memory_stats().reserved == room);
  }
  // Nothing held: the slabs go whole.
  gpu::release_cached_memory();
  CHECK(gpu::memory_stats().cached == 0);
  CHECK(gpu::memory_stats().reserved == 0);
  CHECK(gpu::memory_stats().in_use == in_use);
  // Under a memory budget no new slab is made: a small block is cut from the room of a slab held
  // already, else allocated alone.
  struct BudgetRestored {
    std::size_t previous = gpu::memory_budget();
    ~BudgetRestored() { gpu::set_memory_budget(previous); }
  } restore;
  {
    gpu::DeviceBuffer<unsigned char> opened(1000);  // (no budget yet: opens a slab)
    const std::size_t room = gpu::memory_stats().reserved;
    CHECK(room == kSlab - 1024);
    gpu::set_memory_budget(std::size_t(1) << 40);
    gpu::DeviceBuffer<unsigned char> cut(2000);
    CHECK(gpu::memory_stats().reserved == room - 2048);
  }
  gpu::release_cached_memory();
  CHECK(gpu::memory_stats().reserved == 0);
  { gpu::DeviceBuffer<unsigned char> small(1000); CHECK(gpu::memory_stats().reserved == 0); }
  gpu::set_memory_budget(restore.previous);
  gpu::release_cached_memory();
  gpu::set_memory_caching(false);
  {
    gpu::DeviceBuffer<unsigned char> small(1000);
    CHECK(gpu::memory_stats().reserved == 0);
  }
  CHECK(gpu::memory_stats().cached == 0);
  gpu::set_memory_caching(true);
}

TEST_CASE("Slabs double while a device holds them: larger blocks are cut as it holds more, one cudaMalloc for many",
          "[gpu][pool]") {
  using Pool = gpu::detail::DevicePool;
  gpu::set_memory_caching(true);
  gpu::release_cached_memory();
  REQUIRE(gpu::memory_stats().reserved == 0);  // (no slab held: the next one is the first size)
  const std::size_t in_use = gpu::memory_stats().in_use;
  constexpr std::size_t MiB = std::size_t(1) << 20;
  {
    // No slab held: a block above a quarter of the first slab is allocated alone.
    const std::size_t calls = gpu::memory_stats().allocations;
    gpu::DeviceBuffer<unsigned char> alone(Pool::kSlabBytes / Pool::kCutShare + 256);
    CHECK(gpu::memory_stats().allocations == calls + 1);
    CHECK(gpu::memory_stats().reserved == 0);
  }
  gpu::release_cached_memory();
  std::vector<gpu::DeviceBuffer<unsigned char>> held;
  held.emplace_back(1000);  // opens the first slab
  CHECK(gpu::memory_stats().reserved == Pool::kSlabBytes - 1024);
  // Holding one slab, the next is twice as large, so blocks of 12 MiB (above a quarter of the
  // first) are cut: the first slab's room and one new slab hold five, one call for all.
  const std::size_t calls = gpu::memory_stats().allocations;
  for (int k = 0; k < 5; ++k) held.emplace_back(12 * MiB);
  CHECK(gpu::memory_stats().allocations == calls + 1);
  CHECK(gpu::memory_stats().reserved == (Pool::kSlabBytes - 1024) + (2 * Pool::kSlabBytes - 60 * MiB));
  // A small block takes room a slab still has: no new call.
  held.emplace_back(2 * MiB);
  CHECK(gpu::memory_stats().allocations == calls + 1);
  // Growth stops at kMaxSlabBytes: past a quarter of it blocks are allocated alone whatever is held.
  for (int k = 0; k < 8; ++k) held.emplace_back(Pool::kMaxSlabBytes / Pool::kCutShare / 2);
  const std::size_t before_large = gpu::memory_stats().allocations;
  held.emplace_back(Pool::kMaxSlabBytes / Pool::kCutShare + 256);
  CHECK(gpu::memory_stats().allocations == before_large + 1);
  CHECK(gpu::memory_stats().in_use == in_use + 1000 + 60 * MiB + 2 * MiB + 4 * Pool::kMaxSlabBytes / Pool::kCutShare +
                                          Pool::kMaxSlabBytes / Pool::kCutShare + 256);
  // Each block its own memory: filled with its own byte, read back whole.
  for (std::size_t k = 0; k < held.size(); ++k)
    LWSCCD_CUDA_CHECK(cudaMemset(held[k].data(), static_cast<int>(k + 1), held[k].capacity_bytes()));
  std::size_t wrong = 0;
  for (std::size_t k = 0; k < held.size(); ++k) {
    const std::vector<unsigned char> host = held[k].download();
    wrong += static_cast<std::size_t>(std::count_if(host.begin(), host.end(), [&](unsigned char c) { return c != k + 1; }));
  }
  CHECK(wrong == 0);
  held.clear();
  gpu::release_cached_memory();
  CHECK(gpu::memory_stats().reserved == 0);
  CHECK(gpu::memory_stats().cached == 0);
  CHECK(gpu::memory_stats().in_use == in_use);
}

TEST_CASE("Device blocks given back are kept for the next request of their size, reused only once no earlier work can touch them",
          "[gpu][pool]") {
  gpu::set_memory_caching(true);
  gpu::release_cached_memory();
  CHECK(gpu::memory_stats().cached == 0);
  const std::size_t n = (std::size_t(3) << 20) + 17;  // an odd size: no other buffer of the process has it
  const std::size_t in_use = gpu::memory_stats().in_use;
  const unsigned* first = nullptr;
  {
    gpu::DeviceBuffer<unsigned> a(n);
    first = a.data();
    CHECK(a.capacity_bytes() == n * sizeof(unsigned));  // exactly what was asked for
    CHECK(gpu::memory_stats().in_use == in_use + n * sizeof(unsigned));
  }
  CHECK(gpu::memory_stats().in_use == in_use);
  CHECK(gpu::memory_stats().cached == n * sizeof(unsigned));
  {
    gpu::DeviceBuffer<unsigned> other(n + 1);  // another size: a block of its own
    CHECK(other.data() != first);
    gpu::DeviceBuffer<unsigned> again(n);  // the same size: the block given back
    CHECK(again.data() == first);
    CHECK(gpu::memory_stats().cached == 0);
  }
  // A kernel still writing into a buffer that its owner gave back: the next buffer of that size
  // gets the block only after the kernel is done (else the late writes would land in it).
  gpu::CudaStream side(cudaStreamNonBlocking);
  std::vector<unsigned> host(n);
  for (int round = 0; round < 3; ++round) {
    {
      gpu::DeviceBuffer<unsigned> busy(n);
      late_fill_kernel<<<64, 256, 0, side>>>(busy.data(), n, 0xdeadbeefu, 20'000'000ull);  // ~20 ms
      LWSCCD_CUDA_CHECK_LAUNCH();
    }  // given back while the kernel runs
    gpu::DeviceBuffer<unsigned> fresh(n);
    LWSCCD_CUDA_CHECK(cudaMemset(fresh.data(), 0x11, n * sizeof(unsigned)));
    LWSCCD_CUDA_CHECK(cudaStreamSynchronize(side));
    LWSCCD_CUDA_CHECK(cudaMemcpy(host.data(), fresh.data(), n * sizeof(unsigned), cudaMemcpyDeviceToHost));
    CHECK(std::count(host.begin(), host.end(), 0x11111111u) == static_cast<std::ptrdiff_t>(n));
  }
  // Freed on request, and where a budget needs their room.
  gpu::release_cached_memory();
  CHECK(gpu::memory_stats().cached == 0);
  { gpu::DeviceBuffer<unsigned> a(n); }
  CHECK(gpu::memory_stats().cached == n * sizeof(unsigned));
  const std::size_t previous = gpu::memory_budget();
  gpu::set_memory_budget(gpu::memory_stats().in_use + n * sizeof(unsigned) + 4096);
  {
    gpu::DeviceBuffer<unsigned> b(n + 1);  // fits the budget once the cached block is freed
    CHECK(gpu::memory_stats().cached == 0);
  }
  gpu::set_memory_budget(previous);
  // Caching off: blocks given back are freed at once.
  gpu::release_cached_memory();
  gpu::set_memory_caching(false);
  { gpu::DeviceBuffer<unsigned> a(n); }
  CHECK(gpu::memory_stats().cached == 0);
  gpu::set_memory_caching(true);
}
