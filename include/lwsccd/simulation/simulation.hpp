// lwsccd — the built-in animated scene: a square cloth dropped on a rigid ball, with just enough
// physics to give real folds and self contacts, at any resolution (1K to 10M triangles and more).
#pragma once

#include <cstddef>
#include <memory>
#include <vector>

#include "lwsccd/features/oracle.hpp"
#include "lwsccd/geometry/mesh.hpp"
#include "lwsccd/geometry/vec.hpp"
#include "lwsccd/io/mesh_io.hpp"

namespace lwsccd {

/// A cloth falling onto a ball and the floor under it, frame after frame (60 frames a second).
///
/// The motion comes from a coarse position-based simulation (at most 64 x 64 cloth cells:
/// gravity, stretch, shear and bending constraints, the ball and the floor pushing the cloth out,
/// friction on contact); the rendered cloth interpolates it bilinearly at the requested
/// resolution. So every resolution shows the same folds, and making a frame costs little next to
/// the collision detection on it. Cloth-cloth response is crude (coarse vertices keep a thickness
/// apart): layers rest on each other without merging, and faces that slide fast still pass
/// through between vertices, which is what gives the CCD its self contacts.
///
/// Bodies (layout()): 0 the cloth (deforming, self-colliding), 1 the ball (rigid, never moves).
class ClothBallSimulation {
 public:
  /// `target_triangles` >= 64: the ball takes about a fifth, the cloth the rest.
  explicit ClothBallSimulation(std::size_t target_triangles);

  const std::shared_ptr<const TriangleMesh>& mesh() const { return mesh_; }
  const BodyLayout& layout() const { return layout_; }
  std::size_t frame() const { return frame_; }
  std::size_t cloth_triangles() const { return static_cast<std::size_t>(2 * fine_ * fine_); }
  /// Vertex positions of the current frame (cloth vertices first, then the ball's).
  const std::vector<Vec3d>& positions() const { return positions_; }
  /// Advances the simulation by `frames` frames.
  void advance(std::size_t frames = 1);
  /// The next CCD step; advances the scene by its length. A frame is cut into substeps() steps so
  /// that a step moves the cloth about as far at every resolution, relative to its triangles
  /// (as a simulator's time step shrinks with its mesh): the candidate pairs then grow with the
  /// triangle count, not with its square.
  Step next_step();
  int substeps() const { return substeps_; }

 private:
  void simulate_frame();
  void refine(const std::vector<Vec3d>& coarse_x);
  void repel_layers(std::vector<Vec3d>& x) const;

  int coarse_ = 0, fine_ = 0;  // cloth cells per side
  int substeps_ = 1, substep_ = 0;
  std::vector<Vec3d> coarse_x_, coarse_v_, frame_start_;
  std::vector<Vec3d> positions_;
  std::size_t ball_vertex_offset_ = 0, frame_ = 0;
  std::shared_ptr<const TriangleMesh> mesh_;
  BodyLayout layout_;
};

}  // namespace lwsccd

#include "lwsccd/simulation/detail/simulation_impl.hpp"
