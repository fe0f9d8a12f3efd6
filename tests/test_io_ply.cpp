// Tests of the PLY reader (ascii, binary of either byte order, skipped properties and elements,
// polygons, errors naming where they are), on small files written into a temporary folder.
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

// ---------------------------------------------------------------------------------------------
// PLY

TEST_CASE("load_ply reads an ascii file", "[io]") {
  TempDir dir("ply-ascii");
  write_file(dir.file("tetra.ply"), tetra_ascii_ply());
  const Frame frame = load_ply(dir.file("tetra.ply"));
  check_tetra<double>(frame);
  CHECK(frame.source == dir.file("tetra.ply"));
}

TEST_CASE("load_ply reads binary float and double in both byte orders", "[io]") {
  TempDir dir("ply-binary");
  SECTION("little-endian float") {
    write_file(dir.file("a.ply"), tetra_binary_ply<float>(false, "float"));
    check_tetra<float>(load_ply(dir.file("a.ply")));
  }
  SECTION("big-endian float") {
    write_file(dir.file("a.ply"), tetra_binary_ply<float>(true, "float"));
    check_tetra<float>(load_ply(dir.file("a.ply")));
  }
  SECTION("little-endian double") {
    write_file(dir.file("a.ply"), tetra_binary_ply<double>(false, "double"));
    check_tetra<double>(load_ply(dir.file("a.ply")));
  }
  SECTION("big-endian double, float64 type name") {
    write_file(dir.file("a.ply"), tetra_binary_ply<double>(true, "float64"));
    check_tetra<double>(load_ply(dir.file("a.ply")));
  }
  SECTION("float32 type name") {
    write_file(dir.file("a.ply"), tetra_binary_ply<float>(false, "float32"));
    check_tetra<float>(load_ply(dir.file("a.ply")));
  }
}

TEST_CASE("load_ply skips other vertex properties of every type", "[io]") {
  TempDir dir("ply-props");
  const std::string header =
      "ply\nformat binary_big_endian 1.0\nelement vertex 4\n"
      "property float nx\nproperty double x\nproperty float ny\nproperty double y\nproperty float nz\n"
      "property uchar red\nproperty uint8 green\nproperty char blue\nproperty short s\nproperty ushort us\n"
      "property int i\nproperty uint ui\nproperty int16 s16\nproperty uint32 u32\nproperty double z\n"
      "property list uchar float texcoords\n"
      "element face 4\nproperty list uint8 int32 vertex_indices\nend_header\n";
  ByteWriter body(true);
  for (const Vec3d& p : tetra_positions) {
    body.put(1.5f).put(p.x).put(-2.5f).put(p.y).put(3.5f);
    body.put(std::uint8_t{255}).put(std::uint8_t{7}).put(std::int8_t{-3}).put(std::int16_t{-300});
    body.put(std::uint16_t{60000}).put(std::int32_t{-70000}).put(std::uint32_t{4000000000u});
    body.put(std::int16_t{12}).put(std::uint32_t{13}).put(p.z);
    body.put(std::uint8_t{2}).put(0.25f).put(0.75f);
  }
  for (const Face& f : tetra_faces) body.put(std::uint8_t{3}).put(f.v[0]).put(f.v[1]).put(f.v[2]);
  write_file(dir.file("props.ply"), header + body.bytes());
  check_tetra<double>(load_ply(dir.file("props.ply")));
}

TEST_CASE("load_ply skips extra ascii vertex properties", "[io]") {
  TempDir dir("ply-ascii-props");
  const std::string text =
      "ply\r\nformat ascii 1.0\r\nelement vertex 4\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\n"
      "property float nx\r\nproperty float ny\r\nproperty float nz\r\n"
      "property uchar red\r\nproperty uchar green\r\nproperty uchar blue\r\n"
      "element face 4\r\nproperty list uchar uint vertex_index\r\nend_header\r\n"
      "0.1 0 0 0 0 1 255 0 0\r\n1 0 0 0 0 1 0 255 0\r\n0 1 0.25 0 0 1 0 0 255\r\n0 0 1 0 0 1 9 9 9\r\n"
      "3 0 2 1\r\n3 0 1 3\r\n3 1 2 3\r\n3 0 3 2\r\n";
  write_file(dir.file("props.ply"), text);
  check_tetra<float>(load_ply(dir.file("props.ply")));
}

TEST_CASE("load_ply skips elements before and after, and other face properties", "[io]") {
  TempDir dir("ply-elements");
  const std::string header =
      "ply\nformat binary_little_endian 1.0\n"
      "element material 2\nproperty list ushort uchar name\nproperty float shininess\n"
      "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 4\nproperty uchar flags\nproperty list uint16 uint32 vertex_indices\n"
      "property list uchar float texcoord\n"
      "element edge 2\nproperty int vertex1\nproperty int vertex2\nend_header\n";
  ByteWriter body(false);
  body.put(std::uint16_t{3}).put('a').put('b').put('c').put(0.5f);
  body.put(std::uint16_t{0}).put(0.75f);
  for (const Vec3d& p : tetra_positions)
    body.put(static_cast<float>(p.x)).put(static_cast<float>(p.y)).put(static_cast<float>(p.z));
  for (const Face& f : tetra_faces) {
    body.put(std::uint8_t{1}).put(std::uint16_t{3});
    for (int k = 0; k < 3; ++k) body.put(static_cast<std::uint32_t>(f.v[k]));
    body.put(std::uint8_t{6});
    for (int k = 0; k < 6; ++k) body.put(0.125f * static_cast<float>(k));
  }
  body.put(std::int32_t{0}).put(std::int32_t{1}).put(std::int32_t{1}).put(std::int32_t{2});
  write_file(dir.file("elements.ply"), header + body.bytes());
  check_tetra<float>(load_ply(dir.file("elements.ply")));
}

TEST_CASE("load_ply reports a file that cannot be opened", "[io]") {
  TempDir dir("ply-missing");
  const std::string path = dir.file("absent.ply");
  CHECK_THAT(input_error_message([&] { load_ply(path); }), Contains(path) && Contains("cannot open"));
}

TEST_CASE("load_ply reports a missing or garbled header", "[io]") {
  TempDir dir("ply-header");
  const std::string path = dir.file("bad.ply");
  const auto message = [&](const std::string& text) {
    write_file(path, text);
    return input_error_message([&] { load_ply(path); });
  };
  CHECK_THAT(message(""), Contains(path) && Contains("empty"));
  CHECK_THAT(message("solid ascii\n"), Contains(path) && Contains("header") && Contains("not a PLY file"));
  CHECK_THAT(message("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"),
             Contains(path) && Contains("end_header"));
  CHECK_THAT(message("ply\nformat binary_middle_endian 1.0\nend_header\n"),
             Contains(path) && Contains("line 2") && Contains("unknown format 'binary_middle_endian'"));
  CHECK_THAT(message("ply\nelement vertex 0\nend_header\n"), Contains(path) && Contains("no 'format' line"));
  CHECK_THAT(message("ply\nformat ascii 1.0\nelement vertex many\nend_header\n"),
             Contains(path) && Contains("line 3") && Contains("bad element count 'many'"));
  CHECK_THAT(message("ply\nformat ascii 1.0\nproperty float x\nend_header\n"),
             Contains(path) && Contains("line 3") && Contains("property before any element"));
  CHECK_THAT(message("ply\nformat ascii 1.0\nelement vertex 1\nproperty real x\nend_header\n"),
             Contains(path) && Contains("line 4") && Contains("unknown property type 'real'"));
  CHECK_THAT(message("ply\nformat ascii 1.0\nelement vertex 1\nproperty list float int x\nend_header\n"),
             Contains(path) && Contains("line 4") && Contains("not an integer type"));
  CHECK_THAT(message("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nfoo bar\nend_header\n"),
             Contains(path) && Contains("line 5") && Contains("unknown header keyword 'foo'"));
  CHECK_THAT(message("ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n"),
             Contains(path) && Contains("no 'vertex' element"));
  CHECK_THAT(message("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
                     "property float z\nend_header\n"),
             Contains(path) && Contains("no 'face' element"));
}

TEST_CASE("load_ply reports a missing coordinate property", "[io]") {
  TempDir dir("ply-xyz");
  const std::string path = dir.file("noz.ply");
  write_file(path,
             "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
             "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0\n1 0\n0 1\n3 0 1 2\n");
  CHECK_THAT(input_error_message([&] { load_ply(path); }),
             Contains(path) && Contains("header") && Contains("no 'z' property"));
}

TEST_CASE("load_ply reports a face element without vertex indices", "[io]") {
  TempDir dir("ply-noindices");
  const std::string path = dir.file("noind.ply");
  write_file(path,
             "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
             "element face 1\nproperty list uchar int corners\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  CHECK_THAT(input_error_message([&] { load_ply(path); }), Contains(path) && Contains("vertex_indices"));
}

TEST_CASE("load_ply reports truncated data with the element it ends in", "[io]") {
  TempDir dir("ply-truncated");
  const std::string path = dir.file("cut.ply");
  const std::string full = tetra_binary_ply<float>(false, "float");
  const std::size_t header_size = tetra_ply_header("binary_little_endian", "float").size();

  SECTION("in the vertices (fixed-size records)") {
    write_file(path, full.substr(0, header_size + 2 * 12 + 5));  // vertex 2 is incomplete
    CHECK_THAT(input_error_message([&] { load_ply(path); }),
               Contains(path) && Contains("vertex 2") && Contains("file ends in vertex 2 of 4"));
  }
  SECTION("in the faces") {
    write_file(path, full.substr(0, full.size() - 3));  // the last face loses part of an index
    CHECK_THAT(input_error_message([&] { load_ply(path); }),
               Contains(path) && Contains("face 3") && Contains("file ends in face 3 of 4"));
  }
  SECTION("right after the header") {
    write_file(path, full.substr(0, header_size));
    CHECK_THAT(input_error_message([&] { load_ply(path); }), Contains(path) && Contains("file ends in vertex 0 of 4"));
  }
  SECTION("ascii") {
    const std::string text = tetra_ascii_ply();
    write_file(path, text.substr(0, text.find("3 1 2 3")));
    CHECK_THAT(input_error_message([&] { load_ply(path); }), Contains(path) && Contains("file ends in face 2 of 4"));
  }
}

TEST_CASE("load_ply reports a bad ascii number with its line", "[io]") {
  TempDir dir("ply-badnumber");
  const std::string path = dir.file("bad.ply");
  std::string text = tetra_ascii_ply();
  text.replace(text.find("0 1 0.25"), 8, "0 1 0.2x");
  write_file(path, text);
  // Header is lines 1..10 (with the comment); vertex 2 is on line 13.
  CHECK_THAT(input_error_message([&] { load_ply(path); }),
             Contains(path) && Contains("line 13") && Contains("bad number '0.2x'") && Contains("vertex 2"));
}

TEST_CASE("load_ply triangulates faces of more than 3 vertices and rejects fewer than 3", "[io]") {
  TempDir dir("ply-quad");
  const std::string path = dir.file("quad.ply");
  auto write_faces = [&](const std::vector<std::vector<int>>& faces) {
    ByteWriter body(false);
    for (const Vec3d& p : tetra_positions) body.put(p.x).put(p.y).put(p.z);
    for (const auto& f : faces) {
      body.put(static_cast<std::uint8_t>(f.size()));
      for (int v : f) body.put(v);
    }
    std::string header = tetra_ply_header("binary_little_endian", "double");
    const std::string count = "element face " + std::to_string(faces.size());
    header.replace(header.find("element face 4"), 14, count);
    write_file(path, header + body.bytes());
  };
  write_faces({{0, 1, 2}, {0, 1, 2, 3}});
  const Frame frame = load_ply(path);
  REQUIRE(frame.faces.size() == 3);  // the triangle, then the quad's two
  CHECK(frame.face_source == std::vector<index_t>{0, 1, 1});
  CHECK(frame.polygon_offsets == std::vector<index_t>{0, 3, 7});
  std::set<index_t> corners;
  for (int t = 1; t < 3; ++t)
    for (int k = 0; k < 3; ++k) corners.insert(frame.faces[t].v[k]);
  CHECK(corners == std::set<index_t>{0, 1, 2, 3});
  write_faces({{0, 1, 2}, {0, 1}});
  CHECK_THAT(input_error_message([&] { load_ply(path); }),
             Contains(path) && Contains("face 1") && Contains("2 vertices") && Contains("at least 3"));
  write_faces({{0, 1, 2}, {0, 1, 2, 1}});
  CHECK_THAT(input_error_message([&] { load_ply(path); }),
             Contains(path) && Contains("face 1") && Contains("4 vertices") && Contains("repeats vertex 1"));
}

TEST_CASE("load_ply rejects NaN and infinite coordinates naming the vertex", "[io]") {
  TempDir dir("ply-nan");
  const std::string path = dir.file("nan.ply");
  SECTION("binary NaN") {
    ByteWriter body(true);
    for (std::size_t v = 0; v < 4; ++v)
      body.put(v == 2 ? std::numeric_limits<float>::quiet_NaN() : 0.5f).put(1.0f * static_cast<float>(v)).put(0.0f);
    for (const Face& f : tetra_faces) body.put(std::uint8_t{3}).put(f.v[0]).put(f.v[1]).put(f.v[2]);
    write_file(path, tetra_ply_header("binary_big_endian", "float") + body.bytes());
    CHECK_THAT(input_error_message([&] { load_ply(path); }),
               Contains(path) && Contains("vertex 2") && Contains("NaN or infinite"));
  }
  SECTION("ascii inf") {
    std::string text = tetra_ascii_ply();
    text.replace(text.find("0 0 1\n"), 6, "0 0 inf\n");
    write_file(path, text);
    CHECK_THAT(input_error_message([&] { load_ply(path); }),
               Contains(path) && Contains("vertex 3") && Contains("NaN or infinite"));
  }
}

TEST_CASE("load_ply rejects negative and out-of-range indices", "[io]") {
  TempDir dir("ply-index");
  const std::string path = dir.file("index.ply");
  std::string text = tetra_ascii_ply();
  SECTION("negative") {
    text.replace(text.find("3 1 2 3"), 7, "3 1 -2 3");
    write_file(path, text);
    CHECK_THAT(input_error_message([&] { load_ply(path); }),
               Contains(path) && Contains("face 2") && Contains("negative vertex index -2"));
  }
  SECTION("beyond the vertex count") {
    text.replace(text.find("3 1 2 3"), 7, "3 1 2 9");
    write_file(path, text);
    CHECK_THAT(input_error_message([&] { load_ply(path); }),
               Contains(path) && Contains("face 2") && Contains("vertex index 9 out of range [0, 4)"));
  }
  SECTION("binary uint index beyond 32-bit signed") {
    ByteWriter body(false);
    for (const Vec3d& p : tetra_positions) body.put(p.x).put(p.y).put(p.z);
    body.put(std::uint8_t{3}).put(0u).put(1u).put(4000000000u);
    std::string header = tetra_ply_header("binary_little_endian", "double");
    header.replace(header.find("element face 4"), 14, "element face 1");
    header.replace(header.find("uchar int"), 9, "uchar uint");
    write_file(path, header + body.bytes());
    CHECK_THAT(input_error_message([&] { load_ply(path); }),
               Contains(path) && Contains("face 0") && Contains("4000000000"));
  }
}

TEST_CASE("load_ply rejects an empty mesh", "[io]") {
  TempDir dir("ply-empty");
  const std::string path = dir.file("empty.ply");
  SECTION("no faces") {
    std::string header = tetra_ply_header("ascii", "float");
    header.replace(header.find("element face 4"), 14, "element face 0");
    write_file(path, header + "0 0 0\n1 0 0\n0 1 0\n0 0 1\n");
    CHECK_THAT(input_error_message([&] { load_ply(path); }), Contains(path) && Contains("no faces"));
  }
  SECTION("no vertices") {
    std::string header = tetra_ply_header("ascii", "float");
    header.replace(header.find("element vertex 4"), 16, "element vertex 0");
    header.replace(header.find("element face 4"), 14, "element face 0");
    write_file(path, header);
    CHECK_THAT(input_error_message([&] { load_ply(path); }), Contains(path) && Contains("no vertices"));
  }
}

// ---------------------------------------------------------------------------------------------
// OBJ

}  // namespace lwsccd
