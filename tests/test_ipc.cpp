// <lwsccd/ipc.hpp>: ipc-toolkit's two CCD calls over Eigen matrices, on the CPU backend.
#include <catch2/catch.hpp>

#include <Eigen/Core>

#include <limits>

#include "lwsccd/ipc.hpp"
#include "scene_fixtures.hpp"

using namespace lwsccd;

namespace {

struct Falling {
  Eigen::MatrixXd v0, v1;
  Eigen::MatrixXi edges, faces;
};

// A fixed triangle at z = 0 and a smaller one above it, moved down by `drop` (vertex 3 passes
// z = 0 inside the fixed triangle at t = 1 / drop when drop >= 1).
Falling two_triangles(double drop) {
  Falling s;
  s.v0.resize(6, 3);
  s.v0 << 0, 0, 0, 2, 0, 0, 0, 2, 0, 0.3, 0.3, 1.0, 0.8, 0.3, 1.0, 0.3, 0.8, 1.2;
  s.v1 = s.v0;
  s.v1.bottomRows(3).col(2).array() -= drop;
  s.faces.resize(2, 3);
  s.faces << 0, 1, 2, 3, 4, 5;
  s.edges.resize(6, 2);
  s.edges << 0, 1, 1, 2, 0, 2, 3, 4, 4, 5, 3, 5;
  return s;
}

Eigen::MatrixXd as_matrix(const std::vector<Vec3d>& x) {
  Eigen::MatrixXd m(static_cast<Eigen::Index>(x.size()), 3);
  for (std::size_t i = 0; i < x.size(); ++i) m.row(static_cast<Eigen::Index>(i)) << x[i].x, x[i].y, x[i].z;
  return m;
}

}  // namespace

TEST_CASE("ipc::compute_collision_free_stepsize: the rescaled certified contact, 1 when free", "[ipc]") {
  const Falling s = two_triangles(2.0);
  const ipc::CollisionMesh mesh(s.v0, s.edges, s.faces);
  // The contact is at t = 1/2 exactly; the certified lower bound lies within 1e-6 below it.
  const double step = ipc::compute_collision_free_stepsize(mesh, s.v0, s.v1);
  CHECK(step <= 0.8 * 0.5);
  CHECK(step >= 0.8 * (0.5 - 1e-6));
  CHECK_FALSE(ipc::is_step_collision_free(mesh, s.v0, s.v1));
  // The step it returns is collision free; so is any shorter one.
  const Eigen::MatrixXd stop = s.v0 + step * (s.v1 - s.v0);
  CHECK(ipc::is_step_collision_free(mesh, s.v0, stop));
  ipc::CcdSettings exact_step;
  exact_step.conservative_rescaling = 1.0;
  CHECK(ipc::compute_collision_free_stepsize(mesh, s.v0, s.v1, 0.0, exact_step) == Approx(0.5).margin(1e-6));
  // Stopping short: a full step, free; within a minimum distance of 0.6, not free.
  const Falling short_drop = two_triangles(0.5);
  CHECK(ipc::compute_collision_free_stepsize(mesh, short_drop.v0, short_drop.v1) == 1.0);
  CHECK(ipc::is_step_collision_free(mesh, short_drop.v0, short_drop.v1));
  CHECK_FALSE(ipc::is_step_collision_free(mesh, short_drop.v0, short_drop.v1, 0.6));
  CHECK(ipc::compute_collision_free_stepsize(mesh, short_drop.v0, short_drop.v1, 0.6) < 1.0);
}

TEST_CASE("ipc: a folded cloth's step agrees with the CPU pipeline's earliest contact, call after call", "[ipc]") {
  const auto m = lwsccd_test::folded_cloth(20, 2);
  auto shared = std::make_shared<const TriangleMesh>(m.mesh);
  Eigen::MatrixXi faces(m.mesh.num_faces(), 3), edges(m.mesh.num_edges(), 2);
  for (index_t f = 0; f < m.mesh.num_faces(); ++f) faces.row(f) << m.mesh.face(f).v[0], m.mesh.face(f).v[1], m.mesh.face(f).v[2];
  for (index_t e = 0; e < m.mesh.num_edges(); ++e) edges.row(e) << m.mesh.edges()[e].v[0], m.mesh.edges()[e].v[1];
  const Eigen::MatrixXd v0 = as_matrix(m.x0), v1 = as_matrix(m.x1);
  const ipc::CollisionMesh mesh(v0, edges, faces);
  cpu::CcdPipeline<> contacts(shared);
  const double earliest = contacts.step(m.x0, m.x1).contacts.earliest_toi;
  REQUIRE(earliest < 1.0);
  // A line search's repeated calls (the mesh keeps its pipeline): each is 0.8 x the earliest
  // contact of its own step, which for a shorter step is the same contact later in its time.
  for (double alpha : {1.0, 0.5, 0.25}) {
    const Eigen::MatrixXd end = v0 + alpha * (v1 - v0);
    const double step = ipc::compute_collision_free_stepsize(mesh, v0, end);
    if (earliest < alpha) {
      // Both lower bounds lie within the tolerance (1e-6) below their exact contacts.
      CHECK(step <= 0.8 * (earliest + 1e-6) / alpha + 1e-9);
      CHECK(step >= 0.8 * (earliest / alpha - 1e-6) - 1e-9);
      CHECK_FALSE(ipc::is_step_collision_free(mesh, v0, end));
    } else {
      CHECK(ipc::is_step_collision_free(mesh, v0, end) == (step == 1.0));
    }
  }
}

TEST_CASE("ipc: bad meshes and positions are refused with what and where", "[ipc]") {
  const Falling s = two_triangles(2.0);
  Eigen::MatrixXi loose_edge(7, 2);
  loose_edge << s.edges, Eigen::RowVector2i(0, 4);
  CHECK_THROWS_WITH(ipc::CollisionMesh(s.v0, loose_edge, s.faces), Catch::Contains("belongs to no face"));
  Eigen::MatrixXd extra(7, 3);
  extra << s.v0, Eigen::RowVector3d(5, 5, 5);
  CHECK_THROWS_WITH(ipc::CollisionMesh(extra, s.edges, s.faces), Catch::Contains("vertex 6 belongs to no face"));
  Eigen::MatrixXi bad_faces = s.faces;
  bad_faces(1, 2) = 9;
  CHECK_THROWS_AS(ipc::CollisionMesh(s.v0, s.edges, bad_faces), InputError);
  const ipc::CollisionMesh mesh(s.v0, s.edges, s.faces);
  CHECK_THROWS_WITH(ipc::compute_collision_free_stepsize(mesh, s.v0.topRows(5), s.v1.topRows(5)),
                    Catch::Contains("vertices_t0") && Catch::Contains("6 x 3"));
  Eigen::MatrixXd nan = s.v1;
  nan(4, 1) = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_AS(ipc::compute_collision_free_stepsize(mesh, s.v0, nan), InputError);
  CHECK_THROWS_WITH(ipc::compute_collision_free_stepsize(mesh, s.v0, s.v1, -1.0), Catch::Contains("min_distance"));
  ipc::CcdSettings bad;
  bad.conservative_rescaling = 0;
  CHECK_THROWS_WITH(ipc::compute_collision_free_stepsize(mesh, s.v0, s.v1, 0.0, bad), Catch::Contains("conservative_rescaling"));
  bad = {};
  bad.tolerance = 0;
  CHECK_THROWS_WITH(ipc::is_step_collision_free(mesh, s.v0, s.v1, 0.0, bad), Catch::Contains("tolerance"));
}
