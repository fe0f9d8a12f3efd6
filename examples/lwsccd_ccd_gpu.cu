// lwsccd-ccd — the GPU backend of the main program (compiled where nvcc is; see ccd_app.hpp).
#include <cuda_runtime.h>

#include "ccd_app.hpp"
#include "lwsccd/pipeline.cuh"

namespace ccd_app {

std::string gpu_name() {
  int devices = 0;
  if (cudaGetDeviceCount(&devices) != cudaSuccess || devices == 0) {
    cudaGetLastError();  // clear the "no device" error
    return "";
  }
  cudaDeviceProp prop{};
  LWSCCD_CUDA_CHECK(cudaGetDeviceProperties(&prop, 0));
  return prop.name;
}

std::unique_ptr<AnyPipeline> make_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh> mesh,
                                               const lwsccd::BodyLayout& layout, const lwsccd::PipelineParams& params,
                                               const PolicyChoice& choice) {
  return dispatch_policies(choice, [&](auto bv, auto method, auto scalar) -> std::unique_ptr<AnyPipeline> {
    using BV = typename decltype(bv)::type;
    using Method = typename decltype(method)::type;
    using T = typename decltype(scalar)::type;
    auto make = [&](auto scheduler) -> std::unique_ptr<AnyPipeline> {
      using Pipeline = lwsccd::gpu::CcdPipeline<BV, typename decltype(scheduler)::type, Method, T>;
      return std::make_unique<PipelineAdapter<Pipeline>>(mesh, layout, params);
    };
    if (choice.scheduler == "static") return make(Tag<lwsccd::gpu::StaticTaskList<>>{});
    if (choice.scheduler == "gproximity") return make(Tag<lwsccd::gpu::GProximityBalancer<>>{});
    return make(Tag<lwsccd::gpu::LazyStealScheduler<>>{});
  });
}

}  // namespace ccd_app
