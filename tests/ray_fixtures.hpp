// Rays and a brute-force reference for the ray-casting task's tests.
#pragma once

#include <random>
#include <vector>

#include "lwsccd/traversal/ray_task.hpp"

namespace lwsccd_test {

/// A grid of parallel rays across the mesh's box (coherent) plus random rays (incoherent).
inline std::vector<lwsccd::Ray> test_rays(const std::vector<lwsccd::Vec3f>& x, int grid, int random_count) {
  using namespace lwsccd;
  Aabbf box = Aabbf::empty();
  for (const auto& p : x) box.expand(p);
  const Vec3f size = box.hi - box.lo;
  std::vector<Ray> rays;
  for (int j = 0; j < grid; ++j)
    for (int i = 0; i < grid; ++i) {
      const Vec3f o{box.lo.x + size.x * (i + 0.5f) / grid, box.lo.y + size.y * (j + 0.5f) / grid, box.hi.z + size.z};
      rays.push_back({o, Vec3f{0.01f * (i - grid / 2) / grid, 0.013f, -1.0f}, 1e30f});
    }
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0, 1), d(-1, 1);
  for (int k = 0; k < random_count; ++k) {
    const Vec3f o{box.lo.x + size.x * u(rng), box.lo.y + size.y * u(rng), box.lo.z + size.z * u(rng)};
    rays.push_back({o, Vec3f{d(rng), d(rng), d(rng)}, 1e30f});
  }
  return rays;
}

/// Closest hit of every ray by testing every triangle.
inline std::vector<std::uint64_t> brute_force_hits(const std::vector<lwsccd::Ray>& rays, const std::vector<lwsccd::Face>& faces,
                                                   const std::vector<lwsccd::Vec3f>& x) {
  using namespace lwsccd;
  std::vector<std::uint64_t> best(rays.size(), kNoHit);
  for (std::size_t r = 0; r < rays.size(); ++r)
    for (std::size_t f = 0; f < faces.size(); ++f) {
      const float t = detail::ray_triangle(rays[r], x[faces[f].v[0]], x[faces[f].v[1]], x[faces[f].v[2]]);
      if (t <= rays[r].t_max) best[r] = std::min(best[r], hit_key(t, static_cast<index_t>(f)));
    }
  return best;
}

}  // namespace lwsccd_test
