// lwsccd — pictures of where a step collides: the mesh drawn at the step's earliest contact with the
// colliding triangles highlighted, by the library's own ray caster (RayCastTask through the
// traversal engine: primary rays, one shadow ray per hit), written as PNG with no dependency.
// The pieces (view, rays, shading) are shared with the GPU ray-tracing example; cpu::render is
// the whole picture on the CPU backend. Plain C++.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "lwsccd/bvh/bvh.hpp"
#include "lwsccd/core/error.hpp"
#include "lwsccd/io/png.hpp"
#include "lwsccd/narrow_phase/narrow_phase.hpp"
#include "lwsccd/traversal/cpu_traverse.hpp"
#include "lwsccd/traversal/ray_task.hpp"

namespace lwsccd {

/// A camera looking at a mesh from above and in front, and a light above it.
struct RenderView {
  int width = 800, height = 600;
  Vec3f eye, forward, right, up;
  Vec3f light;
};

/// The view that frames every point of x (width x height pixels). Throws InputError for an empty
/// picture or no points.
inline RenderView frame_view(const std::vector<Vec3f>& x, int width, int height) {
  if (width < 1 || height < 1 || width > 16384 || height > 16384)
    throw InputError("render", "size", std::to_string(width) + "x" + std::to_string(height) + " is not in 1..16384");
  if (x.empty()) throw InputError("render", "positions", "no points to frame");
  Aabbf box = Aabbf::empty();
  for (const auto& p : x) box.expand(p);
  const Vec3f c = box.center(), e = box.extent();
  const float r = std::max(0.5f * norm(e), 1e-30f);
  RenderView v;
  v.width = width;
  v.height = height;
  v.eye = c + Vec3f{0.7f * r, -1.25f * r, 0.85f * r};
  v.forward = c - v.eye;
  v.forward *= 1.0f / norm(v.forward);
  v.right = cross(v.forward, Vec3f{0, 0, 1});
  v.right *= 1.0f / norm(v.right);
  v.up = cross(v.right, v.forward);
  v.light = c + Vec3f{-2.0f * r, -1.0f * r, 4.0f * r};
  return v;
}

/// One ray per pixel, row by row from the top.
inline std::vector<Ray> primary_rays(const RenderView& v) {
  std::vector<Ray> rays;
  rays.reserve(static_cast<std::size_t>(v.width) * v.height);
  const float aspect = float(v.width) / float(v.height);
  for (int j = 0; j < v.height; ++j)
    for (int i = 0; i < v.width; ++i) {
      const float sx = (2.0f * (i + 0.5f) / v.width - 1.0f) * 0.6f * aspect, sy = (1.0f - 2.0f * (j + 0.5f) / v.height) * 0.6f;
      Vec3f d = v.forward + v.right * sx + v.up * sy;
      d *= 1.0f / norm(d);
      rays.push_back({v.eye, d, 1e30f});
    }
  return rays;
}

/// The shadow rays of the pixels whose primary ray hit: from just off the surface toward the light.
struct ShadowRays {
  std::vector<Ray> rays;
  std::vector<std::size_t> pixel;  ///< the pixel of each shadow ray
  std::vector<Vec3f> normal;       ///< the hit triangle's normal, facing the camera
  std::vector<index_t> face;       ///< the hit triangle
};

inline ShadowRays shadow_rays(const RenderView& view, const TriangleMesh& mesh, const std::vector<Vec3f>& x,
                              const std::vector<Ray>& primary, const std::vector<std::uint64_t>& hits) {
  ShadowRays s;
  for (std::size_t r = 0; r < primary.size(); ++r) {
    if (hits[r] == kNoHit) continue;
    const index_t tri = hit_triangle(hits[r]);
    const Face f = mesh.face(tri);
    Vec3f n = cross(x[f.v[1]] - x[f.v[0]], x[f.v[2]] - x[f.v[0]]);
    const float length = norm(n);
    n *= length > 0 ? 1.0f / length : 0.0f;
    if (dot(n, primary[r].direction) > 0) n = -n;
    const Vec3f p = primary[r].origin + primary[r].direction * hit_t(hits[r]) + n * 1e-4f;
    Vec3f to_light = view.light - p;
    const float dist = norm(to_light);
    s.rays.push_back({p, to_light * (1.0f / dist), dist});
    s.pixel.push_back(r);
    s.normal.push_back(n);
    s.face.push_back(tri);
  }
  return s;
}

/// RGB bytes of the picture: a background gradient, Lambert shading with shadows. Without
/// `highlight` the surface is warm; with it, faces f with highlight[f] != 0 are red and the others
/// grey-blue, so that contacts stand out.
inline std::vector<unsigned char> shade(const RenderView& view, const ShadowRays& s, const std::vector<std::uint64_t>& blocked,
                                        const std::vector<unsigned char>& highlight = {}) {
  const std::size_t pixels = static_cast<std::size_t>(view.width) * view.height;
  std::vector<unsigned char> rgb(pixels * 3);
  for (std::size_t r = 0; r < pixels; ++r) {
    const float g = 0.75f - 0.35f * float(r / view.width) / view.height;
    rgb[3 * r] = static_cast<unsigned char>(255 * g * 0.85f);
    rgb[3 * r + 1] = static_cast<unsigned char>(255 * g * 0.9f);
    rgb[3 * r + 2] = static_cast<unsigned char>(255 * g);
  }
  for (std::size_t k = 0; k < s.rays.size(); ++k) {
    const std::size_t r = s.pixel[k];
    const float lambert = std::max(0.0f, dot(s.normal[k], s.rays[k].direction));
    const float light = 0.18f + 0.82f * lambert * (blocked[k] == kNoHit ? 1.0f : 0.25f);
    Vec3f color{0.95f, 0.72f, 0.45f};
    if (!highlight.empty()) color = highlight[s.face[k]] ? Vec3f{1.0f, 0.16f, 0.10f} : Vec3f{0.72f, 0.76f, 0.84f};
    rgb[3 * r] = static_cast<unsigned char>(255 * std::min(1.0f, light * color.x));
    rgb[3 * r + 1] = static_cast<unsigned char>(255 * std::min(1.0f, light * color.y));
    rgb[3 * r + 2] = static_cast<unsigned char>(255 * std::min(1.0f, light * color.z));
  }
  return rgb;
}

/// The faces a step's contacts touch: each vertex-face contact's face and the faces around its
/// vertex, each edge-edge contact's faces around both edges (ids as in NarrowPhaseResult).
template <class T>
std::vector<unsigned char> contact_faces(const TriangleMesh& mesh, const NarrowPhaseResult<T>& contacts) {
  std::vector<unsigned char> mark(static_cast<std::size_t>(mesh.num_faces()), 0);
  const index_t v = mesh.num_vertices(), e = mesh.num_edges();
  for (const auto& h : contacts.vf) {
    mark[h.second - v - e] = 1;
    for (index_t f : mesh.vertex_faces(h.first)) mark[f] = 1;
  }
  for (const auto& h : contacts.ee) {
    const index_t edges[2] = {h.first - v, h.second - v};
    for (index_t edge : edges)
      for (index_t f : mesh.edge_faces(edge)) mark[f] = 1;
  }
  return mark;
}

/// x0 + t (x1 - x0), each vertex on its straight line.
inline std::vector<Vec3d> positions_at(const std::vector<Vec3d>& x0, const std::vector<Vec3d>& x1, double t) {
  std::vector<Vec3d> x(x0.size());
  for (std::size_t i = 0; i < x.size(); ++i) x[i] = x0[i] + (x1[i] - x0[i]) * t;
  return x;
}

namespace cpu {

/// Casts rays against a BVH of the triangles at x (CPU backend, work stealing): per ray the
/// nearest hit's key (hit_t, hit_triangle), or kNoHit; any_hit stops at the first.
inline std::vector<std::uint64_t> cast_rays(const BvhView<Aabbf>& bvh, const TriangleMesh& mesh, const std::vector<Vec3f>& x,
                                            const std::vector<Ray>& rays, bool any_hit) {
  std::vector<RayNode> seeds;
  seeds.reserve(rays.size());
  for (index_t r = 0; r < static_cast<index_t>(rays.size()); ++r) seeds.push_back({r, 0});
  std::vector<std::uint64_t> best(rays.size(), kNoHit);
  const RayCastTask task{bvh, mesh.faces().data(), x.data(), rays.data(), best.data(), any_hit};
  traverse(task, seeds, false, WorkStealingScheduler{});
  return best;
}

/// The mesh at positions x as RGB bytes (width x height), faces with highlight[f] != 0 in red
/// (highlight empty: none). Throws InputError for a position count that differs from the mesh's.
inline std::vector<unsigned char> render(const TriangleMesh& mesh, const std::vector<Vec3d>& x,
                                         const std::vector<unsigned char>& highlight, int width, int height) {
  if (x.size() != static_cast<std::size_t>(mesh.num_vertices()))
    throw InputError("render", "positions", std::to_string(x.size()) + " points for a mesh of " +
                                                std::to_string(mesh.num_vertices()) + " vertices");
  if (!highlight.empty() && highlight.size() != static_cast<std::size_t>(mesh.num_faces()))
    throw InputError("render", "highlight", std::to_string(highlight.size()) + " flags for " +
                                                std::to_string(mesh.num_faces()) + " faces");
  std::vector<Vec3f> xf(x.size());
  for (std::size_t v = 0; v < x.size(); ++v) xf[v] = x[v].cast<float>();
  const Bvh<Aabbf> bvh(mesh, xf, xf);
  const RenderView view = frame_view(xf, width, height);
  const std::vector<Ray> rays = primary_rays(view);
  const ShadowRays shadows = shadow_rays(view, mesh, xf, rays, cast_rays(bvh.view(), mesh, xf, rays, false));
  return shade(view, shadows, cast_rays(bvh.view(), mesh, xf, shadows.rays, true), highlight);
}

/// A step's picture: the mesh at the earliest TOI of `contacts` (t = 1 when nothing collides)
/// with the faces they touch in red, written to `path` as PNG. Throws Error when the file cannot
/// be written.
template <class T>
void render_contacts(const std::string& path, const TriangleMesh& mesh, const std::vector<Vec3d>& x0,
                     const std::vector<Vec3d>& x1, const NarrowPhaseResult<T>& contacts, int width = 800, int height = 600) {
  const double t = std::min(1.0, static_cast<double>(contacts.earliest_toi));
  const std::vector<unsigned char> rgb = render(mesh, positions_at(x0, x1, t), contact_faces(mesh, contacts), width, height);
  if (!png::write_rgb(path, width, height, rgb)) throw Error("render: cannot write " + path);
}

}  // namespace cpu
}  // namespace lwsccd
