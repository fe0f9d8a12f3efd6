// lwsccd-ccd — the GPU backend of the main program (compiled where nvcc is; see ccd_app.hpp).
#include <cuda_runtime.h>

#include "ccd_app.hpp"
#include "lwsccd/pipeline.cuh"

namespace ccd_app {

/// PipelineAdapter for gpu::CcdPipeline, which can also leave a step's contacts on the device.
template <class Pipeline>
class GpuPipelineAdapter final : public PipelineAdapter<Pipeline> {
 public:
  using PipelineAdapter<Pipeline>::PipelineAdapter;
  std::optional<lwsccd::StepStats> step_on_device(const std::vector<lwsccd::Vec3d>& x0,
                                                  const std::vector<lwsccd::Vec3d>& x1) override {
    x0_.upload(x0);
    x1_.upload(x1);
    LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());  // the copies are not part of the step's time
    return this->pipeline_.step_on_device(x0_.data(), x1_.data()).stats;
  }

 private:
  lwsccd::gpu::DeviceBuffer<lwsccd::Vec3d> x0_, x1_;
};

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
      return std::make_unique<GpuPipelineAdapter<Pipeline>>(mesh, layout, params);
    };
    if (choice.scheduler == "static") return make(Tag<lwsccd::gpu::StaticTaskList<>>{});
    if (choice.scheduler == "gproximity") return make(Tag<lwsccd::gpu::GProximityBalancer<>>{});
    return make(Tag<lwsccd::gpu::LazyStealScheduler<>>{});
  });
}

}  // namespace ccd_app
