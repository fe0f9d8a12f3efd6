// The smallest lwsccd program: two moving triangles, their swept boxes, the candidate pair and
// its vertex-face / edge-edge feature pairs. Built against the installed package by CI.
#include <cstdio>
#include <memory>

#include <lwsccd/lwsccd.hpp>

int main() {
  using namespace lwsccd;
  // Triangle 0 lies still in z = 0; triangle 1 falls through it during the step.
  Step step;
  step.mesh = std::make_shared<const TriangleMesh>(6, std::vector<Face>{{{0, 1, 2}}, {{3, 4, 5}}});
  step.x0 = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.2, 0.2, 0.5}, {0.6, 0.2, 0.5}, {0.2, 0.6, 0.5}};
  step.x1 = step.x0;
  for (int v = 3; v < 6; ++v) step.x1[v].z = -0.5;

  const auto boxes = swept_triangle_bvs<Aabbd>(*step.mesh, step.x0, step.x1);
  const auto pairs = brute_force_pairs(*step.mesh, boxes);
  const FeaturePairs features = feature_pairs(*step.mesh, pairs);
  std::printf("%zu candidate triangle pair(s), %zu vertex-face and %zu edge-edge feature pairs\n", pairs.size(),
              features.vf.size(), features.ee.size());
  return pairs.size() == 1 && features.vf.size() == 6 && features.ee.size() == 9 ? 0 : 1;
}
