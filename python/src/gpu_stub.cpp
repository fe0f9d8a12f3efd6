// The Python extension's GPU functions when it is built without CUDA (see gpu_backend.hpp).
#include "gpu_backend.hpp"

namespace lwsccd_python {

const bool kBuiltWithGpu = false;
const bool kBuiltWithNccl = false;

int gpu_count() { return 0; }

std::string gpu_name() { return ""; }

void release_cached_memory() {}

std::unique_ptr<lwsccd::AnyPipeline> make_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh>, const lwsccd::BodyLayout&,
                                                       const lwsccd::PipelineParams&, const lwsccd::PolicyChoice&) {
  throw lwsccd::Error(
      "lwsccd: this build of the Python package has no GPU backend (rebuild with nvcc present and "
      "LWSCCD_PYTHON_GPU=1, see docs/PYTHON.md)");
}

std::unique_ptr<lwsccd::AnyPipeline> make_multi_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh>, const lwsccd::BodyLayout&,
                                                             const lwsccd::PipelineParams&, const lwsccd::PolicyChoice&,
                                                             std::vector<int>) {
  throw lwsccd::Error("lwsccd.Pipeline: devices= needs the GPU backend, which this build of the Python package has not (see docs/PYTHON.md)");
}

DeviceHitArrays copy_device_hits(const void*, std::size_t, bool, std::int64_t, std::int64_t) {
  throw lwsccd::Error("lwsccd: this build of the Python package has no GPU backend");
}

void free_device_array(void*) noexcept {}

void synchronize_stream(std::uintptr_t) {}

}  // namespace lwsccd_python
