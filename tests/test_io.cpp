// Tests of the PLY/OBJ readers, steps, sequences and the dataset's JSON files, on small files
// written into a temporary folder.
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
#include "test_support.hpp"

namespace lwsccd {
namespace {

using Catch::Contains;
using lwsccd_test::TempDir;

void write_file(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out << bytes;
}

// Runs `load` and returns the message of the InputError it throws ("" when it throws none);
// any other exception type escapes and fails the test.
template <class Load>
std::string input_error_message(Load&& load) {
  try {
    load();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

bool host_is_little_endian() {
  const std::uint16_t probe = 1;
  unsigned char first;
  std::memcpy(&first, &probe, 1);
  return first == 1;
}

// Appends values in a chosen byte order, to build binary PLY bodies.
class ByteWriter {
 public:
  explicit ByteWriter(bool big_endian) : swap_(big_endian == host_is_little_endian()) {}
  template <class T>
  ByteWriter& put(T value) {
    char raw[sizeof(T)];
    std::memcpy(raw, &value, sizeof(T));
    if (swap_) std::reverse(raw, raw + sizeof(T));
    bytes_.append(raw, sizeof(T));
    return *this;
  }
  const std::string& bytes() const { return bytes_; }

 private:
  bool swap_;
  std::string bytes_;
};

// A tetrahedron: 4 vertices, 4 outward faces. Coordinates that are not exact in binary (0.1)
// check that float and double files keep their own precision.
const std::vector<Vec3d> tetra_positions = {{0.1, 0, 0}, {1, 0, 0}, {0, 1, 0.25}, {0, 0, 1}};
const std::vector<Face> tetra_faces = {{{0, 2, 1}}, {{0, 1, 3}}, {{1, 2, 3}}, {{0, 3, 2}}};

std::string tetra_ply_header(const std::string& format, const std::string& scalar) {
  return "ply\nformat " + format + " 1.0\ncomment written by test_io\nelement vertex 4\nproperty " + scalar +
         " x\nproperty " + scalar + " y\nproperty " + scalar +
         " z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n";
}

template <class Scalar>
std::string tetra_binary_ply(bool big_endian, const std::string& scalar_name) {
  ByteWriter body(big_endian);
  for (const Vec3d& p : tetra_positions)
    body.put(static_cast<Scalar>(p.x)).put(static_cast<Scalar>(p.y)).put(static_cast<Scalar>(p.z));
  for (const Face& f : tetra_faces) body.put(std::uint8_t{3}).put(f.v[0]).put(f.v[1]).put(f.v[2]);
  return tetra_ply_header(big_endian ? "binary_big_endian" : "binary_little_endian", scalar_name) + body.bytes();
}

std::string tetra_ascii_ply() {
  return tetra_ply_header("ascii", "double") +
         "0.1 0 0\n1 0 0\n0 1 0.25\n0 0 1\n"
         "3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n";
}

template <class Scalar>
void check_tetra(const Frame& frame) {
  REQUIRE(frame.positions.size() == 4);
  REQUIRE(frame.faces.size() == 4);
  for (std::size_t v = 0; v < 4; ++v) {
    CHECK(frame.positions[v].x == static_cast<double>(static_cast<Scalar>(tetra_positions[v].x)));
    CHECK(frame.positions[v].y == static_cast<double>(static_cast<Scalar>(tetra_positions[v].y)));
    CHECK(frame.positions[v].z == static_cast<double>(static_cast<Scalar>(tetra_positions[v].z)));
  }
  for (std::size_t f = 0; f < 4; ++f)
    for (int k = 0; k < 3; ++k) CHECK(frame.faces[f].v[k] == tetra_faces[f].v[k]);
}

std::string tetra_obj() {
  return "v 0.1 0 0\nv 1 0 0\nv 0 1 0.25\nv 0 0 1\n"
         "f 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n";
}

}  // namespace

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
