// Differential fuzzing of the CPU backend (hidden tag [.fuzz]: its own CTest entry runs it with a
// fixed seed; LWSCCD_FUZZ_SEED / LWSCCD_FUZZ_SCENES choose others, reproducibly).
#include <catch2/catch.hpp>

#include <memory>

#include "lwsccd/pipeline/cpu_pipeline.hpp"
#include "fuzz_check.hpp"

using namespace lwsccd;

namespace {

template <class BV, class Method, class T>
void check_cpu(const lwsccd_test::FuzzScene& s, CcdMode mode, const NarrowPhaseResult<T>& oracle) {
  auto& times = lwsccd_test::fuzz_times();
  auto pipeline = lwsccd_test::fuzz_timed(times.construct, [&] {
    return std::make_unique<cpu::CcdPipeline<BV, Method, T>>(s.mesh, s.layout, lwsccd_test::fuzz_params(s, mode));
  });
  const auto got = lwsccd_test::fuzz_timed(times.step, [&] { return pipeline->step(s.x0, s.x1); });
  lwsccd_test::require_fuzz_agreement<BV>(got, oracle, s);
}

template <class Method, class T>
void check_cpu_all_bvs(const lwsccd_test::FuzzScene& s, CcdMode mode) {
  const auto oracle = lwsccd_test::fuzz_timed(lwsccd_test::fuzz_times().oracle, [&] { return lwsccd_test::fuzz_oracle<Method, T>(s, mode); });
  check_cpu<Aabbf, Method, T>(s, mode, oracle);
  check_cpu<Obbf, Method, T>(s, mode, oracle);
  lwsccd_test::fuzz_timed(lwsccd_test::fuzz_times().parts, [&] {
    cpu::CcdPipeline<Aabbf, Method, T> in_parts(s.mesh, s.layout, lwsccd_test::fuzz_part_params(s, mode));
    lwsccd_test::require_parts_agreement(in_parts.step(s.x0, s.x1), oracle, mode);
  });
}

}  // namespace

TEST_CASE("fuzz: random scenes through every CPU BV x method x precision, whole and in parts, equal the oracle", "[.fuzz]") {
  lwsccd_test::run_fuzz("CPU", "(2 BVs + AABB in parts) x 2 methods x 2 precisions", [](const lwsccd_test::FuzzScene& s, CcdMode mode) {
    check_cpu_all_bvs<CertifiedCcd, double>(s, mode);
    check_cpu_all_bvs<CertifiedCcd, float>(s, mode);
    check_cpu_all_bvs<Filtered<InclusionCcd>, double>(s, mode);
    check_cpu_all_bvs<Filtered<InclusionCcd>, float>(s, mode);
  });
}
