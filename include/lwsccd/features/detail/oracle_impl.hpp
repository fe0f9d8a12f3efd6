// lwsccd — definitions for oracle.hpp.
#pragma once

#include <cstdint>

#include <algorithm>
#include <numeric>

#include "lwsccd/core/error.hpp"
#include "lwsccd/core/parallel.hpp"
#include "lwsccd/features/oracle.hpp"

namespace lwsccd {

inline void BodyLayout::validate(const TriangleMesh& mesh) const {
  if (face_body.empty()) return;
  if (face_body.size() != static_cast<std::size_t>(mesh.num_faces()))
    throw InputError("BodyLayout", "", "face_body has " + std::to_string(face_body.size()) +
                                           " entries, the mesh has " + std::to_string(mesh.num_faces()) + " faces");
  for (std::size_t f = 0; f < face_body.size(); ++f) {
    if (face_body[f] < 0 || (!body_self_collides.empty() &&
                             static_cast<std::size_t>(face_body[f]) >= body_self_collides.size()))
      throw InputError("BodyLayout", "face " + std::to_string(f), "unknown body id " + std::to_string(face_body[f]));
  }
}

template <class BV, class U>
std::vector<BV> swept_triangle_bvs(const TriangleMesh& mesh, const std::vector<Vec3<U>>& x0,
                                   const std::vector<Vec3<U>>& x1) {
  require_bounding_volume<BV>();
  std::vector<BV> bvs(static_cast<std::size_t>(mesh.num_faces()));
  for (index_t f = 0; f < mesh.num_faces(); ++f) {
    const Face& t = mesh.face(f);
    bvs[f] = swept_triangle_bv<BV>(x0[t.v[0]], x0[t.v[1]], x0[t.v[2]], x1[t.v[0]], x1[t.v[1]], x1[t.v[2]]);
  }
  return bvs;
}

namespace detail {

inline std::vector<TrianglePair> merge_sorted(std::vector<std::vector<TrianglePair>>& parts) {
  std::vector<TrianglePair> out;
  std::size_t total = 0;
  for (const auto& p : parts) total += p.size();
  out.reserve(total);
  for (auto& p : parts) out.insert(out.end(), p.begin(), p.end());
  parallel_sort(out.begin(), out.end());
  return out;
}

}  // namespace detail

template <class BV>
std::vector<TrianglePair> brute_force_pairs(const TriangleMesh& mesh, const std::vector<BV>& bvs,
                                            const BodyLayout& layout) {
  require_bounding_volume<BV>();
  layout.validate(mesh);
  const index_t n = static_cast<index_t>(bvs.size());
  const unsigned workers = detail::worker_count();
  std::vector<std::vector<TrianglePair>> parts(workers);
  detail::for_each_worker([&](unsigned worker, unsigned) {
    auto& out = parts[worker];
    // Rows are dealt round-robin so that long and short rows spread evenly.
    for (index_t a = static_cast<index_t>(worker); a < n; a += static_cast<index_t>(workers))
      for (index_t b = a + 1; b < n; ++b)
        if (layout.considers(a, b) && bv_traits<BV>::overlap(bvs[a], bvs[b]))
          out.push_back({a, b, mesh.faces_share_vertex(a, b)});
  }, workers);
  return detail::merge_sorted(parts);
}

template <class T>
std::vector<TrianglePair> sweep_and_prune_pairs(const TriangleMesh& mesh, const std::vector<Aabb<T>>& bvs,
                                                const BodyLayout& layout) {
  layout.validate(mesh);
  const index_t n = static_cast<index_t>(bvs.size());
  std::vector<index_t> order(static_cast<std::size_t>(n));
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](index_t i, index_t j) {
    return bvs[i].lo.x != bvs[j].lo.x ? bvs[i].lo.x < bvs[j].lo.x : i < j;
  });
  const unsigned workers = detail::worker_count();
  std::vector<std::vector<TrianglePair>> parts(workers);
  detail::for_each_worker([&](unsigned worker, unsigned) {
    auto& out = parts[worker];
    for (index_t k = static_cast<index_t>(worker); k < n; k += static_cast<index_t>(workers)) {
      const Aabb<T>& box = bvs[order[k]];
      // Every box that starts within [lo.x, hi.x] of this one follows it in the order.
      for (index_t m = k + 1; m < n && bvs[order[m]].lo.x <= box.hi.x; ++m) {
        const index_t a = std::min(order[k], order[m]), b = std::max(order[k], order[m]);
        if (layout.considers(a, b) && box.overlaps(bvs[order[m]]))
          out.push_back({a, b, mesh.faces_share_vertex(a, b)});
      }
    }
  }, workers);
  return detail::merge_sorted(parts);
}

namespace detail {
// Sorts id pairs by (first, second) and removes repeats: an LSD radix sort of the pairs packed as
// 64-bit keys, 8 bits a pass, skipping the bytes that no key uses (ids are far below 2^32). Same
// result as std::sort + std::unique, several times faster on the tens of millions of pairs of a
// large scene.
inline void sort_unique_pairs(std::vector<std::pair<index_t, index_t>>& pairs) {
  const std::size_t n = pairs.size();
  std::vector<std::uint64_t> keys(n), spare(n);
  std::uint64_t used = 0;
  for (std::size_t i = 0; i < n; ++i) {
    keys[i] = (static_cast<std::uint64_t>(static_cast<std::uint32_t>(pairs[i].first)) << 32) |
              static_cast<std::uint32_t>(pairs[i].second);
    used |= keys[i];
  }
  for (int shift = 0; shift < 64; shift += 8) {
    if (((used >> shift) & 0xffu) == 0) continue;  // every key has 0 here: nothing to order
    std::size_t count[257] = {};
    for (const std::uint64_t k : keys) ++count[((k >> shift) & 0xffu) + 1];
    for (int b = 0; b < 256; ++b) count[b + 1] += count[b];
    for (const std::uint64_t k : keys) spare[count[(k >> shift) & 0xffu]++] = k;
    keys.swap(spare);
  }
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  pairs.resize(keys.size());
  for (std::size_t i = 0; i < keys.size(); ++i)
    pairs[i] = {static_cast<index_t>(keys[i] >> 32), static_cast<index_t>(keys[i] & 0xffffffffu)};
}
}  // namespace detail

inline FeaturePairs feature_pairs(const TriangleMesh& mesh, const std::vector<TrianglePair>& pairs) {
  FeaturePairs out;
  out.vf.reserve(pairs.size() * 6);
  out.ee.reserve(pairs.size() * 9);
  for (const TrianglePair& p : pairs) {
    const index_t tri[2] = {p.a, p.b};
    for (int side = 0; side < 2; ++side) {
      const Face& verts = mesh.face(tri[side]);
      const Face& face = mesh.face(tri[1 - side]);
      for (int k = 0; k < 3; ++k) {
        const index_t v = verts.v[k];
        if (v == face.v[0] || v == face.v[1] || v == face.v[2]) continue;
        out.vf.emplace_back(mesh.vertex_feature_id(v), mesh.face_feature_id(tri[1 - side]));
      }
    }
    for (const index_t ea : mesh.face_edges(p.a)) {
      for (const index_t eb : mesh.face_edges(p.b)) {
        const Edge& x = mesh.edge(ea);
        const Edge& y = mesh.edge(eb);
        if (x.v[0] == y.v[0] || x.v[0] == y.v[1] || x.v[1] == y.v[0] || x.v[1] == y.v[1]) continue;
        const index_t ia = mesh.edge_feature_id(ea), ib = mesh.edge_feature_id(eb);
        out.ee.emplace_back(std::min(ia, ib), std::max(ia, ib));
      }
    }
  }
  detail::sort_unique_pairs(out.vf);
  detail::sort_unique_pairs(out.ee);
  return out;
}

}  // namespace lwsccd
