// Elemental CCD tests on constructed queries (no data needed).
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <random>

#include "lwsccd/features/orphans.hpp"
#include "lwsccd/narrow_phase/cubic_ccd.hpp"
#include "lwsccd/narrow_phase/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.hpp"
#include "lwsccd/simulation/scenes.hpp"
#include "scene_fixtures.hpp"

using namespace lwsccd;

namespace {

template <class T>
VertexFaceQuery<T> falling_vertex(T x, T y, T z0, T z1) {
  const Vec3<T> a{0, 0, 0}, b{1, 0, 0}, c{0, 1, 0};
  return {{x, y, z0}, a, b, c, {x, y, z1}, a, b, c};
}

template <class T>
EdgeEdgeQuery<T> crossing_edges(T z0, T z1, T offset = 0) {
  // Edge 1 along x at height z(t); edge 2 along y at z = 0, shifted by `offset` along x.
  return {{-1, 0, z0}, {1, 0, z0}, {offset, -1, 0}, {offset, 1, 0}, {-1, 0, z1}, {1, 0, z1}, {offset, -1, 0}, {offset, 1, 0}};
}

// f(t) = P . (A x B) sampled finely in long double: does the cubic change sign or vanish?
template <class Q>
bool coplanar_somewhere(const Q& q) {
  const auto c = detail::coplanarity_of(q.template cast<double>());
  long double prev = 0;
  for (int i = 0; i <= 2000; ++i) {
    const long double t = i / 2000.0L;
    auto lerp3 = [&](const Vec3d& a, const Vec3d& b, int k) { return a[k] + t * (static_cast<long double>(b[k]) - a[k]); };
    long double p[3], a[3], b[3];
    for (int k = 0; k < 3; ++k) {
      p[k] = lerp3(c.p0, c.p1, k);
      a[k] = lerp3(c.a0, c.a1, k);
      b[k] = lerp3(c.b0, c.b1, k);
    }
    const long double f = p[0] * (a[1] * b[2] - a[2] * b[1]) + p[1] * (a[2] * b[0] - a[0] * b[2]) + p[2] * (a[0] * b[1] - a[1] * b[0]);
    if (f == 0 || (i > 0 && (f < 0) != (prev < 0))) return true;
    prev = f;
  }
  return false;
}

struct TinyHeap {
  static constexpr int kMaxBoxes = 2;
  static constexpr int kBatch = 32;
};
struct SmallHeap {
  static constexpr int kMaxBoxes = 32;
  static constexpr int kBatch = 4;
};

}  // namespace

// How far below the true time the conservative TOI may be: the time tolerance, plus the rounding
// slack of the inclusion test (128 u per unit of coordinate, over a relative speed of ~2 here).
template <class T>
T toi_slack() {
  return T(2e-6) + T(128) * std::numeric_limits<T>::epsilon();
}

TEMPLATE_TEST_CASE("a vertex falling through a triangle: both methods, time of impact", "[narrow]", float, double) {
  using T = TestType;
  const CcdParams<T> params;
  const auto q = falling_vertex<T>(T(0.2), T(0.3), T(1), T(-1));  // crosses z = 0 at t = 0.5
  const auto cubic = CubicCcd::vertex_face(q, params);
  REQUIRE(cubic.hit);
  CHECK(double(cubic.toi) == Approx(0.5).margin(1e-5));
  const auto incl = InclusionCcd::vertex_face(q, params);
  REQUIRE(incl.hit);
  CHECK_FALSE(incl.gave_up);
  CHECK(incl.toi <= T(0.5));             // a lower bound ...
  CHECK(incl.toi >= T(0.5) - toi_slack<T>());   // ... within the time tolerance and rounding
  // Outside the triangle: no contact for either.
  CHECK_FALSE(CubicCcd::vertex_face(falling_vertex<T>(T(0.8), T(0.8), T(1), T(-1)), params).hit);
  CHECK_FALSE(InclusionCcd::vertex_face(falling_vertex<T>(T(0.8), T(0.8), T(1), T(-1)), params).hit);
  // Stops short of the plane.
  CHECK_FALSE(InclusionCcd::vertex_face(falling_vertex<T>(T(0.2), T(0.3), T(1), T(0.01)), params).hit);
  // Touching exactly at the end of the step.
  const auto touch = InclusionCcd::vertex_face(falling_vertex<T>(T(0.2), T(0.3), T(1), T(0)), params);
  CHECK(touch.hit);
  CHECK(touch.toi >= T(1) - toi_slack<T>());
}

TEMPLATE_TEST_CASE("crossing edges, edges that miss, and a minimum separation", "[narrow]", float, double) {
  using T = TestType;
  CcdParams<T> params;
  const auto cross = crossing_edges<T>(T(1), T(-3));  // crosses at t = 0.25
  REQUIRE(CubicCcd::edge_edge(cross, params).hit);
  CHECK(double(CubicCcd::edge_edge(cross, params).toi) == Approx(0.25).margin(1e-5));
  const auto r = InclusionCcd::edge_edge(cross, params);
  REQUIRE(r.hit);
  CHECK(r.toi <= T(0.25));
  CHECK(r.toi >= T(0.25) - toi_slack<T>());
  const auto miss = crossing_edges<T>(T(1), T(-3), T(1.5));  // edge 2 beyond edge 1's end
  CHECK_FALSE(CubicCcd::edge_edge(miss, params).hit);
  CHECK_FALSE(InclusionCcd::edge_edge(miss, params).hit);
  // Passing 0.01 above: no contact; with a separation of 0.02 it is reported, not with 0.005.
  const auto above = crossing_edges<T>(T(1), T(0.01));
  CHECK_FALSE(InclusionCcd::edge_edge(above, params).hit);
  params.min_separation = T(0.02);
  const auto near = InclusionCcd::edge_edge(above, params);
  CHECK(near.hit);
  CHECK(near.toi <= T(0.991));  // reaches 0.02 at t = 0.98/0.99
  params.min_separation = T(0.005);
  CHECK_FALSE(InclusionCcd::edge_edge(above, params).hit);
}

TEMPLATE_TEST_CASE("motion that stays coplanar: the cubic misses, the conservative method does not", "[narrow]", float, double) {
  using T = TestType;
  const CcdParams<T> params;
  // A vertex sliding in the triangle's plane from outside into it: f(t) == 0 throughout.
  const Vec3<T> a{0, 0, 0}, b{1, 0, 0}, c{0, 1, 0};
  const VertexFaceQuery<T> slide{{T(-1), T(0.2), 0}, a, b, c, {T(0.5), T(0.2), 0}, a, b, c};
  const auto incl = InclusionCcd::vertex_face(slide, params);
  REQUIRE(incl.hit);
  CHECK(incl.toi <= T(2) / T(3));  // enters the triangle at t = 2/3
  CHECK(incl.toi >= T(2) / T(3) - toi_slack<T>());
  // Parallel edges sliding onto each other in one plane.
  const EdgeEdgeQuery<T> parallel{{-3, 0, 0}, {-2, 0, 0}, {0, 0, 0}, {1, 0, 0}, {-0.5, 0, 0}, {0.5, 0, 0}, {0, 0, 0}, {1, 0, 0}};
  CHECK(InclusionCcd::edge_edge(parallel, params).hit);
  // f == 0 throughout: the seed's method sees "roots" only at the ends of the step, so it reports
  // the contact at t = 1 (too late) or not at all, never at its real time.
  const auto cubic = CubicCcd::vertex_face(slide, params);
  CHECK((!cubic.hit || cubic.toi > T(0.9)));
}

TEMPLATE_TEST_CASE("the non-penetration filter never culls a pair whose features become coplanar", "[narrow][filter]", float, double) {
  using T = TestType;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  const CcdParams<T> params;
  int culled = 0, kept = 0;
  for (int trial = 0; trial < 4000; ++trial) {
    std::array<Vec3d, 8> pts;
    for (auto& p : pts) p = {u(rng), u(rng), u(rng)};
    if (trial % 2) {  // small motions: most stay on one side
      for (int i = 4; i < 8; ++i) pts[i] = pts[i - 4] + Vec3d{u(rng), u(rng), u(rng)} * 0.05;
    }
    const auto vf = vertex_face_query<T>(pts);
    const auto ee = edge_edge_query<T>(pts);
    for (bool is_vf : {true, false}) {
      const bool may = is_vf ? non_penetration_filter(vf, params) : non_penetration_filter(ee, params);
      const bool coplanar = is_vf ? coplanar_somewhere(vf) : coplanar_somewhere(ee);
      if (coplanar) REQUIRE(may);
      (may ? kept : culled)++;
    }
  }
  CHECK(culled > 1000);  // it does cull
  CHECK(kept > 1000);
  // With a minimum separation the filter does not apply.
  CcdParams<T> with_gap;
  with_gap.min_separation = T(0.1);
  CHECK(non_penetration_filter(falling_vertex<T>(T(0.2), T(0.2), T(1), T(0.5)), with_gap));
  CHECK_FALSE(non_penetration_filter(falling_vertex<T>(T(0.2), T(0.2), T(1), T(0.5)), params));
}

TEMPLATE_TEST_CASE("bounded work: a tiny budget answers hit, never a miss", "[narrow]", float, double) {
  using T = TestType;
  CcdParams<T> params;
  params.max_iterations = 3;
  const auto r = InclusionCcd::vertex_face(falling_vertex<T>(T(0.2), T(0.3), T(1), T(-1)), params);
  CHECK(r.hit);
  CHECK(r.gave_up);
  CHECK(r.toi <= T(0.5));
  // A heap of 2 boxes cannot make progress: the answer is "hit" at the time reached, never a miss.
  params.max_iterations = 1 << 20;
  const auto tiny = InclusionCcdT<TinyHeap>::edge_edge(crossing_edges<T>(T(1), T(-3)), params);
  CHECK(tiny.hit);
  CHECK(tiny.toi <= T(0.25));
}

TEMPLATE_TEST_CASE("a full box heap costs time, not a wrong answer", "[narrow]", float, double) {
  using T = TestType;
  CcdParams<T> params;
  params.max_iterations = 1 << 20;
  // A store of 32 boxes overflows soon; the search drops the latest boxes and searches again
  // from where the excluded part reaches: the same answers as with room to spare.
  const auto edges = InclusionCcdT<SmallHeap>::edge_edge(crossing_edges<T>(T(1), T(-3)), params);  // touch at t = 0.25
  REQUIRE(edges.hit);
  CHECK_FALSE(edges.gave_up);
  CHECK(edges.toi <= T(0.25));
  CHECK(edges.toi >= T(0.25) - toi_slack<T>());
  const auto vertex = InclusionCcdT<SmallHeap>::vertex_face(falling_vertex<T>(T(0.2), T(0.3), T(1), T(-1)), params);
  REQUIRE(vertex.hit);
  CHECK_FALSE(vertex.gave_up);
  CHECK(vertex.toi <= T(0.5));
  CHECK(vertex.toi >= T(0.5) - toi_slack<T>());
  CHECK_FALSE(InclusionCcdT<SmallHeap>::vertex_face(falling_vertex<T>(T(0.8), T(0.8), T(1), T(-1)), params).hit);
  CHECK_FALSE(InclusionCcdT<SmallHeap>::edge_edge(crossing_edges<T>(T(1), T(-3), T(1.5)), params).hit);
}

namespace {
// box_before as written before it became two words: the fields compared one by one.
bool box_before_by_fields(const detail::DyadicBox& a, const detail::DyadicBox& b) {
  const std::uint64_t ka = detail::box_time_key(a), kb = detail::box_time_key(b);
  if (ka != kb) return ka < kb;
  const int la = a.level[0] + a.level[1] + a.level[2], lb = b.level[0] + b.level[1] + b.level[2];
  if (la != lb) return la > lb;
  for (int k = 0; k < 3; ++k)
    if (a.level[k] != b.level[k]) return a.level[k] < b.level[k];
  for (int k = 0; k < 3; ++k)
    if (a.idx[k] != b.idx[k]) return a.idx[k] < b.idx[k];
  return false;
}
}  // namespace

TEST_CASE("the search's box order as two words is the field-by-field order", "[narrow]") {
  std::mt19937 rng(16);
  // Shallow boxes collide in every field (equal times, level sums, levels); deep ones reach the
  // 31 levels and 2^31 - 1 indices the words must hold.
  auto random_box = [&](int max_level) {
    detail::DyadicBox b{};
    for (int k = 0; k < 3; ++k) {
      b.level[k] = static_cast<std::uint8_t>(std::uniform_int_distribution<int>(0, max_level)(rng));
      const std::uint32_t cells = std::uint32_t(1) << b.level[k];
      b.idx[k] = std::uniform_int_distribution<std::uint32_t>(0, cells - 1)(rng);
      if (std::uniform_int_distribution<int>(0, 7)(rng) == 0) b.idx[k] = cells - 1;  // the last cell
    }
    return b;
  };
  int ties = 0, checked = 0;
  for (int max_level : {2, 3, 31}) {
    for (int i = 0; i < 200000; ++i) {
      const detail::DyadicBox a = random_box(max_level), b = random_box(max_level);
      ties += detail::box_time_key(a) == detail::box_time_key(b);
      ++checked;
      if (detail::box_before(a, b) != box_before_by_fields(a, b) || detail::box_before(b, a) != box_before_by_fields(b, a)) {
        FAIL_CHECK("boxes (" << a.idx[0] << "," << a.idx[1] << "," << a.idx[2] << " @ " << int(a.level[0]) << "," << int(a.level[1])
                             << "," << int(a.level[2]) << ") and (" << b.idx[0] << "," << b.idx[1] << "," << b.idx[2] << " @ "
                             << int(b.level[0]) << "," << int(b.level[1]) << "," << int(b.level[2]) << ") ordered differently");
        return;
      }
    }
  }
  CHECK(checked == 600000);
  CHECK(ties > 10000);  // the tie-breaks were exercised, not only the time keys
}

TEST_CASE("a box's order key holds the whole box, its mark ordering it only against itself", "[narrow]") {
  std::mt19937 rng(17);
  int checked = 0;
  for (int i = 0; i < 100000; ++i) {
    detail::DyadicBox b{};
    for (int k = 0; k < 3; ++k) {
      b.level[k] = static_cast<std::uint8_t>(std::uniform_int_distribution<int>(0, detail::kMaxBoxLevel)(rng));
      const std::uint32_t cells = std::uint32_t(1) << b.level[k];
      b.idx[k] = std::uniform_int_distribution<std::uint32_t>(0, cells - 1)(rng);
      if (i % 5 == 0) b.idx[k] = cells - 1;  // every index bit set
    }
    b.accepted = static_cast<std::uint8_t>(i % 2);
    const detail::DyadicBox back = detail::box_of_key(detail::box_order_key(b));
    REQUIRE(back.idx[0] == b.idx[0]);
    REQUIRE(back.idx[1] == b.idx[1]);
    REQUIRE(back.idx[2] == b.idx[2]);
    REQUIRE(back.level[0] == b.level[0]);
    REQUIRE(back.level[1] == b.level[1]);
    REQUIRE(back.level[2] == b.level[2]);
    REQUIRE(back.accepted == b.accepted);
    REQUIRE(detail::box_time_key(detail::box_order_key(b)) == detail::box_time_key(b));
    REQUIRE(detail::is_accepted(detail::box_order_key(b)) == (b.accepted != 0));
    // Marked or not, the box keeps its place against every other box.
    detail::DyadicBox marked = b, other = b;
    marked.accepted = 1;
    other.idx[2] ^= 1u;
    other.level[2] = other.level[2] == 0 ? 1 : other.level[2];
    CHECK(detail::box_before(marked, other) == detail::box_before(b, other));
    CHECK(detail::box_before(other, marked) == detail::box_before(other, b));
    ++checked;
  }
  CHECK(checked == 100000);
  detail::DyadicBox root{};
  detail::whole_domain(root);
  detail::BoxOrderKey root_key{};
  detail::whole_domain(root_key);
  CHECK(detail::box_of_key(root_key).level[2] == root.level[2]);
  CHECK(detail::box_time_key(root_key) == 0);
}

TEST_CASE("a vertex near a sliver triangle that moves away: no contact (it overflowed the heap)", "[narrow]") {
  // cloth-ball 92->93, vertex 11423 and face 246191, in the query's local frame: the vertex is
  // 0.0029 from a nearly collinear triangle at t = 0 and 0.019 at t = 1. The search needs ~2,000
  // boxes and more than 256 live at once; answering "hit" when the heap filled made this the
  // scene's earliest contact, at t = 0.
  const VertexFaceQuery<double> q{{0, 0, 0},
                                  {0.056929945945739746, 0.13329124450683594, 0.062498092651367188},
                                  {-0.063248038291931152, -0.14238786697387695, -0.076035022735595703},
                                  {-0.0097349882125854492, -0.016850948333740234, -0.010957241058349609},
                                  {0.38241994380950928, 0.050976276397705078, -0.055601119995117188},
                                  {0.44626402854919434, 0.17645025253295898, 0.024160861968994141},
                                  {0.32294201850891113, -0.10964393615722656, -0.11288833618164062},
                                  {0.40604197978973389, 0.0056691169738769531, -0.055171966552734375}};
  const CcdParams<double> params;
  const auto r = InclusionCcd::vertex_face(q, params);
  CHECK_FALSE(r.hit);
  CHECK_FALSE(r.gave_up);
  CHECK_FALSE(Filtered<InclusionCcd>::vertex_face(q, params).hit);
  CHECK_FALSE(InclusionCcd::vertex_face(q.cast<float>(), CcdParams<float>{}).hit);
}

TEST_CASE("nearly parallel edges a few micrometres apart are decided in a few hundred boxes", "[narrow]") {
  // cloth-funnel 227->228, in the query's local frame: two edges 6e-3 long, parallel to 1e-4
  // rad, 8e-6 apart at t = 0, whose offset turns through the line of the edges near t = 0.41
  // (crossing: a contact in the ground truth) or passes it 1e-7 away (no contact). Only along
  // the direction of the offset is F far from 0 over a wide (u, v) box: the axis test alone
  // needed > 16,384 boxes and gave up, at t = 0.25; along the separating directions (and with
  // the splits they steer into time) each takes a few hundred.
  const EdgeEdgeQuery<double> crossing{{0, 0, 0},
                                       {0.0035238005220890045, 0.0046004019677639008, -0.0011450052261352539},
                                       {-2.600252628326416e-06, 0, -9.0003013610839844e-06},
                                       {0.0035209022462368011, 0.0046004019677639008, -0.0011540055274963379},
                                       {7.9501420259475708e-05, -7.8696757555007935e-05, -0.0030869841575622559},
                                       {0.0036102011799812317, 0.0045313015580177307, -0.0042350292205810547},
                                       {8.3200633525848389e-05, -7.8696757555007935e-05, -0.0030750036239624023},
                                       {0.0036143027245998383, 0.0045313015580177307, -0.0042219758033752441}};
  const EdgeEdgeQuery<double> passing{{0, 0, 0},
                                      {0.0039592981338500977, 0.004185900092124939, -0.0012859702110290527},
                                      {-2.3990869522094727e-06, 0, -7.9870223999023438e-06},
                                      {0.0039566978812217712, 0.004185900092124939, -0.0012949705123901367},
                                      {7.1499496698379517e-05, -8.7298452854156494e-05, -0.0030829906463623047},
                                      {0.0040387995541095734, 0.004107203334569931, -0.0043729543685913086},
                                      {7.4900686740875244e-05, -8.7298452854156494e-05, -0.0030729770660400391},
                                      {0.004042498767375946, 0.004107203334569931, -0.0043609738349914551}};
  CcdParams<double> params;
  params.max_iterations = 2000;
  const auto crossed = InclusionCcd::edge_edge(crossing, params);
  CHECK(crossed.hit);
  CHECK_FALSE(crossed.gave_up);
  CHECK(crossed.toi > 0.4);  // the offset is >= 2e-6 from the edges' line before t = 0.35
  CHECK(crossed.toi < 0.42);
  const auto passed = InclusionCcd::edge_edge(passing, params);
  CHECK_FALSE(passed.gave_up);
  CHECK_FALSE(passed.hit);
  // Time reversed: the same verdicts (the search runs forward in time, so the boxes differ).
  auto reversed = [](EdgeEdgeQuery<double> q) {
    std::swap(q.a0, q.a1), std::swap(q.b0, q.b1), std::swap(q.c0, q.c1), std::swap(q.d0, q.d1);
    return q;
  };
  const auto crossed_back = InclusionCcd::edge_edge(reversed(crossing), params);
  CHECK(crossed_back.hit);
  CHECK_FALSE(crossed_back.gave_up);
  CHECK(crossed_back.toi > 0.58);
  CHECK_FALSE(InclusionCcd::edge_edge(reversed(passing), params).gave_up);
}

TEST_CASE("CPU narrow phase over a cloth's feature pairs: filtered equals unfiltered", "[narrow]") {
  const auto m = lwsccd_test::folded_cloth(16, 3);
  const auto pairs = brute_force_pairs(m.mesh, swept_triangle_bvs<Aabbd>(m.mesh, m.x0, m.x1));
  const FeaturePairs fp = feature_pairs(m.mesh, pairs);
  const auto plain = cpu::test_feature_pairs<InclusionCcd, double>(m.mesh, m.x0, m.x1, fp);
  const auto filtered = cpu::test_feature_pairs<Filtered<InclusionCcd>, double>(m.mesh, m.x0, m.x1, fp);
  REQUIRE(plain.vf.size() + plain.ee.size() > 0);
  // The filter removes only pairs that cannot touch, so the hits are the same pairs.
  REQUIRE(plain.vf.size() == filtered.vf.size());
  REQUIRE(plain.ee.size() == filtered.ee.size());
  for (std::size_t i = 0; i < plain.vf.size(); ++i) REQUIRE(plain.vf[i].first == filtered.vf[i].first);
  CHECK(plain.earliest_toi == filtered.earliest_toi);
  // Cubic hits are (up to its misses) among the conservative ones.
  const auto cubic = cpu::test_feature_pairs<CubicCcd, double>(m.mesh, m.x0, m.x1, fp);
  std::size_t cubic_not_in_inclusion = 0;
  for (const auto& h : cubic.vf)
    cubic_not_in_inclusion += !std::binary_search(plain.vf.begin(), plain.vf.end(), h);
  CHECK(cubic_not_in_inclusion == 0);
}

TEST_CASE("culling adjacent triangles with orphan sets loses no contact (open cloth, closed ball)", "[narrow][orphans]") {
  // Brute-force feature testing (every feature pair of every candidate triangle pair, adjacent
  // ones included) against the culled stream (non-adjacent pairs + orphans): same contacts.
  const auto cloth = lwsccd_test::folded_cloth(20, 5);
  const MultiBodyStep ball_scene = make_cloth_ball_scene(1500);
  struct Case {
    const TriangleMesh* mesh;
    const std::vector<Vec3d>* x0;
    const std::vector<Vec3d>* x1;
  };
  for (const Case& c : {Case{&cloth.mesh, &cloth.x0, &cloth.x1},
                        Case{ball_scene.step.mesh.get(), &ball_scene.step.x0, &ball_scene.step.x1}}) {
    const auto pairs = brute_force_pairs(*c.mesh, swept_triangle_bvs<Aabbd>(*c.mesh, *c.x0, *c.x1));
    const FeaturePairs all = feature_pairs(*c.mesh, pairs);
    const FeaturePairs culled = culled_feature_pairs(*c.mesh, pairs, find_orphan_sets(*c.mesh));
    const auto everything = cpu::test_feature_pairs<InclusionCcd, double>(*c.mesh, *c.x0, *c.x1, all);
    const auto kept = cpu::test_feature_pairs<InclusionCcd, double>(*c.mesh, *c.x0, *c.x1, culled);
    std::printf("culling: %zu -> %zu feature pairs; contacts %zu + %zu (all) vs %zu + %zu (culled)\n",
                all.vf.size() + all.ee.size(), culled.vf.size() + culled.ee.size(), everything.vf.size(),
                everything.ee.size(), kept.vf.size(), kept.ee.size());
    CHECK(culled.vf.size() + culled.ee.size() < all.vf.size() + all.ee.size());
    // Every contact found by testing everything is found in the culled stream.
    for (const auto& h : everything.vf) REQUIRE(std::binary_search(kept.vf.begin(), kept.vf.end(), h));
    for (const auto& h : everything.ee) REQUIRE(std::binary_search(kept.ee.begin(), kept.ee.end(), h));
    REQUIRE(everything.vf.size() + everything.ee.size() > 0);
  }
}

namespace {

// Two separate triangles: a static one in z = 0 and one whose vertex 3 moves from z = z0 to z1
// (the rest of it far above): a single vertex-face pair (vertex 3, face 0).
lwsccd_test::MovingMesh vertex_over_triangle(double z0, double z1) {
  std::vector<Vec3d> x0 = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.2, 0.2, z0}, {3, 3, 5}, {4, 3, 5}};
  std::vector<Vec3d> x1 = x0;
  x1[3].z = z1;
  return {TriangleMesh(6, {{{0, 1, 2}}, {{3, 4, 5}}}), x0, x1};
}

}  // namespace

TEST_CASE("mode earliest: growing time windows give the earliest TOI of mode contacts", "[narrow][certified]") {
  auto compare = [](const lwsccd_test::MovingMesh& m, const FeaturePairs& fp) {
    CcdParams<double> contacts_params, earliest_params;
    earliest_params.mode = CcdMode::earliest;
    const auto all = cpu::test_feature_pairs<CertifiedCcd, double>(m.mesh, m.x0, m.x1, fp, contacts_params);
    const auto earliest = cpu::test_feature_pairs<CertifiedCcd, double>(m.mesh, m.x0, m.x1, fp, earliest_params);
    INFO("contacts " << all.earliest_toi << ", earliest " << earliest.earliest_toi);
    CHECK(earliest.vf.empty());
    CHECK(earliest.ee.empty());
    // Certified hits of the first window are the very same intervals; a fallback answer may be
    // cut at another time, but stays a lower bound within the tolerance.
    if (all.vf_counts.fallbacks + all.ee_counts.fallbacks == 0) CHECK(earliest.earliest_toi == all.earliest_toi);
    CHECK(earliest.earliest_toi <= all.earliest_toi);
    CHECK(earliest.earliest_toi >= all.earliest_toi - contacts_params.tolerance);
    return earliest;
  };
  SECTION("a folded cloth: contacts early in the step") {
    const auto m = lwsccd_test::folded_cloth(16, 3);
    const FeaturePairs fp = feature_pairs(m.mesh, brute_force_pairs(m.mesh, swept_triangle_bvs<Aabbd>(m.mesh, m.x0, m.x1)));
    const auto r = compare(m, fp);
    CHECK(r.earliest_toi < 1);
  }
  // 6 vertices and 6 edges: face 0's feature id is 12.
  SECTION("one contact at t = 0.5: past the first two windows (2^-16, 2^-8)") {
    const auto m = vertex_over_triangle(1.0, -1.0);
    REQUIRE(m.mesh.num_edges() == 6);
    const FeaturePairs fp{{{3, 12}}, {}};
    const auto r = compare(m, fp);
    CHECK(r.earliest_toi > 0.5 - 1e-6);
    CHECK(r.earliest_toi <= 0.5);
    CHECK(r.vf_counts.certified_hits == 1);  // the last window's counts
  }
  SECTION("one contact at t = 2^-10: in the second window") {
    const auto m = vertex_over_triangle(1.0 / 1024, 1.0 / 1024 - 1.0);
    const FeaturePairs fp{{{3, 12}}, {}};
    const auto r = compare(m, fp);
    CHECK(r.earliest_toi > std::ldexp(1.0, -10) - 1e-6);
  }
  SECTION("no contact: every window, then 1") {
    const auto m = vertex_over_triangle(1.0, 0.5);
    const FeaturePairs fp{{{3, 12}}, {}};
    const auto r = compare(m, fp);
    CHECK(r.earliest_toi == 1);
    CHECK(r.vf_counts.certified_misses == 1);
  }
}

TEMPLATE_TEST_CASE("certified filter, both rounds: a folded cloth's pairs it decides get the whole search's answer", "[narrow][certified]",
                   float, double) {
  // The GPU's filter (CertifiedFilter::decides: intervals at level kInsideFrom, then those left
  // unknown split to the next inside-test level) on every screened pair of a folded cloth, whole
  // step and a time limit: a decided pair is a miss of certified_refine, or undecided from the
  // same noted time; and the second round must decide pairs the first leaves to the search.
  using T = TestType;
  using Filter = detail::CertifiedFilter<CertifiedPolicy>;
  const auto m = lwsccd_test::folded_cloth(24, 4);
  const FeaturePairs fp = feature_pairs(m.mesh, brute_force_pairs(m.mesh, swept_triangle_bvs<Aabbd>(m.mesh, m.x0, m.x1)));
  const MeshFeatures features = mesh_features(m.mesh);
  for (const T limit : {T(1), T(0.3)}) {
    CcdParams<T> params;
    params.time_limit = limit;
    std::size_t screened = 0, first = 0, second = 0, wrong = 0;
    auto check = [&](const auto& q) {
      if (CertifiedCcd::screen(q, params)) return;
      ++screened;
      detail::Noted<T> noted;
      const bool by_first = Filter::decides(q, params, noted, false);
      if (!by_first && !Filter::decides(q, params, noted)) return;
      (by_first ? first : second) += 1;
      const CertifiedAnswer<T> a = CertifiedCcd::refine(q, params);
      if (noted.any) {
        const CertifiedAnswer<T> settled = CertifiedCcd::undecided_from(q, params, noted.lower);
        wrong += a.certainty != settled.certainty || a.lo != noted.lower || a.hi != settled.hi;
      }
      else wrong += a.certainty != Certainty::miss;
    };
    for (const auto& p : fp.vf) check(gather_vertex_face<T>(features, m.x0.data(), m.x1.data(), p.first, p.second));
    for (const auto& p : fp.ee) check(gather_edge_edge<T>(features, m.x0.data(), m.x1.data(), p.first, p.second));
    std::printf("  filter rounds (%s, time limit %.1f): %zu screened pairs, %zu decided by the first round, %zu by the second, %zu wrong\n",
                sizeof(T) == 4 ? "float" : "double", double(limit), screened, first, second, wrong);
    CHECK(wrong == 0);
    CHECK(second > 0);
  }
}

namespace {
// The double path alone (no single-precision passes in front of it).
struct DoubleOnlyPolicy : CertifiedPolicy {
  static constexpr bool kSingleFirst = false;
};
}  // namespace

TEST_CASE("FP32 first in a batch: the single-precision passes read the vertices rounded to float, and never contradict double",
          "[narrow][certified][single]") {
  // The batch's first pass decides in float on SingleVertex records (each coordinate rounded to
  // float, no double subtraction of an origin: gather_single_vertex_face), as the GPU batch does.
  // Its count of single-precision misses must be exactly the pairs that the float screen, the float
  // filter or the search in float decide on those queries, none of them a hit of the double path
  // on the double query;
  // also with the cloth moved far from the origin (2^8 and 2^14 on every axis: float's rounding of
  // the absolute coordinates grows to 2^-17 and 2^-11, so the screen and filter decide fewer pairs).
  const auto base = lwsccd_test::folded_cloth(24, 4);
  const FeaturePairs fp = feature_pairs(base.mesh, brute_force_pairs(base.mesh, swept_triangle_bvs<Aabbd>(base.mesh, base.x0, base.x1)));
  const MeshFeatures features = mesh_features(base.mesh);
  using DoubleOnly = CertifiedCcdT<Filtered<InclusionCcd>, DoubleOnlyPolicy>;
  std::size_t first_near_origin = 0;
  for (const double offset : {0.0, 256.0, 16384.0}) {
    std::vector<Vec3d> x0 = base.x0, x1 = base.x1;
    for (auto* x : {&x0, &x1})
      for (auto& p : *x) p = p + Vec3d{offset, offset, offset};
    const std::vector<SingleVertex> single = single_vertices(x0, x1);
    const CcdParams<double> params;
    std::size_t decided = 0, decided_first = 0, contradicted = 0, double_hits = 0;
    auto check = [&](const auto& s, const auto& q) {
      bool miss = CertifiedCcd::screen_verdict(s, params) != detail::ScreenVerdict::passed || CertifiedCcd::filter_single(s, params);
      decided_first += miss;
      if (!miss) {  // the search in single precision on what those leave (a double tail only for contacts)
        bool done = false;
        miss = CertifiedCcd::refine_single_first(q, params, done).certainty == Certainty::miss && done;
      }
      const bool hit = DoubleOnly::classify(q, params).certainty == Certainty::hit;
      decided += miss;
      double_hits += hit;
      contradicted += miss && hit;
    };
    for (const auto& p : fp.vf)
      check(gather_single_vertex_face(features, single.data(), p.first, p.second),
            gather_vertex_face<double>(features, x0.data(), x1.data(), p.first, p.second));
    for (const auto& p : fp.ee)
      check(gather_single_edge_edge(features, single.data(), p.first, p.second),
            gather_edge_edge<double>(features, x0.data(), x1.data(), p.first, p.second));
    const auto batch = cpu::test_feature_pairs<CertifiedCcd, double>(base.mesh, x0, x1, fp, params);
    std::printf("  folded cloth %+g: %zu feature pairs, %zu decided in single precision (%zu by the screen and filter), %zu "
                "certain hits in double\n", offset, fp.vf.size() + fp.ee.size(), decided, decided_first, double_hits);
    CHECK(batch.vf_counts.single_misses + batch.ee_counts.single_misses == decided);
    CHECK(contradicted == 0);
    CHECK(double_hits > 0);
    // The screen and filter read absolute coordinates rounded to float (B9), so they decide fewer
    // pairs far from the origin; the search in float reads them relative in double (B12).
    if (offset == 0.0) first_near_origin = decided_first;
    else CHECK(decided_first < first_near_origin);
  }
}
