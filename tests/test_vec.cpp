#include <catch2/catch.hpp>

#include <limits>

#include "lwsccd/geometry/vec.hpp"

using namespace lwsccd;

TEST_CASE("Vec3 arithmetic matches component formulas", "[vec]") {
  const Vec3d a{1.5, -2.0, 3.25}, b{-4.0, 0.5, 2.0};
  CHECK(a + b == Vec3d{-2.5, -1.5, 5.25});
  CHECK(a - b == Vec3d{5.5, -2.5, 1.25});
  CHECK(a * 2.0 == Vec3d{3.0, -4.0, 6.5});
  CHECK(dot(a, b) == Approx(1.5 * -4.0 + -2.0 * 0.5 + 3.25 * 2.0));
  const Vec3d c = cross(a, b);
  CHECK(dot(c, a) == Approx(0.0).margin(1e-12));
  CHECK(dot(c, b) == Approx(0.0).margin(1e-12));
  CHECK(c == Vec3d{-2.0 * 2.0 - 3.25 * 0.5, 3.25 * -4.0 - 1.5 * 2.0, 1.5 * 0.5 - -2.0 * -4.0});
  CHECK(norm(Vec3d{3, 4, 12}) == 13.0);
  CHECK(min(a, b) == Vec3d{-4.0, -2.0, 2.0});
  CHECK(max(a, b) == Vec3d{1.5, 0.5, 3.25});
  CHECK(abs(b) == Vec3d{4.0, 0.5, 2.0});
  CHECK(max_component(Vec3d{1, 7, 3}) == 7);
  CHECK(lerp(a, b, 0.0) == a);
  CHECK(lerp(a, b, 1.0) == b);
  CHECK(a[0] == 1.5);
  CHECK(a[2] == 3.25);
}

TEST_CASE("Vec3 finiteness and precision conversion", "[vec]") {
  CHECK(is_finite(Vec3f{1, 2, 3}));
  CHECK_FALSE(is_finite(Vec3f{1, std::numeric_limits<float>::quiet_NaN(), 3}));
  CHECK_FALSE(is_finite(Vec3d{std::numeric_limits<double>::infinity(), 0, 0}));
  const Vec3d d{0.1, 1e30, -3.0};
  const Vec3f f = d.cast<float>();
  CHECK(f.x == 0.1f);
  CHECK(f.y == 1e30f);
  CHECK(f.cast<double>().z == -3.0);
}
