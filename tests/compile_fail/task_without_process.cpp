// Must NOT compile: a traversal task without process().
#include "lwsccd/traversal/traversal_task.hpp"
struct Task {
  using item_type = int;
  using result_type = int;
  static constexpr int kMaxChildren = 1;
  static constexpr int kMaxResults = 1;
};
static_assert(lwsccd::require_traversal_task<Task>::value, "");
int main() {}
