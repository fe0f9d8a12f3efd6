// Must NOT compile: a traversal task that does not say how many items one process() pushes.
#include "lwsccd/traversal/traversal_task.hpp"
struct Task {
  using item_type = int;
  using result_type = int;
  static constexpr int kMaxResults = 1;
  template <class Out>
  void process(const int&, Out&) const {}
};
static_assert(lwsccd::require_traversal_task<Task>::value, "");
int main() {}
