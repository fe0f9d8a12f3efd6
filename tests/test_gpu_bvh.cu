// GPU LBVH build and refit against the CPU backend, node for node.
#include <catch2/catch.hpp>

#include <cstring>
#include <numeric>
#include <random>

#include "lwsccd/bvh/bvh.cuh"
#include "lwsccd/io/dataset.hpp"
#include "lwsccd/io/mesh_io.hpp"
#include "scene_fixtures.hpp"
#include "test_support.hpp"

using namespace lwsccd;
using lwsccd_test::MovingMesh;

namespace {

template <class P>
std::vector<Vec3<P>> as(const std::vector<Vec3d>& x) {
  std::vector<Vec3<P>> out(x.size());
  for (std::size_t i = 0; i < x.size(); ++i) out[i] = x[i].template cast<P>();
  return out;
}

// Host and device round alike (detail/fp.hpp), so node values must agree bit for bit, OBBs too.
template <class BV>
bool same_value(const BV& a, const BV& b) {
  return std::memcmp(&a, &b, sizeof(BV)) == 0;
}

// Same topology exactly and BVs bit for bit; the GPU tree also passes every invariant on its own.
template <class BV, class P>
void compare_trees(const BvhNodes<BV>& gpu, const BvhNodes<BV>& cpu_nodes, const std::vector<Face>& faces,
                   const std::vector<Vec3<P>>& x0, const std::vector<Vec3<P>>& x1) {
  REQUIRE(gpu.num_leaves == cpu_nodes.num_leaves);
  REQUIRE(gpu.leaf_codes == cpu_nodes.leaf_codes);
  REQUIRE(gpu.leaf_primitive == cpu_nodes.leaf_primitive);
  REQUIRE(gpu.left == cpu_nodes.left);
  REQUIRE(gpu.right == cpu_nodes.right);
  REQUIRE(gpu.parent == cpu_nodes.parent);
  for (std::size_t i = 0; i < gpu.ranges.size(); ++i) {
    REQUIRE(gpu.ranges[i].first == cpu_nodes.ranges[i].first);
    REQUIRE(gpu.ranges[i].last == cpu_nodes.ranges[i].last);
  }
  std::size_t differing = 0;
  for (std::size_t i = 0; i < gpu.bvs.size(); ++i) differing += !same_value(gpu.bvs[i], cpu_nodes.bvs[i]);
  CHECK(differing == 0);
  REQUIRE(check_bvh_invariants(gpu.view(), faces, x0, x1) == "");
}

template <class BV, class P>
void build_and_refit_match(const TriangleMesh& mesh, const std::vector<Vec3d>& a0, const std::vector<Vec3d>& a1,
                           const std::vector<Vec3d>& b0, const std::vector<Vec3d>& b1) {
  gpu::DeviceStep<P> step(mesh, a0, a1);
  gpu::Bvh<BV> gbvh;
  gbvh.build(step);
  cpu::Bvh<BV> cbvh(mesh, as<P>(a0), as<P>(a1));
  compare_trees(gbvh.download(), cbvh.nodes(), mesh.faces(), as<P>(a0), as<P>(a1));
  // The cost is a sum in another order (CUB) of surface areas: equal up to rounding.
  CHECK(gbvh.cost_at_build() == Approx(cbvh.cost_at_build()).epsilon(1e-6));
  step.set_positions(b0, b1);
  gbvh.refit(step);
  gbvh.check_status();
  cbvh.refit(as<P>(b0), as<P>(b1));
  compare_trees(gbvh.download(), cbvh.nodes(), mesh.faces(), as<P>(b0), as<P>(b1));
}

}  // namespace

TEMPLATE_TEST_CASE("GPU LBVH equals the CPU LBVH on procedural meshes", "[gpu][bvh]", Aabbf, Aabbd, Obbf, Obbd) {
  using BV = TestType;
  const MovingMesh cloth_a = lwsccd_test::folded_cloth(60, 1), cloth_b = lwsccd_test::folded_cloth(60, 2);
  build_and_refit_match<BV, double>(cloth_a.mesh, cloth_a.x0, cloth_a.x1, cloth_b.x0, cloth_b.x1);
  build_and_refit_match<BV, float>(cloth_a.mesh, cloth_a.x0, cloth_a.x1, cloth_b.x0, cloth_b.x1);
  // (The refit counts arrivals at nodes within a block of gpu::detail::kRefitBlock (512) leaves in
  // shared memory: sizes about one and two blocks.)
  static_assert(gpu::detail::kRefitBlock == 512, "the sizes below straddle one and two refit blocks");
  for (const MovingMesh& m : {lwsccd_test::random_soup(5000, 3), lwsccd_test::coincident_triangles(37),
                              lwsccd_test::random_soup(1, 4), lwsccd_test::random_soup(2, 5), lwsccd_test::random_soup(511, 6),
                              lwsccd_test::random_soup(512, 7), lwsccd_test::random_soup(513, 8), lwsccd_test::random_soup(1025, 9)}) {
    INFO("faces " << m.mesh.num_faces());
    build_and_refit_match<BV, double>(m.mesh, m.x0, m.x1, m.x1, m.x0);
  }
}

TEMPLATE_TEST_CASE("GPU LBVH equals the CPU LBVH on the real scenes and horse-gallop", "[gpu][bvh][data]", Aabbf, Obbf) {
  using BV = TestType;
  if (!lwsccd_test::have_data()) {
    WARN("SKIPPED: shared data not found at " << lwsccd_test::data_dir());
    return;
  }
  for (const char* name : {"cloth-ball", "cloth-funnel", "armadillo-rollers"}) {
    INFO(name);
    const Scene scene = load_scene(lwsccd_test::data_dir() + "/scenes/" + name);
    // Refit target: the step reversed (t1 -> t0), a different set of leaf volumes.
    build_and_refit_match<BV, double>(*scene.step.mesh, scene.step.x0, scene.step.x1, scene.step.x1, scene.step.x0);
  }
  const Sequence horse = load_sequence(lwsccd_test::data_dir() + "/sequences/horse-gallop");
  gpu::DeviceStep<float> step(*horse.mesh(), horse.frame(0), horse.frame(1));
  gpu::Bvh<BV> gbvh;
  gbvh.build(step);
  cpu::Bvh<BV> cbvh(*horse.mesh(), as<float>(horse.frame(0)), as<float>(horse.frame(1)));
  for (std::size_t s = 1; s < horse.num_steps(); ++s) {
    step.set_positions(horse.frame(s), horse.frame(s + 1));
    gbvh.refit(step);
    cbvh.refit(as<float>(horse.frame(s)), as<float>(horse.frame(s + 1)));
    if (s % 5 == 0 || s + 1 == horse.num_steps()) {
      INFO("horse step " << s);
      compare_trees(gbvh.download(), cbvh.nodes(), horse.mesh()->faces(), as<float>(horse.frame(s)),
                    as<float>(horse.frame(s + 1)));
    }
  }
}

TEMPLATE_TEST_CASE("GPU LBVH refit from float positions read in place equals the refit from them widened, bit for bit",
                   "[gpu][bvh][float_input]", Aabbf, Aabbd, Obbf) {
  using BV = TestType;
  MovingMesh m = lwsccd_test::random_soup(1025, 5, 0.02);
  const std::vector<Vec3f> f0 = as<float>(m.x0), f1 = as<float>(m.x1);
  gpu::DeviceBuffer<Vec3f> d0, d1;
  d0.upload(f0);
  d1.upload(f1);
  // The reference: both arrays widened first, then the refit over the step's double arrays.
  gpu::DeviceStep<double> widened(m.mesh);
  widened.set_positions_from_device(d0.data(), d1.data());
  gpu::Bvh<BV> reference;
  reference.set_leaf_margin(typename bv_traits<BV>::scalar_type(1e-3));  // (an inflated leaf too)
  reference.build(widened);
  gpu::DeviceStep<double> later(m.mesh);
  later.widen_later(d0.data(), d1.data());
  REQUIRE(later.widening_due());
  CHECK_THROWS_WITH(later.x0_data(), Catch::Contains("widen"));
  gpu::Bvh<BV> bvh;
  bvh.set_leaf_margin(typename bv_traits<BV>::scalar_type(1e-3));
  CHECK_THROWS_WITH(bvh.build(later), Catch::Contains("widen"));  // a build reads the widened arrays
  later.enqueue_widening(nullptr);
  CHECK_FALSE(later.widening_due());
  bvh.build(later);
  // Refits to the swapped positions: one from the floats in place, one from the widened arrays.
  d0.upload(f1);
  d1.upload(f0);
  widened.set_positions_from_device(d0.data(), d1.data());
  reference.refit(widened);
  later.widen_later(d0.data(), d1.data());
  bvh.refit(later);
  bvh.check_status();
  CHECK(later.widening_due());  // the refit leaves the widening to the caller
  const BvhNodes<BV> a = bvh.download(), b = reference.download();
  REQUIRE(a.bvs.size() == b.bvs.size());
  std::size_t differing = 0;
  for (std::size_t i = 0; i < a.bvs.size(); ++i) differing += !same_value(a.bvs[i], b.bvs[i]);
  CHECK(differing == 0);
  later.enqueue_widening(nullptr);
  CHECK(later.x0.download() == widened.x0.download());
  CHECK(later.x1.download() == widened.x1.download());
  // A NaN among the floats read in place is reported, as from the widened arrays.
  std::vector<Vec3f> bad = f0;
  bad[17].y = std::numeric_limits<float>::quiet_NaN();
  d1.upload(bad);
  later.widen_later(d0.data(), d1.data());
  bvh.refit(later);
  CHECK_THROWS_WITH(bvh.check_status(), Catch::Contains("NaN"));
  CHECK_THROWS_AS(later.widen_later(f0.data(), d1.data()), InputError);
  // The widening handed to the caller (the pipeline widens in the kernel that rounds the vertices).
  later.widen_later(d0.data(), d1.data());
  const auto sources = later.take_widening();
  CHECK(sources.first == d0.data());
  CHECK(sources.second == d1.data());
  CHECK_FALSE(later.widening_due());
  CHECK(later.x0_data() == later.x0.data());
  // Host floats: set_positions widens them at once, upload_to_widen_later leaves them due; both
  // give the widened arrays. A wrong size is an InputError naming the array.
  gpu::DeviceStep<double> host(m.mesh);
  host.set_positions(f1, f0);
  CHECK_FALSE(host.widening_due());
  CHECK(host.x0.download() == widened.x0.download());
  CHECK(host.x1.download() == widened.x1.download());
  host.upload_to_widen_later(Span<const Vec3f>(f1), Span<const Vec3f>(f0));
  REQUIRE(host.widening_due());
  host.enqueue_widening(nullptr);
  CHECK(host.x0.download() == widened.x0.download());
  CHECK(host.x1.download() == widened.x1.download());
  const std::vector<Vec3f> short_f0(f0.begin(), f0.end() - 1);
  CHECK_THROWS_WITH(host.upload_to_widen_later(Span<const Vec3f>(f1), Span<const Vec3f>(short_f0)), Catch::Contains("x1"));
  CHECK_THROWS_WITH(host.set_positions(short_f0, f0), Catch::Contains("x0"));
}

TEST_CASE("GPU LBVH: bad input and the rebuild policy", "[gpu][bvh]") {
  MovingMesh m = lwsccd_test::random_soup(3000, 7, 0.01);
  gpu::Bvh<Aabbf> bvh;
  CHECK_THROWS_WITH(bvh.refit(gpu::DeviceStep<float>{}), Catch::Contains("not been built"));
  CHECK_THROWS_WITH(bvh.build(gpu::DeviceStep<float>{}), Catch::Contains("no faces"));
  auto bad = m.x1;
  bad[11].x = std::numeric_limits<double>::quiet_NaN();
  {
    gpu::DeviceStep<float> step(m.mesh, m.x0, bad);
    CHECK_THROWS_WITH(bvh.build(step), Catch::Contains("NaN"));
  }
  gpu::DeviceStep<float> step(m.mesh, m.x0, m.x1);
  bvh.build(step);
  const auto generation = bvh.generation();
  step.set_positions(m.x0, bad);
  bvh.refit(step);  // asynchronous: reported by the next check
  CHECK_THROWS_WITH(bvh.check_status(), Catch::Contains("NaN"));
  CHECK_THROWS_AS(step.set_positions(m.x0, std::vector<Vec3d>(5)), InputError);
  // Scrambled positions: the cost explodes and the policy rebuilds.
  MovingMesh scrambled = m;
  std::vector<index_t> perm(m.mesh.num_faces());
  std::iota(perm.begin(), perm.end(), 0);
  std::shuffle(perm.begin(), perm.end(), std::mt19937(3));
  for (index_t f = 0; f < m.mesh.num_faces(); ++f)
    for (int k = 0; k < 3; ++k) {
      scrambled.x0[3 * f + k] = m.x0[3 * perm[f] + k];
      scrambled.x1[3 * f + k] = m.x1[3 * perm[f] + k];
    }
  step.set_positions(m.x0, m.x1);
  CHECK_FALSE(bvh.refit_or_rebuild(step));
  step.set_positions(scrambled.x0, scrambled.x1);
  CHECK(bvh.refit_or_rebuild(step));
  CHECK(bvh.generation() == generation + 1);
  cpu::Bvh<Aabbf> reference(scrambled.mesh, as<float>(scrambled.x0), as<float>(scrambled.x1));
  compare_trees(bvh.download(), reference.nodes(), scrambled.mesh.faces(), as<float>(scrambled.x0), as<float>(scrambled.x1));
  CHECK(bvh.device_bytes() > 3000 * sizeof(Aabbf));
  CHECK(gpu::memory_stats().peak >= bvh.device_bytes());
}
