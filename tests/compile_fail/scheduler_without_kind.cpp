// Must NOT compile: a scheduler policy with knobs but no kind tag (traverse() would not know which
// scheduler runs it).
#include "lwsccd/traversal/scheduler_policies.hpp"
struct Policy {
  static constexpr int kBlockThreads = 256;
  static constexpr int kSharedStack = 2048;
};
static_assert(lwsccd::gpu::detail::require_scheduler_policy<Policy>::value, "");
int main() {}
