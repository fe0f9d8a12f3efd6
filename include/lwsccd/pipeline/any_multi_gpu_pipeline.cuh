// lwsccd — gpu::MultiGpuPipeline behind AnyPipeline (any_pipeline.hpp): for programs and bindings
// that pick the backend at run time (the main program's --gpus, the Python package's devices=).
// Default policies only (one instantiation, not one per combination). Needs NCCL, as
// multi_gpu.cuh does: in lwsccd's build the CMake target lwsccd::multi_gpu.
#pragma once

#include <cuda_runtime.h>

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "lwsccd/multi_gpu.cuh"
#include "lwsccd/pipeline/any_pipeline.hpp"

namespace lwsccd::gpu {

namespace detail {

/// AnyPipeline over MultiGpuPipeline<>. Host spans are copied into vectors first (the split
/// pipeline reads std::vectors); device positions are read on the first device, and contacts left
/// on the device stay there.
class AnyMultiGpuPipeline final : public AnyPipeline {
 public:
  AnyMultiGpuPipeline(std::shared_ptr<const TriangleMesh> mesh, const BodyLayout& layout, const PipelineParams& params,
                      std::vector<int> devices)
      : pipeline_(std::move(mesh), layout, std::move(devices), params) {}
  StepOutcome step(const std::vector<Vec3d>& x0, const std::vector<Vec3d>& x1) override { return outcome(pipeline_.step(x0, x1)); }
  StepOutcome step(const std::vector<Vec3f>& x0, const std::vector<Vec3f>& x1) override { return outcome(pipeline_.step(x0, x1)); }
  void step_into(Span<const Vec3d> x0, Span<const Vec3d> x1, StepOutcome& out) override {
    out = step(std::vector<Vec3d>(x0.begin(), x0.end()), std::vector<Vec3d>(x1.begin(), x1.end()));
  }
  void step_into(Span<const Vec3f> x0, Span<const Vec3f> x1, StepOutcome& out) override {
    out = step(std::vector<Vec3f>(x0.begin(), x0.end()), std::vector<Vec3f>(x1.begin(), x1.end()));
  }
  StepOutcome step_from_device(const Vec3d* x0, const Vec3d* x1) override { return outcome(pipeline_.step_from_device(x0, x1)); }
  StepOutcome step_from_device(const Vec3f* x0, const Vec3f* x1) override { return outcome(pipeline_.step_from_device(x0, x1)); }
  AnyDeviceContacts step_on_device(const Vec3d* x0, const Vec3d* x1) override { return lwsccd::detail::any_device_contacts(pipeline_.step_on_device(x0, x1)); }
  AnyDeviceContacts step_on_device(const Vec3f* x0, const Vec3f* x1) override { return lwsccd::detail::any_device_contacts(pipeline_.step_on_device(x0, x1)); }
  void restart_from_root() override { pipeline_.restart_from_root(); }
  const TriangleMesh& mesh() const override { return pipeline_.mesh(); }
  const PipelineParams& params() const override { return pipeline_.params(); }
  std::string backend() const override { return "gpu"; }

 private:
  static StepOutcome outcome(MultiGpuStepResult<double>&& r) { return {r.stats, std::move(r.contacts)}; }
  MultiGpuPipeline<> pipeline_;
};

}  // namespace detail

/// A step split over `devices` (CUDA device ordinals, distinct; one is allowed: a pipeline on that
/// device) behind AnyPipeline. `choice` must name the default policies (aabb, lazy, certified,
/// double): InputError otherwise, from `source` naming `field` (the caller's names: the command
/// line's --gpus, Python's devices=); a device that is not present or listed twice is the
/// pipeline's own InputError.
inline std::unique_ptr<AnyPipeline> make_any_multi_gpu_pipeline(std::shared_ptr<const TriangleMesh> mesh, const BodyLayout& layout,
                                                                const PipelineParams& params, std::vector<int> devices,
                                                                const PolicyChoice& choice = {},
                                                                const std::string& source = "gpu::make_any_multi_gpu_pipeline",
                                                                const std::string& field = "choice") {
  validate(choice);
  const PolicyChoice defaults;
  if (choice.bv != defaults.bv || choice.scheduler != defaults.scheduler || choice.method != defaults.method ||
      choice.precision != defaults.precision)
    throw InputError(source, field, "a step split over GPUs takes the default policies (aabb, lazy, certified, double), got " +
                                            choice.bv + ", " + choice.scheduler + ", " + choice.method + ", " + choice.precision);
  return std::make_unique<detail::AnyMultiGpuPipeline>(std::move(mesh), layout, params, std::move(devices));
}

}  // namespace lwsccd::gpu
