#include <catch2/catch.hpp>

#include <cstring>

#include "lwsccd/bvh/bvh.hpp"
#include "lwsccd/core/error.hpp"
#include "scene_fixtures.hpp"

using namespace lwsccd;
using lwsccd_test::MovingMesh;

namespace {

// Reference fit: each node's BV computed top-down by recursion (independent of the bottom-up
// arrival order).
template <class BV>
BV reference_fit(const BvhView<BV>& bvh, index_t node, const MovingMesh& m) {
  if (bvh.is_leaf(node)) {
    const Face& f = m.mesh.face(bvh.primitive(node));
    return swept_triangle_bv<BV>(m.x0[f.v[0]], m.x0[f.v[1]], m.x0[f.v[2]], m.x1[f.v[0]], m.x1[f.v[1]], m.x1[f.v[2]]);
  }
  return bv_traits<BV>::merge(reference_fit(bvh, bvh.left[node], m), reference_fit(bvh, bvh.right[node], m));
}

template <class BV>
bool same_bits(const BV& a, const BV& b) {
  return std::memcmp(&a, &b, sizeof(BV)) == 0;
}

template <class BV>
void check_matches_reference(const cpu::Bvh<BV>& bvh, const MovingMesh& m) {
  const auto view = bvh.view();
  // Recompute every node's reference value once, from the root, into a table.
  std::vector<BV> ref(static_cast<std::size_t>(view.num_nodes()));
  std::vector<index_t> stack{0};
  while (!stack.empty()) {
    const index_t node = stack.back();
    stack.pop_back();
    ref[node] = reference_fit(view, node, m);
    if (!view.is_leaf(node) && view.ranges[node].last - view.ranges[node].first < 64) continue;  // bounded cost
    if (!view.is_leaf(node)) {
      stack.push_back(view.left[node]);
      stack.push_back(view.right[node]);
    }
  }
  stack = {0};
  while (!stack.empty()) {
    const index_t node = stack.back();
    stack.pop_back();
    REQUIRE(same_bits(view.bvs[node], ref[node]));
    if (!view.is_leaf(node) && view.ranges[node].last - view.ranges[node].first >= 64) {
      stack.push_back(view.left[node]);
      stack.push_back(view.right[node]);
    }
  }
}

}  // namespace

TEMPLATE_TEST_CASE("CPU LBVH: invariants on random, folded and degenerate meshes", "[bvh]", Aabbf, Aabbd, Obbf, Obbd) {
  using BV = TestType;
  for (const MovingMesh& m : {lwsccd_test::folded_cloth(20, 1), lwsccd_test::random_soup(1000, 2),
                              lwsccd_test::coincident_triangles(37), lwsccd_test::random_soup(1, 3),
                              lwsccd_test::random_soup(2, 4), lwsccd_test::random_soup(3, 5)}) {
    const cpu::Bvh<BV> bvh(m.mesh, m.x0, m.x1);
    const auto view = bvh.view();
    INFO("faces " << m.mesh.num_faces());
    REQUIRE(view.num_leaves == m.mesh.num_faces());
    REQUIRE(view.num_nodes() == 2 * m.mesh.num_faces() - 1);
    REQUIRE(check_bvh_invariants(view, m.mesh.faces(), m.x0, m.x1) == "");
    REQUIRE(view.ranges[0].first == 0);
    REQUIRE(view.ranges[0].last == m.mesh.num_faces() - 1);
    // Leaves in non-decreasing Morton order.
    for (index_t k = 1; k < view.num_leaves; ++k) REQUIRE(bvh.nodes().leaf_codes[k - 1] <= bvh.nodes().leaf_codes[k]);
    check_matches_reference(bvh, m);
  }
}

TEST_CASE("CPU LBVH: a single triangle is a leaf root; equal codes keep triangle order", "[bvh]") {
  const MovingMesh one = lwsccd_test::random_soup(1, 9);
  const cpu::Bvh<Aabbf> single(one.mesh, one.x0, one.x1);
  CHECK(single.view().num_nodes() == 1);
  CHECK(single.view().is_leaf(0));
  CHECK(single.view().primitive(0) == 0);
  const MovingMesh same = lwsccd_test::coincident_triangles(16);
  const cpu::Bvh<Aabbd> bvh(same.mesh, same.x0, same.x1);
  for (index_t k = 0; k < 16; ++k) CHECK(bvh.view().leaf_primitive[k] == k);
  // With every code equal the split falls back to positions: a balanced tree of depth 4.
  CHECK(measure_quality(bvh.view()).max_depth == 4);
}

TEMPLATE_TEST_CASE("CPU LBVH: refit equals a fresh fit of the same topology", "[bvh]", Aabbf, Obbd) {
  using BV = TestType;
  const MovingMesh a = lwsccd_test::folded_cloth(16, 1);
  MovingMesh b = lwsccd_test::folded_cloth(16, 7);  // same topology, other positions
  cpu::Bvh<BV> bvh(a.mesh, a.x0, a.x1);
  const auto order_before = bvh.nodes().leaf_primitive;
  const auto generation = bvh.generation();
  bvh.refit(b.x0, b.x1);
  REQUIRE(bvh.generation() == generation);
  REQUIRE(bvh.nodes().leaf_primitive == order_before);  // the topology is kept
  REQUIRE(check_bvh_invariants(bvh.view(), b.mesh.faces(), b.x0, b.x1) == "");
  check_matches_reference(bvh, b);
}

TEST_CASE("CPU LBVH: quality metrics and the rebuild policy", "[bvh]") {
  const MovingMesh m = lwsccd_test::random_soup(2000, 3, 0.01);
  cpu::Bvh<Aabbf> bvh(m.mesh, m.x0, m.x1);
  const BvhQuality q = measure_quality(bvh.view());
  CHECK(q.max_depth >= 11);  // at least log2(2000)
  CHECK(q.max_depth < 64);
  CHECK(q.mean_leaf_depth >= 10.9);
  CHECK(q.sah_cost > 1.0);  // the root alone contributes 1
  CHECK(q.sah_cost == Approx(bvh.cost_at_build()));
  CHECK(q.volume_sum >= 1.0);
  CHECK(q.sibling_overlap >= 0.0);
  // Small motion: the tree stays good, refit only.
  MovingMesh moved = m;
  for (auto& p : moved.x0) p += Vec3d{1e-4, 0, 0};
  for (auto& p : moved.x1) p += Vec3d{1e-4, 0, 0};
  const auto generation = bvh.generation();
  CHECK_FALSE(bvh.refit_or_rebuild(moved.x0, moved.x1));
  CHECK(bvh.generation() == generation);
  // Scramble which triangle is where: the Morton order no longer groups neighbours.
  MovingMesh scrambled = m;
  std::mt19937 rng(5);
  std::vector<index_t> perm(m.mesh.num_faces());
  std::iota(perm.begin(), perm.end(), 0);
  std::shuffle(perm.begin(), perm.end(), rng);
  for (index_t f = 0; f < m.mesh.num_faces(); ++f)
    for (int k = 0; k < 3; ++k) {
      scrambled.x0[3 * f + k] = m.x0[3 * perm[f] + k];
      scrambled.x1[3 * f + k] = m.x1[3 * perm[f] + k];
    }
  bvh.refit(scrambled.x0, scrambled.x1);
  const double decayed = measure_quality(bvh.view()).sah_cost;
  CHECK(decayed > 3 * q.sah_cost);
  CHECK(bvh.refit_or_rebuild(scrambled.x0, scrambled.x1, RebuildPolicy{1.5}));
  CHECK(bvh.generation() == generation + 1);
  CHECK(measure_quality(bvh.view()).sah_cost < 1.5 * q.sah_cost);
  REQUIRE(check_bvh_invariants(bvh.view(), scrambled.mesh.faces(), scrambled.x0, scrambled.x1) == "");
}

TEST_CASE("CPU LBVH: bad input is rejected with a clear error", "[bvh]") {
  MovingMesh m = lwsccd_test::random_soup(10, 1);
  m.x1[7].y = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(cpu::Bvh<Aabbf>(m.mesh, m.x0, m.x1), Catch::Contains("x1 vertex 7") && Catch::Contains("NaN"));
  m.x1.pop_back();
  CHECK_THROWS_WITH(cpu::Bvh<Aabbf>(m.mesh, m.x0, m.x1), Catch::Contains("x1") && Catch::Contains("29 positions"));
  cpu::Bvh<Obbf> unbuilt;
  CHECK_THROWS_WITH(unbuilt.refit(m.x0, m.x0), Catch::Contains("not been built"));
  const MovingMesh ok = lwsccd_test::random_soup(10, 1);
  cpu::Bvh<Obbf> bvh(ok.mesh, ok.x0, ok.x1);
  auto bad = ok.x0;
  bad[0].z = std::numeric_limits<double>::infinity();
  CHECK_THROWS_WITH(bvh.refit(bad, ok.x1), Catch::Contains("x0 vertex 0"));
  CHECK_THROWS_AS(cpu::Bvh<Aabbf>(TriangleMesh(3, {}), ok.x0, ok.x1), InputError);  // empty mesh
}

TEST_CASE("the invariant checker detects corrupted trees", "[bvh]") {
  const MovingMesh m = lwsccd_test::folded_cloth(8, 2);
  const cpu::Bvh<Aabbd> bvh(m.mesh, m.x0, m.x1);
  {
    BvhNodes<Aabbd> t = bvh.nodes();
    t.bvs[t.left[0]].hi.x += 1.0;  // a child sticks out of the root
    CHECK_THAT(check_bvh_invariants(t.view(), m.mesh.faces(), m.x0, m.x1), Catch::Contains("does not enclose"));
  }
  {
    BvhNodes<Aabbd> t = bvh.nodes();
    t.parent[t.right[3]] = 5;
    CHECK_THAT(check_bvh_invariants(t.view(), m.mesh.faces(), m.x0, m.x1), Catch::Contains("parent link"));
  }
  {
    BvhNodes<Aabbd> t = bvh.nodes();
    std::swap(t.leaf_primitive[0], t.leaf_primitive[40]);  // leaves no longer bound their triangles
    CHECK_THAT(check_bvh_invariants(t.view(), m.mesh.faces(), m.x0, m.x1), Catch::Contains("does not enclose its motion"));
  }
  {
    BvhNodes<Aabbd> t = bvh.nodes();
    t.ranges[0].last -= 1;
    CHECK_THAT(check_bvh_invariants(t.view(), m.mesh.faces(), m.x0, m.x1), Catch::Contains("leaf range"));
  }
}
