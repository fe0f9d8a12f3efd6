// lwsccd — the GPU backend of AnyPipeline (any_pipeline.hpp): gpu::make_any_pipeline builds a
// gpu::CcdPipeline with policies chosen by name, the scheduler included. Compiling this header
// instantiates every combination of policies (3 schedulers x 2 BVs x 4 methods x 2 precisions),
// so include it in one translation unit of a program.
#pragma once

#include <cuda_runtime.h>

#include <string>

#include "lwsccd/pipeline/any_pipeline.hpp"
#include "lwsccd/pipeline/gpu_pipeline.cuh"

namespace lwsccd::gpu {

/// AnyPipeline over gpu::CcdPipeline: also steps from device positions and leaves contacts there.
template <class Pipeline>
class AnyPipelineAdapter final : public PipelineAdapter<Pipeline> {
 public:
  template <class... Args>
  explicit AnyPipelineAdapter(Args&&... args) : PipelineAdapter<Pipeline>("gpu", std::forward<Args>(args)...) {}

  StepOutcome step_from_device(const Vec3d* device_x0, const Vec3d* device_x1) override { return from_device(device_x0, device_x1); }
  StepOutcome step_from_device(const Vec3f* device_x0, const Vec3f* device_x1) override { return from_device(device_x0, device_x1); }
  AnyDeviceContacts step_on_device(const Vec3d* device_x0, const Vec3d* device_x1) override { return on_device(device_x0, device_x1); }
  AnyDeviceContacts step_on_device(const Vec3f* device_x0, const Vec3f* device_x1) override { return on_device(device_x0, device_x1); }
  void step_into(Span<const Vec3d> x0, Span<const Vec3d> x1, StepOutcome& out) override { into(x0, x1, out); }
  void step_into(Span<const Vec3f> x0, Span<const Vec3f> x1, StepOutcome& out) override { into(x0, x1, out); }

 private:
  using Scalar = typename Pipeline::scalar_type;
  // The arrays read in place; the contacts straight into out's lists (double TOIs), or into a
  // kept float result and widened into them.
  template <class Q>
  void into(Span<const Vec3<Q>> x0, Span<const Vec3<Q>> x1, StepOutcome& out) {
    if constexpr (std::is_same<Scalar, double>::value) {
      kept_.contacts = std::move(out.contacts);
      this->pipeline_.step_into(x0, x1, kept_);
      out.stats = kept_.stats;
      out.contacts = std::move(kept_.contacts);
    } else {
      this->pipeline_.step_into(x0, x1, kept_);
      out.stats = kept_.stats;
      lwsccd::detail::widen_into(kept_.contacts, out.contacts);
    }
  }
  StepResult<Scalar> kept_;

  template <class Q>
  StepOutcome from_device(const Vec3<Q>* device_x0, const Vec3<Q>* device_x1) {
    return this->outcome(this->pipeline_.step_from_device(device_x0, device_x1));
  }
  template <class Q>
  AnyDeviceContacts on_device(const Vec3<Q>* device_x0, const Vec3<Q>* device_x1) {
    return lwsccd::detail::any_device_contacts(this->pipeline_.step_on_device(device_x0, device_x1));
  }
};

/// A GPU pipeline with the chosen policies. Throws InputError for unknown names, bad parameters
/// or a bad mesh/layout, and lwsccd::Error when there is no CUDA device.
inline std::unique_ptr<AnyPipeline> make_any_pipeline(std::shared_ptr<const TriangleMesh> mesh, const BodyLayout& layout,
                                                      const PipelineParams& params, const PolicyChoice& choice) {
  int devices = 0;
  if (cudaGetDeviceCount(&devices) != cudaSuccess || devices == 0) {
    cudaGetLastError();  // clear the "no device" error
    throw Error("lwsccd: no CUDA device for the GPU backend");
  }
  return dispatch_policies(choice, [&](auto bv, auto method, auto scalar) -> std::unique_ptr<AnyPipeline> {
    using BV = typename decltype(bv)::type;
    using Method = typename decltype(method)::type;
    using T = typename decltype(scalar)::type;
    auto make = [&](auto scheduler) -> std::unique_ptr<AnyPipeline> {
      using Pipeline = CcdPipeline<BV, typename decltype(scheduler)::type, Method, T>;
      return std::make_unique<AnyPipelineAdapter<Pipeline>>(mesh, layout, params);
    };
    if (choice.scheduler == "static") return make(PolicyTag<StaticTaskList>{});
    if (choice.scheduler == "gproximity") return make(PolicyTag<GProximityBalancer>{});
    return make(PolicyTag<LazyStealScheduler>{});
  });
}

/// The first CUDA device's name, or "" when there is none.
inline std::string device_name() {
  int devices = 0;
  if (cudaGetDeviceCount(&devices) != cudaSuccess || devices == 0) {
    cudaGetLastError();
    return "";
  }
  cudaDeviceProp prop{};
  LWSCCD_CUDA_CHECK(cudaGetDeviceProperties(&prop, 0));
  return prop.name;
}

}  // namespace lwsccd::gpu
