#include <catch2/catch.hpp>

#include <random>

#include "lwsccd/geometry/morton.hpp"

using namespace lwsccd;

namespace {
// Straightforward reference: interleave bit by bit.
std::uint64_t interleave_reference(std::uint64_t x, std::uint64_t y, std::uint64_t z, int bits) {
  std::uint64_t code = 0;
  for (int b = bits - 1; b >= 0; --b) code = (code << 3) | (((x >> b) & 1) << 2) | (((y >> b) & 1) << 1) | ((z >> b) & 1);
  return code;
}
}  // namespace

TEST_CASE("Morton codes interleave the grid cells bit by bit", "[morton]") {
  std::mt19937_64 rng(7);
  const Aabbd scene{{-2, -1, 0}, {6, 3, 4}};
  std::uniform_real_distribution<double> ux(-2, 6), uy(-1, 3), uz(0, 4);
  for (int i = 0; i < 2000; ++i) {
    const Vec3d p{ux(rng), uy(rng), uz(rng)};
    const auto cx = detail::grid_cell(p.x, scene.lo.x, scene.hi.x, 1024u);
    const auto cy = detail::grid_cell(p.y, scene.lo.y, scene.hi.y, 1024u);
    const auto cz = detail::grid_cell(p.z, scene.lo.z, scene.hi.z, 1024u);
    REQUIRE(morton30(p, scene) == interleave_reference(cx, cy, cz, 10));
    const auto dx = detail::grid_cell(p.x, scene.lo.x, scene.hi.x, 1u << 21);
    const auto dy = detail::grid_cell(p.y, scene.lo.y, scene.hi.y, 1u << 21);
    const auto dz = detail::grid_cell(p.z, scene.lo.z, scene.hi.z, 1u << 21);
    REQUIRE(morton63(p, scene) == interleave_reference(dx, dy, dz, 21));
    // the cell is where the point lies: cell = floor((x - lo) / extent * cells)
    REQUIRE(cx == static_cast<std::uint32_t>((p.x + 2) / 8 * 1024));
  }
}

TEST_CASE("Morton codes clamp to the box and handle flat boxes", "[morton]") {
  const Aabbf scene{{0, 0, 0}, {1, 1, 1}};
  CHECK(morton30(Vec3f{0, 0, 0}, scene) == 0u);
  CHECK(morton30(Vec3f{1, 1, 1}, scene) == (1u << 30) - 1);
  CHECK(morton30(Vec3f{5, 5, 5}, scene) == (1u << 30) - 1);  // outside: clamped
  CHECK(morton30(Vec3f{-5, -5, -5}, scene) == 0u);
  CHECK(morton63(Vec3f{1, 1, 1}, scene) == (std::uint64_t(1) << 63) - 1);
  const Aabbd flat{{0, 0, 0}, {1, 0, 1}};  // y extent zero: y bits all zero
  const auto code = morton30(Vec3d{1, 0, 1}, flat);
  CHECK((code & 0x12492492u) == 0u);  // the y positions
  CHECK(code == ((1u << 30) - 1 & ~0x12492492u));
}

TEST_CASE("Morton order preserves order along each axis", "[morton]") {
  const Aabbd scene{{0, 0, 0}, {1, 1, 1}};
  for (int i = 0; i + 1 < 1024; ++i) {
    const double a = (i + 0.5) / 1024, b = (i + 1.5) / 1024;
    REQUIRE(morton30(Vec3d{a, 0.3, 0.7}, scene) < morton30(Vec3d{b, 0.3, 0.7}, scene));
    REQUIRE(morton30(Vec3d{0.3, a, 0.7}, scene) < morton30(Vec3d{0.3, b, 0.7}, scene));
  }
}
