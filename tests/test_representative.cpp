// Representative triangles and feature-box culling against the brute-force feature-pair oracle.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iterator>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "lwsccd/features/representative.hpp"
#include "lwsccd/narrow_phase/inclusion_ccd.hpp"
#include "lwsccd/narrow_phase/narrow_phase.hpp"
#include "lwsccd/simulation/scenes.hpp"
#include "scene_fixtures.hpp"

using namespace lwsccd;

namespace {

std::vector<TrianglePair> non_adjacent(const std::vector<TrianglePair>& pairs) {
  std::vector<TrianglePair> out;
  std::copy_if(pairs.begin(), pairs.end(), std::back_inserter(out), [](const TrianglePair& p) { return !p.adjacent; });
  return out;
}

FeaturePairs sorted(FeaturePairs p) {
  std::sort(p.vf.begin(), p.vf.end());
  std::sort(p.ee.begin(), p.ee.end());
  return p;
}

bool has_repeats(const std::vector<std::pair<index_t, index_t>>& sorted_pairs) {
  return std::adjacent_find(sorted_pairs.begin(), sorted_pairs.end()) != sorted_pairs.end();
}

// The pairs of `all` (sorted) that are not in `kept` (sorted).
std::vector<std::pair<index_t, index_t>> left_out(const std::vector<std::pair<index_t, index_t>>& all,
                                                  const std::vector<std::pair<index_t, index_t>>& kept) {
  std::vector<std::pair<index_t, index_t>> out;
  std::set_difference(all.begin(), all.end(), kept.begin(), kept.end(), std::back_inserter(out));
  return out;
}

// The emission over the brute-force AABB candidates equals the brute-force feature oracle, with
// no pair produced twice; the sweep oracle equals the brute-force one. The same with the faces'
// corners (the test of their relative motion), whose lists are a subset in which no pair left out
// touches (certified misses, and none within the inclusion method's tolerance either). Returns
// how many pairs the corners left out.
std::size_t require_emission_equals_oracle(const TriangleMesh& mesh, const std::vector<Vec3d>& x0, const std::vector<Vec3d>& x1,
                                           const BodyLayout& layout = {}, double margin = 0) {
  const RepresentativeTriangles rep(mesh, layout);
  const std::vector<Aabbf> boxes = feature_boxes(mesh, x0, x1, margin);
  const std::vector<FaceCorners> corners = face_corners(mesh, x0, x1);
  std::vector<Aabbf> bvs = swept_triangle_bvs<Aabbf>(mesh, x0, x1);
  if (margin > 0)
    for (auto& b : bvs) b = b.inflated(lwsccd::detail::round_up<float>(margin));
  const auto candidates = non_adjacent(brute_force_pairs(mesh, bvs, layout));
  FeaturePairs oracle;
  std::size_t left = 0;
  for (const std::vector<FaceCorners>* with : {static_cast<const std::vector<FaceCorners>*>(nullptr), &corners}) {
    const FeaturePairs emitted = sorted(emit_feature_pairs(rep, candidates, boxes, with));
    const FeaturePairs expected = brute_force_feature_pairs(rep, boxes, with);
    INFO(mesh.num_faces() << " faces, " << candidates.size() << " candidates, oracle " << expected.vf.size() << " VF + "
                          << expected.ee.size() << " EE" << (with ? ", with the faces' motion" : ""));
    REQUIRE_FALSE(has_repeats(emitted.vf));
    REQUIRE_FALSE(has_repeats(emitted.ee));
    REQUIRE(emitted.vf == expected.vf);
    REQUIRE(emitted.ee == expected.ee);
    const FeaturePairs swept = sweep_feature_pairs(rep, boxes, with);
    REQUIRE(swept.vf == expected.vf);
    REQUIRE(swept.ee == expected.ee);
    if (!with) {
      oracle = expected;
      continue;
    }
    FeaturePairs apart;
    apart.vf = left_out(oracle.vf, expected.vf);
    apart.ee = left_out(oracle.ee, expected.ee);
    REQUIRE(apart.vf.size() + expected.vf.size() == oracle.vf.size());
    REQUIRE(apart.ee.size() + expected.ee.size() == oracle.ee.size());
    const auto certified = cpu::test_feature_pairs<CertifiedCcd, double>(mesh, x0, x1, apart);
    const auto inclusion = cpu::test_feature_pairs<InclusionCcd, double>(mesh, x0, x1, apart);
    REQUIRE(certified.vf.size() + certified.ee.size() == 0);
    REQUIRE(inclusion.vf.size() + inclusion.ee.size() == 0);
    left = apart.vf.size() + apart.ee.size();
  }
  return left;
}

}  // namespace

TEST_CASE("representatives: each used vertex and each edge has exactly one incident representing face", "[representative]") {
  const auto cloth = lwsccd_test::folded_cloth(12, 3);
  const MultiBodyStep ball = make_cloth_ball_scene(1500);
  for (const TriangleMesh* mesh : {&cloth.mesh, ball.step.mesh.get()}) {
    const RepresentativeTriangles rep(*mesh);
    std::vector<int> vertex_count(static_cast<std::size_t>(mesh->num_vertices()), 0), edge_count(static_cast<std::size_t>(mesh->num_edges()), 0);
    int most_vertices = 0, most_edges = 0;
    for (index_t f = 0; f < mesh->num_faces(); ++f) {
      const unsigned bits = rep.represents()[f];
      REQUIRE(bits < 64u);
      int vertices = 0, edges = 0;
      for (int k = 0; k < 3; ++k) {
        if ((bits >> k) & 1u) {
          const index_t v = mesh->face(f).v[k];
          ++vertex_count[v], ++vertices;
          REQUIRE(rep.vertex_owner(v) == f);
        }
        if ((bits >> (3 + k)) & 1u) {
          const index_t e = mesh->face_edges(f)[k];
          ++edge_count[e], ++edges;
          REQUIRE(rep.edge_owner(e) == f);
        }
      }
      most_vertices = std::max(most_vertices, vertices);
      most_edges = std::max(most_edges, edges);
    }
    for (index_t v = 0; v < mesh->num_vertices(); ++v) REQUIRE(vertex_count[v] == (mesh->vertex_faces(v).size() > 0 ? 1 : 0));
    for (index_t e = 0; e < mesh->num_edges(); ++e) REQUIRE(edge_count[e] == 1);
    // Balanced: about half a vertex and 1.5 edges per face, so no face carries all six.
    CHECK(most_vertices <= 2);
    CHECK(most_edges <= 2);
    CHECK(rep.owner_of_feature(mesh->face_feature_id(7)) == 7);
  }
}

TEST_CASE("representatives: the orphans are exactly the non-incident pairs whose representing faces share a vertex",
          "[representative]") {
  const auto cloth = lwsccd_test::folded_cloth(6, 1);
  const MultiBodyStep ball = make_cloth_ball_scene(300);
  for (const TriangleMesh* mesh : {&cloth.mesh, ball.step.mesh.get()}) {
    const RepresentativeTriangles rep(*mesh);
    OrphanSets expected;
    for (index_t v = 0; v < mesh->num_vertices(); ++v)
      for (index_t f = 0; f < mesh->num_faces(); ++f) {
        const Face& t = mesh->face(f);
        const index_t owner = rep.vertex_owner(v);
        if (owner < 0 || t.v[0] == v || t.v[1] == v || t.v[2] == v) continue;
        if (mesh->faces_share_vertex(owner, f)) expected.vf.emplace_back(v, mesh->face_feature_id(f));
      }
    for (index_t e = 0; e < mesh->num_edges(); ++e)
      for (index_t g = e + 1; g < mesh->num_edges(); ++g) {
        const Edge &a = mesh->edge(e), &b = mesh->edge(g);
        if (a.v[0] == b.v[0] || a.v[0] == b.v[1] || a.v[1] == b.v[0] || a.v[1] == b.v[1]) continue;
        REQUIRE(rep.edge_owner(e) != rep.edge_owner(g));  // two edges of one face always touch
        if (mesh->faces_share_vertex(rep.edge_owner(e), rep.edge_owner(g)))
          expected.ee.emplace_back(mesh->edge_feature_id(e), mesh->edge_feature_id(g));
      }
    INFO(expected.vf.size() << " VF, " << expected.ee.size() << " EE orphans");
    REQUIRE(rep.orphans().vf == expected.vf);
    REQUIRE(rep.orphans().ee == expected.ee);
    CHECK(!expected.vf.empty());
  }
}

TEST_CASE("representatives: the orphans found in parallel ranges equal one serial pass over a large mesh, sorted alike",
          "[representative]") {
  // Enough vertices and edges for many ranges per thread (ordered_parts), on several thread counts.
  const MultiBodyStep ball = make_cloth_ball_scene(40000);
  const TriangleMesh& mesh = *ball.step.mesh;
  for (const unsigned threads : {1u, 2u, 5u}) {
    INFO(threads << " threads");
    const RepresentativeTriangles rep = cpu::ThreadLimit(threads).run([&] { return RepresentativeTriangles(mesh); });
    // The definition, serially: each vertex with the faces of its representing face's vertex
    // ring, each edge with the edges that ring's faces represent, sorted at the end.
    OrphanSets expected;
    std::vector<index_t> ring;
    for (index_t v = 0; v < mesh.num_vertices(); ++v) {
      const index_t owner = rep.vertex_owner(v);
      if (owner < 0) continue;
      ring.clear();
      for (const index_t x : mesh.face(owner).v)
        for (const index_t g : mesh.vertex_faces(x)) ring.push_back(g);
      std::sort(ring.begin(), ring.end());
      ring.erase(std::unique(ring.begin(), ring.end()), ring.end());
      for (const index_t g : ring) {
        const Face& t = mesh.face(g);
        if (g == owner || t.v[0] == v || t.v[1] == v || t.v[2] == v) continue;
        expected.vf.emplace_back(mesh.vertex_feature_id(v), mesh.face_feature_id(g));
      }
    }
    for (index_t e = 0; e < mesh.num_edges(); ++e) {
      ring.clear();
      for (const index_t x : mesh.face(rep.edge_owner(e)).v)
        for (const index_t g : mesh.vertex_faces(x)) ring.push_back(g);
      std::sort(ring.begin(), ring.end());
      ring.erase(std::unique(ring.begin(), ring.end()), ring.end());
      for (const index_t g : ring) {
        if (g == rep.edge_owner(e)) continue;
        for (const index_t other : mesh.face_edges(g)) {
          const Edge &a = mesh.edge(e), &b = mesh.edge(other);
          if (rep.edge_owner(other) != g || other <= e || a.v[0] == b.v[0] || a.v[0] == b.v[1] || a.v[1] == b.v[0] ||
              a.v[1] == b.v[1])
            continue;
          expected.ee.emplace_back(mesh.edge_feature_id(e), mesh.edge_feature_id(other));
        }
      }
    }
    std::sort(expected.vf.begin(), expected.vf.end());
    std::sort(expected.ee.begin(), expected.ee.end());
    INFO(expected.vf.size() << " VF, " << expected.ee.size() << " EE orphans");
    CHECK(expected.vf.size() > 1000);
    CHECK(rep.orphans().vf == expected.vf);
    CHECK(rep.orphans().ee == expected.ee);
  }
}

TEST_CASE("representatives: the CPU's packed emission keeps the view's pairs, in its order", "[representative]") {
  // Every triangle pair among a cloth-ball mesh's first faces and random others, with boxes that
  // overlap often (random small boxes in a small space), some empty or NaN: the pairs
  // emit_packed_triangle_pair keeps are emit_triangle_pair's, in the same order.
  const MultiBodyStep ball = make_cloth_ball_scene(4000);
  const TriangleMesh& mesh = *ball.step.mesh;
  const RepresentativeTriangles rep(mesh);
  const auto features = static_cast<std::size_t>(mesh.num_vertices() + mesh.num_edges() + mesh.num_faces());
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> at(0.0f, 1.0f), size(0.0f, 0.9f);
  std::vector<Aabbf> boxes(features);
  for (std::size_t i = 0; i < features; ++i) {
    const Vec3f lo{at(rng), at(rng), at(rng)};
    boxes[i] = {lo, {lo.x + size(rng), lo.y + size(rng), lo.z + size(rng)}};
    if (i % 97 == 0) boxes[i].lo.y = std::numeric_limits<float>::quiet_NaN();
    if (i % 89 == 0) boxes[i] = Aabbf::empty();
  }
  // With the scene's corners too (the test of the faces' motion), which then parts some pairs.
  const std::vector<FaceCorners> corners = face_corners(mesh, ball.step.x0, ball.step.x1);
  std::size_t kept_without = 0;
  for (const FaceCorners* with : {static_cast<const FaceCorners*>(nullptr), corners.data()}) {
    const EmissionView view = rep.view(boxes.data(), with);
    detail::PackedEmission packed;
    detail::pack_emission(view, mesh.num_faces(), packed);
    std::vector<std::pair<index_t, index_t>> expected, got;
    std::size_t pairs = 0;
    std::mt19937 pick(9);
    for (index_t a = 0; a < 300; ++a)
      for (int j = 0; j < 60; ++j) {
        // (Near faces as often as far ones: the corners part only some of the near.)
        const index_t b = j % 2 ? static_cast<index_t>(pick() % static_cast<unsigned>(mesh.num_faces()))
                                : static_cast<index_t>((a + 1 + pick() % 40) % mesh.num_faces());
        if (b == a) continue;
        ++pairs;
        auto to = [](std::vector<std::pair<index_t, index_t>>& out, int kind) {
          return [&out, kind](index_t x, index_t y) { out.emplace_back(kind * (1 << 30) + x, y); };
        };
        emit_triangle_pair(view, a, b, to(expected, 0), to(expected, 1));
        detail::emit_packed_triangle_pair(packed, a, b, to(got, 0), to(got, 1));
      }
    INFO(pairs << " triangle pairs, " << expected.size() << " feature pairs" << (with ? ", with corners" : ""));
    CHECK(expected.size() > (with ? 0 : pairs / 2));
    CHECK(got == expected);
    if (!with) kept_without = expected.size();
    else CHECK(expected.size() < kept_without);
  }
}

TEST_CASE("representatives: faces_apart from the faces' summaries gives faces_apart's verdict", "[representative]") {
  // Random faces near each other (every coordinate on a coarse grid half the time, so that ties
  // and differences at the margins occur), some coordinates replaced by values that are not
  // finite, zeros of either sign, huge, tiny or subnormal ones, or next to 2^60 (where the
  // summaries stop being tame): the overload the CPU emission calls with summaries made once a
  // face agrees with the one from the corners, both ways round.
  std::mt19937 rng(21);
  std::uniform_real_distribution<float> at(-1.0f, 1.0f), motion(-0.05f, 0.05f);
  const float specials[] = {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                            -std::numeric_limits<float>::infinity(), -0.0f, 0.0f, 1e30f, -1e30f, 0x1p-140f, 3e38f,
                            0x1.fffffep59f, -0x1.fffffep59f, 0x1p60f};  // (around the summaries' tame bound)
  auto random_face = [&](const Vec3f& centre, bool on_grid) {
    FaceCorners f;
    for (int k = 0; k < 3; ++k) {
      f.at[k] = {centre.x + 0.3f * at(rng), centre.y + 0.3f * at(rng), centre.z + 0.3f * at(rng)};
      f.at[3 + k] = {f.at[k].x + motion(rng), f.at[k].y + motion(rng), f.at[k].z + motion(rng)};
    }
    if (on_grid)
      for (auto& corner : f.at)
        for (int axis = 0; axis < 3; ++axis) corner[axis] = std::round(corner[axis] * 8.0f) / 8.0f;
    if (rng() % 8 == 0) f.at[rng() % 6][static_cast<int>(rng() % 3)] = specials[rng() % std::size(specials)];
    return f;
  };
  std::size_t apart = 0, not_apart = 0;
  for (int i = 0; i < 200000; ++i) {
    const Vec3f centre{0.8f * at(rng), 0.8f * at(rng), 0.8f * at(rng)};
    const FaceCorners a = random_face({0.0f, 0.0f, 0.0f}, i % 2 == 0), b = random_face(centre, i % 2 == 0);
    const FaceCornerSummary sa = summarize_corners(a), sb = summarize_corners(b);
    const bool expected = faces_apart(a, b);
    if (faces_apart(sa, a, sb, b) != expected || faces_apart(sb, b, sa, a) != faces_apart(b, a)) {
      FAIL("pair " << i << ": the verdict from summaries differs");
    }
    ++(expected ? apart : not_apart);
  }
  INFO(apart << " pairs apart, " << not_apart << " not");
  CHECK(apart > 10000);
  CHECK(not_apart > 10000);
}

TEST_CASE("representatives: emission equals the brute-force feature oracle, each pair once", "[representative]") {
  SECTION("folded cloth, several motions") {
    for (std::uint64_t seed = 1; seed <= 3; ++seed) {
      const auto m = lwsccd_test::folded_cloth(14, seed);
      require_emission_equals_oracle(m.mesh, m.x0, m.x1);
    }
  }
  SECTION("folded cloth with a margin (proximity): more pairs, still the oracle's") {
    const auto m = lwsccd_test::folded_cloth(14, 2);
    require_emission_equals_oracle(m.mesh, m.x0, m.x1, {}, 0.01);
    const RepresentativeTriangles rep(m.mesh);
    CHECK(brute_force_feature_pairs(rep, feature_boxes(m.mesh, m.x0, m.x1, 0.01)).ee.size() >
          brute_force_feature_pairs(rep, feature_boxes(m.mesh, m.x0, m.x1)).ee.size());
  }
  SECTION("random soup (no adjacency: no orphans)") {
    const auto m = lwsccd_test::random_soup(300, 5, 0.08);
    REQUIRE(RepresentativeTriangles(m.mesh).orphans().vf.empty());
    require_emission_equals_oracle(m.mesh, m.x0, m.x1);
  }
  SECTION("coincident triangles (every box overlaps every other)") {
    const auto m = lwsccd_test::coincident_triangles(12);
    require_emission_equals_oracle(m.mesh, m.x0, m.x1);
  }
  SECTION("cloth over a ball, one body and with a rigid ball") {
    const MultiBodyStep scene = make_cloth_ball_scene(1200);
    const std::size_t apart = require_emission_equals_oracle(*scene.step.mesh, scene.step.x0, scene.step.x1);
    std::printf("  cloth over a ball: %zu feature pairs left out by their faces' relative motion\n", apart);
    CHECK(apart > 0);  // (the cloth's neighbours move together: the test has work here)
    require_emission_equals_oracle(*scene.step.mesh, scene.step.x0, scene.step.x1, scene.layout);
  }
  SECTION("a non-manifold book: three faces on one edge, and a fan") {
    const std::vector<Vec3d> x0 = {{0, 0, 0}, {1, 0, 0}, {0.5, 1, 0}, {0.5, -1, 0}, {0.5, 0.2, 1}, {2, 0.5, 0}, {1.5, 1.2, 0}};
    std::vector<Vec3d> x1 = x0;
    for (auto& p : x1) p = p + Vec3d{0.01, -0.02, 0.05};
    const TriangleMesh book(7, {{{0, 1, 2}}, {{1, 0, 3}}, {{0, 1, 4}}, {{1, 5, 2}}, {{2, 5, 6}}}, "book");
    require_emission_equals_oracle(book, x0, x1);
  }
}

TEST_CASE("representatives: adjacent candidates add nothing; the orphans matter", "[representative]") {
  const auto m = lwsccd_test::folded_cloth(12, 2);
  const RepresentativeTriangles rep(m.mesh);
  const auto boxes = feature_boxes(m.mesh, m.x0, m.x1);
  const auto all = brute_force_pairs(m.mesh, swept_triangle_bvs<Aabbf>(m.mesh, m.x0, m.x1));
  const FeaturePairs from_all = emit_feature_pairs(rep, all, boxes);
  const FeaturePairs from_separated = emit_feature_pairs(rep, non_adjacent(all), boxes);
  REQUIRE(from_all.vf == from_separated.vf);  // same order too: adjacent pairs emit nothing
  REQUIRE(from_all.ee == from_separated.ee);
  // Without candidates, only the kept orphans come out: pairs the oracle needs.
  const FeaturePairs orphans_only = sorted(emit_feature_pairs(rep, {}, boxes));
  const FeaturePairs oracle = brute_force_feature_pairs(rep, boxes);
  CHECK(orphans_only.vf.size() > 0);
  CHECK(orphans_only.ee.size() > 0);
  CHECK(std::includes(oracle.vf.begin(), oracle.vf.end(), orphans_only.vf.begin(), orphans_only.vf.end()));
  CHECK(std::includes(oracle.ee.begin(), oracle.ee.end(), orphans_only.ee.begin(), orphans_only.ee.end()));
  CHECK(orphans_only.vf.size() < rep.orphans().vf.size());  // some orphans are culled by their boxes
}

TEST_CASE("representatives: OBB candidates lose no contact of the AABB feature oracle", "[representative][obb]") {
  const auto m = lwsccd_test::folded_cloth(14, 4);
  const RepresentativeTriangles rep(m.mesh);
  const auto boxes = feature_boxes(m.mesh, m.x0, m.x1);
  const auto candidates = non_adjacent(brute_force_pairs(m.mesh, swept_triangle_bvs<Obbf>(m.mesh, m.x0, m.x1)));
  const FeaturePairs emitted = sorted(emit_feature_pairs(rep, candidates, boxes));
  const FeaturePairs oracle = brute_force_feature_pairs(rep, boxes);
  // Tighter triangle BVs give a subset of the feature pairs...
  REQUIRE(std::includes(oracle.vf.begin(), oracle.vf.end(), emitted.vf.begin(), emitted.vf.end()));
  REQUIRE(std::includes(oracle.ee.begin(), oracle.ee.end(), emitted.ee.begin(), emitted.ee.end()));
  // ...that keeps every contact.
  const auto expected = cpu::test_feature_pairs<CertifiedCcd, double>(m.mesh, m.x0, m.x1, oracle);
  const auto got = cpu::test_feature_pairs<CertifiedCcd, double>(m.mesh, m.x0, m.x1, emitted);
  REQUIRE(expected.vf.size() + expected.ee.size() > 0);
  REQUIRE(got.vf.size() == expected.vf.size());
  REQUIRE(got.ee.size() == expected.ee.size());
  for (std::size_t i = 0; i < got.vf.size(); ++i) REQUIRE(got.vf[i].toi == expected.vf[i].toi);
}

TEST_CASE("representatives: bad input is refused with a message", "[representative]") {
  const auto m = lwsccd_test::folded_cloth(4, 1);
  const RepresentativeTriangles rep(m.mesh);
  std::vector<Aabbf> short_boxes(3);
  CHECK_THROWS_AS(emit_feature_pairs(rep, {}, short_boxes), InputError);
  const std::vector<FaceCorners> short_corners(2);
  const auto boxes = feature_boxes(m.mesh, m.x0, m.x1);
  CHECK_THROWS_AS(emit_feature_pairs(rep, {}, boxes, &short_corners), InputError);
  CHECK_THROWS_AS(brute_force_feature_pairs(rep, boxes, &short_corners), InputError);
  CHECK_THROWS_AS(sweep_feature_pairs(rep, boxes, &short_corners), InputError);
  CHECK_THROWS_AS(face_corners(m.mesh, m.x0, std::vector<Vec3d>(2)), InputError);
  BodyLayout wrong;
  wrong.face_body = {0, 1};
  CHECK_THROWS_AS(RepresentativeTriangles(m.mesh, wrong), InputError);
}

TEST_CASE("representatives: candidates read from several lists give the one list's feature pairs, in its order",
          "[representative]") {
  const auto m = lwsccd_test::folded_cloth(30, 4);
  const RepresentativeTriangles rep(m.mesh);
  const auto boxes = feature_boxes(m.mesh, m.x0, m.x1);
  const auto all = brute_force_pairs(m.mesh, swept_triangle_bvs<Aabbf>(m.mesh, m.x0, m.x1));
  REQUIRE(all.size() > 600);
  // Uneven lists, one of them empty, as a traversal's threads leave them.
  const std::size_t cut1 = all.size() / 7, cut2 = all.size() / 2;
  const std::vector<std::vector<TrianglePair>> lists{std::vector<TrianglePair>(all.begin(), all.begin() + cut1), {},
                                                     std::vector<TrianglePair>(all.begin() + cut1, all.begin() + cut2),
                                                     std::vector<TrianglePair>(all.begin() + cut2, all.end())};
  // One FeaturePairParts throughout: with the orphans, then without (their lists emptied), then
  // with again (every list's memory reused).
  FeaturePairParts parts;
  for (bool with_orphans : {true, false, true}) {
    const FeaturePairs one = emit_feature_pairs(rep, all.data(), all.size(), boxes, with_orphans);
    REQUIRE(one.ee.size() > 0);
    emit_feature_pairs_into(rep, lists, boxes, with_orphans, parts);
    REQUIRE(parts.vf_size() == one.vf.size());
    REQUIRE(parts.ee_size() == one.ee.size());
    const FeaturePairs joined = parts.joined();
    REQUIRE(joined.vf == one.vf);
    REQUIRE(joined.ee == one.ee);
    // Indexed where they lie, element for element.
    const lwsccd::detail::ConcatenatedLists<std::pair<index_t, index_t>> vf(parts.vf_lists()), ee(parts.ee_lists());
    REQUIRE(vf.size() == one.vf.size());
    REQUIRE(ee.size() == one.ee.size());
    std::size_t vf_differ = 0, ee_differ = 0;
    for (std::size_t i = 0; i < one.vf.size(); ++i) vf_differ += vf[i] != one.vf[i];
    for (std::size_t i = 0; i < one.ee.size(); ++i) ee_differ += ee[i] != one.ee[i];
    CHECK(vf_differ == 0);
    CHECK(ee_differ == 0);
    // The narrow phase reads them there: the answer over the one list, hit for hit.
    for (const CcdMode mode : {CcdMode::contacts, CcdMode::earliest}) {
      CcdParams<double> params;
      params.mode = mode;
      const auto expected = cpu::test_feature_pairs<CertifiedCcd, double>(m.mesh, m.x0, m.x1, one, params);
      const auto got = cpu::test_feature_pairs<CertifiedCcd, double>(m.mesh, m.x0, m.x1, parts, params);
      CHECK(got.earliest_toi == expected.earliest_toi);
      CHECK(got.vf_counts.pairs == expected.vf_counts.pairs);
      CHECK(got.ee_counts.certified_misses == expected.ee_counts.certified_misses);
      CHECK(got.ee_counts.screened == expected.ee_counts.screened);
      REQUIRE(got.vf.size() == expected.vf.size());
      REQUIRE(got.ee.size() == expected.ee.size());
      for (std::size_t i = 0; i < got.ee.size(); ++i) {
        REQUIRE(got.ee[i].first == expected.ee[i].first);
        REQUIRE(got.ee[i].second == expected.ee[i].second);
        REQUIRE(got.ee[i].toi == expected.ee[i].toi);
      }
      for (std::size_t i = 0; i < got.vf.size(); ++i) REQUIRE(got.vf[i].toi == expected.vf[i].toi);
      if (mode == CcdMode::contacts) REQUIRE(expected.ee.size() + expected.vf.size() > 0);
    }
    // The orphans' pairs come last, and only when asked for.
    std::size_t orphan_pairs = 0;
    for (const auto& list : parts.orphans_vf) orphan_pairs += list.size();
    for (const auto& list : parts.orphans_ee) orphan_pairs += list.size();
    CHECK((orphan_pairs > 0) == with_orphans);
  }
}

TEST_CASE("concatenated lists: element i of lists of every size, empty ones included", "[representative]") {
  // Lists around the index's block size (1,024), empty ones between them and at both ends.
  const std::vector<std::size_t> sizes{0, 3, 1024, 0, 0, 1, 1023, 2049, 0, 5000, 0};
  std::vector<std::vector<int>> lists;
  int next = 0;
  for (const std::size_t n : sizes) {
    lists.emplace_back();
    for (std::size_t k = 0; k < n; ++k) lists.back().push_back(next++);
  }
  std::vector<const std::vector<int>*> pointers;
  for (const auto& l : lists) pointers.push_back(&l);
  const lwsccd::detail::ConcatenatedLists<int> all(pointers);
  REQUIRE(all.size() == static_cast<std::size_t>(next));
  std::size_t wrong = 0;
  for (std::size_t i = 0; i < all.size(); ++i) wrong += all[i] != static_cast<int>(i);
  CHECK(wrong == 0);
  CHECK(lwsccd::detail::ConcatenatedLists<int>().size() == 0);
  CHECK(lwsccd::detail::ConcatenatedLists<int>(std::vector<const std::vector<int>*>{}).size() == 0);
  const std::vector<int> none;
  CHECK(lwsccd::detail::ConcatenatedLists<int>(std::vector<const std::vector<int>*>{&none, &none}).size() == 0);
}
