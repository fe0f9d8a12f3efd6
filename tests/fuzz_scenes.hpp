// Random scenes for differential fuzzing, reproducible from a seed: soups, folded sheets, stacked
// coincident layers, tiny and huge coordinates, degenerate triangles, several bodies, a minimum
// separation now and then. Small (at most a few hundred triangles) so that the brute-force oracle
// stays cheap.
#pragma once

#include <cmath>
#include <cstdint>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "lwsccd/features/oracle.hpp"
#include "lwsccd/geometry/mesh.hpp"
#include "scene_fixtures.hpp"

namespace lwsccd_test {

struct FuzzScene {
  std::string what;  ///< how it was made, for messages
  std::uint64_t seed = 0;  ///< the seed that makes it again
  std::shared_ptr<const lwsccd::TriangleMesh> mesh;
  lwsccd::BodyLayout layout;
  std::vector<lwsccd::Vec3d> x0, x1;
  double min_separation = 0;
};

namespace detail {

// Several flat n x n sheets stacked at the same height (exactly coincident), each moving up or
// down a little, some of them alike.
inline MovingMesh coincident_layers(int layers, int n, std::mt19937_64& rng) {
  using namespace lwsccd;
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<Face> faces;
  std::vector<Vec3d> x0, x1;
  for (int l = 0; l < layers; ++l) {
    const index_t base = static_cast<index_t>(x0.size());
    const Vec3d motion = l % 2 ? Vec3d{0, 0, 0.01 * u(rng)} : Vec3d{0.002 * u(rng), 0.002 * u(rng), 0.01};
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) {
        const Vec3d p{double(i) / n, double(j) / n, 0};
        x0.push_back(p);
        x1.push_back(p + motion);
      }
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const index_t a = base + j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
        faces.push_back({{a, b, d}});
        faces.push_back({{a, d, c}});
      }
  }
  return {TriangleMesh(static_cast<index_t>(x0.size()), faces), x0, x1};
}

// Collapses some triangles of a soup: two corners made equal, or the three made collinear.
inline void degenerate_some(MovingMesh& m, std::mt19937_64& rng) {
  std::uniform_int_distribution<int> coin(0, 3);
  for (const lwsccd::Face& f : m.mesh.faces()) {
    const int what = coin(rng);
    if (what == 0) {
      m.x0[f.v[1]] = m.x0[f.v[0]];
      m.x1[f.v[1]] = m.x1[f.v[0]];
    } else if (what == 1) {
      m.x0[f.v[2]] = m.x0[f.v[0]] + (m.x0[f.v[1]] - m.x0[f.v[0]]) * 0.5;
      m.x1[f.v[2]] = m.x1[f.v[0]] + (m.x1[f.v[1]] - m.x1[f.v[0]]) * 0.5;
    }
  }
}

// Two moving meshes as one, with a body per part.
inline MovingMesh joined(const MovingMesh& a, const MovingMesh& b, lwsccd::BodyLayout& layout, bool second_self_collides) {
  using namespace lwsccd;
  std::vector<Face> faces = a.mesh.faces();
  const index_t shift = a.mesh.num_vertices();
  for (Face f : b.mesh.faces()) faces.push_back({{f.v[0] + shift, f.v[1] + shift, f.v[2] + shift}});
  MovingMesh out{TriangleMesh(a.mesh.num_vertices() + b.mesh.num_vertices(), faces), a.x0, a.x1};
  out.x0.insert(out.x0.end(), b.x0.begin(), b.x0.end());
  out.x1.insert(out.x1.end(), b.x1.begin(), b.x1.end());
  layout.face_body.assign(static_cast<std::size_t>(a.mesh.num_faces()), 0);
  layout.face_body.insert(layout.face_body.end(), static_cast<std::size_t>(b.mesh.num_faces()), 1);
  layout.body_self_collides = {true, second_self_collides};
  return out;
}

}  // namespace detail

/// The scene of `seed` (the same on every machine: std::mt19937_64 and exact power-of-two scales).
inline FuzzScene make_fuzz_scene(std::uint64_t seed) {
  using namespace lwsccd;
  std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ull + 1);
  std::uniform_int_distribution<int> kind_of(0, 6);
  const int kind = kind_of(rng);
  auto between = [&](int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng); };
  FuzzScene scene;
  MovingMesh m;
  switch (kind) {
    case 0:
      m = random_soup(between(20, 200), rng(), 0.05 + 0.1 * between(0, 2));
      scene.what = "soup";
      break;
    case 1:
      m = folded_cloth(between(4, 12), rng());
      scene.what = "folded sheet";
      break;
    case 2:
      m = detail::coincident_layers(between(2, 4), between(2, 6), rng);
      scene.what = "coincident layers";
      break;
    case 3:
    case 4: {  // tiny or huge coordinates: a sheet or a soup scaled by 2^k, maybe far from the origin
      m = between(0, 1) ? folded_cloth(between(4, 10), rng()) : random_soup(between(20, 120), rng(), 0.1);
      const int exponent = kind == 3 ? -between(20, 40) : between(20, 40);
      const bool far = between(0, 1) == 1;
      for (auto* xs : {&m.x0, &m.x1})
        for (Vec3d& p : *xs) {
          p = p * std::ldexp(1.0, exponent);
          if (far) p = p + Vec3d{1e6, -1e6, 1e6} * std::ldexp(1.0, exponent);
        }
      scene.what = std::string(kind == 3 ? "tiny" : "huge") + " (2^" + std::to_string(exponent) + (far ? ", far)" : ")");
      break;
    }
    case 5:
      m = random_soup(between(20, 150), rng(), 0.1);
      detail::degenerate_some(m, rng);
      scene.what = "soup with degenerate triangles";
      break;
    default: {
      const bool self = between(0, 1) == 1;
      m = detail::joined(folded_cloth(between(4, 9), rng()), random_soup(between(10, 80), rng(), 0.1), scene.layout, self);
      scene.what = std::string("two bodies (second ") + (self ? "self-colliding)" : "not self-colliding)");
      break;
    }
  }
  if (between(0, 5) == 0) {  // a minimum separation in the scene's units
    double extent = 0;
    for (const Vec3d& p : m.x0) extent = std::fmax(extent, std::fmax(std::fabs(p.x), std::fmax(std::fabs(p.y), std::fabs(p.z))));
    scene.min_separation = extent * std::ldexp(1.0, -between(8, 14));
    scene.what += ", min separation " + std::to_string(scene.min_separation);
  }
  scene.seed = seed;
  scene.what = "seed " + std::to_string(seed) + ": " + scene.what + ", " + std::to_string(m.mesh.num_faces()) + " triangles";
  scene.mesh = std::make_shared<const TriangleMesh>(m.mesh);
  scene.x0 = std::move(m.x0);
  scene.x1 = std::move(m.x1);
  return scene;
}

}  // namespace lwsccd_test
