// An IPC-style line search whose step bound comes from lwsccd (plain C++, Eigen matrices as
// ipc-toolkit takes them; no GPU needed). ipc-toolkit's line search calls
//     ipc::compute_collision_free_stepsize(collision_mesh, V0, V1)
// and this one calls the same function of lwsccd::ipc: the one line that changes.
//
//   lwsccd-ipc-line-search [--triangles N] [--steps K]
//
// Each step of the built-in scene (a folded cloth dropped on a ball) proposes a move twice as long
// as the simulation's own, like an optimizer that overshoots; the line search takes the largest
// collision-free fraction of it and checks the result with is_step_collision_free.
#include <Eigen/Core>

#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

#include "lwsccd/ipc.hpp"
#include "lwsccd/simulation/simulation.hpp"

namespace {

Eigen::MatrixXd matrix_of(const std::vector<lwsccd::Vec3d>& points) {
  Eigen::MatrixXd m(static_cast<Eigen::Index>(points.size()), 3);
  for (std::size_t v = 0; v < points.size(); ++v) m.row(static_cast<Eigen::Index>(v)) << points[v].x, points[v].y, points[v].z;
  return m;
}

}  // namespace

int main(int argc, char** argv) {
  std::size_t triangles = 20000;
  int steps = 3;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if ((arg == "--triangles" || arg == "--steps") && i + 1 < argc) {
      const long value = std::strtol(argv[++i], nullptr, 10);
      if (value <= 0) {
        std::fprintf(stderr, "lwsccd-ipc-line-search: %s takes a positive number\n", arg.c_str());
        return 1;
      }
      if (arg == "--triangles") triangles = static_cast<std::size_t>(value);
      else steps = static_cast<int>(value);
    } else {
      std::fprintf(stderr, "usage: lwsccd-ipc-line-search [--triangles N] [--steps K]\n");
      return 1;
    }
  }
  try {
    lwsccd::ClothBallSimulation sim(triangles);
    const lwsccd::TriangleMesh& mesh = *sim.mesh();
    Eigen::MatrixXi edges(mesh.num_edges(), 2), faces(mesh.num_faces(), 3);
    for (lwsccd::index_t e = 0; e < mesh.num_edges(); ++e) edges.row(e) << mesh.edges()[e].v[0], mesh.edges()[e].v[1];
    for (lwsccd::index_t f = 0; f < mesh.num_faces(); ++f)
      faces.row(f) << mesh.faces()[f].v[0], mesh.faces()[f].v[1], mesh.faces()[f].v[2];
    sim.advance(30);  // (the cloth near the ball)
    const lwsccd::Step first = sim.next_step();
    // The collision mesh, made once; it keeps its pipeline between calls.
    const lwsccd::ipc::CollisionMesh collision_mesh(matrix_of(first.x0), edges, faces);
    std::printf("lwsccd-ipc-line-search: %d triangles, %d vertices\n", mesh.num_faces(), mesh.num_vertices());
    for (int s = 0; s < steps; ++s) {
      const lwsccd::Step step = s == 0 ? first : sim.next_step();
      const Eigen::MatrixXd V0 = matrix_of(step.x0);
      const Eigen::MatrixXd V1 = V0 + 2.0 * (matrix_of(step.x1) - V0);  // the overshooting proposal
      const double alpha = lwsccd::ipc::compute_collision_free_stepsize(collision_mesh, V0, V1);  // was ipc::...
      const Eigen::MatrixXd taken = V0 + alpha * (V1 - V0);
      const bool free = lwsccd::ipc::is_step_collision_free(collision_mesh, V0, taken);
      std::printf("step %d: collision-free step size %.9g of the proposal; the step taken is collision free: %s\n", s,
                  alpha, free ? "yes" : "no");
      if (!free) return 2;
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lwsccd-ipc-line-search: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
