// lwsccd — built-in procedural scenes, so programs and tests run with no data files.
#pragma once

#include <cstddef>
#include <vector>

#include "lwsccd/features/oracle.hpp"
#include "lwsccd/io/mesh_io.hpp"

namespace lwsccd {

/// A step with several bodies: which faces belong to which body and which bodies self-collide.
struct MultiBodyStep {
  Step step;
  BodyLayout layout;
};

/// A cloth draped and folded over a ball, one step of it falling. Body 0 is the cloth
/// (self-colliding), body 1 the ball (rigid: no self pairs). `target_triangles` sets the
/// resolution (at least 64); the cloth takes about 80% of the triangles.
///
/// The cloth has two folds that bring its layers within a fraction of an edge length of each
/// other, so the step has real self contacts as well as cloth-ball contacts.
MultiBodyStep make_cloth_ball_scene(std::size_t target_triangles);

}  // namespace lwsccd

#include "lwsccd/simulation/detail/scenes_impl.hpp"
