// lwsccd-ccd — --gpus N: the step split over several GPUs (gpu::MultiGpuPipeline) behind the
// program's AnyPipeline interface; compiled where CMake found NCCL (ccd_backends.cpp refuses the
// option elsewhere). Default policies only: one instantiation, not one per choice.
#include "ccd_app.hpp"
#include "lwsccd/multi_gpu.cuh"

namespace ccd_app {

namespace {

class MultiGpuAdapter : public AnyPipeline {
 public:
  MultiGpuAdapter(std::shared_ptr<const lwsccd::TriangleMesh> mesh, const lwsccd::BodyLayout& layout,
                  const lwsccd::PipelineParams& params, std::vector<int> devices)
      : pipeline_(std::move(mesh), layout, std::move(devices), params) {}
  StepOutcome step(const std::vector<lwsccd::Vec3d>& x0, const std::vector<lwsccd::Vec3d>& x1) override {
    return outcome(pipeline_.step(x0, x1));
  }
  StepOutcome step(const std::vector<lwsccd::Vec3f>& x0, const std::vector<lwsccd::Vec3f>& x1) override {
    return outcome(pipeline_.step(x0, x1));
  }
  void step_into(lwsccd::Span<const lwsccd::Vec3d> x0, lwsccd::Span<const lwsccd::Vec3d> x1, StepOutcome& out) override {
    out = step(std::vector<lwsccd::Vec3d>(x0.begin(), x0.end()), std::vector<lwsccd::Vec3d>(x1.begin(), x1.end()));
  }
  void step_into(lwsccd::Span<const lwsccd::Vec3f> x0, lwsccd::Span<const lwsccd::Vec3f> x1, StepOutcome& out) override {
    out = step(std::vector<lwsccd::Vec3f>(x0.begin(), x0.end()), std::vector<lwsccd::Vec3f>(x1.begin(), x1.end()));
  }
  StepOutcome step_from_device(const lwsccd::Vec3d* x0, const lwsccd::Vec3d* x1) override {
    return outcome(pipeline_.step_from_device(x0, x1));
  }
  StepOutcome step_from_device(const lwsccd::Vec3f* x0, const lwsccd::Vec3f* x1) override {
    return outcome(pipeline_.step_from_device(x0, x1));
  }
  lwsccd::AnyDeviceContacts step_on_device(const lwsccd::Vec3d* x0, const lwsccd::Vec3d* x1) override { return contacts(pipeline_.step_on_device(x0, x1)); }
  lwsccd::AnyDeviceContacts step_on_device(const lwsccd::Vec3f* x0, const lwsccd::Vec3f* x1) override { return contacts(pipeline_.step_on_device(x0, x1)); }
  void restart_from_root() override { pipeline_.restart_from_root(); }
  const lwsccd::TriangleMesh& mesh() const override { return pipeline_.mesh(); }
  const lwsccd::PipelineParams& params() const override { return pipeline_.params(); }
  std::string backend() const override { return "gpu"; }

 private:
  static StepOutcome outcome(lwsccd::gpu::MultiGpuStepResult<double>&& r) { return {r.stats, std::move(r.contacts)}; }
  static lwsccd::AnyDeviceContacts contacts(const lwsccd::DeviceStepResult<double>& r) {
    lwsccd::AnyDeviceContacts c;
    c.stats = r.stats;
    c.vf = r.contacts.vf;
    c.ee = r.contacts.ee;
    c.num_vf = r.contacts.num_vf;
    c.num_ee = r.contacts.num_ee;
    c.earliest_toi = r.contacts.earliest_toi;
    c.gave_up = r.contacts.gave_up;
    c.vf_counts = r.contacts.vf_counts;
    c.ee_counts = r.contacts.ee_counts;
    return c;
  }
  lwsccd::gpu::MultiGpuPipeline<> pipeline_;
};

}  // namespace

std::unique_ptr<AnyPipeline> make_multi_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh> mesh,
                                                     const lwsccd::BodyLayout& layout, const lwsccd::PipelineParams& params,
                                                     const PolicyChoice& choice, int gpus) {
  const PolicyChoice defaults;
  if (choice.bv != defaults.bv || choice.scheduler != defaults.scheduler || choice.method != defaults.method ||
      choice.precision != defaults.precision)
    throw lwsccd::InputError("command line", "--gpus", "a step split over GPUs takes the default policies (aabb, lazy, certified, double)");
  int available = 0;
  LWSCCD_CUDA_CHECK(cudaGetDeviceCount(&available));
  if (gpus > available)
    throw lwsccd::InputError("command line", "--gpus", std::to_string(gpus) + " GPUs asked, " + std::to_string(available) + " present");
  std::vector<int> devices;
  for (int d = 0; d < gpus; ++d) devices.push_back(d);
  return std::make_unique<MultiGpuAdapter>(std::move(mesh), layout, params, std::move(devices));
}

}  // namespace ccd_app
