// lwsccd-ccd — the GPU backend of the main program (compiled where nvcc is; see ccd_app.hpp).
#include "ccd_app.hpp"
#include "lwsccd/pipeline/any_pipeline.cuh"

namespace ccd_app {

std::string gpu_name() { return lwsccd::gpu::device_name(); }

std::unique_ptr<AnyPipeline> make_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh> mesh,
                                               const lwsccd::BodyLayout& layout, const lwsccd::PipelineParams& params,
                                               const PolicyChoice& choice) {
  return lwsccd::gpu::make_any_pipeline(std::move(mesh), layout, params, choice);
}

void release_gpu_cached_memory() { lwsccd::gpu::release_cached_memory(); }

namespace {
template <class P>
std::optional<lwsccd::StepStats> resident_step(AnyPipeline& pipeline, const std::vector<lwsccd::Vec3<P>>& x0,
                                               const std::vector<lwsccd::Vec3<P>>& x1) {
  if (pipeline.backend() != "gpu") return std::nullopt;
  lwsccd::gpu::DeviceBuffer<lwsccd::Vec3<P>> d_x0, d_x1;
  d_x0.upload(x0);
  d_x1.upload(x1);
  LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());  // the copies are not part of the step's time
  return pipeline.step_on_device(d_x0.data(), d_x1.data()).stats;
}
}  // namespace

std::optional<lwsccd::StepStats> device_resident_step(AnyPipeline& pipeline, const std::vector<lwsccd::Vec3d>& x0,
                                                      const std::vector<lwsccd::Vec3d>& x1) {
  return resident_step(pipeline, x0, x1);
}
std::optional<lwsccd::StepStats> device_resident_step(AnyPipeline& pipeline, const std::vector<lwsccd::Vec3f>& x0,
                                                      const std::vector<lwsccd::Vec3f>& x1) {
  return resident_step(pipeline, x0, x1);
}

}  // namespace ccd_app
