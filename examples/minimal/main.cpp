// The smallest lwsccd program: two moving triangles, their swept boxes, the candidate pair, its
// vertex-face / edge-edge feature pairs and the contacts among them with their time of impact.
// Built against the installed package by CI.
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
  const auto contacts =
      cpu::test_feature_pairs<CertifiedCcd, double>(*step.mesh, step.x0, step.x1, features);
  std::printf("%zu candidate triangle pair(s), %zu vertex-face and %zu edge-edge feature pairs, "
              "%zu + %zu in contact, earliest at t = %.6f\n",
              pairs.size(), features.vf.size(), features.ee.size(), contacts.vf.size(), contacts.ee.size(),
              contacts.earliest_toi);
  // The falling triangle's vertices reach z = 0 at t = 0.5, inside the still one.
  const bool ok = pairs.size() == 1 && features.vf.size() == 6 && features.ee.size() == 9 && contacts.vf.size() >= 3 &&
                  contacts.earliest_toi <= 0.5 && contacts.earliest_toi > 0.49;
  return ok ? 0 : 1;
}
