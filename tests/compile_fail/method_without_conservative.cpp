// Must NOT compile: a CCD method that does not say whether it is conservative.
#include "lwsccd/narrow_phase/ccd_query.hpp"
struct Method {
  static constexpr const char* name = "unsaid";
  template <class T>
  static lwsccd::CcdResult<T> vertex_face(const lwsccd::VertexFaceQuery<T>&, const lwsccd::CcdParams<T>&) {
    return {};
  }
  template <class T>
  static lwsccd::CcdResult<T> edge_edge(const lwsccd::EdgeEdgeQuery<T>&, const lwsccd::CcdParams<T>&) {
    return {};
  }
};
static_assert(lwsccd::require_ccd_method<Method>::value, "");
int main() {}
