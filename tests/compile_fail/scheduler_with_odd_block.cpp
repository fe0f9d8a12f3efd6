// Must NOT compile: a scheduler policy whose blocks are not whole warps.
#include "lwsccd/traversal/scheduler_policies.hpp"
struct OddBlocks : lwsccd::gpu::LazyStealScheduler {
  static constexpr int kBlockThreads = 100;
};
static_assert(lwsccd::gpu::detail::require_scheduler_policy<OddBlocks>::value, "");
int main() {}
