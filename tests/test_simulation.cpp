// The built-in animated scene: deterministic, steps that chain, bodies, real self contacts.
#include <catch2/catch.hpp>

#include "lwsccd/pipeline/cpu_pipeline.hpp"
#include "lwsccd/simulation/simulation.hpp"

using namespace lwsccd;

TEST_CASE("ClothBallSimulation: deterministic steps that chain, a ball that never moves", "[simulation]") {
  ClothBallSimulation a(5000), b(5000);
  REQUIRE(a.mesh()->num_faces() >= 4000);
  REQUIRE(a.mesh()->num_faces() <= 6000);
  REQUIRE(a.layout().face_body.size() == static_cast<std::size_t>(a.mesh()->num_faces()));
  REQUIRE(a.layout().body_self_collides == std::vector<bool>{true, false});
  a.advance(20);
  b.advance(20);
  CHECK(a.positions() == b.positions());
  const std::size_t cloth_vertices = a.cloth_triangles() / 2 + 2 * static_cast<std::size_t>(std::sqrt(a.cloth_triangles() / 2.0)) + 1;
  Step previous = a.next_step();
  for (int s = 0; s < 2 * a.substeps(); ++s) {
    const Step next = a.next_step();
    REQUIRE(next.x0 == previous.x1);  // each step starts where the last ended
    for (std::size_t v = cloth_vertices; v < next.x0.size(); ++v) REQUIRE(next.x0[v] == next.x1[v]);  // rigid ball
    previous = next;
  }
  CHECK_THROWS_AS(ClothBallSimulation(10), InputError);
}

TEST_CASE("ClothBallSimulation: the cloth lands on the ball with self contacts that the pipeline finds", "[simulation]") {
  ClothBallSimulation sim(4000);
  sim.advance(30);
  cpu::CcdPipeline<> pipeline(sim.mesh(), sim.layout());
  std::size_t contacts = 0;
  for (int s = 0; s < 3; ++s) {
    const Step step = sim.next_step();
    const auto r = pipeline.step(step.x0, step.x1);
    contacts += r.stats.hits_vf + r.stats.hits_ee;
    // The ball keeps the cloth a margin away: every VF contact is on a cloth face.
    const auto& body = sim.layout().face_body;
    const index_t first_face_feature = sim.mesh()->num_vertices() + sim.mesh()->num_edges();
    for (const auto& h : r.contacts.vf) REQUIRE(body[h.second - first_face_feature] == 0);
  }
  CHECK(contacts > 0);
}
