// Tests of frames, steps, sequences and the dataset's JSON files and scene folders, on small
// files written into a temporary folder (the PLY and OBJ readers: test_io_ply.cpp, test_io_obj.cpp).
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <set>
#include <string>
#include <vector>

#include "lwsccd/io/dataset.hpp"
#include "lwsccd/io/mesh_io.hpp"
#include "io_test_support.hpp"
#include "test_support.hpp"

namespace lwsccd {

using Catch::Contains;
using lwsccd_test::TempDir;
using namespace io_test;

TEST_CASE("load_frame picks the reader by extension", "[io]") {
  TempDir dir("frame");
  write_file(dir.file("a.PLY"), tetra_ascii_ply());
  write_file(dir.file("b.Obj"), tetra_obj());
  write_file(dir.file("c.stl"), "solid\n");
  check_tetra<double>(load_frame(dir.file("a.PLY")));
  check_tetra<double>(load_frame(dir.file("b.Obj")));
  CHECK_THAT(input_error_message([&] { load_frame(dir.file("c.stl")); }),
             Contains(dir.file("c.stl")) && Contains("unknown mesh file extension '.stl'"));
}

// ---------------------------------------------------------------------------------------------
// Steps and sequences

TEST_CASE("make_step pairs two frames of one topology", "[io]") {
  TempDir dir("step");
  write_file(dir.file("t0.obj"), tetra_obj());
  write_file(dir.file("t1.ply"), tetra_binary_ply<double>(false, "double"));
  const Step step = load_step(dir.file("t0.obj"), dir.file("t1.ply"));
  CHECK(step.name == "t0->t1");
  REQUIRE(step.mesh);
  CHECK(step.mesh->num_vertices() == 4);
  CHECK(step.mesh->num_faces() == 4);
  CHECK(step.mesh->num_edges() == 6);
  CHECK(step.x0.size() == 4);
  CHECK(step.x1.size() == 4);
  CHECK(step.x1[2] == tetra_positions[2]);
}

TEST_CASE("make_step rejects frames of different vertex count or faces", "[io]") {
  Frame t0{tetra_faces, tetra_positions, "first.obj"};
  SECTION("vertex count") {
    Frame t1 = t0;
    t1.source = "second.obj";
    t1.positions.push_back({2, 2, 2});
    CHECK_THAT(input_error_message([&] { make_step(t0, t1); }),
               Contains("first.obj") && Contains("second.obj") && Contains("5 vertices") && Contains("has 4"));
  }
  SECTION("face count") {
    Frame t1 = t0;
    t1.source = "second.obj";
    t1.faces.pop_back();
    CHECK_THAT(input_error_message([&] { make_step(t0, t1); }),
               Contains("first.obj") && Contains("second.obj") && Contains("3 faces"));
  }
  SECTION("a differing face") {
    Frame t1 = t0;
    t1.source = "second.obj";
    t1.faces[2] = Face{{1, 3, 2}};
    CHECK_THAT(input_error_message([&] { make_step(t0, t1); }),
               Contains("first.obj") && Contains("second.obj") && Contains("face 2") && Contains("(1 3 2)") &&
                   Contains("(1 2 3)"));
  }
  SECTION("a repeated index is caught by the mesh") {
    t0.faces[1] = Face{{0, 1, 1}};
    Frame t1 = t0;
    t1.source = "second.obj";
    CHECK_THAT(input_error_message([&] { make_step(t0, t1); }),
               Contains("first.obj") && Contains("face 1") && Contains("repeated vertex index"));
  }
  SECTION("a non-finite position given directly") {
    Frame t1 = t0;
    t1.source = "second.obj";
    t1.positions[3].y = std::numeric_limits<double>::infinity();
    CHECK_THAT(input_error_message([&] { make_step(t0, t1); }),
               Contains("second.obj") && Contains("vertex 3") && Contains("NaN or infinite"));
  }
}

TEST_CASE("a degenerate triangle is reported but loads", "[io]") {
  TempDir dir("degenerate");
  // Face 1 has three collinear vertices (0, 1, 3).
  const std::string text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\n";
  write_file(dir.file("t0.obj"), text);
  write_file(dir.file("t1.obj"), text);
  const Step step = load_step(dir.file("t0.obj"), dir.file("t1.obj"));
  const std::vector<index_t> degenerate = find_degenerate_faces(*step.mesh, step.x0);
  REQUIRE(degenerate.size() == 1);
  CHECK(degenerate[0] == 1);
}

TEST_CASE("load_sequence loads frames in name order as steps over one mesh", "[io]") {
  TempDir dir("sequence");
  // Names sort numerically: f9 before f10. Other files are ignored.
  const char* names[] = {"f9.obj", "f10.obj", "f11.ply"};
  for (int i = 0; i < 3; ++i) {
    std::string text = "v 0 0 " + std::to_string(i) + "\nv 1 0 0\nv 0 1 0\nv 0 0 1\n";
    text += "f 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n";
    if (i < 2) {
      write_file(dir.file(names[i]), text);
    } else {
      write_file(dir.file(names[i]), "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                                     "property float z\nelement face 4\nproperty list uchar int vertex_indices\n"
                                     "end_header\n0 0 2\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n");
    }
  }
  write_file(dir.file("notes.txt"), "not a mesh\n");
  const Sequence sequence = load_sequence(dir.path());
  REQUIRE(sequence.num_frames() == 3);
  CHECK(sequence.num_steps() == 2);
  CHECK(sequence.frame_name(0) == "f9");
  CHECK(sequence.frame_name(1) == "f10");
  CHECK(sequence.frame_name(2) == "f11");
  for (std::size_t i = 0; i < 3; ++i) CHECK(sequence.frame(i)[0].z == static_cast<double>(i));
  const Step step = sequence.step(1);
  CHECK(step.x0 == sequence.frame(1));
  CHECK(step.x1 == sequence.frame(2));
  CHECK(step.mesh == sequence.mesh());
  CHECK(sequence.step(0).mesh.get() == step.mesh.get());
  CHECK(step.name == "f10->f11");
  CHECK_THROWS_AS(sequence.step(2), std::out_of_range);
}

TEST_CASE("load_sequence rejects a frame of another topology and too few frames", "[io]") {
  TempDir dir("sequence-bad");
  write_file(dir.file("0001.obj"), tetra_obj());
  write_file(dir.file("0002.obj"), tetra_obj());
  write_file(dir.file("0003.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 4 3\nf 1 4 3\n");
  CHECK_THAT(input_error_message([&] { load_sequence(dir.path()); }),
             Contains(dir.file("0003.obj")) && Contains("face 2") && Contains("same topology"));

  TempDir single("sequence-single");
  write_file(single.file("0001.obj"), tetra_obj());
  CHECK_THAT(input_error_message([&] { load_sequence(single.path()); }),
             Contains(single.path()) && Contains("has 1 mesh files") && Contains("at least 2"));
  CHECK_THAT(input_error_message([&] { load_sequence(single.file("nowhere")); }),
             Contains(single.file("nowhere")) && Contains("not a folder"));
}

// ---------------------------------------------------------------------------------------------
// JSON ground truth and scene folders

TEST_CASE("load_json_pairs and load_json_bools read the dataset's shapes", "[io]") {
  TempDir dir("json");
  write_file(dir.file("pairs.json"), " [ [1,2],\n [ 30 , 40 ]\r\n,[5,6]]\n");
  const auto pairs = load_json_pairs(dir.file("pairs.json"));
  REQUIRE(pairs.size() == 3);
  CHECK(pairs[0] == std::make_pair(index_t{1}, index_t{2}));
  CHECK(pairs[1] == std::make_pair(index_t{30}, index_t{40}));
  CHECK(pairs[2] == std::make_pair(index_t{5}, index_t{6}));

  write_file(dir.file("bools.json"), "[true,false ,\n\ttrue]");
  CHECK(load_json_bools(dir.file("bools.json")) == std::vector<bool>{true, false, true});

  write_file(dir.file("empty.json"), "[ ]\n");
  CHECK(load_json_pairs(dir.file("empty.json")).empty());
  CHECK(load_json_bools(dir.file("empty.json")).empty());
}

TEST_CASE("the JSON readers report malformed input with its character offset", "[io]") {
  TempDir dir("json-bad");
  const std::string path = dir.file("bad.json");
  const auto pairs_message = [&](const std::string& text) {
    write_file(path, text);
    return input_error_message([&] { load_json_pairs(path); });
  };
  const auto bools_message = [&](const std::string& text) {
    write_file(path, text);
    return input_error_message([&] { load_json_bools(path); });
  };
  CHECK_THAT(pairs_message(""), Contains(path) && Contains("character offset 0") && Contains("end of file"));
  CHECK_THAT(pairs_message("{}"), Contains(path) && Contains("character offset 0") && Contains("expected '['"));
  CHECK_THAT(pairs_message("[[1,2],[3 4]]"), Contains(path) && Contains("character offset 10") && Contains("expected ','"));
  CHECK_THAT(pairs_message("[[1,2],[3,4]"), Contains(path) && Contains("character offset 12") && Contains("end of file"));
  CHECK_THAT(pairs_message("[[1,2] [3,4]]"), Contains(path) && Contains("character offset 7") &&
                                                Contains("expected ',' or ']'"));
  CHECK_THAT(pairs_message("[[1,2],]"), Contains(path) && Contains("character offset 7") && Contains("expected '['"));
  CHECK_THAT(pairs_message("[[1.5,2]]"), Contains(path) && Contains("character offset 2") && Contains("fractional"));
  CHECK_THAT(pairs_message("[[-1,2]]"), Contains(path) && Contains("character offset 2") && Contains("-1"));
  CHECK_THAT(pairs_message("[[1,99999999999]]"), Contains(path) && Contains("character offset 4"));
  CHECK_THAT(pairs_message("[[1,2]] x"), Contains(path) && Contains("character offset 8") && Contains("after the array"));
  CHECK_THAT(bools_message("[true,tru]"), Contains(path) && Contains("character offset 6") && Contains("true or false"));
  CHECK_THAT(bools_message("[true,1]"), Contains(path) && Contains("character offset 6") && Contains("found '1'"));
  CHECK_THAT(input_error_message([&] { load_json_bools(dir.file("absent.json")); }),
             Contains(dir.file("absent.json")) && Contains("cannot open"));
}

namespace {

// Two triangles sharing edge (0, 2): V = 4, E = 5, F = 2, so vertex ids are 0..3, edge ids
// 4..8 and face ids 9..10.
const std::string two_triangles_obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n";

void write_scene(const TempDir& dir, const std::string& vf_pairs, const std::string& ee_pairs,
                 const std::string& vf_bools, const std::string& ee_bools) {
  namespace fs = std::filesystem;
  fs::create_directories(dir.file("frames"));
  fs::create_directories(dir.file("boxes"));
  fs::create_directories(dir.file("mma_bool"));
  // 10 after 9 in name order although "10" < "9" as plain strings.
  write_file(dir.file("frames/9.obj"), two_triangles_obj);
  write_file(dir.file("frames/10.obj"), two_triangles_obj + "# moved\n");
  write_file(dir.file("boxes/9vf.json"), vf_pairs);
  write_file(dir.file("boxes/9ee.json"), ee_pairs);
  write_file(dir.file("mma_bool/9vf_mma_bool.json"), vf_bools);
  write_file(dir.file("mma_bool/9ee_mma_bool.json"), ee_bools);
}

}  // namespace

TEST_CASE("load_scene reads a scene folder with ground truth", "[io]") {
  TempDir dir("scene");
  write_scene(dir, "[[1, 10]]", "[[4, 8], [5, 6]]", "[true]", "[false, true]");
  const Scene scene = load_scene(dir.path() + "/");
  CHECK(scene.name == std::filesystem::path(dir.path()).filename().string());
  CHECK(scene.step_id == "9");
  CHECK(scene.step.name == "9->10");
  REQUIRE(scene.has_ground_truth);
  CHECK(scene.truth.vf.size() == 1);
  CHECK(scene.truth.ee.size() == 2);
  CHECK(scene.truth.vf_collides == std::vector<bool>{true});
  CHECK(scene.truth.ee_collides == std::vector<bool>{false, true});
}

TEST_CASE("load_scene without mma_bool has no ground truth", "[io]") {
  TempDir dir("scene-nogt");
  write_scene(dir, "[[1, 10]]", "[]", "[true]", "[]");
  std::filesystem::remove(dir.file("mma_bool/9ee_mma_bool.json"));
  const Scene scene = load_scene(dir.path());
  CHECK(scene.step_id == "9");
  CHECK_FALSE(scene.has_ground_truth);
  CHECK(scene.truth.vf.empty());
}

TEST_CASE("load_scene rejects mismatched sizes, ids out of range and a wrong frame count", "[io]") {
  TempDir dir("scene-bad");
  SECTION("sizes differ") {
    write_scene(dir, "[[1, 10]]", "[[4, 8]]", "[true, false]", "[true]");
    CHECK_THAT(input_error_message([&] { load_scene(dir.path()); }),
               Contains("9vf_mma_bool.json") && Contains("9vf.json") && Contains("2 values") && Contains("1 pairs"));
  }
  SECTION("vf face id out of range") {
    write_scene(dir, "[[1, 10], [2, 11]]", "[[4, 8]]", "[true, false]", "[true]");
    CHECK_THAT(input_error_message([&] { load_scene(dir.path()); }),
               Contains("9vf.json") && Contains("pair 1") && Contains("face id outside [9, 11)"));
  }
  SECTION("vf vertex id out of range") {
    write_scene(dir, "[[4, 10]]", "[[4, 8]]", "[true]", "[true]");
    CHECK_THAT(input_error_message([&] { load_scene(dir.path()); }),
               Contains("9vf.json") && Contains("pair 0") && Contains("vertex id outside [0, 4)"));
  }
  SECTION("ee edge id out of range") {
    write_scene(dir, "[[1, 10]]", "[[3, 8]]", "[true]", "[true]");
    CHECK_THAT(input_error_message([&] { load_scene(dir.path()); }),
               Contains("9ee.json") && Contains("pair 0") && Contains("edge id outside [4, 9)"));
  }
  SECTION("three frames") {
    write_scene(dir, "[]", "[]", "[]", "[]");
    write_file(dir.file("frames/11.obj"), two_triangles_obj);
    CHECK_THAT(input_error_message([&] { load_scene(dir.path()); }),
               Contains("frames") && Contains("has 3 mesh files") && Contains("exactly 2"));
  }
}

}  // namespace lwsccd
