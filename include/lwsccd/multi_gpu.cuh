// lwsccd — a CCD step split over several GPUs, as users include it: gpu::MultiGpuPipeline
// (pipeline/multi_gpu_pipeline.cuh), the same contacts as gpu::CcdPipeline from one process driving
// several GPUs or from one process per GPU. Needs NCCL: in lwsccd's build the CMake target
// lwsccd::multi_gpu; against the installed package, lwsccd::lwsccd and NCCL (-lnccl).
#pragma once

#include "lwsccd/pipeline/multi_gpu_pipeline.cuh"
