// Differential fuzzing of the GPU backend (hidden tag [.fuzz]: its own CTest entry, skipped
// without a GPU; LWSCCD_FUZZ_SEED / LWSCCD_FUZZ_SCENES choose the scenes, reproducibly): every
// scheduler, both BVs, both methods and both precisions (24 pipelines a scene), and two AABB
// pipelines in parts under a budget (8 more), against the oracle of fuzz_check.hpp.
#include <catch2/catch.hpp>

#include <memory>

#include "lwsccd/pipeline.cuh"
#include "fuzz_check.hpp"

using namespace lwsccd;

namespace {

template <class BV, class Scheduler, class Method, class T>
void check_gpu(const char* config, const lwsccd_test::FuzzScene& s, CcdMode mode, const NarrowPhaseResult<T>& oracle) {
  INFO("pipeline " << config << ", " << (std::is_same<T, float>::value ? "float" : "double") << ", "
                   << (lwsccd::detail::certified_of<Method>::value ? "CertifiedCcd" : "Filtered<InclusionCcd>"));
  auto& times = lwsccd_test::fuzz_times();
  auto pipeline = lwsccd_test::fuzz_timed(times.construct, [&] {
    return std::make_unique<gpu::CcdPipeline<BV, Scheduler, Method, T>>(s.mesh, s.layout, lwsccd_test::fuzz_params(s, mode));
  });
  const auto got = lwsccd_test::fuzz_timed(times.step, [&] { return pipeline->step(s.x0, s.x1); });
  lwsccd_test::require_fuzz_agreement<BV>(got, oracle, s);
}

// Every scheduler and BV with one method and precision, against that method's oracle.
template <class Method, class T>
void check_gpu_all(const lwsccd_test::FuzzScene& s, CcdMode mode) {
  const auto oracle = lwsccd_test::fuzz_timed(lwsccd_test::fuzz_times().oracle, [&] { return lwsccd_test::fuzz_oracle<Method, T>(s, mode); });
  check_gpu<Aabbf, gpu::LazyStealScheduler, Method, T>("AABB lazy", s, mode, oracle);
  check_gpu<Aabbf, gpu::StaticTaskList, Method, T>("AABB static", s, mode, oracle);
  check_gpu<Aabbf, gpu::GProximityBalancer, Method, T>("AABB gproximity", s, mode, oracle);
  check_gpu<Obbf, gpu::LazyStealScheduler, Method, T>("OBB lazy", s, mode, oracle);
  check_gpu<Obbf, gpu::StaticTaskList, Method, T>("OBB static", s, mode, oracle);
  check_gpu<Obbf, gpu::GProximityBalancer, Method, T>("OBB gproximity", s, mode, oracle);
  // Steps in parts: a few candidate pairs (and orphans) a part, under a budget (the streamed path).
  if (!lwsccd_test::fuzz_in_parts(s.seed)) return;
  lwsccd_test::fuzz_timed(lwsccd_test::fuzz_times().parts, [&] {
    PipelineParams parts = lwsccd_test::fuzz_part_params(s, mode);
    parts.device_memory_budget = std::size_t(1) << 30;
    gpu::CcdPipeline<Aabbf, gpu::LazyStealScheduler, Method, T> lazy_parts(s.mesh, s.layout, parts);
    lwsccd_test::require_parts_agreement(lazy_parts.step(s.x0, s.x1), oracle, mode);
    gpu::CcdPipeline<Aabbf, gpu::StaticTaskList, Method, T> static_parts(s.mesh, s.layout, parts);
    lwsccd_test::require_parts_agreement(static_parts.step(s.x0, s.x1), oracle, mode);
  });
}

}  // namespace

TEST_CASE("fuzz: random scenes through every GPU scheduler x BV x method x precision equal the oracle", "[.fuzz][gpu]") {
  lwsccd_test::run_fuzz("GPU", "(3 schedulers x 2 BVs + 2 in parts) x 2 methods x 2 precisions", [](const lwsccd_test::FuzzScene& s, CcdMode mode) {
    check_gpu_all<CertifiedCcd, double>(s, mode);
    check_gpu_all<CertifiedCcd, float>(s, mode);
    check_gpu_all<Filtered<InclusionCcd>, double>(s, mode);
    check_gpu_all<Filtered<InclusionCcd>, float>(s, mode);
  });
}
