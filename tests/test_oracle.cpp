#include <catch2/catch.hpp>

#include <cmath>
#include <random>
#include <set>

#include "lwsccd/features/oracle.hpp"
#include "scene_fixtures.hpp"

using namespace lwsccd;

using Soup = lwsccd_test::MovingMesh;
using lwsccd_test::folded_cloth;
using lwsccd_test::random_soup;

TEST_CASE("sweep and prune gives exactly the brute-force pair set", "[oracle]") {
  for (std::uint64_t seed = 1; seed <= 3; ++seed) {
    for (const Soup& s : {folded_cloth(12, seed), random_soup(400, seed)}) {
      const auto bvs = swept_triangle_bvs<Aabbd>(s.mesh, s.x0, s.x1);
      const auto brute = brute_force_pairs(s.mesh, bvs);
      const auto swept = sweep_and_prune_pairs(s.mesh, bvs);
      REQUIRE(brute.size() > 50);
      REQUIRE(brute == swept);
      // Float leaf boxes are rounded outward: a superset of the double pairs.
      const auto bvs_f = swept_triangle_bvs<Aabbf>(s.mesh, s.x0, s.x1);
      const auto brute_f = brute_force_pairs(s.mesh, bvs_f);
      REQUIRE(std::includes(brute_f.begin(), brute_f.end(), brute.begin(), brute.end()));
    }
  }
}

TEST_CASE("brute-force pairs: sorted, distinct, overlapping, adjacency flagged, complete", "[oracle]") {
  const Soup s = folded_cloth(10, 4);
  const auto bvs = swept_triangle_bvs<Obbd>(s.mesh, s.x0, s.x1);
  const auto pairs = brute_force_pairs(s.mesh, bvs);
  REQUIRE(std::is_sorted(pairs.begin(), pairs.end()));
  std::set<std::pair<index_t, index_t>> seen;
  int adjacent = 0;
  for (const auto& p : pairs) {
    REQUIRE(p.a < p.b);
    REQUIRE(seen.insert({p.a, p.b}).second);
    REQUIRE(Obbd::overlap(bvs[p.a], bvs[p.b]));
    REQUIRE(p.adjacent == s.mesh.faces_share_vertex(p.a, p.b));
    adjacent += p.adjacent;
  }
  // Completeness: every pair left out is separated.
  std::size_t overlapping = 0;
  for (index_t a = 0; a < s.mesh.num_faces(); ++a)
    for (index_t b = a + 1; b < s.mesh.num_faces(); ++b) overlapping += Obbd::overlap(bvs[a], bvs[b]);
  REQUIRE(overlapping == pairs.size());
  // Adjacent triangles always touch, so every adjacent pair of the mesh is present.
  std::size_t adjacent_in_mesh = 0;
  for (index_t a = 0; a < s.mesh.num_faces(); ++a)
    for (index_t b = a + 1; b < s.mesh.num_faces(); ++b) adjacent_in_mesh += s.mesh.faces_share_vertex(a, b);
  CHECK(static_cast<std::size_t>(adjacent) == adjacent_in_mesh);
  CHECK(pairs.size() > adjacent_in_mesh);  // the fold produces non-adjacent candidates too
}

TEST_CASE("body layout: self pairs only for self-colliding bodies, inter pairs always", "[oracle]") {
  Soup s = random_soup(300, 8);
  BodyLayout layout;
  for (index_t f = 0; f < s.mesh.num_faces(); ++f) layout.face_body.push_back(f % 3);
  layout.body_self_collides = {true, false, false};  // body 1 and 2: rigid, no self pairs
  const auto bvs = swept_triangle_bvs<Aabbd>(s.mesh, s.x0, s.x1);
  const auto all = brute_force_pairs(s.mesh, bvs);
  const auto filtered = brute_force_pairs(s.mesh, bvs, layout);
  REQUIRE(filtered == sweep_and_prune_pairs(s.mesh, bvs, layout));
  std::vector<TrianglePair> expected;
  for (const auto& p : all) {
    const int ba = p.a % 3, bb = p.b % 3;
    if (ba != bb || ba == 0) expected.push_back(p);
  }
  REQUIRE(filtered == expected);
  REQUIRE(filtered.size() < all.size());
  layout.face_body.pop_back();
  CHECK_THROWS_WITH(brute_force_pairs(s.mesh, bvs, layout), Catch::Contains("face_body"));
  layout.face_body.push_back(7);
  CHECK_THROWS_WITH(brute_force_pairs(s.mesh, bvs, layout), Catch::Contains("unknown body id 7"));
}

TEST_CASE("feature pairs: 6 VF + 9 EE per pair, incident features culled, de-duplicated", "[oracle]") {
  // Two triangles far apart topologically: all 15 pairs.
  const TriangleMesh two(6, {{{0, 1, 2}}, {{3, 4, 5}}});
  auto fp = feature_pairs(two, {{0, 1, false}});
  CHECK(fp.vf.size() == 6);
  CHECK(fp.ee.size() == 9);
  // Sharing an edge (0-2): vertex 1 vs face 1 and vertex 3 vs face 0 remain; EE pairs sharing
  // no endpoint: (0,1)x(2,3), (1,2)x(3,0)... computed by a reference below.
  const TriangleMesh quad(4, {{{0, 1, 2}}, {{0, 2, 3}}});
  fp = feature_pairs(quad, {{0, 1, true}});
  CHECK(fp.vf == std::vector<std::pair<index_t, index_t>>{{1, quad.face_feature_id(1)}, {3, quad.face_feature_id(0)}});
  std::set<std::pair<index_t, index_t>> ee_ref;
  for (index_t ea : quad.face_edges(0))
    for (index_t eb : quad.face_edges(1)) {
      const Edge x = quad.edge(ea), y = quad.edge(eb);
      std::set<index_t> ends = {x.v[0], x.v[1], y.v[0], y.v[1]};
      if (ends.size() == 4)
        ee_ref.insert({std::min(quad.edge_feature_id(ea), quad.edge_feature_id(eb)),
                       std::max(quad.edge_feature_id(ea), quad.edge_feature_id(eb))});
    }
  CHECK(fp.ee == std::vector<std::pair<index_t, index_t>>(ee_ref.begin(), ee_ref.end()));
  CHECK(fp.ee.size() == 2);  // (0,1)x(2,3) and (1,2)x(0,3)

  // Across many pairs: sorted, unique, equal to the union of per-pair sets.
  const Soup s = folded_cloth(8, 2);
  const auto pairs = brute_force_pairs(s.mesh, swept_triangle_bvs<Aabbd>(s.mesh, s.x0, s.x1));
  const auto all = feature_pairs(s.mesh, pairs);
  std::set<std::pair<index_t, index_t>> vf_union, ee_union;
  for (const auto& p : pairs) {
    const auto one = feature_pairs(s.mesh, {p});
    vf_union.insert(one.vf.begin(), one.vf.end());
    ee_union.insert(one.ee.begin(), one.ee.end());
  }
  REQUIRE(all.vf == std::vector<std::pair<index_t, index_t>>(vf_union.begin(), vf_union.end()));
  REQUIRE(all.ee == std::vector<std::pair<index_t, index_t>>(ee_union.begin(), ee_union.end()));
  const index_t nv = s.mesh.num_vertices(), ne = s.mesh.num_edges();
  for (const auto& p : all.vf) {
    REQUIRE(p.first < nv);
    REQUIRE(p.second >= nv + ne);
  }
  for (const auto& p : all.ee) {
    REQUIRE(p.first < p.second);
    REQUIRE(p.first >= nv);
    REQUIRE(p.second < nv + ne);
  }
}
