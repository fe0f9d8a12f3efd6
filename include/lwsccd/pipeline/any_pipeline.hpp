// lwsccd — a pipeline whose policies are chosen at run time, by name: for programs and bindings
// that take the bounding volume, scheduler, method and precision from their user (the main
// program, the benchmark, the Python package). One dispatch turns the names into the library's
// compile-time policies; the pipeline then sits behind a virtual interface, so the caller does
// not care which backend or policies it runs. Plain C++: the GPU backend's factory is in
// any_pipeline.cuh. Each combination of policies is compiled where its factory is instantiated.
#pragma once

#include <memory>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "lwsccd/core/error.hpp"
#include "lwsccd/core/span.hpp"
#include "lwsccd/geometry/aabb.hpp"
#include "lwsccd/geometry/obb.hpp"
#include "lwsccd/narrow_phase/cubic_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.hpp"
#include "lwsccd/pipeline/cpu_pipeline.hpp"

namespace lwsccd {

/// Policies by name.
struct PolicyChoice {
  std::string bv = "aabb";           ///< aabb | obb (float volumes, rounded outward)
  std::string scheduler = "lazy";    ///< GPU traversal load balancer: lazy | gproximity | static
  std::string method = "certified";  ///< certified | filtered-inclusion | inclusion | cubic
  std::string precision = "double";  ///< narrow-phase scalar: double | float
};

/// Throws InputError naming the field, the value and the accepted values, unless every name is known.
inline void validate(const PolicyChoice& c) {
  auto check = [](const char* field, const std::string& value, std::initializer_list<const char*> accepted) {
    std::string list;
    for (const char* a : accepted) {
      if (value == a) return;
      list += list.empty() ? a : std::string(", ") + a;
    }
    throw InputError("PolicyChoice", field, "unknown '" + value + "' (accepted: " + list + ")");
  };
  check("bv", c.bv, {"aabb", "obb"});
  check("scheduler", c.scheduler, {"lazy", "gproximity", "static"});
  check("method", c.method, {"certified", "filtered-inclusion", "inclusion", "cubic"});
  check("precision", c.precision, {"double", "float"});
}

/// A step's outcome, with contacts in double whatever the narrow phase's precision (a float TOI
/// converts exactly).
struct StepOutcome {
  StepStats stats;
  NarrowPhaseResult<double> contacts;
};

/// A step's contacts left in device memory (AnyPipeline::step_on_device): arrays of
/// FeatureHit<float> or FeatureHit<double> (`toi_is_double`), hit_bytes apart, valid until the
/// pipeline's next step.
struct AnyDeviceContacts {
  StepStats stats;
  const void* vf = nullptr;  ///< num_vf vertex-face hits (device memory)
  const void* ee = nullptr;  ///< num_ee edge-edge hits (device memory)
  std::size_t num_vf = 0, num_ee = 0;
  bool toi_is_double = true;
  std::size_t hit_bytes = sizeof(FeatureHit<double>);
  double earliest_toi = 1;
  std::size_t gave_up = 0;
  NarrowPhaseCounts vf_counts, ee_counts;
};

/// A pipeline of any backend and policies.
class AnyPipeline {
 public:
  virtual ~AnyPipeline() = default;
  /// One step from host positions (each mesh().num_vertices() points), double or float: float
  /// positions are widened exactly, so the answers are certified for them as given.
  virtual StepOutcome step(const std::vector<Vec3d>& x0, const std::vector<Vec3d>& x1) = 0;
  virtual StepOutcome step(const std::vector<Vec3f>& x0, const std::vector<Vec3f>& x1) = 0;
  /// One step from host arrays of any origin (e.g. a NumPy array's memory) into `out`. The GPU
  /// backend reads the arrays in place and reuses out's contact lists' memory
  /// (gpu::CcdPipeline::step_into: a loop that keeps one outcome pays no page faults for its
  /// contacts); the CPU backend copies the arrays and fills new lists.
  virtual void step_into(Span<const Vec3d> x0, Span<const Vec3d> x1, StepOutcome& out) = 0;
  virtual void step_into(Span<const Vec3f> x0, Span<const Vec3f> x1, StepOutcome& out) = 0;
  /// GPU backend: one step from positions in device memory (double or float). The CPU backend
  /// throws InputError.
  virtual StepOutcome step_from_device(const Vec3d* /*device_x0*/, const Vec3d* /*device_x1*/) { return no_device_positions(); }
  virtual StepOutcome step_from_device(const Vec3f* /*device_x0*/, const Vec3f* /*device_x1*/) { return no_device_positions(); }
  /// GPU backend: as step_from_device, with the contacts left in device memory. The CPU backend
  /// throws InputError.
  virtual AnyDeviceContacts step_on_device(const Vec3d* /*device_x0*/, const Vec3d* /*device_x1*/) { return no_device_results(); }
  virtual AnyDeviceContacts step_on_device(const Vec3f* /*device_x0*/, const Vec3f* /*device_x1*/) { return no_device_results(); }
  /// The next step traverses from the BVTT's root, not the last step's front (gpu::CcdPipeline::
  /// restart_from_root). Same answer either way.
  virtual void restart_from_root() = 0;
  virtual const TriangleMesh& mesh() const = 0;
  virtual const PipelineParams& params() const = 0;
  /// "cpu" or "gpu".
  virtual std::string backend() const = 0;

 private:
  [[noreturn]] StepOutcome no_device_positions() const {
    throw InputError("AnyPipeline::step_from_device", "", "the " + backend() + " backend takes host positions (this needs the GPU backend)");
  }
  [[noreturn]] AnyDeviceContacts no_device_results() const {
    throw InputError("AnyPipeline::step_on_device", "", "the " + backend() + " backend has no device results (this needs the GPU backend)");
  }
};

namespace detail {

/// AnyDeviceContacts of a step whose contacts a GPU pipeline left in device memory (its
/// step_on_device's result: stats and contacts with vf/ee device arrays, their counts, the
/// earliest time, the answers given up and the narrow phase's counts).
template <class DeviceStepResult>
AnyDeviceContacts any_device_contacts(const DeviceStepResult& r) {
  using Hit = std::remove_cv_t<std::remove_pointer_t<decltype(r.contacts.vf)>>;
  AnyDeviceContacts out;
  out.stats = r.stats;
  out.vf = r.contacts.vf;
  out.ee = r.contacts.ee;
  out.num_vf = r.contacts.num_vf;
  out.num_ee = r.contacts.num_ee;
  out.toi_is_double = std::is_same<std::remove_cv_t<decltype(Hit::toi)>, double>::value;
  out.hit_bytes = sizeof(Hit);
  out.earliest_toi = static_cast<double>(r.contacts.earliest_toi);
  out.gave_up = r.contacts.gave_up;
  out.vf_counts = r.contacts.vf_counts;
  out.ee_counts = r.contacts.ee_counts;
  return out;
}

template <class T>
NarrowPhaseResult<double> to_double(NarrowPhaseResult<T>&& r) {
  if constexpr (std::is_same<T, double>::value) {
    return std::move(r);
  } else {
    NarrowPhaseResult<double> out;
    out.vf.reserve(r.vf.size());
    out.ee.reserve(r.ee.size());
    for (const auto& h : r.vf) out.vf.push_back({h.first, h.second, double(h.toi)});
    for (const auto& h : r.ee) out.ee.push_back({h.first, h.second, double(h.toi)});
    out.earliest_toi = double(r.earliest_toi);
    out.gave_up = r.gave_up;
    out.vf_counts = r.vf_counts;
    out.ee_counts = r.ee_counts;
    return out;
  }
}

// `from`'s hits and numbers into `to`, its lists' memory reused (TOIs widened to double).
template <class T>
void widen_into(const NarrowPhaseResult<T>& from, NarrowPhaseResult<double>& to) {
  auto widen = [](const std::vector<FeatureHit<T>>& a, std::vector<FeatureHit<double>>& b) {
    b.resize(a.size());
    for (std::size_t i = 0; i < a.size(); ++i) b[i] = {a[i].first, a[i].second, double(a[i].toi)};
  };
  widen(from.vf, to.vf);
  widen(from.ee, to.ee);
  to.earliest_toi = double(from.earliest_toi);
  to.gave_up = from.gave_up;
  to.vf_counts = from.vf_counts;
  to.ee_counts = from.ee_counts;
}

}  // namespace detail

/// AnyPipeline over a pipeline type with step(x0, x1) -> StepResult<T>, mesh() and params().
template <class Pipeline>
class PipelineAdapter : public AnyPipeline {
 public:
  template <class... Args>
  explicit PipelineAdapter(std::string backend, Args&&... args)
      : pipeline_(std::forward<Args>(args)...), backend_(std::move(backend)) {}
  StepOutcome step(const std::vector<Vec3d>& x0, const std::vector<Vec3d>& x1) override { return outcome(pipeline_.step(x0, x1)); }
  StepOutcome step(const std::vector<Vec3f>& x0, const std::vector<Vec3f>& x1) override { return outcome(pipeline_.step(x0, x1)); }
  // (The GPU adapter overrides these: its pipeline steps from the arrays in place.)
  void step_into(Span<const Vec3d> x0, Span<const Vec3d> x1, StepOutcome& out) override {
    out = outcome(pipeline_.step(copied(x0, copy0_), copied(x1, copy1_)));
  }
  void step_into(Span<const Vec3f> x0, Span<const Vec3f> x1, StepOutcome& out) override {
    out = outcome(pipeline_.step(copied(x0, copy0f_), copied(x1, copy1f_)));
  }
  void restart_from_root() override { pipeline_.restart_from_root(); }
  const TriangleMesh& mesh() const override { return pipeline_.mesh(); }
  const PipelineParams& params() const override { return pipeline_.params(); }
  std::string backend() const override { return backend_; }
  Pipeline& pipeline() { return pipeline_; }

 protected:
  template <class Result>
  static StepOutcome outcome(Result&& r) {
    return {r.stats, detail::to_double(std::move(r.contacts))};
  }
  Pipeline pipeline_;
  std::string backend_;

 private:
  template <class Q>
  static const std::vector<Vec3<Q>>& copied(Span<const Vec3<Q>> from, std::vector<Vec3<Q>>& to) {
    to.assign(from.begin(), from.end());
    return to;
  }
  std::vector<Vec3d> copy0_, copy1_;  ///< step_into's positions, for a pipeline that takes vectors
  std::vector<Vec3f> copy0f_, copy1f_;
};

/// A type carried as a value (for the generic lambdas of dispatch_policies).
template <class T>
struct PolicyTag {
  using type = T;
};

/// Calls f(PolicyTag<BV>{}, PolicyTag<Method>{}, PolicyTag<T>{}) for the choice (validated first)
/// and returns what it returns. The scheduler is the GPU factory's to dispatch.
template <class F>
auto dispatch_policies(const PolicyChoice& c, F&& f) {
  validate(c);
  auto with_bv = [&](auto method, auto scalar) {
    if (c.bv == "obb") return f(PolicyTag<Obbf>{}, method, scalar);
    return f(PolicyTag<Aabbf>{}, method, scalar);
  };
  auto with_method = [&](auto scalar) {
    if (c.method == "inclusion") return with_bv(PolicyTag<InclusionCcd>{}, scalar);
    if (c.method == "cubic") return with_bv(PolicyTag<CubicCcd>{}, scalar);
    if (c.method == "filtered-inclusion") return with_bv(PolicyTag<Filtered<InclusionCcd>>{}, scalar);
    return with_bv(PolicyTag<CertifiedCcd>{}, scalar);
  };
  if (c.precision == "float") return with_method(PolicyTag<float>{});
  return with_method(PolicyTag<double>{});
}

namespace cpu {

/// A CPU pipeline with the chosen policies (the scheduler is not used: the CPU backend traverses
/// with its own engine). Throws InputError for unknown names, bad parameters or a bad mesh/layout.
inline std::unique_ptr<AnyPipeline> make_any_pipeline(std::shared_ptr<const TriangleMesh> mesh, const BodyLayout& layout,
                                                      const PipelineParams& params, const PolicyChoice& choice) {
  return dispatch_policies(choice, [&](auto bv, auto method, auto scalar) -> std::unique_ptr<AnyPipeline> {
    using Pipeline = CcdPipeline<typename decltype(bv)::type, typename decltype(method)::type, typename decltype(scalar)::type>;
    return std::make_unique<PipelineAdapter<Pipeline>>("cpu", mesh, layout, params);
  });
}

}  // namespace cpu
}  // namespace lwsccd
