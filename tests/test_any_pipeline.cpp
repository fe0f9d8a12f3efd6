// Policies chosen by name (any_pipeline.hpp): the run-time dispatch gives the pipeline the
// compile-time policies would, names are validated, and the CPU backend refuses device positions.
#include <catch2/catch.hpp>

#include "lwsccd/pipeline/any_pipeline.hpp"
#include "contact_compare.hpp"
#include "scene_fixtures.hpp"

using namespace lwsccd;

namespace {

template <class BV, class Method, class T>
void require_same_as_direct(const PolicyChoice& choice) {
  const auto m = lwsccd_test::folded_cloth(14, 3);
  auto mesh = std::make_shared<const TriangleMesh>(m.mesh);
  PipelineParams params;
  auto any = cpu::make_any_pipeline(mesh, BodyLayout{}, params, choice);
  cpu::CcdPipeline<BV, Method, T> direct(mesh, params);
  const StepOutcome got = any->step(m.x0, m.x1);
  const NarrowPhaseResult<double> expected = lwsccd::detail::to_double(direct.step(m.x0, m.x1).contacts);
  lwsccd_test::require_same_contacts(got.contacts, expected);
  lwsccd_test::require_same_counts(got.contacts.vf_counts, expected.vf_counts);
  CHECK(got.contacts.vf.size() + got.contacts.ee.size() > 0);
  CHECK(any->backend() == "cpu");
  CHECK(any->mesh().num_faces() == mesh->num_faces());
}

}  // namespace

TEST_CASE("AnyPipeline: policies by name equal the compile-time pipeline", "[any_pipeline]") {
  require_same_as_direct<Aabbf, CertifiedCcd, double>(PolicyChoice{});
  require_same_as_direct<Obbf, Filtered<InclusionCcd>, float>(PolicyChoice{"obb", "lazy", "filtered-inclusion", "float"});
  require_same_as_direct<Aabbf, CertifiedCcd, float>(PolicyChoice{"aabb", "static", "certified", "float"});
}

TEST_CASE("AnyPipeline: unknown names and device positions on the CPU are clear errors", "[any_pipeline]") {
  CHECK_THROWS_WITH(validate(PolicyChoice{"sphere", "lazy", "certified", "double"}),
                    Catch::Contains("bv") && Catch::Contains("'sphere'") && Catch::Contains("aabb, obb"));
  CHECK_THROWS_AS(validate(PolicyChoice{"aabb", "fifo", "certified", "double"}), InputError);
  CHECK_THROWS_AS(validate(PolicyChoice{"aabb", "lazy", "exact", "double"}), InputError);
  CHECK_THROWS_WITH(validate(PolicyChoice{"aabb", "lazy", "certified", "half"}), Catch::Contains("float"));
  const auto m = lwsccd_test::folded_cloth(4, 1);
  auto mesh = std::make_shared<const TriangleMesh>(m.mesh);
  CHECK_THROWS_AS(cpu::make_any_pipeline(mesh, BodyLayout{}, PipelineParams{}, PolicyChoice{"obb", "lazy", "cubic", "quad"}),
                  InputError);
  auto any = cpu::make_any_pipeline(mesh, BodyLayout{}, PipelineParams{}, PolicyChoice{});
  CHECK_THROWS_WITH(any->step_from_device(m.x0.data(), m.x1.data()), Catch::Contains("host positions"));
  CHECK_THROWS_AS(any->step_on_device(m.x0.data(), m.x1.data()), InputError);
}

TEST_CASE("AnyPipeline: float positions are certified as given (the pipeline on their exact double values)",
          "[any_pipeline][float_input]") {
  // Float input is widened exactly, so its answers are those of the double pipeline on the float
  // values, pair for pair and count for count; rounding moved some points, so the contacts of the
  // float positions are a different (not necessarily equal) set from the double positions'.
  const auto m = lwsccd_test::folded_cloth(14, 3);
  auto mesh = std::make_shared<const TriangleMesh>(m.mesh);
  const auto [f0, f1, w0, w1] = lwsccd_test::float_rounded(m.x0, m.x1);
  CHECK(w0 != m.x0);  // rounding changed the input
  auto any = cpu::make_any_pipeline(mesh, BodyLayout{}, PipelineParams{}, PolicyChoice{});
  cpu::CcdPipeline<> direct(mesh);
  const StepOutcome got = any->step(f0, f1);
  const auto expected = direct.step(w0, w1);
  lwsccd_test::require_same_contacts(got.contacts, expected.contacts);
  lwsccd_test::require_same_counts(got.contacts.vf_counts, expected.contacts.vf_counts);
  lwsccd_test::require_same_counts(got.contacts.ee_counts, expected.contacts.ee_counts);
  CHECK(got.contacts.vf.size() + got.contacts.ee.size() > 0);
  CHECK_THROWS_AS(any->step(std::vector<Vec3f>(f0.begin(), f0.end() - 1), f1), InputError);
  CHECK_THROWS_WITH(any->step_from_device(f0.data(), f1.data()), Catch::Contains("host positions"));
}

TEST_CASE("AnyPipeline: step_into from host arrays equals step, double and float, outcome after outcome",
          "[any_pipeline][step_into]") {
  const auto first = lwsccd_test::folded_cloth(14, 1);
  auto mesh = std::make_shared<const TriangleMesh>(first.mesh);
  auto stepped = cpu::make_any_pipeline(mesh, BodyLayout{}, PipelineParams{}, PolicyChoice{});
  auto into = cpu::make_any_pipeline(mesh, BodyLayout{}, PipelineParams{}, PolicyChoice{});
  StepOutcome kept;
  std::size_t contacts = 0;
  for (const int s : {1, 4, 2}) {  // (the counts change from step to step)
    INFO("fold step " << s);
    const auto m = lwsccd_test::folded_cloth(14, s);
    const StepOutcome expected = stepped->step(m.x0, m.x1);
    into->step_into(Span<const Vec3d>(m.x0.data(), m.x0.size()), Span<const Vec3d>(m.x1.data(), m.x1.size()), kept);
    lwsccd_test::require_same_contacts(kept.contacts, expected.contacts);
    CHECK(kept.stats.hits_vf == expected.stats.hits_vf);
    CHECK(kept.stats.triangle_pairs == expected.stats.triangle_pairs);
    contacts += kept.contacts.vf.size() + kept.contacts.ee.size();
  }
  CHECK(contacts > 0);
  // Float arrays: as step() on the same float vectors.
  const auto m = lwsccd_test::folded_cloth(14, 3);
  const lwsccd_test::FloatRounded r = lwsccd_test::float_rounded(m.x0, m.x1);
  const std::vector<Vec3f>& f0 = r.f0;
  const std::vector<Vec3f>& f1 = r.f1;
  const StepOutcome expected = stepped->step(f0, f1);
  into->step_into(Span<const Vec3f>(f0), Span<const Vec3f>(f1), kept);
  lwsccd_test::require_same_contacts(kept.contacts, expected.contacts);
  CHECK_THROWS_AS(into->step_into(Span<const Vec3f>(f0.data(), f0.size() - 1), Span<const Vec3f>(f1), kept), InputError);
}
