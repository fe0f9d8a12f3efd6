// lwsccd-ccd — what the main program's CPU part (lwsccd_ccd.cpp) and GPU part (lwsccd_ccd_gpu.cu)
// share: the run-time choice of policies, turned into the library's compile-time policies by one
// dispatch, and a pipeline behind a virtual interface so that main() does not care which it runs.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "lwsccd/lwsccd.hpp"
#include "lwsccd/pipeline.hpp"

namespace ccd_app {

/// Policies chosen on the command line.
struct PolicyChoice {
  std::string bv = "aabb";                   ///< aabb | obb (float volumes, rounded outward)
  std::string scheduler = "lazy";            ///< GPU: static | gproximity | lazy
  std::string method = "certified";          ///< certified | filtered-inclusion | inclusion | cubic
  std::string precision = "double";          ///< narrow-phase scalar: float | double
};

/// One step's outcome with contacts in double whatever the narrow phase's precision.
struct StepOutcome {
  lwsccd::StepStats stats;
  lwsccd::NarrowPhaseResult<double> contacts;
};

/// A pipeline of any backend and policies.
class AnyPipeline {
 public:
  virtual ~AnyPipeline() = default;
  virtual StepOutcome step(const std::vector<lwsccd::Vec3d>& x0, const std::vector<lwsccd::Vec3d>& x1) = 0;
  /// GPU only: the step from positions copied to the device beforehand (not timed), contacts left
  /// there (gpu::CcdPipeline::step_on_device); nothing for the CPU backend.
  virtual std::optional<lwsccd::StepStats> step_on_device(const std::vector<lwsccd::Vec3d>&, const std::vector<lwsccd::Vec3d>&) {
    return std::nullopt;
  }
};

template <class T>
lwsccd::NarrowPhaseResult<double> to_double(lwsccd::NarrowPhaseResult<T>&& r) {
  if constexpr (std::is_same<T, double>::value) {
    return std::move(r);
  } else {
    lwsccd::NarrowPhaseResult<double> out;
    for (const auto& h : r.vf) out.vf.push_back({h.first, h.second, double(h.toi)});
    for (const auto& h : r.ee) out.ee.push_back({h.first, h.second, double(h.toi)});
    out.earliest_toi = double(r.earliest_toi);
    out.gave_up = r.gave_up;
    out.vf_counts = r.vf_counts;
    out.ee_counts = r.ee_counts;
    return out;
  }
}

/// Wraps any pipeline type with step(x0, x1) -> StepResult<T>.
template <class Pipeline>
class PipelineAdapter : public AnyPipeline {
 public:
  template <class... Args>
  explicit PipelineAdapter(Args&&... args) : pipeline_(std::forward<Args>(args)...) {}
  StepOutcome step(const std::vector<lwsccd::Vec3d>& x0, const std::vector<lwsccd::Vec3d>& x1) override {
    auto r = pipeline_.step(x0, x1);
    return {r.stats, to_double(std::move(r.contacts))};
  }

 protected:
  Pipeline pipeline_;
};

template <class T>
struct Tag {
  using type = T;
};

/// Calls f(Tag<BV>{}, Tag<Method>{}, Tag<T>{}) for the choice (validated by parse()).
template <class F>
auto dispatch_policies(const PolicyChoice& c, F&& f) {
  auto with_bv = [&](auto method, auto scalar) {
    if (c.bv == "obb") return f(Tag<lwsccd::Obbf>{}, method, scalar);
    return f(Tag<lwsccd::Aabbf>{}, method, scalar);
  };
  auto with_method = [&](auto scalar) {
    if (c.method == "inclusion") return with_bv(Tag<lwsccd::InclusionCcd>{}, scalar);
    if (c.method == "cubic") return with_bv(Tag<lwsccd::CubicCcd>{}, scalar);
    if (c.method == "filtered-inclusion") return with_bv(Tag<lwsccd::Filtered<lwsccd::InclusionCcd>>{}, scalar);
    return with_bv(Tag<lwsccd::CertifiedCcd>{}, scalar);
  };
  if (c.precision == "float") return with_method(Tag<float>{});
  return with_method(Tag<double>{});
}

std::unique_ptr<AnyPipeline> make_cpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh> mesh,
                                               const lwsccd::BodyLayout& layout, const lwsccd::PipelineParams& params,
                                               const PolicyChoice& choice);

/// The first CUDA device's name, or "" when there is none (or the program was built without CUDA).
std::string gpu_name();

/// Throws lwsccd::Error when built without CUDA.
std::unique_ptr<AnyPipeline> make_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh> mesh,
                                               const lwsccd::BodyLayout& layout, const lwsccd::PipelineParams& params,
                                               const PolicyChoice& choice);

}  // namespace ccd_app
