// lwsccd — the traversal stage on the GPU, as users include it (card):
//
//   #include <lwsccd/traverse.cuh>
//   lwsccd::gpu::TraversalOutput<Task> out;
//   lwsccd::gpu::traverse<lwsccd::gpu::LazyStealScheduler>(task, seeds, num_seeds, out, record_front, stream);
//
// The engine and its scheduler policies (traversal/gpu_traverse.cuh), the library's tasks (BVTT
// self and inter collision: traversal/bvtt.hpp; rays: traversal/ray_task.hpp) and Karras's
// per-leaf traversal that the benchmark compares with (traversal/independent_traversal.cuh).
// A task of one's own needs only traversal/traversal_task.hpp (the contract) and this header.
#pragma once

#include "lwsccd/traversal/bvtt.hpp"
#include "lwsccd/traversal/gpu_traverse.cuh"
#include "lwsccd/traversal/independent_traversal.cuh"
#include "lwsccd/traversal/ray_task.hpp"
#include "lwsccd/traversal/traversal_task.hpp"
