#include <catch2/catch.hpp>

#include <Eigen/Dense>

#include <cmath>
#include <random>
#include <vector>

#include "lwsccd/geometry/bv_traits.hpp"

using namespace lwsccd;
using ld = long double;

namespace {

// Slab containment of the stored box, evaluated in long double (a stricter reference than the
// library's own test: no rounding slack).
template <class T, class U>
bool obb_contains_exactly(const Obb<T>& box, const Vec3<U>& p) {
  for (int i = 0; i < 3; ++i) {
    const ld s = ld(box.axis[i].x) * (ld(p.x) - ld(box.center.x)) + ld(box.axis[i].y) * (ld(p.y) - ld(box.center.y)) +
                 ld(box.axis[i].z) * (ld(p.z) - ld(box.center.z));
    if (std::fabs(s) > ld(box.half[i])) return false;
  }
  return true;
}

template <class T>
std::vector<Vec3d> random_cloud(std::mt19937_64& rng, int n, double offset, double scale) {
  // Anisotropic cloud, randomly rotated: the case the covariance fit is for.
  std::normal_distribution<double> g(0, 1);
  Eigen::Quaterniond q(g(rng), g(rng), g(rng), g(rng));
  q.normalize();
  const Eigen::Matrix3d r = q.toRotationMatrix();
  std::uniform_real_distribution<double> u(-1, 1);
  const Eigen::Vector3d stretch(1.0, 0.3, 0.01);
  std::vector<Vec3d> pts;
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3d v(u(rng), u(rng), u(rng));
    v = r * v.cwiseProduct(stretch) * scale;
    pts.push_back({v.x() + offset, v.y() - offset, v.z() + 0.5 * offset});
  }
  return pts;
}

// Reference separating-axis test in long double on the stored boxes, with no slack at all.
// Returns the largest normalized gap over the 15 axes (> 0: separated by that distance).
template <class T>
ld reference_separation(const Obb<T>& a, const Obb<T>& b) {
  auto vec = [](const Vec3<T>& v) { return Eigen::Matrix<ld, 3, 1>(v.x, v.y, v.z); };
  const Eigen::Matrix<ld, 3, 1> t = vec(b.center) - vec(a.center);
  std::vector<Eigen::Matrix<ld, 3, 1>> axes;
  for (int i = 0; i < 3; ++i) {
    axes.push_back(vec(a.axis[i]));
    axes.push_back(vec(b.axis[i]));
    for (int j = 0; j < 3; ++j) axes.push_back(vec(a.axis[i]).cross(vec(b.axis[j])));
  }
  ld best = -1e300L;
  for (auto& l : axes) {
    const ld len = l.norm();
    if (len < 1e-9L) continue;
    l /= len;
    ld ra = 0, rb = 0;
    for (int i = 0; i < 3; ++i) {
      ra += ld(a.half[i]) * std::fabs(vec(a.axis[i]).dot(l));
      rb += ld(b.half[i]) * std::fabs(vec(b.axis[i]).dot(l));
    }
    best = std::max(best, std::fabs(t.dot(l)) - ra - rb);
  }
  return best;
}

}  // namespace

TEST_CASE("symmetric 3x3 eigen solver matches Eigen on random and degenerate matrices", "[bv][eigen]") {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<Eigen::Matrix3d> cases;
  for (int i = 0; i < 500; ++i) {
    Eigen::Matrix3d m;
    for (int r = 0; r < 3; ++r)
      for (int c = r; c < 3; ++c) m(r, c) = m(c, r) = u(rng);
    cases.push_back(m);
  }
  cases.push_back(Eigen::Matrix3d::Zero());
  cases.push_back(Eigen::Matrix3d::Identity() * 3.0);                    // triple eigenvalue
  cases.push_back(Eigen::Vector3d(2, 2, -1).asDiagonal().toDenseMatrix());  // double eigenvalue
  Eigen::Matrix3d rank1 = Eigen::Vector3d(1, 2, 3) * Eigen::Vector3d(1, 2, 3).transpose();
  cases.push_back(rank1);
  cases.push_back(rank1 * 1e300);
  cases.push_back(rank1 * 1e-300);
  for (const Eigen::Matrix3d& m : cases) {
    const detail::SymMat3<double> s{m(0, 0), m(1, 1), m(2, 2), m(0, 1), m(0, 2), m(1, 2)};
    const auto eig = detail::symmetric_eigen3(s);
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> ref(m);
    const double mag = std::max(m.cwiseAbs().maxCoeff(), 1e-300);
    for (int i = 0; i < 3; ++i) {
      REQUIRE(std::fabs(eig.values[i] - ref.eigenvalues()(2 - i)) <= 1e-12 * mag);  // ours descending
      const Eigen::Vector3d v(eig.vectors[i].x, eig.vectors[i].y, eig.vectors[i].z);
      REQUIRE(std::fabs(v.norm() - 1.0) < 1e-12);
      REQUIRE((m * v - eig.values[i] * v).stableNorm() <= 1e-11 * mag);
      for (int j = i + 1; j < 3; ++j)
        REQUIRE(std::fabs(dot(eig.vectors[i], eig.vectors[j])) < 1e-12);
    }
    REQUIRE(dot(cross(eig.vectors[0], eig.vectors[1]), eig.vectors[2]) > 0.99);
  }
}

TEMPLATE_TEST_CASE("AABB fit, merge, overlap and inflate are exact or outward", "[bv][aabb]", float, double) {
  using T = TestType;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1e3, 1e3);
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<Vec3d> pts(7);
    for (auto& p : pts) p = {u(rng) * 1.000000001, u(rng) / 3.0, u(rng) * 1e-7};
    const Aabb<T> box = bv_traits<Aabb<T>>::fit(pts.data(), 7);
    for (const auto& p : pts) {  // checked in double: the float box must contain double points
      REQUIRE(double(box.lo.x) <= p.x);
      REQUIRE(p.x <= double(box.hi.x));
      REQUIRE(double(box.lo.y) <= p.y);
      REQUIRE(p.y <= double(box.hi.y));
      REQUIRE(double(box.lo.z) <= p.z);
      REQUIRE(p.z <= double(box.hi.z));
    }
    // Tight: each face is the input extreme rounded outward, not further.
    double max_x = pts[0].x;
    for (const auto& p : pts) max_x = std::max(max_x, p.x);
    REQUIRE(box.hi.x == detail::round_up<T>(max_x));
    const Aabb<T> other = bv_traits<Aabb<T>>::fit(pts.data() + 3, 4);
    const Aabb<T> merged = bv_traits<Aabb<T>>::merge(box, other);
    REQUIRE(merged.lo == min(box.lo, other.lo));
    REQUIRE(merged.hi == max(box.hi, other.hi));
    const Aabb<T> grown = bv_traits<Aabb<T>>::inflate(box, T(0.1));
    REQUIRE(double(grown.lo.x) <= double(box.lo.x) - 0.1);
    REQUIRE(double(grown.hi.z) >= double(box.hi.z) + 0.1);
  }
  // Overlap on closed boxes: touching counts, a gap of one ulp does not.
  const Aabb<T> a{{0, 0, 0}, {1, 1, 1}};
  CHECK(bv_traits<Aabb<T>>::overlap(a, Aabb<T>{{1, 0, 0}, {2, 1, 1}}));
  CHECK_FALSE(bv_traits<Aabb<T>>::overlap(a, Aabb<T>{{std::nextafter(T(1), T(2)), 0, 0}, {2, 1, 1}}));
  CHECK_FALSE(bv_traits<Aabb<T>>::overlap(a, Aabb<T>{{0, 0, 2}, {1, 1, 3}}));
  CHECK(bv_traits<Aabb<T>>::volume(Aabb<T>{{0, 0, 0}, {2, 3, 4}}) == T(24));
  CHECK(bv_traits<Aabb<T>>::surface_area(Aabb<T>{{0, 0, 0}, {2, 3, 4}}) == T(52));
  CHECK(Aabb<T>::empty().is_empty());
  CHECK(Aabb<T>::empty().volume() == T(0));
}

TEMPLATE_TEST_CASE("OBB fit contains every point: random, flat, coincident, huge and tiny", "[bv][obb]", float, double) {
  using T = TestType;
  std::mt19937_64 rng(5);
  const double offsets[] = {0.0, 1.0, 1e6, -3e8};
  const double scales[] = {1.0, 1e-6, 1e-30, 1e30};
  for (double offset : offsets) {
    for (double scale : scales) {
      if (offset != 0 && scale > 1e10) continue;
      for (int trial = 0; trial < 40; ++trial) {
        const auto pts = random_cloud<T>(rng, 6 + trial % 10, offset * scale, scale);
        const Obb<T> box = Obb<T>::fit(pts.data(), static_cast<int>(pts.size()));
        for (const auto& p : pts) {
          REQUIRE(obb_contains_exactly(box, p));
          REQUIRE(box.contains(p));
        }
        for (int i = 0; i < 3; ++i) REQUIRE(std::isfinite(box.half[i]));
      }
    }
  }
  // Degenerate point sets.
  const std::vector<std::vector<Vec3d>> degenerate = {
      {{1, 2, 3}},                                              // one point
      {{1, 2, 3}, {1, 2, 3}, {1, 2, 3}},                        // coincident
      {{0, 0, 0}, {1, 1, 1}, {2, 2, 2}, {3, 3, 3}},             // collinear
      {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 0}, {2, 0, 0}, {0, 2, 0}},  // flat swept triangle
      {{1e7, 1e7, 1e7}, {1e7 + 1e-3, 1e7, 1e7}, {1e7, 1e7 + 1e-3, 1e7}},  // tiny triangle far away
  };
  for (const auto& pts : degenerate) {
    const Obb<T> box = Obb<T>::fit(pts.data(), static_cast<int>(pts.size()));
    for (const auto& p : pts) REQUIRE(obb_contains_exactly(box, p));
    REQUIRE(std::isfinite(box.center.x));
  }
  // An axis-aligned brick gets its own dimensions back.
  std::vector<Vec3d> brick;
  for (int k = 0; k < 8; ++k) brick.push_back({(k & 1) ? 4.0 : 0.0, (k & 2) ? 2.0 : 0.0, (k & 4) ? 1.0 : 0.0});
  const Obb<T> b = Obb<T>::fit(brick.data(), 8);
  CHECK(double(b.volume()) == Approx(8.0).epsilon(1e-5));
  CHECK(double(b.half.x) == Approx(2.0).epsilon(1e-5));
  CHECK(double(b.half.z) == Approx(0.5).epsilon(1e-5));
}

TEMPLATE_TEST_CASE("OBB separating-axis test never misses an overlap and separates clear gaps", "[bv][obb]", float, double) {
  using T = TestType;
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> shift(-2.0, 2.0);
  int separated = 0, overlapping = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    const double scale = trial % 3 == 0 ? 1e5 : 1.0;
    auto pa = random_cloud<T>(rng, 8, 0.0, scale);
    auto pb = random_cloud<T>(rng, 8, 0.0, scale);
    const Vec3d d{shift(rng) * scale, shift(rng) * scale, shift(rng) * scale};
    for (auto& p : pb) p += d;
    if (trial % 4 == 0) pb[0] = pa[trial % 8];  // a shared point: they must overlap
    const Obb<T> a = Obb<T>::fit(pa.data(), 8), b = Obb<T>::fit(pb.data(), 8);
    const bool ours = Obb<T>::overlap(a, b);
    REQUIRE(ours == Obb<T>::overlap(b, a));
    if (trial % 4 == 0) REQUIRE(ours);
    const ld gap = reference_separation(a, b);
    if (gap <= 0) REQUIRE(ours);  // overlapping in exact arithmetic: never culled
    if (gap > 1e-3L * scale) REQUIRE_FALSE(ours);  // a clear gap: culled
    (ours ? overlapping : separated)++;
  }
  CHECK(separated > 300);
  CHECK(overlapping > 300);
  // Touching faces (gap exactly zero) overlap.
  std::vector<Vec3d> c1, c2;
  for (int k = 0; k < 8; ++k) {
    c1.push_back({(k & 1) ? 1.0 : 0.0, (k & 2) ? 1.0 : 0.0, (k & 4) ? 1.0 : 0.0});
    c2.push_back({(k & 1) ? 2.0 : 1.0, (k & 2) ? 1.0 : 0.0, (k & 4) ? 1.0 : 0.0});
  }
  CHECK(Obb<T>::overlap(Obb<T>::fit(c1.data(), 8), Obb<T>::fit(c2.data(), 8)));
}

TEMPLATE_TEST_CASE("OBB merge encloses both children", "[bv][obb]", float, double) {
  using T = TestType;
  std::mt19937_64 rng(13);
  for (int trial = 0; trial < 500; ++trial) {
    const double scale = trial % 2 ? 1.0 : 1e4;
    auto pa = random_cloud<T>(rng, 6, 0.0, scale);
    auto pb = random_cloud<T>(rng, 6, trial % 5 ? 3.0 * scale : 0.0, scale);
    const Obb<T> a = Obb<T>::fit(pa.data(), 6), b = Obb<T>::fit(pb.data(), 6);
    const Obb<T> m = bv_traits<Obb<T>>::merge(a, b);
    for (const auto& p : pa) REQUIRE(obb_contains_exactly(m, p));
    for (const auto& p : pb) REQUIRE(obb_contains_exactly(m, p));
    // The children's corners, computed in long double from the stored boxes.
    for (const Obb<T>* child : {&a, &b}) {
      for (int k = 0; k < 8; ++k) {
        ld corner[3];
        for (int c = 0; c < 3; ++c) {
          corner[c] = ld(child->center[c]);
          for (int i = 0; i < 3; ++i) corner[c] += ((k >> i) & 1 ? 1 : -1) * ld(child->half[i]) * ld(child->axis[i][c]);
        }
        for (int i = 0; i < 3; ++i) {
          ld s = 0;
          for (int c = 0; c < 3; ++c) s += ld(m.axis[i][c]) * (corner[c] - ld(m.center[c]));
          REQUIRE(std::fabs(s) <= ld(m.half[i]));
        }
      }
    }
    REQUIRE(bv_traits<Obb<T>>::overlap(m, a));
    REQUIRE(bv_traits<Obb<T>>::overlap(m, b));
  }
}

TEMPLATE_TEST_CASE("swept triangle BVs contain the triangle at every time of the step", "[bv][swept]", float, double) {
  using T = TestType;
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> u(-1, 1), unit(0, 1);
  for (int trial = 0; trial < 300; ++trial) {
    Vec3d p0[3], p1[3];
    const double scale = trial % 3 == 0 ? 1e4 : 1.0;
    for (int k = 0; k < 3; ++k) {
      p0[k] = Vec3d{u(rng), u(rng), u(rng)} * scale;
      p1[k] = p0[k] + Vec3d{u(rng), u(rng), u(rng)} * (0.3 * scale);
    }
    if (trial % 7 == 0) p0[2] = p0[1];  // zero-area triangle at t0
    const auto box = swept_triangle_bv<Aabb<T>>(p0[0], p0[1], p0[2], p1[0], p1[1], p1[2]);
    const auto obb = swept_triangle_bv<Obb<T>>(p0[0], p0[1], p0[2], p1[0], p1[1], p1[2]);
    for (int s = 0; s < 50; ++s) {
      const ld t = unit(rng), b1 = unit(rng), b2 = unit(rng) * (1 - b1);
      const ld w[3] = {1 - b1 - b2, b1, b2};
      Vec3<ld> q{0, 0, 0};
      for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 3; ++c) q[c] += w[k] * ((1 - t) * ld(p0[k][c]) + t * ld(p1[k][c]));
      // Sampled points are rounded to double; the exact containment is up to that rounding.
      const Vec3d qd{double(q.x), double(q.y), double(q.z)};
      for (int c = 0; c < 3; ++c) {
        REQUIRE(double(box.lo[c]) <= qd[c] + 1e-15 * scale);
        REQUIRE(qd[c] <= double(box.hi[c]) + 1e-15 * scale);
      }
      REQUIRE(obb.inflated(T(1e-14 * scale)).contains(qd));
    }
  }
}
