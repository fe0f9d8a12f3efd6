// lwsccd — the PLY reader (ascii and binary of either byte order): after the header
// (ply_header.hpp), a body read one value at a time so that errors name the element instance,
// vertices, faces and skipped elements.
// Part of mesh_io_impl.hpp: include <lwsccd/io/mesh_io.hpp>, not this file.
#pragma once

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "lwsccd/core/error.hpp"
#include "lwsccd/io/detail/mesh_file_common.hpp"
#include "lwsccd/io/detail/ply_header.hpp"
#include "lwsccd/io/detail/polygons.hpp"
#include "lwsccd/io/mesh_io.hpp"

namespace lwsccd {

namespace detail {

// ---------------------------------------------------------------------------------------------
// PLY

// Reads the values of the body one at a time, in either encoding. It knows which element
// instance it is in, so running out of data or a bad ascii token is reported precisely.
class PlyBodyReader {
 public:
  PlyBodyReader(const std::string& bytes, const PlyHeader& header, const std::string& path)
      : data_(bytes.data()),
        pos_(header.body_offset),
        size_(bytes.size()),
        ascii_(header.format == PlyFormat::ascii),
        swap_(header.format != PlyFormat::ascii &&
              (header.format == PlyFormat::binary_little_endian) != host_is_little_endian()),
        line_(header.body_line),
        path_(path) {}

  void enter(const PlyElement& element, std::size_t index) {
    element_ = &element;
    index_ = index;
  }

  bool is_ascii() const { return ascii_; }
  bool needs_swap() const { return swap_; }
  std::size_t position() const { return pos_; }
  std::size_t remaining() const { return size_ - pos_; }
  void advance(std::size_t n) { pos_ += n; }
  const char* data() const { return data_; }

  std::string where() const { return element_->name + " " + std::to_string(index_); }

  [[noreturn]] void fail_truncated() const {
    throw InputError(path_, where(), "file ends in " + element_->name + " " + std::to_string(index_) + " of " +
                                         std::to_string(element_->count));
  }

  double read(PlyType type) {
    if (!ascii_) return read_binary(type);
    // An ascii "float" property holds what a binary file of the same mesh would.
    const double value = read_ascii();
    return type == PlyType::float32 ? static_cast<double>(static_cast<float>(value)) : value;
  }

  // Converts raw little/big-endian bytes at `p` to a double.
  double decode(const char* p, PlyType type) const {
    unsigned char raw[8];
    const std::size_t n = ply_type_size(type);
    std::memcpy(raw, p, n);
    if (swap_) std::reverse(raw, raw + n);
    switch (type) {
      case PlyType::int8: { std::int8_t v; std::memcpy(&v, raw, 1); return v; }
      case PlyType::uint8: { std::uint8_t v; std::memcpy(&v, raw, 1); return v; }
      case PlyType::int16: { std::int16_t v; std::memcpy(&v, raw, 2); return v; }
      case PlyType::uint16: { std::uint16_t v; std::memcpy(&v, raw, 2); return v; }
      case PlyType::int32: { std::int32_t v; std::memcpy(&v, raw, 4); return v; }
      case PlyType::uint32: { std::uint32_t v; std::memcpy(&v, raw, 4); return v; }
      case PlyType::float32: { float v; std::memcpy(&v, raw, 4); return v; }
      case PlyType::float64: { double v; std::memcpy(&v, raw, 8); return v; }
    }
    return 0;
  }

 private:
  double read_binary(PlyType type) {
    const std::size_t n = ply_type_size(type);
    if (size_ - pos_ < n) fail_truncated();
    const double value = decode(data_ + pos_, type);
    pos_ += n;
    return value;
  }

  double read_ascii() {
    while (pos_ < size_ && std::isspace(static_cast<unsigned char>(data_[pos_]))) {
      if (data_[pos_] == '\n') ++line_;
      ++pos_;
    }
    if (pos_ >= size_) fail_truncated();
    const std::size_t start = pos_;
    while (pos_ < size_ && !std::isspace(static_cast<unsigned char>(data_[pos_]))) ++pos_;
    double value = 0;
    if (!parse_double(data_ + start, data_ + pos_, value))
      throw InputError(path_, "line " + std::to_string(line_),
                       "bad number '" + std::string(data_ + start, pos_ - start) + "' in " + where());
    return value;
  }

  const char* data_;
  std::size_t pos_;
  std::size_t size_;
  bool ascii_;
  bool swap_;
  int line_;
  const std::string& path_;
  const PlyElement* element_ = nullptr;
  std::size_t index_ = 0;
};

inline int find_property(const PlyElement& element, const char* name) {
  for (std::size_t i = 0; i < element.properties.size(); ++i)
    if (element.properties[i].name == name) return static_cast<int>(i);
  return -1;
}

// A list length: a non-negative integer (ascii files could hold anything).
inline std::size_t read_list_length(PlyBodyReader& reader, const PlyProperty& property, const std::string& path) {
  const double count = reader.read(property.count_type);
  if (!(count >= 0) || count != std::floor(count))
    throw InputError(path, reader.where(), "bad list length in property '" + property.name + "'");
  return static_cast<std::size_t>(count);
}

inline void read_ply_vertices(PlyBodyReader& reader, const PlyElement& element, const std::string& path,
                              std::vector<Vec3d>& positions) {
  int xyz[3] = {find_property(element, "x"), find_property(element, "y"), find_property(element, "z")};
  for (int k = 0; k < 3; ++k) {
    if (xyz[k] < 0)
      throw InputError(path, "header", std::string("vertex element has no '") + "xyz"[k] + "' property");
    if (element.properties[xyz[k]].is_list)
      throw InputError(path, "header", std::string("vertex property '") + "xyz"[k] + "' is a list");
  }
  positions.resize(element.count);
  const auto check_finite = [&](std::size_t v) {
    if (!is_finite(positions[v]))
      throw InputError(path, "vertex " + std::to_string(v),
                       "coordinate is NaN or infinite " +
                           coordinates_text(positions[v].x, positions[v].y, positions[v].z));
  };

  const bool fixed_size = std::none_of(element.properties.begin(), element.properties.end(),
                                       [](const PlyProperty& p) { return p.is_list; });
  if (!reader.is_ascii() && fixed_size) {
    // Fast path: every vertex has the same byte layout, so x/y/z sit at fixed offsets.
    std::size_t stride = 0, offset[3] = {0, 0, 0};
    for (std::size_t i = 0; i < element.properties.size(); ++i) {
      for (int k = 0; k < 3; ++k)
        if (static_cast<int>(i) == xyz[k]) offset[k] = stride;
      stride += ply_type_size(element.properties[i].type);
    }
    if (stride > 0 && reader.remaining() / stride < element.count) {
      reader.enter(element, reader.remaining() / stride);
      reader.fail_truncated();
    }
    const PlyType types[3] = {element.properties[xyz[0]].type, element.properties[xyz[1]].type,
                              element.properties[xyz[2]].type};
    const char* base = reader.data() + reader.position();
    for (std::size_t v = 0; v < element.count; ++v) {
      const char* record = base + v * stride;
      positions[v] = Vec3d{reader.decode(record + offset[0], types[0]), reader.decode(record + offset[1], types[1]),
                           reader.decode(record + offset[2], types[2])};
      check_finite(v);
    }
    reader.advance(element.count * stride);
    return;
  }

  for (std::size_t v = 0; v < element.count; ++v) {
    reader.enter(element, v);
    for (std::size_t i = 0; i < element.properties.size(); ++i) {
      const PlyProperty& property = element.properties[i];
      if (property.is_list) {
        const std::size_t n = read_list_length(reader, property, path);
        for (std::size_t j = 0; j < n; ++j) reader.read(property.type);
        continue;
      }
      const double value = reader.read(property.type);
      for (int k = 0; k < 3; ++k)
        if (static_cast<int>(i) == xyz[k]) positions[v][k] = value;
    }
    check_finite(v);
  }
}

inline void read_ply_faces(PlyBodyReader& reader, const PlyElement& element, const std::string& path, Frame& frame) {
  int indices = find_property(element, "vertex_indices");
  if (indices < 0) indices = find_property(element, "vertex_index");
  if (indices < 0) throw InputError(path, "header", "face element has no 'vertex_indices' list property");
  const PlyProperty& index_property = element.properties[indices];
  if (!index_property.is_list) throw InputError(path, "header", "face property '" + index_property.name + "' is not a list");
  if (!ply_type_is_integer(index_property.type))
    throw InputError(path, "header", "face property '" + index_property.name + "' has a non-integer item type");

  frame.polygon_offsets.assign(1, 0);
  frame.polygon_offsets.reserve(element.count + 1);
  frame.polygon_vertices.reserve(3 * element.count);
  for (std::size_t f = 0; f < element.count; ++f) {
    reader.enter(element, f);
    for (std::size_t i = 0; i < element.properties.size(); ++i) {
      const PlyProperty& property = element.properties[i];
      if (!property.is_list) {
        reader.read(property.type);
        continue;
      }
      const std::size_t n = read_list_length(reader, property, path);
      if (static_cast<int>(i) != indices) {
        for (std::size_t j = 0; j < n; ++j) reader.read(property.type);
        continue;
      }
      if (n < 3) throw InputError(path, reader.where(), "face has " + std::to_string(n) + " vertices (at least 3 needed)");
      if (n > static_cast<std::size_t>(std::numeric_limits<index_t>::max()) - frame.polygon_vertices.size())
        throw InputError(path, reader.where(), "too many face vertices");
      for (std::size_t k = 0; k < n; ++k) {
        const double index = reader.read(property.type);
        if (index != std::floor(index))
          throw InputError(path, reader.where(), "vertex index is not an integer");
        if (index < 0)
          throw InputError(path, reader.where(), "negative vertex index " + std::to_string(static_cast<long long>(index)));
        if (index > static_cast<double>(std::numeric_limits<index_t>::max()))
          throw InputError(path, reader.where(), "vertex index " + std::to_string(static_cast<long long>(index)) +
                                                     " is too large");
        frame.polygon_vertices.push_back(static_cast<index_t>(index));
      }
    }
    frame.polygon_offsets.push_back(static_cast<index_t>(frame.polygon_vertices.size()));
  }
}

inline void skip_ply_element(PlyBodyReader& reader, const PlyElement& element, const std::string& path) {
  const bool fixed_size = std::none_of(element.properties.begin(), element.properties.end(),
                                       [](const PlyProperty& p) { return p.is_list; });
  if (!reader.is_ascii() && fixed_size) {
    std::size_t stride = 0;
    for (const PlyProperty& p : element.properties) stride += ply_type_size(p.type);
    if (stride > 0 && reader.remaining() / stride < element.count) {
      reader.enter(element, reader.remaining() / stride);
      reader.fail_truncated();
    }
    reader.advance(stride * element.count);
    return;
  }
  for (std::size_t e = 0; e < element.count; ++e) {
    reader.enter(element, e);
    for (const PlyProperty& property : element.properties) {
      if (!property.is_list) {
        reader.read(property.type);
        continue;
      }
      const std::size_t n = read_list_length(reader, property, path);
      for (std::size_t j = 0; j < n; ++j) reader.read(property.type);
    }
  }
}

}  // namespace detail

inline Frame load_ply(const std::string& path) {
  const std::string bytes = detail::read_whole_file(path);
  const detail::PlyHeader header = detail::parse_ply_header(bytes, path);

  const detail::PlyElement* vertex_element = nullptr;
  const detail::PlyElement* face_element = nullptr;
  for (const auto& element : header.elements) {
    if (element.name == "vertex" && !vertex_element) vertex_element = &element;
    if (element.name == "face" && !face_element) face_element = &element;
  }
  if (!vertex_element) throw InputError(path, "header", "no 'vertex' element");
  if (!face_element) throw InputError(path, "header", "no 'face' element");

  Frame frame;
  frame.source = path;
  detail::PlyBodyReader reader(bytes, header, path);
  for (const auto& element : header.elements) {
    if (&element == vertex_element) detail::read_ply_vertices(reader, element, path, frame.positions);
    else if (&element == face_element) detail::read_ply_faces(reader, element, path, frame);
    else detail::skip_ply_element(reader, element, path);
  }
  if (frame.positions.empty()) throw InputError(frame.source, "", "mesh has no vertices");
  detail::check_face_indices(frame);
  detail::triangulate_frame(frame, [](std::size_t f) { return "face " + std::to_string(f); });
  detail::check_frame_not_empty(frame);
  return frame;
}

}  // namespace lwsccd
