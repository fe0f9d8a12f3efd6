// lwsccd — definitions for simulation.hpp.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <utility>
#include <vector>
#include <string>

#include "lwsccd/core/error.hpp"
#include "lwsccd/simulation/detail/scenes_impl.hpp"
#include "lwsccd/simulation/simulation.hpp"

namespace lwsccd {

namespace detail {
// The scene's fixed geometry and physics (SI-like units: metres, seconds).
struct ClothBallSetup {
  static constexpr double kBallRadius = 0.5;
  static constexpr double kFloor = -0.5;         // the floor touches the ball's bottom
  static constexpr double kClothSide = 2.4;
  static constexpr double kDropHeight = 0.75;    // the cloth starts flat at this height
  static constexpr double kContactMargin = 0.01;  // the coarse cloth keeps this far from the ball and floor
  static constexpr double kFrameSeconds = 1.0 / 60.0;
  static constexpr int kSubsteps = 8, kIterations = 4, kMaxCoarseCells = 64;
  static constexpr double kFoldRadius = 0.02;
  static constexpr double kThickness = 0.6;  // in coarse cells
  static constexpr double kGravity = -9.81, kDamping = 0.998, kFriction = 0.6, kBendStiffness = 0.2;
};
}  // namespace detail

inline ClothBallSimulation::ClothBallSimulation(std::size_t target_triangles) {
  using S = detail::ClothBallSetup;
  if (target_triangles < 64)
    throw InputError("ClothBallSimulation", "target_triangles", "must be at least 64, got " + std::to_string(target_triangles));
  std::vector<Vec3d> ball_points;
  std::vector<Face> ball_faces;
  detail::icosphere(detail::ball_level(target_triangles), ball_points, ball_faces);
  const std::size_t cloth_target = target_triangles > ball_faces.size() + 8 ? target_triangles - ball_faces.size() : 8;
  fine_ = std::max(2, static_cast<int>(std::lround(std::sqrt(double(cloth_target) / 2.0))));
  coarse_ = std::min(fine_, static_cast<int>(S::kMaxCoarseCells));

  // The coarse cloth starts folded once, like a napkin (the second half laid back over the first
  // around a crease of radius kFoldRadius), turned and off the ball's centre. Both layers drape
  // over the ball and come to rest against it at the same distance: they touch and cross.
  const double angle = 0.5, c = std::cos(angle), s = std::sin(angle), r = S::kFoldRadius;
  const double pi = 3.14159265358979323846;
  for (int j = 0; j <= coarse_; ++j)
    for (int i = 0; i <= coarse_; ++i) {
      const double u = (double(i) / coarse_ - 0.5) * S::kClothSide, v = (double(j) / coarse_ - 0.5) * S::kClothSide;
      double x = u, z = S::kDropHeight;
      if (u > 0 && u <= pi * r) {
        x = r * std::sin(u / r);
        z += r * (1 - std::cos(u / r));
      } else if (u > pi * r) {
        x = -(u - pi * r);
        z += 2 * r;
      }
      x += 0.25 * S::kClothSide;  // the folded napkin's middle over the ball
      coarse_x_.push_back({c * x - s * v + 0.1, s * x + c * v + 0.05, z});
    }
  coarse_v_.assign(coarse_x_.size(), Vec3d{0, 0, 0});

  std::vector<Face> faces;
  const int n = fine_;
  faces.reserve(static_cast<std::size_t>(2 * n * n) + ball_faces.size());
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const index_t a = j * (n + 1) + i, b = a + 1, cc = a + n + 1, d = cc + 1;
      faces.push_back({{a, b, d}});
      faces.push_back({{a, d, cc}});
    }
  ball_vertex_offset_ = static_cast<std::size_t>((n + 1) * (n + 1));
  const auto offset = static_cast<index_t>(ball_vertex_offset_);
  for (const Face& f : ball_faces) faces.push_back({{f.v[0] + offset, f.v[1] + offset, f.v[2] + offset}});
  positions_.resize(ball_vertex_offset_ + ball_points.size());
  for (std::size_t k = 0; k < ball_points.size(); ++k) positions_[ball_vertex_offset_ + k] = ball_points[k] * S::kBallRadius;
  const auto cloth_faces = static_cast<std::size_t>(2 * n * n);
  mesh_ = std::make_shared<const TriangleMesh>(static_cast<index_t>(positions_.size()), std::move(faces),
                                               "built-in cloth-ball simulation");
  layout_.face_body.assign(static_cast<std::size_t>(mesh_->num_faces()), 1);
  std::fill(layout_.face_body.begin(), layout_.face_body.begin() + static_cast<std::ptrdiff_t>(cloth_faces), 0);
  layout_.body_self_collides = {true, false};
  substeps_ = std::max(1, static_cast<int>(std::lround(double(fine_) / coarse_)));
  refine(coarse_x_);
}

inline void ClothBallSimulation::advance(std::size_t frames) {
  for (std::size_t f = 0; f < frames; ++f) simulate_frame();
  substep_ = 0;
  refine(coarse_x_);
}

inline Step ClothBallSimulation::next_step() {
  // A frame's motion is linear between its coarse end states, so a substep is an exact part of it.
  if (substep_ == 0) {
    frame_start_ = coarse_x_;
    simulate_frame();
  }
  auto at = [&](int sub) {
    const double s = double(sub) / substeps_;
    std::vector<Vec3d> coarse(coarse_x_.size());
    for (std::size_t k = 0; k < coarse.size(); ++k) coarse[k] = frame_start_[k] * (1 - s) + coarse_x_[k] * s;
    refine(coarse);
    return positions_;
  };
  Step step;
  step.mesh = mesh_;
  step.name = "builtin-cloth-ball-" + std::to_string(mesh_->num_faces()) + " frame " + std::to_string(frame_ - 1) +
              (substeps_ > 1 ? "." + std::to_string(substep_) + "/" + std::to_string(substeps_) : std::string());
  step.x0 = substep_ == 0 ? at(0) : positions_;
  step.x1 = at(substep_ + 1);
  substep_ = (substep_ + 1) % substeps_;
  return step;
}

// Position-based dynamics on the coarse grid: predict under gravity, project the distance
// constraints (Gauss-Seidel, in a fixed order: deterministic) and the ball and floor, derive the
// velocities, damp them, and slow the contacts' motion (friction).
inline void ClothBallSimulation::simulate_frame() {
  using S = detail::ClothBallSetup;
  const int m = coarse_, w = m + 1;
  const double h = S::kClothSide / m, dt = S::kFrameSeconds / S::kSubsteps;
  struct Link {
    int a, b;
    double rest, stiffness;
  };
  std::vector<Link> links;
  links.reserve(static_cast<std::size_t>(6 * w * w));
  for (int j = 0; j <= m; ++j)
    for (int i = 0; i <= m; ++i) {
      const int a = j * w + i;
      if (i < m) links.push_back({a, a + 1, h, 1.0});
      if (j < m) links.push_back({a, a + w, h, 1.0});
      if (i < m && j < m) links.push_back({a, a + w + 1, h * std::sqrt(2.0), 1.0});
      if (i > 0 && j < m) links.push_back({a, a + w - 1, h * std::sqrt(2.0), 1.0});
      if (i + 2 <= m) links.push_back({a, a + 2, 2 * h, S::kBendStiffness});
      if (j + 2 <= m) links.push_back({a, a + 2 * w, 2 * h, S::kBendStiffness});
    }
  std::vector<Vec3d> predicted(coarse_x_.size());
  std::vector<unsigned char> touching(coarse_x_.size());
  for (int sub = 0; sub < S::kSubsteps; ++sub) {
    for (std::size_t k = 0; k < coarse_x_.size(); ++k) {
      coarse_v_[k].z += S::kGravity * dt;
      predicted[k] = coarse_x_[k] + coarse_v_[k] * dt;
    }
    std::fill(touching.begin(), touching.end(), 0);
    for (int it = 0; it < S::kIterations; ++it) {
      for (const Link& l : links) {
        const Vec3d d = predicted[l.b] - predicted[l.a];
        const double len = norm(d);
        if (len <= 0) continue;
        const Vec3d fix = d * (0.5 * l.stiffness * (len - l.rest) / len);
        predicted[l.a] += fix;
        predicted[l.b] -= fix;
      }
      for (std::size_t k = 0; k < predicted.size(); ++k) {
        Vec3d& p = predicted[k];
        const double r = norm(p), keep = S::kBallRadius + S::kContactMargin;
        if (r < keep && r > 0) {
          p *= keep / r;
          touching[k] = 1;
        }
        if (p.z < S::kFloor + S::kContactMargin) {
          p.z = S::kFloor + S::kContactMargin;
          touching[k] = 1;
        }
      }
      repel_layers(predicted);  // after the ball and floor, so that upper layers move out, not in
    }
    for (std::size_t k = 0; k < coarse_x_.size(); ++k) {
      coarse_v_[k] = (predicted[k] - coarse_x_[k]) * (S::kDamping / dt);
      if (touching[k]) coarse_v_[k] *= 1.0 - S::kFriction;
      coarse_x_[k] = predicted[k];
    }
  }
  ++frame_;
}

// Cloth thickness, crudely: coarse vertices that are not grid neighbours and come closer than
// kThickness cells are pushed apart (a hash grid finds them). Layers then stay apart where they
// rest on each other, as in a real simulation; where they slide fast, faces still pass through
// between the vertices, and those are the self contacts.
inline void ClothBallSimulation::repel_layers(std::vector<Vec3d>& x) const {
  using S = detail::ClothBallSetup;
  const int w = coarse_ + 1;
  const double thickness = S::kThickness * S::kClothSide / coarse_, inv = 1.0 / thickness;
  auto cell_key = [&](const Vec3d& p) {
    const auto c = [&](double v) { return static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(v * inv)) + (1 << 20)); };
    return (c(p.x) << 42) | (c(p.y) << 21) | c(p.z);
  };
  std::vector<std::pair<std::uint64_t, int>> cells(x.size());
  for (std::size_t k = 0; k < x.size(); ++k) cells[k] = {cell_key(x[k]), static_cast<int>(k)};
  std::sort(cells.begin(), cells.end());
  auto find_cell = [&](std::uint64_t key) {
    return std::lower_bound(cells.begin(), cells.end(), std::make_pair(key, -1));
  };
  for (std::size_t k = 0; k < x.size(); ++k) {
    const int a = static_cast<int>(k), ai = a % w, aj = a / w;
    const auto c = [&](double v) { return static_cast<std::int64_t>(std::floor(v * inv)); };
    const std::int64_t cx = c(x[k].x), cy = c(x[k].y), cz = c(x[k].z);
    for (std::int64_t dx = -1; dx <= 1; ++dx)
      for (std::int64_t dy = -1; dy <= 1; ++dy)
        for (std::int64_t dz = -1; dz <= 1; ++dz) {
          const Vec3d probe{(double(cx + dx) + 0.5) * thickness, (double(cy + dy) + 0.5) * thickness,
                            (double(cz + dz) + 0.5) * thickness};
          const std::uint64_t key = cell_key(probe);
          for (auto it = find_cell(key); it != cells.end() && it->first == key; ++it) {
            const int b = it->second;
            if (b <= a || (std::abs(b % w - ai) <= 2 && std::abs(b / w - aj) <= 2)) continue;  // near on the cloth
            const Vec3d d = x[b] - x[a];
            const double len = norm(d);
            if (len >= thickness || len <= 0) continue;
            const Vec3d fix = d * (0.5 * (thickness - len) / len);
            x[a] -= fix;
            x[b] += fix;
          }
        }
  }
}

// Bilinear interpolation of the coarse cloth at the fine grid's vertices.
inline void ClothBallSimulation::refine(const std::vector<Vec3d>& coarse_x) {
  const int m = coarse_, n = fine_, w = m + 1;
  for (int j = 0; j <= n; ++j) {
    const double sj = double(j) * m / n;
    const int cj = std::min(static_cast<int>(sj), m - 1);
    const double fj = sj - cj;
    for (int i = 0; i <= n; ++i) {
      const double si = double(i) * m / n;
      const int ci = std::min(static_cast<int>(si), m - 1);
      const double fi = si - ci;
      const int a = cj * w + ci;
      const Vec3d bottom = coarse_x[a] * (1 - fi) + coarse_x[a + 1] * fi;
      const Vec3d top = coarse_x[a + w] * (1 - fi) + coarse_x[a + w + 1] * fi;
      positions_[static_cast<std::size_t>(j * (n + 1) + i)] = bottom * (1 - fj) + top * fj;
    }
  }
}

}  // namespace lwsccd
