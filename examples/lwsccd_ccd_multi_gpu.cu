// lwsccd-ccd — --gpus N: the step split over several GPUs (gpu::make_any_multi_gpu_pipeline);
// compiled where CMake found NCCL (ccd_backends.cpp refuses the option elsewhere).
#include "ccd_app.hpp"
#include "lwsccd/pipeline/any_multi_gpu_pipeline.cuh"

namespace ccd_app {

std::unique_ptr<AnyPipeline> make_multi_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh> mesh,
                                                     const lwsccd::BodyLayout& layout, const lwsccd::PipelineParams& params,
                                                     const PolicyChoice& choice, int gpus) {
  int available = 0;
  LWSCCD_CUDA_CHECK(cudaGetDeviceCount(&available));
  if (gpus > available)
    throw lwsccd::InputError("command line", "--gpus", std::to_string(gpus) + " GPUs asked, " + std::to_string(available) + " present");
  std::vector<int> devices;
  for (int d = 0; d < gpus; ++d) devices.push_back(d);
  return lwsccd::gpu::make_any_multi_gpu_pipeline(std::move(mesh), layout, params, std::move(devices), choice, "command line", "--gpus");
}

}  // namespace ccd_app
