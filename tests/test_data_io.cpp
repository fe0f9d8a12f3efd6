// Loading the real scenes and the animation of ../shared/data, checked against the counts its
// README gives.
#include <catch2/catch.hpp>

#include <cstddef>
#include <string>

#include "lwsccd/io/dataset.hpp"
#include "lwsccd/io/mesh_io.hpp"
#include "test_support.hpp"

namespace lwsccd {
namespace {

struct ExpectedScene {
  const char* folder;
  const char* step_id;
  index_t vertices, faces;
  std::size_t vf_pairs, vf_true, ee_pairs, ee_true;
};

std::size_t count_true(const std::vector<bool>& values) {
  std::size_t n = 0;
  for (bool b : values) n += b ? 1 : 0;
  return n;
}

}  // namespace

TEST_CASE("the dataset's scenes load with the README's counts", "[io]") {
  const ExpectedScene expected = GENERATE(values<ExpectedScene>({
      {"cloth-ball", "92", 46598, 92230, 19034, 19032, 94825, 94822},
      {"cloth-funnel", "227", 9450, 18484, 92, 27, 263, 107},
      {"armadillo-rollers", "326", 12135, 24242, 4652, 4650, 19313, 19308},
  }));
  INFO("scene " << expected.folder);
  const Scene scene = load_scene(lwsccd_test::data_dir() + "/scenes/" + expected.folder);
  CHECK(scene.name == expected.folder);
  CHECK(scene.step_id == expected.step_id);
  const TriangleMesh& mesh = *scene.step.mesh;
  CHECK(mesh.num_vertices() == expected.vertices);
  CHECK(mesh.num_faces() == expected.faces);
  CHECK(scene.step.x0.size() == static_cast<std::size_t>(expected.vertices));
  CHECK(scene.step.x1.size() == static_cast<std::size_t>(expected.vertices));

  REQUIRE(scene.has_ground_truth);
  const GroundTruth& truth = scene.truth;
  CHECK(truth.vf.size() == expected.vf_pairs);
  CHECK(truth.ee.size() == expected.ee_pairs);
  CHECK(count_true(truth.vf_collides) == expected.vf_true);
  CHECK(count_true(truth.ee_collides) == expected.ee_true);

  // The edge-id convention must match the dataset's: ee pairs are ordered (smaller id first)...
  std::size_t unordered_ee = 0;
  for (const auto& pair : truth.ee) unordered_ee += pair.first < pair.second ? 0 : 1;
  CHECK(unordered_ee == 0);

  // ...and a colliding vf pair never joins a vertex to a face that contains it (those pairs
  // touch trivially and are excluded from the candidates).
  const index_t first_face_id = mesh.face_feature_id(0);
  std::size_t vertex_in_face = 0;
  for (std::size_t i = 0; i < truth.vf.size(); ++i) {
    if (!truth.vf_collides[i]) continue;
    const index_t v = truth.vf[i].first;
    const Face& face = mesh.face(truth.vf[i].second - first_face_id);
    vertex_in_face += (face.v[0] == v || face.v[1] == v || face.v[2] == v) ? 1 : 0;
  }
  CHECK(vertex_in_face == 0);
}

TEST_CASE("the horse-gallop animation loads as one sequence", "[io]") {
  const Sequence sequence = load_sequence(lwsccd_test::data_dir() + "/sequences/horse-gallop");
  CHECK(sequence.num_frames() == 48);
  CHECK(sequence.num_steps() == 47);
  CHECK(sequence.mesh()->num_vertices() == 8431);
  CHECK(sequence.mesh()->num_faces() == 16843);
  CHECK(sequence.frame_name(0) == "0001");
  CHECK(sequence.frame_name(47) == "0048");
  const Step last = sequence.step(46);
  CHECK(last.name == "0047->0048");
  CHECK(last.x1 == sequence.frame(47));
  // Consecutive frames of an animation differ.
  CHECK(sequence.frame(0) != sequence.frame(1));
}

}  // namespace lwsccd
