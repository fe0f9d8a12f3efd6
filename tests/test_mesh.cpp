#include <catch2/catch.hpp>

#include <algorithm>
#include <map>
#include <random>
#include <set>
#include <string>

#include "lwsccd/core/error.hpp"
#include "lwsccd/core/parallel.hpp"
#include "lwsccd/geometry/mesh.hpp"

using namespace lwsccd;

namespace {

// A w x h grid of quads, two triangles each (an open cloth).
std::vector<Face> grid_faces(int w, int h) {
  std::vector<Face> faces;
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      const index_t a = j * (w + 1) + i, b = a + 1, c = a + w + 1, d = c + 1;
      faces.push_back({{a, b, d}});
      faces.push_back({{a, d, c}});
    }
  return faces;
}

}  // namespace

TEST_CASE("edges follow the dataset order: unique (min, max) sorted by (max, min)", "[mesh]") {
  const TriangleMesh quad(4, {{{0, 1, 2}}, {{0, 2, 3}}});
  REQUIRE(quad.num_edges() == 5);
  const std::vector<std::pair<int, int>> expected = {{0, 1}, {0, 2}, {1, 2}, {0, 3}, {2, 3}};
  for (index_t e = 0; e < 5; ++e) {
    CHECK(quad.edge(e).v[0] == expected[e].first);
    CHECK(quad.edge(e).v[1] == expected[e].second);
  }
  // face_edges: (v0,v1), (v1,v2), (v2,v0)
  CHECK(quad.face_edges(0) == std::array<index_t, 3>{0, 2, 1});
  CHECK(quad.face_edges(1) == std::array<index_t, 3>{1, 4, 3});
  CHECK(quad.edge_faces(1).size() == 2);
  CHECK(quad.is_boundary_edge(0));
  CHECK_FALSE(quad.is_boundary_edge(1));
  CHECK(quad.face_neighbors(0).size() == 1);
  CHECK(quad.face_neighbors(0)[0] == 1);
  CHECK(quad.vertex_faces(0).size() == 2);
  CHECK(quad.vertex_faces(1).size() == 1);
  CHECK(quad.find_edge(2, 0) == 1);
  CHECK(quad.find_edge(1, 3) == -1);
  CHECK(quad.vertex_feature_id(3) == 3);
  CHECK(quad.edge_feature_id(0) == 4);
  CHECK(quad.face_feature_id(1) == 4 + 5 + 1);
  CHECK(quad.faces_share_vertex(0, 1));
}

namespace {

// Checks every derived list of `mesh` against its definition from `faces` by ordered sets: edges
// unique and sorted by (max, min), face_edges, and the face lists of vertices, edges and faces
// (ascending, as the accessors promise). Returns the number of boundary edges.
int check_against_definition(const TriangleMesh& mesh, const std::vector<Face>& faces, index_t nv) {
  std::set<std::pair<int, int>> by_max_min;  // (max, min)
  for (const Face& f : faces)
    for (int k = 0; k < 3; ++k) {
      const int a = f.v[k], b = f.v[(k + 1) % 3];
      by_max_min.insert({std::max(a, b), std::min(a, b)});
    }
  REQUIRE(mesh.num_vertices() == nv);
  REQUIRE(mesh.num_edges() == static_cast<index_t>(by_max_min.size()));
  index_t e = 0;
  for (const auto& mm : by_max_min) {
    REQUIRE(mesh.edge(e).v[0] == mm.second);
    REQUIRE(mesh.edge(e).v[1] == mm.first);
    REQUIRE(mesh.find_edge(mm.first, mm.second) == e);
    ++e;
  }
  std::map<index_t, std::set<index_t>> ref_edge_faces, ref_vertex_faces;
  for (index_t f = 0; f < mesh.num_faces(); ++f)
    for (int k = 0; k < 3; ++k) {
      const index_t edge = mesh.face_edges(f)[k];
      const Edge& ev = mesh.edge(edge);
      const index_t a = faces[f].v[k], b = faces[f].v[(k + 1) % 3];
      REQUIRE(((ev.v[0] == a && ev.v[1] == b) || (ev.v[0] == b && ev.v[1] == a)));
      ref_edge_faces[edge].insert(f);
      ref_vertex_faces[faces[f].v[k]].insert(f);
    }
  int boundary = 0;
  for (index_t edge = 0; edge < mesh.num_edges(); ++edge) {
    const auto span = mesh.edge_faces(edge);
    REQUIRE(std::vector<index_t>(span.begin(), span.end()) ==
            std::vector<index_t>(ref_edge_faces[edge].begin(), ref_edge_faces[edge].end()));
    boundary += mesh.is_boundary_edge(edge);
  }
  for (index_t v = 0; v < nv; ++v) {
    const auto span = mesh.vertex_faces(v);
    const auto it = ref_vertex_faces.find(v);
    const std::vector<index_t> ref = it == ref_vertex_faces.end() ? std::vector<index_t>{}
                                                                  : std::vector<index_t>(it->second.begin(), it->second.end());
    REQUIRE(std::vector<index_t>(span.begin(), span.end()) == ref);
  }
  for (index_t f = 0; f < mesh.num_faces(); ++f) {
    std::set<index_t> ref;
    for (index_t edge : mesh.face_edges(f))
      for (index_t g : ref_edge_faces[edge])
        if (g != f) ref.insert(g);
    const auto span = mesh.face_neighbors(f);
    REQUIRE(std::vector<index_t>(span.begin(), span.end()) == std::vector<index_t>(ref.begin(), ref.end()));
  }
  return boundary;
}

}  // namespace

TEST_CASE("derived edges and adjacency agree with a set-based reference on a random cloth", "[mesh]") {
  auto faces = grid_faces(13, 9);
  std::mt19937 rng(1);
  std::shuffle(faces.begin(), faces.end(), rng);  // ids must not depend on face order
  const index_t nv = 14 * 10;
  const TriangleMesh mesh(nv, faces);
  CHECK(check_against_definition(mesh, faces, nv) == 2 * (13 + 9));
}

TEST_CASE("a large mesh's edges and adjacency, built on several threads, agree with the reference", "[mesh][threads]") {
  // A shuffled 150 x 100 cloth (many vertex and face ranges per thread), fins on some of its
  // edges (three or four faces on one edge) and vertices in no face.
  const int w = 150, h = 100;
  auto faces = grid_faces(w, h);
  index_t nv = (w + 1) * (h + 1);
  std::mt19937 rng(7);
  for (int i = 0; i < 500; ++i) {
    const Face& f = faces[rng() % faces.size()];
    const int k = static_cast<int>(rng() % 3);
    faces.push_back({{f.v[k], f.v[(k + 1) % 3], nv++}});
  }
  nv += 37;  // isolated vertices
  std::shuffle(faces.begin(), faces.end(), rng);
  for (const unsigned threads : {1u, 2u, 5u}) {
    const TriangleMesh mesh = cpu::ThreadLimit(threads).run([&] { return TriangleMesh(nv, faces); });
    check_against_definition(mesh, faces, nv);
    CHECK(mesh == TriangleMesh(nv, faces));
  }
  // Duplicates: the one on the first edge in id order is named, whatever the threads.
  auto twice = faces;
  twice.push_back(faces[10]);                                                    // face n
  twice.push_back({{faces[3].v[2], faces[3].v[0], faces[3].v[1]}});             // face n + 1, a rotation
  const std::size_t n = faces.size();
  const TriangleMesh plain(nv, faces);
  auto lowest_edge = [&](const Face& f) {
    index_t e = plain.num_edges();
    for (int k = 0; k < 3; ++k) e = std::min(e, plain.find_edge(f.v[k], f.v[(k + 1) % 3]));
    return e;
  };
  const bool tenth_first = lowest_edge(faces[10]) < lowest_edge(faces[3]);
  const std::string expected = tenth_first ? "face " + std::to_string(n) + ": duplicate of face 10"
                                           : "face " + std::to_string(n + 1) + ": duplicate of face 3";
  for (const unsigned threads : {1u, 2u, 5u})
    CHECK_THROWS_WITH(cpu::ThreadLimit(threads).run([&] { return TriangleMesh(nv, twice, "m"); }), Catch::Contains(expected));
}

TEST_CASE("closed and non-manifold meshes", "[mesh]") {
  const TriangleMesh tet(4, {{{0, 1, 2}}, {{0, 3, 1}}, {{1, 3, 2}}, {{0, 2, 3}}});
  CHECK(tet.num_edges() == 6);
  for (index_t e = 0; e < 6; ++e) CHECK(tet.edge_faces(e).size() == 2);
  for (index_t f = 0; f < 4; ++f) CHECK(tet.face_neighbors(f).size() == 3);
  // Three faces on one edge (a "book"): each is a neighbour of the other two.
  const TriangleMesh book(5, {{{0, 1, 2}}, {{0, 1, 3}}, {{0, 1, 4}}});
  CHECK(book.edge_faces(book.find_edge(0, 1)).size() == 3);
  CHECK(book.face_neighbors(2).size() == 2);
}

TEST_CASE("invalid topology is rejected with the face and the problem named", "[mesh]") {
  CHECK_THROWS_WITH(TriangleMesh(3, {{{0, 1, 3}}}, "cube.obj"),
                    Catch::Contains("cube.obj") && Catch::Contains("face 0") && Catch::Contains("out of range"));
  CHECK_THROWS_WITH(TriangleMesh(3, {{{0, 1, 2}}, {{0, -1, 2}}}, "m"),
                    Catch::Contains("face 1") && Catch::Contains("out of range"));
  CHECK_THROWS_WITH(TriangleMesh(3, {{{0, 1, 1}}}, "m"), Catch::Contains("face 0") && Catch::Contains("repeated"));
  CHECK_THROWS_WITH(TriangleMesh(3, {}, "empty.ply"), Catch::Contains("empty.ply") && Catch::Contains("no faces"));
  CHECK_THROWS_WITH(TriangleMesh(0, {{{0, 1, 2}}}, "m"), Catch::Contains("no vertices"));
  CHECK_THROWS_WITH(TriangleMesh(4, {{{0, 1, 2}}, {{0, 1, 3}}, {{2, 0, 1}}}, "m"),
                    Catch::Contains("face 2") && Catch::Contains("duplicate of face 0"));
  CHECK_THROWS_AS(TriangleMesh(3, {{{0, 1, 7}}}), InputError);
}

TEST_CASE("positions are validated and degenerate faces reported, not rejected", "[mesh]") {
  const TriangleMesh mesh(5, {{{0, 1, 2}}, {{1, 3, 2}}, {{2, 3, 4}}});
  std::vector<Vec3d> x = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {2, 2, 0}};
  validate_positions(mesh, x, "frame.ply");
  // face 2: vertices 2, 3, 4 are not collinear; make face 1 collinear and face 2 coincident.
  x[3] = {0.5, 0.5, 0};            // on the segment from 1 to 2: face 1 zero area
  x[4] = x[2];                     // face 2 has two coincident vertices
  const auto degenerate = find_degenerate_faces(mesh, x);
  CHECK(degenerate == std::vector<index_t>{1, 2});
  x[4].y = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(validate_positions(mesh, x, "frame.ply"),
                    Catch::Contains("frame.ply") && Catch::Contains("vertex 4") && Catch::Contains("NaN"));
  x.pop_back();
  CHECK_THROWS_WITH(validate_positions(mesh, x, "frame.ply"), Catch::Contains("4 vertex positions"));
}
