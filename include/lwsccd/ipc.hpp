// lwsccd — ipc-toolkit's CCD calls on lwsccd's CPU backend, over Eigen matrices as ipc-toolkit
// takes them: a one-namespace switch for an IPC line search.
//
//   lwsccd::ipc::CollisionMesh mesh(rest_vertices, edges, faces);        // was ipc::CollisionMesh
//   double step = lwsccd::ipc::compute_collision_free_stepsize(mesh, V0, V1);
//   bool free = lwsccd::ipc::is_step_collision_free(mesh, V0, V1);
//
// The mesh keeps one pipeline per question (its front, BVH and buffers), so a line search's
// repeated calls run at the steady-state speed. What the answers mean, and how they differ from
// ipc-toolkit's (all on the safe side): docs/PYTHON.md, "ipc-toolkit's calls". Plain C++ (needs
// Eigen 3.3 on the include path); the GPU backend is reached through the Python package's
// lwsccd.ipc or gpu::CcdPipeline.
#pragma once

#include <Eigen/Core>

#include <cmath>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "lwsccd/core/error.hpp"
#include "lwsccd/geometry/mesh.hpp"
#include "lwsccd/pipeline/cpu_pipeline.hpp"

namespace lwsccd::ipc {

/// The narrow phase's settings (ipc-toolkit's TightInclusionCCD has the same first and last).
struct CcdSettings {
  double tolerance = 1e-6;              ///< time resolution of the certified earliest contact
  int max_iterations = 16384;           ///< lwsccd's narrow-phase work bound per pair
  double conservative_rescaling = 0.8;  ///< the step returned: this times the earliest contact's lower bound
  unsigned threads = 0;                 ///< CPU threads (0: every core)
};

/// A triangle mesh's topology for CCD: ipc::CollisionMesh's constructor (rest positions, edges,
/// faces), triangles only. Edges that belong to no face, or vertices in no face (codimensional
/// elements, which ipc-toolkit also checks), are refused with an InputError rather than left
/// unchecked.
class CollisionMesh {
 public:
  CollisionMesh(const Eigen::MatrixXd& rest_positions, const Eigen::MatrixXi& edges, const Eigen::MatrixXi& faces);

  int num_vertices() const { return mesh_->num_vertices(); }
  const TriangleMesh& mesh() const { return *mesh_; }

  /// The pipeline answering `mode` with these settings (made on first use, kept: a new one when
  /// the settings change).
  cpu::CcdPipeline<>& pipeline(CcdMode mode, double min_distance, const CcdSettings& settings) const;

 private:
  std::shared_ptr<const TriangleMesh> mesh_;
  struct Cached {
    std::unique_ptr<cpu::CcdPipeline<>> pipeline;
    PipelineParams params;
  };
  mutable Cached earliest_, set_;
};

/// A step size in [0, 1] that is collision free (ipc::compute_collision_free_stepsize): 1 when no
/// two elements come within `min_distance` while the vertices move from `vertices_t0` (assumed
/// intersection free) to `vertices_t1`, else conservative_rescaling x a certified lower bound of
/// the earliest such time (at most `tolerance` before it). Throws InputError for bad shapes or
/// non-finite positions.
double compute_collision_free_stepsize(const CollisionMesh& mesh, const Eigen::MatrixXd& vertices_t0,
                                       const Eigen::MatrixXd& vertices_t1, double min_distance = 0.0,
                                       const CcdSettings& settings = {});

/// Whether no two elements come within `min_distance` during the step (ipc::is_step_collision_free).
/// Conservative: a pair within the tolerance of contact counts as a collision.
bool is_step_collision_free(const CollisionMesh& mesh, const Eigen::MatrixXd& vertices_t0,
                            const Eigen::MatrixXd& vertices_t1, double min_distance = 0.0, const CcdSettings& settings = {});

// ---- definitions ----

namespace detail {

inline std::vector<Vec3d> positions_of(const Eigen::MatrixXd& v, int num_vertices, const char* name) {
  if (v.cols() != 3 || v.rows() != num_vertices)
    throw InputError("lwsccd::ipc", name,
                     "must be " + std::to_string(num_vertices) + " x 3, got " + std::to_string(v.rows()) + " x " +
                         std::to_string(v.cols()));
  std::vector<Vec3d> out(static_cast<std::size_t>(num_vertices));
  for (int i = 0; i < num_vertices; ++i) out[static_cast<std::size_t>(i)] = {v(i, 0), v(i, 1), v(i, 2)};
  return out;
}

inline void check_settings(double min_distance, const CcdSettings& s) {
  if (!(min_distance >= 0) || !std::isfinite(min_distance))
    throw InputError("lwsccd::ipc", "min_distance", "must be finite and >= 0");
  if (!(s.conservative_rescaling > 0 && s.conservative_rescaling <= 1))
    throw InputError("lwsccd::ipc", "conservative_rescaling", "must be in (0, 1]");
}

}  // namespace detail

inline CollisionMesh::CollisionMesh(const Eigen::MatrixXd& rest_positions, const Eigen::MatrixXi& edges,
                                    const Eigen::MatrixXi& faces) {
  const auto n = static_cast<index_t>(rest_positions.rows());
  if (rest_positions.cols() != 3) throw InputError("lwsccd::ipc::CollisionMesh", "rest_positions", "must have 3 columns (3D)");
  if (faces.cols() != 3 || faces.rows() == 0)
    throw InputError("lwsccd::ipc::CollisionMesh", "faces", "must be num_faces (> 0) x 3");
  std::vector<Face> f(static_cast<std::size_t>(faces.rows()));
  for (Eigen::Index i = 0; i < faces.rows(); ++i)
    for (int k = 0; k < 3; ++k) f[static_cast<std::size_t>(i)].v[k] = faces(i, k);
  mesh_ = std::make_shared<const TriangleMesh>(n, std::move(f), "lwsccd::ipc::CollisionMesh");  // checks indices
  if (edges.size() && edges.cols() != 2) throw InputError("lwsccd::ipc::CollisionMesh", "edges", "must be num_edges x 2");
  for (Eigen::Index i = 0; i < edges.rows() && edges.size(); ++i) {
    const index_t a = std::min(edges(i, 0), edges(i, 1)), b = std::max(edges(i, 0), edges(i, 1));
    bool in_a_face = false;
    if (a >= 0 && b < n)
      for (index_t face : mesh_->vertex_faces(a))
        for (int k = 0; k < 3; ++k)
          if (mesh_->face(face).v[k] == b) in_a_face = true;
    if (!in_a_face)
      throw InputError("lwsccd::ipc::CollisionMesh", "edges",
                       "edge " + std::to_string(i) + " (" + std::to_string(edges(i, 0)) + ", " + std::to_string(edges(i, 1)) +
                           ") belongs to no face: lwsccd checks triangle meshes only");
  }
  for (index_t v = 0; v < n; ++v)
    if (mesh_->vertex_faces(v).empty())
      throw InputError("lwsccd::ipc::CollisionMesh", "rest_positions",
                       "vertex " + std::to_string(v) + " belongs to no face: lwsccd checks triangle meshes only");
}

inline cpu::CcdPipeline<>& CollisionMesh::pipeline(CcdMode mode, double min_distance, const CcdSettings& settings) const {
  Cached& c = mode == CcdMode::earliest ? earliest_ : set_;
  PipelineParams p;
  p.mode = mode;
  p.min_separation = min_distance;
  p.tolerance = settings.tolerance;
  p.max_iterations = settings.max_iterations;
  p.threads = settings.threads;
  p.validate();
  const bool same = c.pipeline && c.params.min_separation == p.min_separation && c.params.tolerance == p.tolerance &&
                    c.params.max_iterations == p.max_iterations && c.params.threads == p.threads;
  if (!same) {
    c.pipeline = std::make_unique<cpu::CcdPipeline<>>(mesh_, p);
    c.params = p;
  }
  return *c.pipeline;
}

inline double compute_collision_free_stepsize(const CollisionMesh& mesh, const Eigen::MatrixXd& vertices_t0,
                                              const Eigen::MatrixXd& vertices_t1, double min_distance,
                                              const CcdSettings& settings) {
  detail::check_settings(min_distance, settings);
  const std::vector<Vec3d> x0 = detail::positions_of(vertices_t0, mesh.num_vertices(), "vertices_t0");
  const std::vector<Vec3d> x1 = detail::positions_of(vertices_t1, mesh.num_vertices(), "vertices_t1");
  const double toi = mesh.pipeline(CcdMode::earliest, min_distance, settings).step(x0, x1).contacts.earliest_toi;
  return toi >= 1.0 ? 1.0 : settings.conservative_rescaling * toi;
}

inline bool is_step_collision_free(const CollisionMesh& mesh, const Eigen::MatrixXd& vertices_t0,
                                   const Eigen::MatrixXd& vertices_t1, double min_distance, const CcdSettings& settings) {
  detail::check_settings(min_distance, settings);
  const std::vector<Vec3d> x0 = detail::positions_of(vertices_t0, mesh.num_vertices(), "vertices_t0");
  const std::vector<Vec3d> x1 = detail::positions_of(vertices_t1, mesh.num_vertices(), "vertices_t1");
  const auto r = mesh.pipeline(CcdMode::set, min_distance, settings).step(x0, x1);
  return r.contacts.vf.empty() && r.contacts.ee.empty();
}

}  // namespace lwsccd::ipc
