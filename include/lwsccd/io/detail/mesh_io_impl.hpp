// lwsccd — definitions for mesh_io.hpp: a reader per format (PLY, OBJ) on what they share, then
// frames by extension, steps and sequences.
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
#include "lwsccd/io/detail/mesh_file_common.hpp"
#include "lwsccd/io/detail/obj_reader.hpp"
#include "lwsccd/io/detail/ply_reader.hpp"
#include "lwsccd/io/detail/polygons.hpp"
#include "lwsccd/io/mesh_io.hpp"

namespace lwsccd {

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
