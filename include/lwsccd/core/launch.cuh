// lwsccd — a kernel launched to overlap the end of the kernel before it on its stream (programmatic
// dependent launch, sm_90 and later): its blocks are set up while the earlier grid finishes and
// wait on the device until it has completed, instead of the stream waiting between the two.
#pragma once

#include <cuda_runtime.h>

#include <utility>

#include "lwsccd/core/cuda_check.cuh"

namespace lwsccd::detail {

/// First thing in a kernel that launch_after_previous may launch: waits until the grids before it
/// on its stream have completed and their writes are visible. A no-op for a kernel launched
/// plainly, and before sm_90.
__device__ __forceinline__ void await_previous_grids() {
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900
  asm volatile("griddepcontrol.wait;" ::: "memory");
#endif
}

/// Lets the next kernel on the stream, where launch_after_previous launched it, start its blocks
/// now (they wait in await_previous_grids). Only once every block of this grid has said so, so the
/// next grid never takes the place of one of this grid's blocks. A no-op before sm_90.
__device__ __forceinline__ void allow_next_grid() {
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900
  asm volatile("griddepcontrol.launch_dependents;" ::: "memory");
#endif
}

/// Both, the first thing in a kernel that launch_after_previous may launch.
__device__ __forceinline__ void start_after_previous_grids() {
  await_previous_grids();
  allow_next_grid();
}

/// True where launch_after_previous can overlap launches: a device of compute capability 9.0 or
/// later.
inline bool device_overlaps_launches(int device) {
  int major = 0;
  LWSCCD_CUDA_CHECK(cudaDeviceGetAttribute(&major, cudaDevAttrComputeCapabilityMajor, device));
  return major >= 9;
}

/// Launches `kernel` on `stream`; with `overlap`, allowed to start before the kernel before it on
/// the stream has ended (the kernel must call await_previous_grids before it reads what earlier
/// work wrote). The launch is checked.
template <class... Params, class... Args>
void launch_after_previous(bool overlap, void (*kernel)(Params...), unsigned grid, unsigned block, cudaStream_t stream,
                           Args&&... args) {
  if (!overlap) {
    kernel<<<grid, block, 0, stream>>>(std::forward<Args>(args)...);
    LWSCCD_CUDA_CHECK_LAUNCH();
    return;
  }
  cudaLaunchAttribute attribute[1] = {};
  attribute[0].id = cudaLaunchAttributeProgrammaticStreamSerialization;
  attribute[0].val.programmaticStreamSerializationAllowed = 1;
  cudaLaunchConfig_t config = {};
  config.gridDim = dim3(grid);
  config.blockDim = dim3(block);
  config.dynamicSmemBytes = 0;
  config.stream = stream;
  config.attrs = attribute;
  config.numAttrs = 1;
  LWSCCD_CUDA_CHECK(cudaLaunchKernelEx(&config, kernel, std::forward<Args>(args)...));
}

}  // namespace lwsccd::detail
