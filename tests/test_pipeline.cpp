// The CPU pipeline against its stages composed by hand from the oracles.
#include <catch2/catch.hpp>

#include "lwsccd/pipeline.hpp"
#include "scene_fixtures.hpp"

using namespace lwsccd;

TEST_CASE("CPU pipeline: refit + front tracking + culling + narrow phase equal the oracles, step after step", "[pipeline]") {
  const auto first = lwsccd_test::folded_cloth(30, 1);
  auto mesh = std::make_shared<const TriangleMesh>(first.mesh);
  cpu::CcdPipeline<Aabbf> pipeline(mesh);
  const OrphanSets orphans = find_orphan_sets(*mesh);
  for (int s = 0; s < 4; ++s) {
    INFO("step " << s);
    const auto m = lwsccd_test::folded_cloth(30, 1 + s);
    const auto r = pipeline.step(m.x0, m.x1);
    std::vector<TrianglePair> non_adjacent;
    for (const auto& p : brute_force_pairs(*mesh, swept_triangle_bvs<Aabbf>(*mesh, m.x0, m.x1)))
      if (!p.adjacent) non_adjacent.push_back(p);
    const FeaturePairs features = culled_feature_pairs(*mesh, non_adjacent, orphans);
    const auto expected = cpu::test_feature_pairs<Filtered<InclusionCcd>, double>(*mesh, m.x0, m.x1, features);
    REQUIRE(r.stats.triangle_pairs == non_adjacent.size());
    REQUIRE(r.stats.feature_pairs_vf == features.vf.size());
    REQUIRE(r.stats.feature_pairs_ee == features.ee.size());
    REQUIRE(r.contacts.vf.size() == expected.vf.size());
    REQUIRE(r.contacts.ee.size() == expected.ee.size());
    for (std::size_t i = 0; i < expected.vf.size(); ++i) REQUIRE(r.contacts.vf[i].toi == expected.vf[i].toi);
    REQUIRE(r.contacts.earliest_toi == expected.earliest_toi);
    CHECK(r.stats.hits_vf + r.stats.hits_ee > 0);
    CHECK(r.stats.restarted_from_root == (s == 0));
  }
}
