// lwsccd — loading meshes, steps and sequences from PLY and OBJ files.
//
// A Frame is what one file holds (faces + positions). A Step is one topology with the vertex
// positions at t0 and t1 (linear motion over the step [0, 1]). A Sequence is one topology with
// many frames; consecutive frames are its steps.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "lwsccd/geometry/mesh.hpp"
#include "lwsccd/geometry/vec.hpp"

namespace lwsccd {

/// The contents of one mesh file. Positions are stored in double (float files convert exactly).
struct Frame {
  std::vector<Face> faces;
  std::vector<Vec3d> positions;
  std::string source;  ///< the file it came from, for messages
  /// Only where the file has faces of more than 3 vertices (polygons, triangulated on loading):
  /// each triangle's face in the file (0-based, file order), and the file's faces themselves
  /// (face f: polygon_vertices[polygon_offsets[f] .. polygon_offsets[f + 1])), by which frames of
  /// one animation compare. All three empty when every face of the file is a triangle.
  std::vector<index_t> face_source = {};
  std::vector<index_t> polygon_offsets = {}, polygon_vertices = {};
};

/// Reads a PLY file: ascii, binary_little_endian or binary_big_endian; vertex x/y/z as float or
/// double (other vertex properties are skipped); faces as a list property (any integer count and
/// index types). Faces of more than 3 vertices are triangulated (a fan where the polygon is
/// convex, ear clipping in its best-fit plane where it is not; Frame::face_source maps the
/// triangles back). Throws InputError naming the file, the element and the problem for malformed
/// headers, truncated data, faces of fewer than 3 vertices, degenerate polygons (a repeated
/// vertex, no area, no triangulation: self-intersecting), and NaN/inf coordinates.
Frame load_ply(const std::string& path);

/// Reads a Wavefront OBJ file: `v x y z` and `f a b c ...` lines (indices 1-based or
/// negative-relative, `a/b/c` forms accepted; polygons triangulated as load_ply's); other
/// statements are ignored. Throws InputError naming file and line.
Frame load_obj(const std::string& path);

/// Picks load_ply or load_obj by the extension (case-insensitive).
Frame load_frame(const std::string& path);

/// One topology and the vertex positions at the start (t0) and end (t1) of a time step.
struct Step {
  std::shared_ptr<const TriangleMesh> mesh;
  std::vector<Vec3d> x0;
  std::vector<Vec3d> x1;
  std::string name;
  /// Triangle -> face of the t0 file, where that file had polygons (else empty: the same ids).
  std::vector<index_t> face_source;
};

/// Builds a Step from two frames: checks that both have the same vertex count and identical
/// faces - the files' own faces where they had polygons, whose triangulation is then t0's -
/// (InputError naming both files otherwise), validates indices and positions.
Step make_step(const Frame& t0, const Frame& t1);

/// load_frame on both paths, then make_step.
Step load_step(const std::string& path_t0, const std::string& path_t1);

/// One topology and a series of frames (an animation).
class Sequence {
 public:
  /// `face_source`: triangle -> face of the files, where they had polygons (Step::face_source).
  Sequence(std::shared_ptr<const TriangleMesh> mesh, std::vector<std::vector<Vec3d>> frames,
           std::vector<std::string> frame_names, std::vector<index_t> face_source = {});

  const std::shared_ptr<const TriangleMesh>& mesh() const { return mesh_; }
  std::size_t num_frames() const { return frames_.size(); }
  std::size_t num_steps() const { return frames_.empty() ? 0 : frames_.size() - 1; }
  const std::vector<Vec3d>& frame(std::size_t i) const { return frames_.at(i); }
  const std::string& frame_name(std::size_t i) const { return names_.at(i); }
  /// Step i goes from frame i to frame i + 1.
  Step step(std::size_t i) const;

 private:
  std::shared_ptr<const TriangleMesh> mesh_;
  std::vector<std::vector<Vec3d>> frames_;
  std::vector<std::string> names_;
  std::vector<index_t> face_source_;
};

/// Loads every .obj/.ply file of a folder, in name order, as one sequence. Every frame must have
/// the topology of the first (InputError naming the file otherwise); at least two frames.
Sequence load_sequence(const std::string& folder);

}  // namespace lwsccd

#include "lwsccd/io/detail/mesh_io_impl.hpp"
