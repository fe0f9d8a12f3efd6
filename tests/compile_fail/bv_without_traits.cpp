// Must NOT compile: a bounding volume with no bv_traits specialization.
#include "lwsccd/geometry/bv_traits.hpp"
struct Sphere {
  float r;
};
static_assert(lwsccd::require_bounding_volume<Sphere>::value, "");
int main() {}
