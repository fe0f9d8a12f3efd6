// The Python extension's GPU backend (see gpu_backend.hpp): every policy combination of
// gpu::CcdPipeline (any_pipeline.cuh), and device results copied into arrays Python can own.
#include <cuda_runtime.h>

#include "gpu_backend.hpp"
#include "lwsccd/pipeline/any_pipeline.cuh"
#if defined(LWSCCD_PYTHON_WITH_NCCL)
#include "lwsccd/pipeline/any_multi_gpu_pipeline.cuh"
#endif

namespace lwsccd_python {

const bool kBuiltWithGpu = true;
#if defined(LWSCCD_PYTHON_WITH_NCCL)
const bool kBuiltWithNccl = true;
#else
const bool kBuiltWithNccl = false;
#endif

int gpu_count() {
  int n = 0;
  if (cudaGetDeviceCount(&n) != cudaSuccess) {
    cudaGetLastError();  // (no driver or no device: not an error here)
    return 0;
  }
  return n;
}

std::string gpu_name() { return lwsccd::gpu::device_name(); }

void release_cached_memory() { lwsccd::gpu::release_cached_memory(); }

std::unique_ptr<lwsccd::AnyPipeline> make_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh> mesh,
                                                       const lwsccd::BodyLayout& layout, const lwsccd::PipelineParams& params,
                                                       const lwsccd::PolicyChoice& choice) {
  return lwsccd::gpu::make_any_pipeline(std::move(mesh), layout, params, choice);
}

std::unique_ptr<lwsccd::AnyPipeline> make_multi_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh> mesh,
                                                             const lwsccd::BodyLayout& layout, const lwsccd::PipelineParams& params,
                                                             const lwsccd::PolicyChoice& choice, std::vector<int> devices) {
#if defined(LWSCCD_PYTHON_WITH_NCCL)
  return lwsccd::gpu::make_any_multi_gpu_pipeline(std::move(mesh), layout, params, std::move(devices), choice, "lwsccd.Pipeline",
                                                  "devices");
#else
  (void)mesh, (void)layout, (void)params, (void)choice, (void)devices;
  throw lwsccd::Error(
      "lwsccd.Pipeline: devices= needs NCCL, which this build of the Python package was made without (install NCCL, e.g. "
      "pip install nvidia-nccl-cu12, set LWSCCD_NCCL_ROOT to it and rebuild; see docs/PYTHON.md)");
#endif
}

namespace {

template <class T>
__global__ void split_hits_kernel(const lwsccd::FeatureHit<T>* hits, std::size_t n, std::int64_t first_base,
                                  std::int64_t second_base, std::int64_t* pairs, double* toi) {
  const std::size_t i = blockIdx.x * static_cast<std::size_t>(blockDim.x) + threadIdx.x;
  if (i >= n) return;
  pairs[2 * i] = static_cast<std::int64_t>(hits[i].first) - first_base;
  pairs[2 * i + 1] = static_cast<std::int64_t>(hits[i].second) - second_base;
  toi[i] = static_cast<double>(hits[i].toi);
}

}  // namespace

DeviceHitArrays copy_device_hits(const void* hits, std::size_t n, bool toi_is_double, std::int64_t first_base,
                                 std::int64_t second_base) {
  DeviceHitArrays out;
  out.n = n;
  const std::size_t room = n > 0 ? n : 1;  // empty lists still get device arrays (of shape 0)
  LWSCCD_CUDA_CHECK(cudaMalloc(&out.pairs, 2 * room * sizeof(std::int64_t)));
  if (cudaMalloc(&out.toi, room * sizeof(double)) != cudaSuccess) {
    cudaFree(out.pairs);
    throw lwsccd::Error("lwsccd: out of device memory for the step's device results");
  }
  if (n == 0) return out;
  const unsigned blocks = static_cast<unsigned>((n + 255) / 256);
  if (toi_is_double)
    split_hits_kernel<<<blocks, 256>>>(static_cast<const lwsccd::FeatureHit<double>*>(hits), n, first_base, second_base,
                                       out.pairs, out.toi);
  else
    split_hits_kernel<<<blocks, 256>>>(static_cast<const lwsccd::FeatureHit<float>*>(hits), n, first_base, second_base,
                                       out.pairs, out.toi);
  LWSCCD_CUDA_CHECK_LAUNCH();
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(nullptr));  // ready for any stream of the caller's
  return out;
}

void free_device_array(void* p) noexcept { cudaFree(p); }

void synchronize_stream(std::uintptr_t stream) {
  LWSCCD_CUDA_CHECK(cudaStreamSynchronize(reinterpret_cast<cudaStream_t>(stream)));
}

}  // namespace lwsccd_python
