// lwsccd-ccd — what the main program's CPU part (lwsccd_ccd.cpp) and GPU part (lwsccd_ccd_gpu.cu)
// share: pipelines with policies chosen by name (the library's AnyPipeline, any_pipeline.hpp),
// made by one function per backend so that only lwsccd_ccd_gpu.cu is compiled by nvcc.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lwsccd/lwsccd.hpp"
#include "lwsccd/pipeline/any_pipeline.hpp"

namespace ccd_app {

using lwsccd::AnyPipeline;
using lwsccd::PolicyChoice;
using lwsccd::StepOutcome;
using lwsccd::detail::to_double;

/// Calls f(tag of BV, tag of Method, tag of T) for the choice (lwsccd::dispatch_policies).
template <class F>
auto dispatch_policies(const PolicyChoice& c, F&& f) {
  return lwsccd::dispatch_policies(c, std::forward<F>(f));
}

inline std::unique_ptr<AnyPipeline> make_cpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh> mesh,
                                                      const lwsccd::BodyLayout& layout, const lwsccd::PipelineParams& params,
                                                      const PolicyChoice& choice) {
  return lwsccd::cpu::make_any_pipeline(std::move(mesh), layout, params, choice);
}

/// The threads the CPU backend uses for `params` (PipelineParams::threads, or every core).
inline unsigned cpu_threads(const lwsccd::PipelineParams& params = {}) {
  return lwsccd::cpu::ThreadLimit(params.threads).effective_threads();
}

/// The first CUDA device's name, or "" when there is none (or the program was built without CUDA).
std::string gpu_name();

/// Throws lwsccd::Error when built without CUDA.
std::unique_ptr<AnyPipeline> make_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh> mesh,
                                               const lwsccd::BodyLayout& layout, const lwsccd::PipelineParams& params,
                                               const PolicyChoice& choice);

/// A step split over GPUs 0 .. gpus - 1 (gpu::MultiGpuPipeline, default policies only). Throws
/// lwsccd::Error when built without NCCL, InputError for other policies or too few GPUs.
std::unique_ptr<AnyPipeline> make_multi_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh> mesh,
                                                     const lwsccd::BodyLayout& layout, const lwsccd::PipelineParams& params,
                                                     const PolicyChoice& choice, int gpus);

/// Frees the device blocks the process keeps for later GPU pipelines (gpu::release_cached_memory),
/// so that the next pipeline's first step runs on new memory; nothing without CUDA.
void release_gpu_cached_memory();

/// GPU pipelines: the step from positions copied to the device beforehand (not timed), contacts
/// left there (AnyPipeline::step_on_device); nothing for the CPU backend.
std::optional<lwsccd::StepStats> device_resident_step(AnyPipeline& pipeline, const std::vector<lwsccd::Vec3d>& x0,
                                                      const std::vector<lwsccd::Vec3d>& x1);
/// The same from float positions (AnyPipeline::step_on_device's Vec3f form: they cross as float
/// and are widened on the device).
std::optional<lwsccd::StepStats> device_resident_step(AnyPipeline& pipeline, const std::vector<lwsccd::Vec3f>& x0,
                                                      const std::vector<lwsccd::Vec3f>& x1);

}  // namespace ccd_app
