// lwsccd — the PLY header: property types and their sizes, elements and their properties, the
// header's parse (format, byte order, where the body starts), which the body reader
// (ply_reader.hpp) follows.
// Part of mesh_io_impl.hpp: include <lwsccd/io/mesh_io.hpp>, not this file.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <sstream>
#include <string>
#include <vector>

#include "lwsccd/core/error.hpp"
#include "lwsccd/io/detail/mesh_file_common.hpp"

namespace lwsccd::detail {

enum class PlyType { int8, uint8, int16, uint16, int32, uint32, float32, float64 };

inline bool ply_type_from_name(const std::string& name, PlyType& type) {
  static const std::pair<const char*, PlyType> names[] = {
      {"char", PlyType::int8},     {"int8", PlyType::int8},       {"uchar", PlyType::uint8},
      {"uint8", PlyType::uint8},   {"short", PlyType::int16},     {"int16", PlyType::int16},
      {"ushort", PlyType::uint16}, {"uint16", PlyType::uint16},   {"int", PlyType::int32},
      {"int32", PlyType::int32},   {"uint", PlyType::uint32},     {"uint32", PlyType::uint32},
      {"float", PlyType::float32}, {"float32", PlyType::float32}, {"double", PlyType::float64},
      {"float64", PlyType::float64}};
  for (const auto& entry : names) {
    if (name == entry.first) {
      type = entry.second;
      return true;
    }
  }
  return false;
}

inline std::size_t ply_type_size(PlyType type) {
  switch (type) {
    case PlyType::int8: case PlyType::uint8: return 1;
    case PlyType::int16: case PlyType::uint16: return 2;
    case PlyType::int32: case PlyType::uint32: case PlyType::float32: return 4;
    case PlyType::float64: return 8;
  }
  return 0;
}

inline bool ply_type_is_integer(PlyType type) { return type != PlyType::float32 && type != PlyType::float64; }

struct PlyProperty {
  std::string name;
  bool is_list = false;
  PlyType type = PlyType::float32;        // value type (of the items, for a list)
  PlyType count_type = PlyType::uint8;    // list length type
};

struct PlyElement {
  std::string name;
  std::size_t count = 0;
  std::vector<PlyProperty> properties;
  int header_line = 0;
};

enum class PlyFormat { ascii, binary_little_endian, binary_big_endian };

struct PlyHeader {
  PlyFormat format = PlyFormat::ascii;
  std::vector<PlyElement> elements;
  std::size_t body_offset = 0;  // first byte after the end_header line
  int body_line = 0;            // line number of the first body line (for ascii messages)
};

inline bool host_is_little_endian() {
  const std::uint16_t probe = 1;
  unsigned char first;
  std::memcpy(&first, &probe, 1);
  return first == 1;
}

inline std::vector<std::string> split_words(const std::string& line) {
  std::vector<std::string> words;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    const std::size_t start = i;
    while (i < line.size() && !std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    if (i > start) words.push_back(line.substr(start, i - start));
  }
  return words;
}

inline PlyHeader parse_ply_header(const std::string& bytes, const std::string& path) {
  PlyHeader header;
  bool have_format = false;
  std::size_t pos = 0;
  int line_number = 0;
  const auto where = [&] { return "line " + std::to_string(line_number); };
  while (true) {
    if (pos >= bytes.size())
      throw InputError(path, "header", line_number == 0 ? "file is empty" : "file ends before 'end_header'");
    std::size_t end = bytes.find('\n', pos);
    if (end == std::string::npos) end = bytes.size();
    std::string line = bytes.substr(pos, end - pos);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    pos = end + 1;
    ++line_number;

    if (line_number == 1) {
      if (line != "ply") throw InputError(path, "header", "not a PLY file (first line is not 'ply')");
      continue;
    }
    const std::vector<std::string> words = split_words(line);
    if (words.empty()) continue;
    const std::string& keyword = words[0];
    if (keyword == "comment" || keyword == "obj_info") continue;
    if (keyword == "end_header") break;
    if (keyword == "format") {
      if (words.size() != 3) throw InputError(path, where(), "expected 'format <type> <version>'");
      if (words[1] == "ascii") header.format = PlyFormat::ascii;
      else if (words[1] == "binary_little_endian") header.format = PlyFormat::binary_little_endian;
      else if (words[1] == "binary_big_endian") header.format = PlyFormat::binary_big_endian;
      else throw InputError(path, where(), "unknown format '" + words[1] + "'");
      have_format = true;
    } else if (keyword == "element") {
      if (words.size() != 3) throw InputError(path, where(), "expected 'element <name> <count>'");
      unsigned long long count = 0;
      const char* first = words[2].data();
      const char* last = first + words[2].size();
      const auto result = std::from_chars(first, last, count);
      if (result.ec != std::errc() || result.ptr != last || count > std::numeric_limits<std::uint32_t>::max())
        throw InputError(path, where(), "bad element count '" + words[2] + "'");
      PlyElement element;
      element.name = words[1];
      element.count = static_cast<std::size_t>(count);
      element.header_line = line_number;
      header.elements.push_back(element);
    } else if (keyword == "property") {
      if (header.elements.empty()) throw InputError(path, where(), "property before any element");
      PlyProperty property;
      if (words.size() >= 2 && words[1] == "list") {
        if (words.size() != 5)
          throw InputError(path, where(), "expected 'property list <count type> <item type> <name>'");
        if (!ply_type_from_name(words[2], property.count_type))
          throw InputError(path, where(), "unknown property type '" + words[2] + "'");
        if (!ply_type_is_integer(property.count_type))
          throw InputError(path, where(), "list count type '" + words[2] + "' is not an integer type");
        if (!ply_type_from_name(words[3], property.type))
          throw InputError(path, where(), "unknown property type '" + words[3] + "'");
        property.is_list = true;
        property.name = words[4];
      } else {
        if (words.size() != 3) throw InputError(path, where(), "expected 'property <type> <name>'");
        if (!ply_type_from_name(words[1], property.type))
          throw InputError(path, where(), "unknown property type '" + words[1] + "'");
        property.name = words[2];
      }
      header.elements.back().properties.push_back(property);
    } else {
      throw InputError(path, where(), "unknown header keyword '" + keyword + "'");
    }
  }
  if (!have_format) throw InputError(path, "header", "no 'format' line");
  header.body_offset = pos;
  header.body_line = line_number + 1;
  return header;
}

}  // namespace lwsccd::detail
