// What the Python extension needs of the GPU backend, in plain C++ (no nanobind in CUDA code):
// gpu_backend.cu defines it where the module is built with CUDA, gpu_stub.cpp where it is not.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "lwsccd/pipeline/any_pipeline.hpp"

namespace lwsccd_python {

extern const bool kBuiltWithGpu;
/// True when the GPU backend can split a step over several GPUs (built with NCCL).
extern const bool kBuiltWithNccl;

/// The number of CUDA devices (0 without the GPU backend or a driver).
int gpu_count();

/// The first CUDA device's name; "" when there is none or the module has no GPU backend.
std::string gpu_name();

/// gpu::make_any_pipeline; throws lwsccd::Error when the module has no GPU backend.
std::unique_ptr<lwsccd::AnyPipeline> make_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh> mesh,
                                                       const lwsccd::BodyLayout& layout, const lwsccd::PipelineParams& params,
                                                       const lwsccd::PolicyChoice& choice);

/// gpu::make_any_multi_gpu_pipeline over `devices`; throws lwsccd::Error when the module has no GPU
/// backend or no NCCL, InputError for other policies than the default ones or a device not present.
std::unique_ptr<lwsccd::AnyPipeline> make_multi_gpu_pipeline(std::shared_ptr<const lwsccd::TriangleMesh> mesh,
                                                             const lwsccd::BodyLayout& layout, const lwsccd::PipelineParams& params,
                                                             const lwsccd::PolicyChoice& choice, std::vector<int> devices);

/// One list of device hits as new device arrays: `pairs` (n x 2 element indices, int64) and
/// `toi` (n, float64), each freed by free_device_array (allocated also when n is 0).
struct DeviceHitArrays {
  std::int64_t* pairs = nullptr;
  double* toi = nullptr;
  std::size_t n = 0;
};

/// Copies a list of FeatureHit (feature ids) into DeviceHitArrays, ids turned into element indices
/// by subtracting first_base / second_base.
DeviceHitArrays copy_device_hits(const void* hits, std::size_t n, bool toi_is_double, std::int64_t first_base,
                                 std::int64_t second_base);
void free_device_array(void* p) noexcept;

/// gpu::release_cached_memory(); nothing without the GPU backend.
void release_cached_memory();

/// Waits for a CUDA stream given by its handle's address (a producer's stream in
/// __cuda_array_interface__); nothing without the GPU backend.
void synchronize_stream(std::uintptr_t stream);

}  // namespace lwsccd_python
