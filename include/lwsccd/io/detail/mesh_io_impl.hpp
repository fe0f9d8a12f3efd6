// lwsccd — definitions for mesh_io.hpp: PLY and OBJ readers, steps and sequences.
//
// Both readers load the whole file into memory and parse it in place: the dataset's frames are
// tens of thousands of vertices and a multi-frame run reads dozens of files.
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
#include "lwsccd/io/mesh_io.hpp"

namespace lwsccd {

namespace detail {

inline std::string read_whole_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "", "cannot open file");
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) throw InputError(path, "", "cannot determine the file size");
  std::string bytes(static_cast<std::size_t>(size), '\0');
  in.seekg(0, std::ios::beg);
  if (size > 0 && !in.read(&bytes[0], size)) throw InputError(path, "", "cannot read file");
  return bytes;
}

inline std::string lowercase(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

inline std::string extension_lowercase(const std::string& path) {
  return lowercase(std::filesystem::path(path).extension().string());
}

inline bool is_mesh_file_extension(const std::string& ext_lowercase) {
  return ext_lowercase == ".ply" || ext_lowercase == ".obj";
}

// Orders names with digit runs compared as numbers, so "frame9" < "frame10" and "227" < "228".
inline bool natural_less(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  const auto is_digit = [](char c) { return c >= '0' && c <= '9'; };
  while (i < a.size() && j < b.size()) {
    if (is_digit(a[i]) && is_digit(b[j])) {
      std::size_t ie = i, je = j;
      while (ie < a.size() && is_digit(a[ie])) ++ie;
      while (je < b.size() && is_digit(b[je])) ++je;
      std::size_t ia = i, jb = j;  // skip leading zeros, then longer run = larger number
      while (ia + 1 < ie && a[ia] == '0') ++ia;
      while (jb + 1 < je && b[jb] == '0') ++jb;
      if (ie - ia != je - jb) return ie - ia < je - jb;
      const int c = a.compare(ia, ie - ia, b, jb, je - jb);
      if (c != 0) return c < 0;
      i = ie;
      j = je;
    } else {
      if (a[i] != b[j]) return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
      ++i;
      ++j;
    }
  }
  if ((i < a.size()) != (j < b.size())) return j < b.size();
  return a < b;  // equal up to zero padding: any fixed tie-break
}

// The mesh files (.ply/.obj, any case) directly inside `folder`, in natural name order.
inline std::vector<std::string> list_mesh_files(const std::string& folder) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) throw InputError(folder, "", "not a folder");
  std::vector<std::pair<std::string, std::string>> name_path;
  for (const auto& entry : fs::directory_iterator(folder, ec)) {
    std::error_code entry_ec;
    if (!entry.is_regular_file(entry_ec)) continue;
    if (!is_mesh_file_extension(extension_lowercase(entry.path().string()))) continue;
    name_path.emplace_back(entry.path().filename().string(), entry.path().string());
  }
  if (ec) throw InputError(folder, "", "cannot list folder: " + ec.message());
  std::sort(name_path.begin(), name_path.end(),
            [](const auto& x, const auto& y) { return natural_less(x.first, y.first); });
  std::vector<std::string> paths;
  for (auto& np : name_path) paths.push_back(std::move(np.second));
  return paths;
}

inline std::string file_stem(const std::string& path) { return std::filesystem::path(path).stem().string(); }

inline std::string face_text(const Face& f) {
  return "(" + std::to_string(f.v[0]) + " " + std::to_string(f.v[1]) + " " + std::to_string(f.v[2]) + ")";
}

inline std::string coordinates_text(double x, double y, double z) {
  std::ostringstream s;
  s << "(" << x << ", " << y << ", " << z << ")";
  return s.str();
}

// Parses a whole token as a double; from_chars is locale-independent and rejects a leading '+'.
inline bool parse_double(const char* first, const char* last, double& out) {
  if (first != last && *first == '+') ++first;
  if (first == last) return false;
  const auto result = std::from_chars(first, last, out);
  return result.ec == std::errc() && result.ptr == last;
}

// Empty meshes and indices beyond the vertex count are checked once the whole file is read,
// since a face may name a vertex that is listed later.
inline void check_frame_not_empty(const Frame& frame) {
  if (frame.positions.empty()) throw InputError(frame.source, "", "mesh has no vertices");
  if (frame.faces.empty()) throw InputError(frame.source, "", "mesh has no faces");
}

// ---------------------------------------------------------------------------------------------
// PLY

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

// Indices that name no vertex, reported with the face that holds them.
// ---------------------------------------------------------------------------------------------
// Polygons

// Triangulates one polygon (vertex ids `ids`, n >= 3, in the file's order) into `out`, keeping its
// winding. Returns an empty string, or why it cannot: a repeated vertex, no area (Newell's normal
// is zero: collinear or coincident corners), no ear left (self-intersecting in its best-fit plane).
// A convex polygon becomes a fan from its first corner; any other, ear clipping in the plane
// normal to its largest Newell component, O(n^2) per ear.
inline std::string triangulate_polygon(const std::vector<Vec3d>& positions, const index_t* ids, int n, std::vector<Face>& out) {
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j)
      if (ids[i] == ids[j]) return "repeats vertex " + std::to_string(ids[i]);
  if (n == 3) {
    out.push_back(Face{{ids[0], ids[1], ids[2]}});
    return "";
  }
  Vec3d normal{0, 0, 0};  // Newell: twice the vector area
  for (int i = 0; i < n; ++i) {
    const Vec3d& a = positions[static_cast<std::size_t>(ids[i])];
    const Vec3d& b = positions[static_cast<std::size_t>(ids[(i + 1) % n])];
    normal.x += (a.y - b.y) * (a.z + b.z);
    normal.y += (a.z - b.z) * (a.x + b.x);
    normal.z += (a.x - b.x) * (a.y + b.y);
  }
  const double nx = std::fabs(normal.x), ny = std::fabs(normal.y), nz = std::fabs(normal.z);
  if (!(nx > 0 || ny > 0 || nz > 0)) return "has no area (its corners are collinear or coincide)";
  // 2D coordinates in the plane of the largest normal component, turned so that the polygon
  // winds counter-clockwise there.
  const int drop = nx >= ny && nx >= nz ? 0 : (ny >= nz ? 1 : 2);
  const double sign = normal[drop] > 0 ? 1.0 : -1.0;
  std::vector<double> u(static_cast<std::size_t>(n)), v(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    const Vec3d& a = positions[static_cast<std::size_t>(ids[i])];
    const double c[3] = {a.x, a.y, a.z};
    u[i] = c[(drop + 1) % 3];
    v[i] = sign * c[(drop + 2) % 3];
  }
  auto turn = [&](int a, int b, int c) { return (u[b] - u[a]) * (v[c] - v[a]) - (v[b] - v[a]) * (u[c] - u[a]); };
  bool convex = true;
  for (int i = 0; i < n && convex; ++i) convex = turn(i, (i + 1) % n, (i + 2) % n) >= 0;
  if (convex) {
    for (int i = 1; i + 1 < n; ++i) out.push_back(Face{{ids[0], ids[i], ids[i + 1]}});
    return "";
  }
  std::vector<int> left(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) left[i] = i;
  auto inside_or_on = [&](int p, int a, int b, int c) { return turn(a, b, p) >= 0 && turn(b, c, p) >= 0 && turn(c, a, p) >= 0; };
  while (left.size() > 3) {
    const int m = static_cast<int>(left.size());
    bool clipped = false;
    for (int k = 0; k < m && !clipped; ++k) {
      const int a = left[(k + m - 1) % m], b = left[k], c = left[(k + 1) % m];
      if (!(turn(a, b, c) > 0)) continue;  // reflex or flat corner: not an ear
      bool empty = true;
      for (int j = 0; j < m && empty; ++j) {
        const int p = left[j];
        if (p == a || p == b || p == c) continue;
        empty = !inside_or_on(p, a, b, c);
      }
      if (!empty) continue;
      out.push_back(Face{{ids[a], ids[b], ids[c]}});
      left.erase(left.begin() + k);
      clipped = true;
    }
    if (!clipped) return "cannot be triangulated (it intersects itself in its plane)";
  }
  out.push_back(Face{{ids[left[0]], ids[left[1]], ids[left[2]]}});
  return "";
}

// Turns the file's faces (polygon_offsets / polygon_vertices, indices already checked) into
// triangles. Where every face was a triangle the polygon arrays are dropped (Frame's contract).
// `where(f)` names face f in messages (its line, or "face f").
template <class Where>
void triangulate_frame(Frame& frame, Where&& where) {
  const std::size_t num_polygons = frame.polygon_offsets.empty() ? 0 : frame.polygon_offsets.size() - 1;
  bool only_triangles = true;
  for (std::size_t f = 0; f < num_polygons; ++f) only_triangles = only_triangles && frame.polygon_offsets[f + 1] - frame.polygon_offsets[f] == 3;
  frame.faces.clear();
  frame.faces.reserve(num_polygons);
  frame.face_source.clear();
  for (std::size_t f = 0; f < num_polygons; ++f) {
    const index_t begin = frame.polygon_offsets[f];
    const int n = static_cast<int>(frame.polygon_offsets[f + 1] - begin);
    const std::size_t before = frame.faces.size();
    const std::string problem = triangulate_polygon(frame.positions, frame.polygon_vertices.data() + begin, n, frame.faces);
    if (!problem.empty()) throw InputError(frame.source, where(f), "face of " + std::to_string(n) + " vertices " + problem);
    if (!only_triangles) frame.face_source.insert(frame.face_source.end(), frame.faces.size() - before, static_cast<index_t>(f));
  }
  if (only_triangles) {
    frame.polygon_offsets.clear();
    frame.polygon_vertices.clear();
  }
}

inline void check_face_indices(const Frame& frame) {
  const auto num_vertices = static_cast<index_t>(frame.positions.size());
  const std::size_t num_polygons = frame.polygon_offsets.empty() ? 0 : frame.polygon_offsets.size() - 1;
  for (std::size_t f = 0; f < num_polygons; ++f) {
    for (index_t k = frame.polygon_offsets[f]; k < frame.polygon_offsets[f + 1]; ++k) {
      const index_t v = frame.polygon_vertices[static_cast<std::size_t>(k)];
      if (v < 0 || v >= num_vertices)
        throw InputError(frame.source, "face " + std::to_string(f),
                         "vertex index " + std::to_string(v) + " out of range [0, " + std::to_string(num_vertices) + ")");
    }
  }
}

// ---------------------------------------------------------------------------------------------
// OBJ

// One whitespace-separated token of an OBJ line; '#' starts a comment that ends the line.
inline bool next_obj_token(const char*& p, const char* line_end, const char*& token, const char*& token_end) {
  while (p < line_end && (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\f' || *p == '\v')) ++p;
  if (p >= line_end || *p == '#') return false;
  token = p;
  while (p < line_end && !(*p == ' ' || *p == '\t' || *p == '\r' || *p == '\f' || *p == '\v' || *p == '#')) ++p;
  token_end = p;
  return true;
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

inline Frame load_obj(const std::string& path) {
  const std::string bytes = detail::read_whole_file(path);
  Frame frame;
  frame.source = path;
  std::vector<int> face_lines;  // for range messages, checked once every vertex is known

  const char* p = bytes.data();
  const char* const end = p + bytes.size();
  int line_number = 0;
  while (p < end) {
    ++line_number;
    const char* line_end = static_cast<const char*>(std::memchr(p, '\n', static_cast<std::size_t>(end - p)));
    if (!line_end) line_end = end;
    const auto where = [&] { return "line " + std::to_string(line_number); };

    const char *token = nullptr, *token_end = nullptr;
    const char* cursor = p;
    p = line_end + 1;
    if (!detail::next_obj_token(cursor, line_end, token, token_end)) continue;
    const std::size_t keyword_length = static_cast<std::size_t>(token_end - token);

    if (keyword_length == 1 && token[0] == 'v') {
      double xyz[3];
      for (int k = 0; k < 3; ++k) {
        if (!detail::next_obj_token(cursor, line_end, token, token_end))
          throw InputError(path, where(), "vertex has fewer than 3 coordinates");
        if (!detail::parse_double(token, token_end, xyz[k]))
          throw InputError(path, where(), "bad number '" + std::string(token, token_end) + "'");
      }
      const Vec3d position{xyz[0], xyz[1], xyz[2]};
      if (!is_finite(position))
        throw InputError(path, where(), "vertex " + std::to_string(frame.positions.size()) +
                                            " coordinate is NaN or infinite " +
                                            detail::coordinates_text(xyz[0], xyz[1], xyz[2]));
      frame.positions.push_back(position);  // any further values (w, colors) are ignored
    } else if (keyword_length == 1 && token[0] == 'f') {
      if (frame.polygon_offsets.empty()) frame.polygon_offsets.push_back(0);
      int corners = 0;
      while (detail::next_obj_token(cursor, line_end, token, token_end)) {
        // Only the position index matters: "a", "a/b", "a//c", "a/b/c".
        const char* slash = std::find(token, token_end, '/');
        long long index = 0;
        const auto result = std::from_chars(token, slash, index);
        if (result.ec != std::errc() || result.ptr != slash)
          throw InputError(path, where(), "bad vertex index '" + std::string(token, token_end) + "'");
        if (index == 0) throw InputError(path, where(), "vertex index 0 (OBJ indices start at 1)");
        const auto defined = static_cast<long long>(frame.positions.size());
        if (index < 0) {
          if (-index > defined)
            throw InputError(path, where(), "relative vertex index " + std::to_string(index) + " reaches before the first vertex (" +
                                                std::to_string(defined) + " defined so far)");
          index += defined;  // -1 is the latest vertex
        } else {
          --index;
        }
        if (index > std::numeric_limits<index_t>::max())
          throw InputError(path, where(), "vertex index " + std::string(token, slash) + " is too large");
        frame.polygon_vertices.push_back(static_cast<index_t>(index));
        ++corners;
      }
      if (corners < 3) throw InputError(path, where(), "face has " + std::to_string(corners) + " vertices (at least 3 needed)");
      frame.polygon_offsets.push_back(static_cast<index_t>(frame.polygon_vertices.size()));
      face_lines.push_back(line_number);
    }
    // Everything else (vn, vt, o, g, s, usemtl, mtllib, l, ...) does not affect the geometry.
  }

  if (frame.positions.empty()) throw InputError(frame.source, "", "mesh has no vertices");
  const auto num_vertices = static_cast<index_t>(frame.positions.size());
  for (std::size_t f = 0; f + 1 < frame.polygon_offsets.size(); ++f) {
    for (index_t k = frame.polygon_offsets[f]; k < frame.polygon_offsets[f + 1]; ++k) {
      const index_t v = frame.polygon_vertices[static_cast<std::size_t>(k)];
      if (v >= num_vertices)
        throw InputError(path, "line " + std::to_string(face_lines[f]),
                         "vertex index " + std::to_string(v + 1) + " out of range (the file has " +
                             std::to_string(num_vertices) + " vertices)");
    }
  }
  detail::triangulate_frame(frame, [&](std::size_t f) { return "line " + std::to_string(face_lines[f]); });
  detail::check_frame_not_empty(frame);
  return frame;
}

inline Frame load_frame(const std::string& path) {
  const std::string ext = detail::extension_lowercase(path);
  if (ext == ".ply") return load_ply(path);
  if (ext == ".obj") return load_obj(path);
  throw InputError(path, "", "unknown mesh file extension '" + ext + "' (expected .ply or .obj)");
}

namespace detail {

// Throws unless `other` has the vertex count and the faces of `reference`, naming both files.
inline void check_same_topology(const Frame& reference, const Frame& other) {
  if (other.positions.size() != reference.positions.size())
    throw InputError(other.source, "",
                     "has " + std::to_string(other.positions.size()) + " vertices but " + reference.source + " has " +
                         std::to_string(reference.positions.size()));
  // Files with polygons compare by their own faces (a polygon may triangulate differently in
  // another frame; the step keeps the first frame's triangles).
  if (!reference.polygon_offsets.empty() || !other.polygon_offsets.empty()) {
    if (reference.polygon_offsets == other.polygon_offsets && reference.polygon_vertices == other.polygon_vertices) return;
    throw InputError(other.source, "",
                     "has other faces than " + reference.source + " (" + std::to_string(other.polygon_offsets.size() ? other.polygon_offsets.size() - 1 : other.faces.size()) +
                         " against " + std::to_string(reference.polygon_offsets.size() ? reference.polygon_offsets.size() - 1 : reference.faces.size()) +
                         " in the files, or the same number with other vertices); the frames must have the same topology");
  }
  if (other.faces.size() != reference.faces.size())
    throw InputError(other.source, "",
                     "has " + std::to_string(other.faces.size()) + " faces but " + reference.source + " has " +
                         std::to_string(reference.faces.size()));
  for (std::size_t f = 0; f < reference.faces.size(); ++f) {
    const Face& a = reference.faces[f];
    const Face& b = other.faces[f];
    if (a.v[0] != b.v[0] || a.v[1] != b.v[1] || a.v[2] != b.v[2])
      throw InputError(other.source, "face " + std::to_string(f),
                       "is " + face_text(b) + " but face " + std::to_string(f) + " of " + reference.source + " is " +
                           face_text(a) + "; the frames must have the same topology");
  }
}

}  // namespace detail

inline Step make_step(const Frame& t0, const Frame& t1) {
  detail::check_same_topology(t0, t1);
  Step step;
  step.mesh = std::make_shared<const TriangleMesh>(static_cast<index_t>(t0.positions.size()), t0.faces, t0.source);
  validate_positions(*step.mesh, t0.positions, t0.source);
  validate_positions(*step.mesh, t1.positions, t1.source);
  step.x0 = t0.positions;
  step.x1 = t1.positions;
  step.name = detail::file_stem(t0.source) + "->" + detail::file_stem(t1.source);
  step.face_source = t0.face_source;
  return step;
}

inline Step load_step(const std::string& path_t0, const std::string& path_t1) {
  return make_step(load_frame(path_t0), load_frame(path_t1));
}

inline Sequence::Sequence(std::shared_ptr<const TriangleMesh> mesh, std::vector<std::vector<Vec3d>> frames,
                          std::vector<std::string> frame_names, std::vector<index_t> face_source)
    : mesh_(std::move(mesh)), frames_(std::move(frames)), names_(std::move(frame_names)), face_source_(std::move(face_source)) {
  if (!mesh_) throw InputError("sequence", "", "no mesh");
  if (!face_source_.empty() && face_source_.size() != static_cast<std::size_t>(mesh_->num_faces()))
    throw InputError("sequence", "", "face_source has " + std::to_string(face_source_.size()) + " entries for " +
                                         std::to_string(mesh_->num_faces()) + " triangles");
  if (names_.size() != frames_.size())
    throw InputError("sequence", "", std::to_string(frames_.size()) + " frames but " + std::to_string(names_.size()) + " names");
  for (std::size_t i = 0; i < frames_.size(); ++i) validate_positions(*mesh_, frames_[i], names_[i]);
}

inline Step Sequence::step(std::size_t i) const {
  if (i + 1 >= frames_.size())
    throw std::out_of_range("Sequence::step(" + std::to_string(i) + "): the sequence has " +
                            std::to_string(num_steps()) + " steps");
  Step step;
  step.mesh = mesh_;
  step.x0 = frames_[i];
  step.x1 = frames_[i + 1];
  step.name = names_[i] + "->" + names_[i + 1];
  step.face_source = face_source_;
  return step;
}

inline Sequence load_sequence(const std::string& folder) {
  const std::vector<std::string> paths = detail::list_mesh_files(folder);
  if (paths.size() < 2)
    throw InputError(folder, "", "has " + std::to_string(paths.size()) +
                                     " mesh files (.obj/.ply); a sequence needs at least 2");
  Frame first = load_frame(paths[0]);
  auto mesh = std::make_shared<const TriangleMesh>(static_cast<index_t>(first.positions.size()), first.faces, first.source);

  std::vector<std::vector<Vec3d>> frames{first.positions};
  std::vector<std::string> names{detail::file_stem(paths[0])};
  for (std::size_t i = 1; i < paths.size(); ++i) {
    Frame frame = load_frame(paths[i]);
    detail::check_same_topology(first, frame);
    frames.push_back(std::move(frame.positions));
    names.push_back(detail::file_stem(paths[i]));
  }
  return Sequence(std::move(mesh), std::move(frames), std::move(names), std::move(first.face_source));
}

}  // namespace lwsccd
