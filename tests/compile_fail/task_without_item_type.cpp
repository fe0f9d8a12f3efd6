// Must NOT compile: a traversal task without item_type.
#include "lwsccd/traversal/traversal_task.hpp"
struct Task {
  using result_type = int;
  static constexpr int kMaxChildren = 1;
  static constexpr int kMaxResults = 1;
  template <class Out>
  void process(const int&, Out&) const {}
};
static_assert(lwsccd::require_traversal_task<Task>::value, "");
int main() {}
