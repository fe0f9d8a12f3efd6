// lwsccd-ccd — the CPU backend of the main program and of the pipeline benchmark (plain C++);
// the GPU one is lwsccd_ccd_gpu.cu, compiled where nvcc is.
#include "ccd_app.hpp"

namespace ccd_app {

std::unique_ptr<AnyPipeline> make_cpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh> mesh,
                                               const lwsccd::BodyLayout& layout, const lwsccd::PipelineParams& params,
                                               const PolicyChoice& choice) {
  return dispatch_policies(choice, [&](auto bv, auto method, auto scalar) -> std::unique_ptr<AnyPipeline> {
    using Pipeline = lwsccd::cpu::CcdPipeline<typename decltype(bv)::type, typename decltype(method)::type,
                                              typename decltype(scalar)::type>;
    return std::make_unique<PipelineAdapter<Pipeline>>(mesh, layout, params);
  });
}

#ifndef LWSCCD_CCD_WITH_GPU
std::string gpu_name() { return ""; }
std::unique_ptr<AnyPipeline> make_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh>, const lwsccd::BodyLayout&,
                                               const lwsccd::PipelineParams&, const PolicyChoice&) {
  throw lwsccd::Error("lwsccd-ccd was built without CUDA: no GPU backend");
}
#endif

}  // namespace ccd_app
