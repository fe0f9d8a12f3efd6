// lwsccd-ccd — the main program's functions for a build without CUDA (plain C++); with nvcc,
// lwsccd_ccd_gpu.cu defines them instead (and lwsccd_ccd_multi_gpu.cu the split over GPUs, with NCCL).
#include "ccd_app.hpp"

#ifndef LWSCCD_CCD_WITH_GPU
namespace ccd_app {

std::string gpu_name() { return ""; }

std::unique_ptr<AnyPipeline> make_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh>, const lwsccd::BodyLayout&,
                                               const lwsccd::PipelineParams&, const PolicyChoice&) {
  throw lwsccd::Error("lwsccd-ccd was built without CUDA: no GPU backend");
}

std::optional<lwsccd::StepStats> device_resident_step(AnyPipeline&, const std::vector<lwsccd::Vec3d>&,
                                                      const std::vector<lwsccd::Vec3d>&) {
  return std::nullopt;
}
std::optional<lwsccd::StepStats> device_resident_step(AnyPipeline&, const std::vector<lwsccd::Vec3f>&,
                                                      const std::vector<lwsccd::Vec3f>&) {
  return std::nullopt;
}

void release_gpu_cached_memory() {}

}  // namespace ccd_app
#endif

#ifndef LWSCCD_CCD_WITH_NCCL
namespace ccd_app {

std::unique_ptr<AnyPipeline> make_multi_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh>, const lwsccd::BodyLayout&,
                                                     const lwsccd::PipelineParams&, const PolicyChoice&, int) {
  throw lwsccd::Error("--gpus: lwsccd-ccd was built without NCCL (CMake found no nccl.h / libnccl): one GPU only");
}

}  // namespace ccd_app
#endif
