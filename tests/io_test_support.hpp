// What the I/O tests share (test_io_ply.cpp, test_io_obj.cpp, test_io.cpp): files written into a
// temporary folder, binary PLY bodies in either byte order, a tetrahedron in every format.
#pragma once

#include <catch2/catch.hpp>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "lwsccd/io/mesh_io.hpp"
#include "test_support.hpp"

namespace lwsccd::io_test {

inline void write_file(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out << bytes;
}

// Runs `load` and returns the message of the InputError it throws ("" when it throws none);
// any other exception type escapes and fails the test.
template <class Load>
inline std::string input_error_message(Load&& load) {
  try {
    load();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

inline bool host_is_little_endian() {
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
inline const std::vector<Vec3d> tetra_positions = {{0.1, 0, 0}, {1, 0, 0}, {0, 1, 0.25}, {0, 0, 1}};
inline const std::vector<Face> tetra_faces = {{{0, 2, 1}}, {{0, 1, 3}}, {{1, 2, 3}}, {{0, 3, 2}}};

inline std::string tetra_ply_header(const std::string& format, const std::string& scalar) {
  return "ply\nformat " + format + " 1.0\ncomment written by test_io\nelement vertex 4\nproperty " + scalar +
         " x\nproperty " + scalar + " y\nproperty " + scalar +
         " z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n";
}

template <class Scalar>
inline std::string tetra_binary_ply(bool big_endian, const std::string& scalar_name) {
  ByteWriter body(big_endian);
  for (const Vec3d& p : tetra_positions)
    body.put(static_cast<Scalar>(p.x)).put(static_cast<Scalar>(p.y)).put(static_cast<Scalar>(p.z));
  for (const Face& f : tetra_faces) body.put(std::uint8_t{3}).put(f.v[0]).put(f.v[1]).put(f.v[2]);
  return tetra_ply_header(big_endian ? "binary_big_endian" : "binary_little_endian", scalar_name) + body.bytes();
}

inline std::string tetra_ascii_ply() {
  return tetra_ply_header("ascii", "double") +
         "0.1 0 0\n1 0 0\n0 1 0.25\n0 0 1\n"
         "3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n";
}

template <class Scalar>
inline void check_tetra(const Frame& frame) {
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

inline std::string tetra_obj() {
  return "v 0.1 0 0\nv 1 0 0\nv 0 1 0.25\nv 0 0 1\n"
         "f 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n";
}

}  // namespace lwsccd::io_test
