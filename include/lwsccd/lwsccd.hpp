// lwsccd — everything that compiles with a plain C++17 compiler: the CPU backend of every stage,
// I/O and the built-in simulation. The stages, in the order a step runs them (docs/DESIGN.md):
// geometry -> bvh -> traversal (broad phase) -> features -> narrow_phase, composed by pipeline.
// The GPU backend adds <lwsccd/traverse.cuh> and <lwsccd/pipeline.cuh>.
#pragma once

#include "lwsccd/core/config.hpp"
#include "lwsccd/core/error.hpp"
#include "lwsccd/core/span.hpp"

#include "lwsccd/geometry/aabb.hpp"
#include "lwsccd/geometry/bv_traits.hpp"
#include "lwsccd/geometry/mesh.hpp"
#include "lwsccd/geometry/morton.hpp"
#include "lwsccd/geometry/obb.hpp"
#include "lwsccd/geometry/vec.hpp"

#include "lwsccd/bvh/bvh.hpp"

#include "lwsccd/traversal/bvtt.hpp"
#include "lwsccd/traversal/cpu_traverse.hpp"
#include "lwsccd/traversal/ray_task.hpp"
#include "lwsccd/traversal/traversal_task.hpp"

#include "lwsccd/features/oracle.hpp"
#include "lwsccd/features/orphans.hpp"
#include "lwsccd/features/representative.hpp"

#include "lwsccd/narrow_phase/ccd_filters.hpp"
#include "lwsccd/narrow_phase/ccd_query.hpp"
#include "lwsccd/narrow_phase/certified_ccd.hpp"
#include "lwsccd/narrow_phase/cubic_ccd.hpp"
#include "lwsccd/narrow_phase/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.hpp"

#include "lwsccd/pipeline/cpu_pipeline.hpp"

#include "lwsccd/io/dataset.hpp"
#include "lwsccd/io/mesh_io.hpp"
#include "lwsccd/io/png.hpp"
#include "lwsccd/io/query_io.hpp"
#include "lwsccd/io/render.hpp"

#include "lwsccd/simulation/scenes.hpp"
#include "lwsccd/simulation/simulation.hpp"
