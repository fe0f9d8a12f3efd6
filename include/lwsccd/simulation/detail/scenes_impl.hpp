// lwsccd — definitions for scenes.hpp.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <memory>
#include <string>

#include "lwsccd/simulation/scenes.hpp"

namespace lwsccd {

namespace detail {

// Subdivided icosahedron on the unit sphere: 20 * 4^level triangles.
inline void icosphere(int level, std::vector<Vec3d>& points, std::vector<Face>& faces) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  points = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
            {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  faces = {{{0, 11, 5}}, {{0, 5, 1}}, {{0, 1, 7}},  {{0, 7, 10}}, {{0, 10, 11}}, {{1, 5, 9}}, {{5, 11, 4}},
           {{11, 10, 2}}, {{10, 7, 6}}, {{7, 1, 8}},  {{3, 9, 4}},  {{3, 4, 2}},   {{3, 2, 6}}, {{3, 6, 8}},
           {{3, 8, 9}},  {{4, 9, 5}},  {{2, 4, 11}}, {{6, 2, 10}}, {{8, 6, 7}},   {{9, 8, 1}}};
  for (auto& p : points) p *= 1.0 / norm(p);
  for (int l = 0; l < level; ++l) {
    std::unordered_map<std::uint64_t, index_t> midpoint;
    midpoint.reserve(faces.size() * 2);
    auto mid = [&](index_t a, index_t b) {
      const std::uint64_t key = (static_cast<std::uint64_t>(std::min(a, b)) << 32) | static_cast<std::uint32_t>(std::max(a, b));
      const auto it = midpoint.find(key);
      if (it != midpoint.end()) return it->second;
      Vec3d m = (points[a] + points[b]) * 0.5;
      points.push_back(m * (1.0 / norm(m)));
      return midpoint[key] = static_cast<index_t>(points.size() - 1);
    };
    std::vector<Face> next;
    next.reserve(faces.size() * 4);
    for (const Face& f : faces) {
      const index_t a = mid(f.v[0], f.v[1]), b = mid(f.v[1], f.v[2]), c = mid(f.v[2], f.v[0]);
      next.push_back({{f.v[0], a, c}});
      next.push_back({{f.v[1], b, a}});
      next.push_back({{f.v[2], c, b}});
      next.push_back({{a, b, c}});
    }
    faces.swap(next);
  }
}

// The icosphere level whose size is closest to 20% of a scene's triangles (at least level 1).
inline int ball_level(std::size_t target_triangles) {
  int level = 1;
  while (20.0 * std::pow(4.0, level + 1) <= 0.2 * double(target_triangles)) ++level;
  return level;
}

// Cloth draped over a ball of radius r at the origin, (u, v) in [-1, 1]^2: it rests on top of
// the ball, falls away outside it, and two sinusoidal folds stack layers closely.
inline Vec3d draped_cloth_point(double u, double v, double r, double drop) {
  const double rho = std::sqrt(u * u + v * v);
  const double reach = 1.05 * r;  // where the cloth leaves the ball
  double z = rho < reach ? std::sqrt(std::max(reach * reach - rho * rho, 0.0)) : -(rho - reach) * 1.2;
  // Two folds: a wave whose amplitude grows with distance from the top, so far layers overlap.
  const double fold = 0.12 * rho * std::sin(9.0 * u + 2.0 * v);
  const double x = u * (1.0 - 0.25 * rho) + fold * 0.6;
  const double y = v * (1.0 - 0.25 * rho);
  z += 0.5 * fold - drop;
  return {x, y, z};
}

}  // namespace detail

inline MultiBodyStep make_cloth_ball_scene(std::size_t target_triangles) {
  target_triangles = std::max<std::size_t>(target_triangles, 64);
  std::vector<Vec3d> ball_points;
  std::vector<Face> ball_faces;
  detail::icosphere(detail::ball_level(target_triangles), ball_points, ball_faces);
  const std::size_t cloth_target = target_triangles > ball_faces.size() + 8 ? target_triangles - ball_faces.size() : 8;
  const int n = std::max(2, static_cast<int>(std::lround(std::sqrt(double(cloth_target) / 2.0))));

  const double radius = 0.5;
  std::vector<Face> faces;
  std::vector<Vec3d> x0, x1;
  const double h = 2.0 / n;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double u = -1.0 + i * h, v = -1.0 + j * h;
      x0.push_back(detail::draped_cloth_point(u, v, radius, 0.0));
      x1.push_back(detail::draped_cloth_point(u, v, radius, 0.3 * h));  // falls a third of an edge
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const index_t a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      faces.push_back({{a, b, d}});
      faces.push_back({{a, d, c}});
    }
  const auto cloth_faces = faces.size();
  const auto offset = static_cast<index_t>(x0.size());
  for (const Vec3d& p : ball_points) {
    x0.push_back(p * radius);
    x1.push_back(p * radius);  // the ball does not move
  }
  for (const Face& f : ball_faces) faces.push_back({{f.v[0] + offset, f.v[1] + offset, f.v[2] + offset}});

  MultiBodyStep scene;
  scene.step.mesh = std::make_shared<const TriangleMesh>(static_cast<index_t>(x0.size()), std::move(faces),
                                                         "built-in cloth-ball scene");
  scene.step.x0 = std::move(x0);
  scene.step.x1 = std::move(x1);
  scene.step.name = "builtin-cloth-ball-" + std::to_string(scene.step.mesh->num_faces());
  scene.layout.face_body.assign(static_cast<std::size_t>(scene.step.mesh->num_faces()), 1);
  std::fill(scene.layout.face_body.begin(), scene.layout.face_body.begin() + static_cast<std::ptrdiff_t>(cloth_faces), 0);
  scene.layout.body_self_collides = {true, false};
  return scene;
}

}  // namespace lwsccd
