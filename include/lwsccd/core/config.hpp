// lwsccd — configuration macros shared by every header.
//
// Every header of the library compiles both with nvcc and with a plain C++17 host compiler
// (the cuBQL habit): pure math is marked LWSCCD_HD and runs on the CPU backend and on the GPU.
#pragma once

#include <cassert>

#if defined(__CUDACC__)
#define LWSCCD_HD __host__ __device__
#define LWSCCD_DEVICE __device__
#define LWSCCD_HAS_CUDA_COMPILER 1
#else
#define LWSCCD_HD
#define LWSCCD_DEVICE
#define LWSCCD_HAS_CUDA_COMPILER 0
#endif

#if defined(__CUDA_ARCH__)
#define LWSCCD_IN_DEVICE_CODE 1
#else
#define LWSCCD_IN_DEVICE_CODE 0
#endif

// A function kept out of line on the device: a rarely taken path's registers stay out of its
// callers' allocation.
#if defined(__CUDACC__)
#define LWSCCD_NOINLINE __noinline__
#else
#define LWSCCD_NOINLINE
#endif

// Full unrolling of short fixed-count loops, so that small arrays indexed by the loop counter
// stay in registers on the device (no local-memory stack frame).
#if defined(__CUDACC__)
#define LWSCCD_UNROLL _Pragma("unroll")
#else
#define LWSCCD_UNROLL
#endif

// Before a __host__ __device__ template whose instantiations may call host-only code (a task's
// process() with the CPU backend's emitter): only the instantiations actually used on each side
// are compiled there, so nvcc's cross-execution-space warning does not apply.
#if defined(__CUDACC__)
#define LWSCCD_EXEC_CHECK_DISABLE _Pragma("nv_exec_check_disable")
#else
#define LWSCCD_EXEC_CHECK_DISABLE
#endif

// Device-side and host-side invariant checks. On the host, invalid *input* is reported by
// exceptions (see error.hpp); these asserts only guard internal invariants.
#define LWSCCD_ASSERT(cond) assert(cond)

#define LWSCCD_VERSION_MAJOR 0
#define LWSCCD_VERSION_MINOR 1
#define LWSCCD_VERSION_PATCH 0

// Small hot helpers of the certified narrow phase: forced inline in host code, where GCC kept them
// as calls (a third of the CPU backend's certified pass went to calls and their argument copies).
// Device code keeps nvcc's own inlining, with which the kernels' register use was tuned.
#if !defined(__CUDA_ARCH__) && (defined(__GNUC__) || defined(__clang__))
#define LWSCCD_HOST_INLINE __attribute__((always_inline)) inline
#else
#define LWSCCD_HOST_INLINE inline
#endif
