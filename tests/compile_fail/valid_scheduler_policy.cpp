// Must compile: policies derived from the library's, knobs overridden by name; a derived knob
// (kShareWhenHungry: half of kPushThreshold unless set) follows the overridden one.
#include "lwsccd/traversal/scheduler_policies.hpp"
struct SmallBlocks : lwsccd::gpu::LazyStealScheduler {
  static constexpr int kBlockThreads = 128;
  static constexpr int kPushThreshold = 2048;
};
struct DeepStatic : lwsccd::gpu::StaticTaskList {
  static constexpr int kSharedStack = 4096;
};
using lwsccd::gpu::detail::require_scheduler_policy;
using lwsccd::gpu::detail::share_when_hungry;
static_assert(require_scheduler_policy<SmallBlocks>::value && require_scheduler_policy<DeepStatic>::value &&
                  require_scheduler_policy<lwsccd::gpu::RayWalkLazySteal>::value &&
                  require_scheduler_policy<lwsccd::gpu::GProximityBalancer>::value, "");
static_assert(share_when_hungry<lwsccd::gpu::LazyStealScheduler>() == 512, "the default: half of 1,024");
static_assert(share_when_hungry<SmallBlocks>() == 1024, "recomputed from the derived kPushThreshold");
static_assert(SmallBlocks::kPopSize == lwsccd::gpu::LazyStealScheduler::kPopSize, "knobs not overridden are inherited");
int main() {}
