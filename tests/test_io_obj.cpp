// Tests of the OBJ reader (statement forms, polygons triangulated with their winding, errors
// naming the line), on small files written into a temporary folder.
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

TEST_CASE("load_obj reads plain triangles", "[io]") {
  TempDir dir("obj-plain");
  write_file(dir.file("tetra.obj"), tetra_obj());
  check_tetra<double>(load_obj(dir.file("tetra.obj")));
}

TEST_CASE("load_obj accepts slash forms, negative indices, comments and other statements", "[io]") {
  TempDir dir("obj-forms");
  const std::string text =
      "# a tetrahedron\r\n"
      "mtllib tetra.mtl\r\n"
      "o tetra\r\n"
      "v 0.1 0 0 1.0\r\n"
      "v 1 0 0   # trailing comment\r\n"
      "v\t0 1 +0.25\r\n"
      "v 0 0 1e0 0.5 0.5 0.5\r\n"
      "vt 0 0\r\nvt 1 0\r\nvt 0 1\r\n"
      "vn 0 0 1\r\n"
      "g body\r\ns 1\r\nusemtl skin\r\n"
      "\r\n"
      "f 1/1 3/3 2/2\r\n"
      "f 1//1 2//1 4//1\r\n"
      "f 2/2/1 3/3/1 4/1/1\r\n"
      "f -4 -1 -2\r\n"
      "l 1 2\r\n";
  write_file(dir.file("forms.obj"), text);
  check_tetra<double>(load_obj(dir.file("forms.obj")));
}

TEST_CASE("load_obj accepts faces listed before their vertices", "[io]") {
  TempDir dir("obj-forward");
  write_file(dir.file("forward.obj"), "f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n");
  const Frame frame = load_obj(dir.file("forward.obj"));
  CHECK(frame.positions.size() == 3);
  REQUIRE(frame.faces.size() == 1);
  CHECK(frame.faces[0].v[2] == 2);
}

TEST_CASE("load_obj reports a bad number with its line", "[io]") {
  TempDir dir("obj-badnumber");
  const std::string path = dir.file("bad.obj");
  write_file(path, "v 0 0 0\nv 1 0 0\nv 0 1.5.2 0\nf 1 2 3\n");
  CHECK_THAT(input_error_message([&] { load_obj(path); }),
             Contains(path) && Contains("line 3") && Contains("bad number '1.5.2'"));
  write_file(path, "v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n");
  CHECK_THAT(input_error_message([&] { load_obj(path); }),
             Contains(path) && Contains("line 2") && Contains("fewer than 3 coordinates"));
  write_file(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2x 3\n");
  CHECK_THAT(input_error_message([&] { load_obj(path); }),
             Contains(path) && Contains("line 4") && Contains("bad vertex index '2x'"));
}

TEST_CASE("load_obj rejects index 0 and out-of-range indices naming the line", "[io]") {
  TempDir dir("obj-index");
  const std::string path = dir.file("index.obj");
  write_file(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
  CHECK_THAT(input_error_message([&] { load_obj(path); }),
             Contains(path) && Contains("line 4") && Contains("vertex index 0"));
  write_file(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 4\n");
  CHECK_THAT(input_error_message([&] { load_obj(path); }),
             Contains(path) && Contains("line 5") && Contains("vertex index 4 out of range"));
  write_file(path, "v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n");
  CHECK_THAT(input_error_message([&] { load_obj(path); }),
             Contains(path) && Contains("line 3") && Contains("relative vertex index -3"));
}

TEST_CASE("load_obj rejects NaN and infinite coordinates naming the line", "[io]") {
  TempDir dir("obj-nan");
  const std::string path = dir.file("nan.obj");
  write_file(path, "v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n");
  CHECK_THAT(input_error_message([&] { load_obj(path); }),
             Contains(path) && Contains("line 2") && Contains("vertex 1") && Contains("NaN or infinite"));
  write_file(path, "v 0 0 0\nv 1 0 0\nv 0 1 -inf\nf 1 2 3\n");
  CHECK_THAT(input_error_message([&] { load_obj(path); }),
             Contains(path) && Contains("line 3") && Contains("NaN or infinite"));
}

namespace {
// Twice the signed area of triangle t of `frame` seen along +z.
double twice_area_z(const Frame& frame, std::size_t t) {
  const Vec3d& a = frame.positions[frame.faces[t].v[0]];
  const Vec3d& b = frame.positions[frame.faces[t].v[1]];
  const Vec3d& c = frame.positions[frame.faces[t].v[2]];
  return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
}
}  // namespace

TEST_CASE("load_obj triangulates convex and non-convex polygons, keeping their winding", "[io]") {
  TempDir dir("obj-polygons");
  const std::string path = dir.file("polygons.obj");
  // A unit square (1-4), a regular-ish pentagon (5-9), an L-shaped hexagon of area 3 (10-15),
  // the L given clockwise (seen from +z) to check that the winding is kept.
  write_file(path,
             "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
             "v 3 0 0\nv 4 0.5 0\nv 3.8 1.5 0\nv 2.2 1.5 0\nv 2 0.5 0\n"
             "v 5 0 0\nv 7 0 0\nv 7 1 0\nv 6 1 0\nv 6 2 0\nv 5 2 0\n"
             "f 1 2 3 4\nf 5 6 7 8 9\nf 10 15 14 13 12 11\nf 1 2 4\n");
  const Frame frame = load_obj(path);
  REQUIRE(frame.faces.size() == 2 + 3 + 4 + 1);
  CHECK(frame.face_source == std::vector<index_t>{0, 0, 1, 1, 1, 2, 2, 2, 2, 3});
  double square = 0, pentagon = 0, l_shape = 0;
  for (std::size_t t = 0; t < frame.faces.size(); ++t) {
    const double a = twice_area_z(frame, t);
    const index_t f = frame.face_source[t];
    if (f == 2) {
      CHECK(a < 0);  // clockwise kept
      l_shape -= a / 2;
      // Non-convex: every triangle lies inside the L (its centroid is not in the notch x > 6, y > 1).
      const Vec3d& p = frame.positions[frame.faces[t].v[0]];
      const Vec3d& q = frame.positions[frame.faces[t].v[1]];
      const Vec3d& r = frame.positions[frame.faces[t].v[2]];
      const double cx = (p.x + q.x + r.x) / 3, cy = (p.y + q.y + r.y) / 3;
      CHECK_FALSE((cx > 6 && cy > 1));
    } else {
      CHECK(a > 0);
      if (f == 0) square += a / 2;
      if (f == 1) pentagon += a / 2;
    }
  }
  CHECK(square == Approx(1.0));
  CHECK(pentagon == Approx(2.3));  // shoelace
  CHECK(l_shape == Approx(3.0));
  // Every vertex of the L is used, and no triangle is degenerate.
  std::set<index_t> used;
  for (std::size_t t = 5; t < 9; ++t) {
    CHECK(twice_area_z(frame, t) != 0);
    for (int k = 0; k < 3; ++k) used.insert(frame.faces[t].v[k]);
  }
  CHECK(used == std::set<index_t>{9, 10, 11, 12, 13, 14});
}

TEST_CASE("load_obj rejects faces of fewer than 3 vertices and degenerate polygons naming the line", "[io]") {
  TempDir dir("obj-quad");
  const std::string path = dir.file("quad.obj");
  write_file(path, "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2\n");
  CHECK_THAT(input_error_message([&] { load_obj(path); }),
             Contains(path) && Contains("line 4") && Contains("2 vertices") && Contains("at least 3"));
  write_file(path, "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 2 3 2\n");
  CHECK_THAT(input_error_message([&] { load_obj(path); }),
             Contains(path) && Contains("line 6") && Contains("4 vertices") && Contains("repeats vertex 1"));
  write_file(path, "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3 4\n");  // collinear
  CHECK_THAT(input_error_message([&] { load_obj(path); }), Contains(path) && Contains("line 5") && Contains("no area"));
  write_file(path, "v 0 0 0\nv 1 1 0\nv 1 0 0\nv 0 1 0\nf 1 2 3 4\n");  // a bow tie: its halves cancel
  CHECK_THAT(input_error_message([&] { load_obj(path); }), Contains(path) && Contains("line 5") && Contains("no area"));
}

TEST_CASE("frames with polygons pair by the files' faces; their steps map triangles back", "[io]") {
  TempDir dir("obj-polygon-frames");
  // An L-shaped hexagon whose reflex corner moves: the ear clipping of the two frames may differ,
  // the step keeps the first frame's triangles.
  const std::string a = dir.file("0001.obj"), b = dir.file("0002.obj"), c = dir.file("0003.obj");
  write_file(a, "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\nf 1 2 3 4 5 6\n");
  write_file(b, "v 0 0 0.1\nv 2 0 0.1\nv 2 1 0.1\nv 1.9 1.9 0.1\nv 1 2 0.1\nv 0 2 0.1\nf 1 2 3 4 5 6\n");
  write_file(c, "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\nf 1 2 3 4 5\nf 1 5 6\n");
  const Step step = load_step(a, b);
  CHECK(step.mesh->num_faces() == 4);
  CHECK(step.face_source == std::vector<index_t>{0, 0, 0, 0});
  const Frame first = load_obj(a);
  REQUIRE(step.mesh->faces().size() == first.faces.size());
  for (std::size_t t = 0; t < first.faces.size(); ++t)
    for (int k = 0; k < 3; ++k) CHECK(step.mesh->faces()[t].v[k] == first.faces[t].v[k]);
  CHECK_THAT(input_error_message([&] { load_step(a, c); }), Contains(c) && Contains("same topology"));
  Frame triangles_only = first;  // the same triangles, given as triangles: not the same files' faces
  triangles_only.face_source.clear();
  triangles_only.polygon_offsets.clear();
  triangles_only.polygon_vertices.clear();
  CHECK_THAT(input_error_message([&] { make_step(triangles_only, load_obj(b)); }), Contains("same topology"));
  std::remove(c.c_str());
  const Sequence seq = load_sequence(dir.path());
  REQUIRE(seq.num_steps() == 1);
  CHECK(seq.step(0).face_source == step.face_source);
}

TEST_CASE("load_obj rejects an empty mesh and a missing file", "[io]") {
  TempDir dir("obj-empty");
  const std::string path = dir.file("empty.obj");
  write_file(path, "# nothing but vertices\nv 0 0 0\nv 1 0 0\nv 0 1 0\n");
  CHECK_THAT(input_error_message([&] { load_obj(path); }), Contains(path) && Contains("no faces"));
  write_file(path, "");
  CHECK_THAT(input_error_message([&] { load_obj(path); }), Contains(path) && Contains("no vertices"));
  CHECK_THAT(input_error_message([&] { load_obj(dir.file("absent.obj")); }),
             Contains(dir.file("absent.obj")) && Contains("cannot open"));
}

}  // namespace lwsccd
