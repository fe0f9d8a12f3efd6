// The CPU backend without oneTBB (std::threads started per call; what a build without libtbb-dev
// runs): the thread limit holds inside ThreadLimit::run, and every thread count gives the same
// steps. A program of its own, so that this fallback and the TBB build never meet in one binary.
#undef LWSCCD_WITH_TBB
#define LWSCCD_WITH_TBB 0

#include <algorithm>
#include <cstdio>

#include "lwsccd/pipeline/cpu_pipeline.hpp"
#include "lwsccd/simulation/simulation.hpp"

template <class Hits>
bool same_hits(const Hits& a, const Hits& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (a[i].first != b[i].first || a[i].second != b[i].second || a[i].toi != b[i].toi) return false;
  return true;
}

int main() {
  static_assert(!lwsccd::cpu::kUsesTbb, "this program tests the std::thread fallback");
  int failures = 0;
  auto check = [&](bool ok, const char* what) {
    if (!ok) std::printf("FAILED: %s\n", what), ++failures;
  };
  check(lwsccd::cpu::ThreadLimit(3).run([] { return lwsccd::detail::worker_count(); }) == 3u, "3 workers inside the limit");
  check(lwsccd::detail::worker_count() >= 1u, "every core outside it");
  lwsccd::ClothBallSimulation simulation(6000);
  simulation.advance(30);
  auto with_threads = [&](unsigned n) {
    lwsccd::PipelineParams params;
    params.threads = n;
    return lwsccd::cpu::CcdPipeline<>(simulation.mesh(), simulation.layout(), params);
  };
  auto one = with_threads(1), three = with_threads(3);
  std::size_t contacts = 0;
  for (int s = 0; s < 3; ++s) {
    const lwsccd::Step step = simulation.next_step();
    const auto a = one.step(step.x0, step.x1), b = three.step(step.x0, step.x1);
    check(same_hits(a.contacts.vf, b.contacts.vf) && same_hits(a.contacts.ee, b.contacts.ee), "same contacts and TOIs");
    check(a.stats.triangle_pairs == b.stats.triangle_pairs && a.stats.front_size == b.stats.front_size, "same counts");
    contacts += a.contacts.vf.size() + a.contacts.ee.size();
  }
  check(contacts > 0, "the steps have contacts");
  // A traversal from the root hands parts of a thread's stack on (here to the same thread, after
  // its item): the results and work of one thread.
  {
    const lwsccd::Step step = simulation.next_step();
    const lwsccd::cpu::Bvh<lwsccd::Aabbf> bvh(*simulation.mesh(), step.x0, step.x1);
    const lwsccd::SelfCollisionTask<lwsccd::Aabbf> task{bvh.view(), lwsccd::LeafFilter{nullptr, nullptr, simulation.mesh()->faces().data(), false}};
    auto serial = lwsccd::cpu::traverse(task, {lwsccd::NodePair{0, 0}}, true);
    auto stolen = lwsccd::cpu::traverse(task, {lwsccd::NodePair{0, 0}}, true, lwsccd::cpu::WorkStealingScheduler{3});
    std::sort(serial.results.begin(), serial.results.end());
    std::sort(stolen.results.begin(), stolen.results.end());
    check(stolen.stats.handed_on > 0, "parts of a stack handed on");
    check(stolen.results == serial.results && stolen.front.size() == serial.front.size() &&
              stolen.stats.items_processed == serial.stats.items_processed,
          "the traversal's results, front and work");
  }
  std::printf("CPU backend without oneTBB: %zu contacts over 3 steps, 1 and 3 threads alike; %d failures\n", contacts, failures);
  return failures ? 1 : 0;
}
