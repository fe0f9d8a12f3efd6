// GPU helpers shared by the benchmark programs.
#pragma once

#include <cuda_runtime.h>

#include <cstdio>
#include <vector>

#include "lwsccd/core/cuda_check.cuh"

namespace lwsccd_bench {

/// Properties of device 0, or false (with a message naming `program`) when there is no GPU.
inline bool first_gpu(cudaDeviceProp& prop, const char* program) {
  int devices = 0;
  if (cudaGetDeviceCount(&devices) != cudaSuccess || devices == 0) {
    std::fprintf(stderr, "%s: no CUDA device; nothing to measure\n", program);
    return false;
  }
  LWSCCD_CUDA_CHECK(cudaGetDeviceProperties(&prop, 0));
  return true;
}

/// Milliseconds of each of `reps` calls of f, measured with CUDA events on the default stream.
template <class F>
std::vector<double> time_with_events(int reps, F&& f) {
  cudaEvent_t start, stop;
  LWSCCD_CUDA_CHECK(cudaEventCreate(&start));
  LWSCCD_CUDA_CHECK(cudaEventCreate(&stop));
  std::vector<double> ms;
  for (int r = 0; r < reps; ++r) {
    LWSCCD_CUDA_CHECK(cudaEventRecord(start));
    f();
    LWSCCD_CUDA_CHECK(cudaEventRecord(stop));
    LWSCCD_CUDA_CHECK(cudaEventSynchronize(stop));
    float t = 0;
    LWSCCD_CUDA_CHECK(cudaEventElapsedTime(&t, start, stop));
    ms.push_back(t);
  }
  LWSCCD_CUDA_CHECK(cudaEventDestroy(start));
  LWSCCD_CUDA_CHECK(cudaEventDestroy(stop));
  return ms;
}

}  // namespace lwsccd_bench
