// Procedural meshes shared by the tests.
#pragma once

#include <cmath>
#include <random>
#include <vector>

#include "lwsccd/geometry/mesh.hpp"

namespace lwsccd_test {

struct MovingMesh {
  lwsccd::TriangleMesh mesh;
  std::vector<lwsccd::Vec3d> x0, x1;
};

/// A cloth folded over itself along s = 0.5 (self contacts), moving with some noise.
inline MovingMesh folded_cloth(int n, std::uint64_t seed) {
  using namespace lwsccd;
  std::vector<Face> faces;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const index_t a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      faces.push_back({{a, b, d}});
      faces.push_back({{a, d, c}});
    }
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<Vec3d> x0, x1;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double s = double(i) / n, t = double(j) / n;
      const double angle = s < 0.5 ? 0.0 : 3.0 * (s - 0.5);
      const Vec3d p{s < 0.5 ? s : 0.5 - 0.05 * std::sin(angle), t, s < 0.5 ? 0.0 : 0.05 * (1 - std::cos(angle)) + 0.02};
      x0.push_back(p + Vec3d{u(rng), u(rng), u(rng)} * 0.002);
      x1.push_back(p + Vec3d{u(rng), u(rng), u(rng) - 1.0} * 0.01);
    }
  return {TriangleMesh(static_cast<index_t>(x0.size()), faces), x0, x1};
}

/// n separate triangles scattered in the unit cube, each translating.
inline MovingMesh random_soup(int n, std::uint64_t seed, double size = 0.05) {
  using namespace lwsccd;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1), d(-size, size);
  std::vector<Face> faces;
  std::vector<Vec3d> x0, x1;
  for (int f = 0; f < n; ++f) {
    const Vec3d c{u(rng), u(rng), u(rng)};
    const Vec3d v{d(rng), d(rng), d(rng)};
    for (int k = 0; k < 3; ++k) {
      const Vec3d p = c + Vec3d{d(rng), d(rng), d(rng)};
      x0.push_back(p);
      x1.push_back(p + v);
    }
    faces.push_back({{3 * f, 3 * f + 1, 3 * f + 2}});
  }
  return {TriangleMesh(3 * n, faces), x0, x1};
}

/// n copies of one triangle at the same place: every Morton code equal.
inline MovingMesh coincident_triangles(int n) {
  using namespace lwsccd;
  std::vector<Face> faces;
  std::vector<Vec3d> x0, x1;
  for (int f = 0; f < n; ++f) {
    for (const Vec3d& p : {Vec3d{0, 0, 0}, Vec3d{1, 0, 0}, Vec3d{0, 1, 0}}) {
      x0.push_back(p);
      x1.push_back(p + Vec3d{0, 0, 0.1});
    }
    faces.push_back({{3 * f, 3 * f + 1, 3 * f + 2}});
  }
  return {TriangleMesh(3 * n, faces), x0, x1};
}

/// A cloth seam: two n x n/2 sheets side by side in one (tilted) plane, the second's first row a
/// copy of the first's last row moved by ~1e-6 within the plane (duplicated vertices), everything
/// sliding in the plane over the step, each vertex by its own ~1e-5 more. Pairs of edges along the
/// seam stay coplanar within float's rounding over the whole step (cloth-funnel's seams).
inline MovingMesh seam_sheets(int n, std::uint64_t seed) {
  using namespace lwsccd;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  const auto unit = [](const Vec3d& a) { return a * (1.0 / norm(a)); };
  const Vec3d e1 = unit(Vec3d{0.8, 0.1, 0.3}), e2 = unit(cross(Vec3d{0.2, -0.3, 0.9}, e1));
  const Vec3d origin{0.31, -0.17, 0.52};
  std::vector<Face> faces;
  std::vector<Vec3d> x0, x1;
  const int rows = n / 2;
  for (int sheet = 0; sheet < 2; ++sheet) {
    const auto first = static_cast<index_t>(x0.size());
    for (int j = 0; j < rows; ++j)
      for (int i = 0; i < n; ++i) {
        const index_t a = first + j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
        faces.push_back({{a, b, d}});
        faces.push_back({{a, d, c}});
      }
    for (int j = 0; j <= rows; ++j)
      for (int i = 0; i <= n; ++i) {
        double s = double(i) / n, t = 0.5 * double(sheet * rows + j) / rows;
        if (sheet == 1 && j == 0) s += 1e-6 * u(rng), t += 1e-6 * u(rng);
        const Vec3d p = origin + e1 * s + e2 * t;
        x0.push_back(p);
        x1.push_back(p + e1 * (0.01 + 1e-5 * u(rng)) + e2 * (1e-5 * u(rng)));
      }
  }
  return {TriangleMesh(static_cast<index_t>(x0.size()), faces), x0, x1};
}

/// A step's positions rounded to float (what a float32 caller passes) and those floats widened back
/// to double, exactly (what the pipelines certify float input as).
struct FloatRounded {
  std::vector<lwsccd::Vec3f> f0, f1;
  std::vector<lwsccd::Vec3d> w0, w1;
};
inline FloatRounded float_rounded(const std::vector<lwsccd::Vec3d>& x0, const std::vector<lwsccd::Vec3d>& x1) {
  FloatRounded r;
  for (std::size_t v = 0; v < x0.size(); ++v) {
    r.f0.push_back(x0[v].cast<float>());
    r.f1.push_back(x1[v].cast<float>());
    r.w0.push_back(r.f0.back().cast<double>());
    r.w1.push_back(r.f1.back().cast<double>());
  }
  return r;
}

}  // namespace lwsccd_test
