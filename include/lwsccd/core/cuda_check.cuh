// lwsccd — checking CUDA runtime calls (host side).
#pragma once

#include <cuda_runtime.h>

#include <string>

#include "lwsccd/core/error.hpp"

namespace lwsccd::detail {

inline void throw_on_cuda_error(cudaError_t status, const char* call, const char* file, int line) {
  if (status != cudaSuccess) {
    throw CudaError(std::string(file) + ":" + std::to_string(line) + ": " + call + " failed: " +
                    cudaGetErrorName(status) + " (" + cudaGetErrorString(status) + ")");
  }
}

}  // namespace lwsccd::detail

/// Wraps a CUDA runtime call; throws lwsccd::CudaError naming the call, file and line.
#define LWSCCD_CUDA_CHECK(call) ::lwsccd::detail::throw_on_cuda_error((call), #call, __FILE__, __LINE__)

/// Checks the launch that was just made (configuration errors) without synchronizing.
#define LWSCCD_CUDA_CHECK_LAUNCH() LWSCCD_CUDA_CHECK(cudaPeekAtLastError())
