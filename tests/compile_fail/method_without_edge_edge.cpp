// Must NOT compile: a CCD method without edge_edge.
#include "lwsccd/narrow_phase/ccd_query.hpp"
struct Method {
  static constexpr const char* name = "half";
  static constexpr bool conservative = false;
  template <class T>
  static lwsccd::CcdResult<T> vertex_face(const lwsccd::VertexFaceQuery<T>&, const lwsccd::CcdParams<T>&) {
    return {};
  }
};
static_assert(lwsccd::require_ccd_method<Method>::value, "");
int main() {}
