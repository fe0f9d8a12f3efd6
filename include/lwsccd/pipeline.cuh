// lwsccd — the CCD pipeline on the GPU, as users include it (card): gpu::CcdPipeline (every stage
// of a step on the device, pipeline/gpu_pipeline.cuh) beside cpu::CcdPipeline
// (pipeline/cpu_pipeline.hpp), same API and same answers. The pipeline with its BV, scheduler,
// method and precision chosen at run time is pipeline/any_pipeline.cuh.
#pragma once

#include "lwsccd/pipeline/cpu_pipeline.hpp"
#include "lwsccd/pipeline/gpu_pipeline.cuh"
