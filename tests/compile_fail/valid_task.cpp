// MUST compile: the control case of the compile-fail tests (same flags, a valid task and BV).
#include "lwsccd/traversal/bvtt.hpp"
static_assert(lwsccd::require_traversal_task<lwsccd::SelfCollisionTask<lwsccd::Aabbf>>::value, "");
static_assert(lwsccd::require_bounding_volume<lwsccd::Obbd>::value, "");
int main() {}
