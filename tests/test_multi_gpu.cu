// A step split over GPUs: shares of the BVTT that find each contact once (several pipelines on one
// GPU), gpu::MultiGpuPipeline against one GPU pair for pair and TOI for TOI over moving fronts,
// restarts and modes, from one process and from one process per GPU (ncclCommInitRank).
// Cases that need two GPUs say so and pass where there is one.
#define CATCH_CONFIG_RUNNER
#include <catch2/catch.hpp>

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "lwsccd/io/dataset.hpp"
#include "lwsccd/multi_gpu.cuh"
#include "lwsccd/simulation/scenes.hpp"
#include "lwsccd/simulation/simulation.hpp"
#include "contact_compare.hpp"
#include "scene_fixtures.hpp"
#include "test_support.hpp"

extern char** environ;

using namespace lwsccd;

namespace {

int device_count() {
  int n = 0;
  return cudaGetDeviceCount(&n) == cudaSuccess ? n : 0;
}

// The hits of several shares, merged and sorted as one pipeline gives them.
NarrowPhaseResult<double> merged(const std::vector<StepResult<double>>& shares) {
  NarrowPhaseResult<double> all;
  for (const auto& s : shares) add_narrow_phase_part(s.contacts, all);
  std::sort(all.vf.begin(), all.vf.end());
  std::sort(all.ee.begin(), all.ee.end());
  return all;
}

// A sequence of steps of the built-in scene (cloth over a ball: two bodies, the ball's pruned).
std::vector<Step> builtin_steps(std::size_t triangles, int steps, std::shared_ptr<ClothBallSimulation>& sim) {
  sim = std::make_shared<ClothBallSimulation>(triangles);
  sim->advance(30);
  std::vector<Step> out;
  for (int s = 0; s < steps; ++s) out.push_back(sim->next_step());
  return out;
}

}  // namespace

TEST_CASE("Shares of the BVTT on one GPU find every contact once: pipelines with set_share equal one pipeline",
          "[multi_gpu][share]") {
  std::shared_ptr<ClothBallSimulation> sim;
  const std::vector<Step> steps = builtin_steps(20000, 6, sim);
  for (std::size_t count : {2, 3}) {
    INFO(count << " shares");
    gpu::CcdPipeline<> whole(sim->mesh(), sim->layout());
    std::vector<std::unique_ptr<gpu::CcdPipeline<>>> shares;
    for (std::size_t k = 0; k < count; ++k) {
      shares.push_back(std::make_unique<gpu::CcdPipeline<>>(sim->mesh(), sim->layout()));
      shares.back()->set_share(k, count);
    }
    for (std::size_t s = 0; s < steps.size(); ++s) {
      INFO("step " << s);
      // Rebuilds and restarts together, as MultiGpuPipeline agrees on them.
      bool rebuild = false, restart = false;
      for (auto& p : shares) rebuild = rebuild || p->rebuild_due(), restart = restart || p->wants_restart();
      for (auto& p : shares) {
        if (rebuild) p->rebuild_next();
        if (rebuild || restart) p->restart_from_root();
      }
      const StepResult<double> w = whole.step(steps[s].x0, steps[s].x1);
      std::vector<StepResult<double>> parts;
      std::size_t triangle_pairs = 0, feature_pairs = 0, front = 0;
      for (auto& p : shares) {
        parts.push_back(p->step(steps[s].x0, steps[s].x1));
        triangle_pairs += parts.back().stats.triangle_pairs;
        feature_pairs += parts.back().stats.feature_pairs_vf + parts.back().stats.feature_pairs_ee;
        front += p->kept_front_size();
        CHECK(parts.back().stats.restarted_from_root == parts.front().stats.restarted_from_root);
        if (s == 0) CHECK(parts.back().stats.restarted_from_root);
      }
      const NarrowPhaseResult<double> all = merged(parts);
      lwsccd_test::require_same_hits(all.vf, w.contacts.vf);
      lwsccd_test::require_same_hits(all.ee, w.contacts.ee);
      CHECK(all.earliest_toi == w.contacts.earliest_toi);
      // Nothing found twice: the candidate and feature pairs add up to one pipeline's.
      CHECK(triangle_pairs == w.stats.triangle_pairs);
      CHECK(feature_pairs == w.stats.feature_pairs_vf + w.stats.feature_pairs_ee);
      CHECK(front > 0);
      CHECK(w.stats.hits_vf + w.stats.hits_ee > 0);
      // Front entries moved from the first share to the last: still one partition.
      if (s == 2) {
        gpu::CcdPipeline<>& from = *shares.front();
        gpu::CcdPipeline<>& to = *shares.back();
        const std::size_t move = from.kept_front_size() / 3, keep = from.kept_front_size() - move, had = to.kept_front_size();
        REQUIRE(move > 0);
        to.resize_kept_front(had + move, nullptr);
        LWSCCD_CUDA_CHECK(cudaMemcpy(to.kept_front() + had, from.kept_front() + keep, move * sizeof(NodePair), cudaMemcpyDeviceToDevice));
        from.resize_kept_front(keep, nullptr);
      }
    }
  }
  gpu::CcdPipeline<> p(sim->mesh());
  CHECK_THROWS_AS(p.set_share(2, 2), InputError);
  CHECK_THROWS_AS(p.set_share(0, 0), InputError);
  PipelineParams streamed;
  streamed.part_pairs = 1000;
  gpu::CcdPipeline<> q(sim->mesh(), streamed);
  CHECK_THROWS_AS(q.set_share(0, 2), InputError);
  CHECK_NOTHROW(q.set_share(0, 1));
  // A budget set after the share: refused at the step, not streamed with duplicates.
  gpu::CcdPipeline<> r(sim->mesh(), sim->layout());
  r.set_share(1, 2);
  r.set_device_memory_budget(std::size_t(1) << 30);
  CHECK_THROWS_AS(r.step(steps[0].x0, steps[0].x1), InputError);
}

TEST_CASE("A share of a mesh with fewer node pairs than shares finds its part, maybe none", "[multi_gpu][share]") {
  const auto m = lwsccd_test::folded_cloth(2, 1);  // 8 triangles
  auto mesh = std::make_shared<const TriangleMesh>(m.mesh);
  gpu::CcdPipeline<> whole(mesh);
  const StepResult<double> w = whole.step(m.x0, m.x1);
  std::vector<StepResult<double>> parts;
  for (std::size_t k = 0; k < 5; ++k) {
    gpu::CcdPipeline<> share(mesh);
    share.set_share(k, 5);
    parts.push_back(share.step(m.x0, m.x1));
  }
  const NarrowPhaseResult<double> all = merged(parts);
  lwsccd_test::require_same_hits(all.vf, w.contacts.vf);
  lwsccd_test::require_same_hits(all.ee, w.contacts.ee);
}

TEST_CASE("MultiGpuPipeline refuses bad devices and positions with InputError", "[multi_gpu]") {
  std::shared_ptr<ClothBallSimulation> sim;
  const std::vector<Step> steps = builtin_steps(2000, 1, sim);
  const int n = device_count();
  CHECK_THROWS_AS(gpu::MultiGpuPipeline<>(sim->mesh(), std::vector<int>{}), InputError);
  CHECK_THROWS_AS(gpu::MultiGpuPipeline<>(sim->mesh(), std::vector<int>{n}), InputError);
  CHECK_THROWS_AS(gpu::MultiGpuPipeline<>(sim->mesh(), std::vector<int>{0, 0}), InputError);
  CHECK_THROWS_AS(gpu::MultiGpuPipeline<>(nullptr, std::vector<int>{0}), InputError);
  PipelineParams budget;
  budget.device_memory_budget = std::size_t(1) << 30;
  if (n >= 2) CHECK_THROWS_AS(gpu::MultiGpuPipeline<>(sim->mesh(), std::vector<int>{0, 1}, budget), InputError);
  gpu::MultiGpuPipeline<> one(sim->mesh(), sim->layout(), std::vector<int>{0});
  std::vector<Vec3d> short_x = steps[0].x0;
  short_x.pop_back();
  CHECK_THROWS_AS(one.step(short_x, steps[0].x1), InputError);
}

TEST_CASE("MultiGpuPipeline equals one GPU pair for pair over steps with fronts moved between GPUs, restarts and modes",
          "[multi_gpu]") {
  const int n = device_count();
  std::shared_ptr<ClothBallSimulation> sim;
  const std::vector<Step> steps = builtin_steps(60000, 8, sim);
  std::vector<int> devices;
  for (int d = 0; d < std::min(n, 2); ++d) devices.push_back(d);
  if (n < 2) WARN("SKIPPED in part: one CUDA device; the split runs as one share on it");
  for (CcdMode mode : {CcdMode::contacts, CcdMode::earliest, CcdMode::set}) {
    INFO("mode " << static_cast<int>(mode));
    PipelineParams params;
    params.mode = mode;
    gpu::CcdPipeline<> one(sim->mesh(), sim->layout(), params);
    gpu::MultiGpuPipeline<> split(sim->mesh(), sim->layout(), devices, params);
    REQUIRE(split.num_shares() == devices.size());
    gpu::DeviceBuffer<Vec3d> x0, x1;
    std::size_t moved = 0, from_front = 0;
    for (std::size_t s = 0; s < steps.size(); ++s) {
      INFO("step " << s);
      if (s == 5) split.restart_from_root();
      const StepResult<double> w = one.step(steps[s].x0, steps[s].x1);
      gpu::MultiGpuStepResult<double> m;
      if (s % 2 == 0) {
        m = split.step(steps[s].x0, steps[s].x1);
      } else {
        x0.upload(steps[s].x0);
        x1.upload(steps[s].x1);
        LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
        m = split.step_from_device(x0.data(), x1.data());
      }
      if (mode == CcdMode::earliest) {
        // (Each GPU skips its own windows once one holds a contact: the counts are its own.)
        CHECK(m.contacts.vf.empty());
        CHECK(m.contacts.ee.empty());
        REQUIRE(m.contacts.earliest_toi == w.contacts.earliest_toi);
      } else {
        lwsccd_test::require_same_contacts(m.contacts, w.contacts);
        lwsccd_test::require_same_counts(m.contacts.vf_counts, w.contacts.vf_counts);
        lwsccd_test::require_same_counts(m.contacts.ee_counts, w.contacts.ee_counts);
        CHECK(m.stats.hits_vf == w.stats.hits_vf);
      }
      CHECK(m.stats.triangle_pairs == w.stats.triangle_pairs);
      CHECK(m.stats.feature_pairs_vf == w.stats.feature_pairs_vf);
      REQUIRE(m.devices.size() == devices.size());
      if (s == 0 || s == 5) CHECK(m.stats.restarted_from_root);
      for (const StepStats& d : m.devices) CHECK(d.restarted_from_root == m.stats.restarted_from_root);  // together
      for (const StepStats& d : m.devices) CHECK(d.peak_device_bytes > 0);
      moved += m.moved_front_entries;
      from_front += !m.stats.restarted_from_root;
    }
    CHECK(from_front >= 4);
    std::printf("MultiGpuPipeline on %zu GPU(s), mode %d: %zu front entries moved over %zu steps\n", devices.size(),
                static_cast<int>(mode), moved, steps.size());
    // Contacts left on the root GPU: the same once copied.
    x0.upload(steps.back().x0);
    x1.upload(steps.back().x1);
    LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
    const StepResult<double> w = one.step(steps.back().x0, steps.back().x1);
    const DeviceStepResult<double> d = split.step_on_device(x0.data(), x1.data());
    NarrowPhaseResult<double> copied;
    copied.vf.resize(d.contacts.num_vf);
    copied.ee.resize(d.contacts.num_ee);
    LWSCCD_CUDA_CHECK(cudaSetDevice(devices[0]));
    LWSCCD_CUDA_CHECK(cudaMemcpy(copied.vf.data(), d.contacts.vf, copied.vf.size() * sizeof(FeatureHit<double>), cudaMemcpyDeviceToHost));
    LWSCCD_CUDA_CHECK(cudaMemcpy(copied.ee.data(), d.contacts.ee, copied.ee.size() * sizeof(FeatureHit<double>), cudaMemcpyDeviceToHost));
    copied.earliest_toi = d.contacts.earliest_toi;
    copied.gave_up = d.contacts.gave_up;
    if (mode == CcdMode::earliest) {
      CHECK(copied.vf.empty());
      CHECK(copied.earliest_toi == w.contacts.earliest_toi);
    } else {
      lwsccd_test::require_same_contacts(copied, w.contacts);
    }
  }
}

TEST_CASE("MultiGpuPipeline: an error on one GPU alone ends every GPU's wait, and later steps are refused",
          "[multi_gpu][abort]") {
  if (device_count() < 2) {
    WARN("SKIPPED: needs two CUDA devices");
    return;
  }
  std::shared_ptr<ClothBallSimulation> sim;
  const std::vector<Step> steps = builtin_steps(60000, 2, sim);
  gpu::MultiGpuPipeline<> split(sim->mesh(), sim->layout(), std::vector<int>{0, 1});
  const std::size_t n = steps[0].x0.size();
  LWSCCD_CUDA_CHECK(cudaSetDevice(0));
  gpu::DeviceBuffer<Vec3d> x0, x1;
  gpu::DeviceBuffer<Vec3f> f0, f1;
  x0.upload(steps[0].x0);
  x1.upload(steps[0].x1);
  std::vector<Vec3f> f(n);
  for (std::size_t i = 0; i < n; ++i) f[i] = {float(steps[1].x0[i].x), float(steps[1].x0[i].y), float(steps[1].x0[i].z)};
  f0.upload(f);
  for (std::size_t i = 0; i < n; ++i) f[i] = {float(steps[1].x1[i].x), float(steps[1].x1[i].y), float(steps[1].x1[i].z)};
  f1.upload(f);
  LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
  REQUIRE_NOTHROW(split.step_from_device(x0.data(), x1.data()));
  // From float device positions only the second GPU needs new buffers (its copies of the
  // broadcast): a budget short of them fails there alone, while the first GPU's broadcast waits.
  gpu::release_cached_memory();  // (a budget frees a device's cached blocks before it refuses)
  const std::size_t previous = gpu::memory_budget();
  gpu::set_memory_budget(gpu::memory_stats().in_use + n * sizeof(Vec3f) / 2);
  bool threw = false;
  try {
    split.step_from_device(f0.data(), f1.data());
  } catch (const Error& e) {
    threw = true;
    std::printf("one GPU failed: %s\n", e.what());
  }
  gpu::set_memory_budget(previous);
  CHECK(threw);
  CHECK_THROWS_WITH(split.step_from_device(x0.data(), x1.data()), Catch::Contains("aborted"));
}

TEST_CASE("MultiGpuPipeline equals one GPU on the real scenes", "[multi_gpu][data]") {
  if (!lwsccd_test::have_data()) {
    WARN("SKIPPED: shared data not found at " << lwsccd_test::data_dir());
    return;
  }
  const int n = device_count();
  std::vector<int> devices;
  for (int d = 0; d < std::min(n, 2); ++d) devices.push_back(d);
  for (const char* name : {"cloth-funnel", "armadillo-rollers", "cloth-ball"}) {
    INFO(name);
    const Scene scene = load_scene(lwsccd_test::data_dir() + "/scenes/" + name);
    gpu::CcdPipeline<> one(scene.step.mesh);
    gpu::MultiGpuPipeline<> split(scene.step.mesh, devices);
    for (int s = 0; s < 3; ++s) {
      const auto w = one.step(scene.step.x0, scene.step.x1);
      const auto m = split.step(scene.step.x0, scene.step.x1);
      lwsccd_test::require_same_contacts(m.contacts, w.contacts);
      CHECK(score_against_truth(scene.truth, m.contacts).false_negatives == 0);
      std::printf("%s step %d on %zu GPU(s): %zu + %zu contacts, earliest %.9g; busy per GPU", name, s, devices.size(),
                  m.contacts.vf.size(), m.contacts.ee.size(), m.contacts.earliest_toi);
      for (const StepStats& d : m.devices) std::printf(" %.3f", d.traverse_ms + d.features_ms + d.narrow_ms);
      std::printf(" ms, %zu moved\n", m.moved_front_entries);
    }
  }
}

// One process per GPU: this program started once per rank, the communicator's unique id shared
// through a file (as MPI or torch.distributed would share it).
namespace {
int run_rank(int rank, int ranks, const std::string& id_file) {
  ncclUniqueId id;
  std::ifstream in(id_file, std::ios::binary);
  in.read(reinterpret_cast<char*>(&id), sizeof id);
  if (!in) return 3;
  LWSCCD_CUDA_CHECK(cudaSetDevice(rank));
  ncclComm_t comm;
  LWSCCD_NCCL_CHECK(ncclCommInitRank(&comm, ranks, id, rank));
  int failures = 0;
  {
    std::shared_ptr<ClothBallSimulation> sim;
    const std::vector<Step> steps = builtin_steps(60000, 4, sim);
    gpu::MultiGpuPipeline<> split(sim->mesh(), sim->layout(), comm);
    gpu::CcdPipeline<> one(sim->mesh(), sim->layout());
    gpu::DeviceBuffer<Vec3d> x0, x1;
    for (const Step& step : steps) {
      x0.upload(step.x0);
      x1.upload(step.x1);
      LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
      const auto m = split.step_from_device(x0.data(), x1.data());
      const auto w = one.step(step.x0, step.x1);
      failures += m.contacts.earliest_toi != w.contacts.earliest_toi;
      failures += m.stats.triangle_pairs != w.stats.triangle_pairs;
      if (rank == 0) {
        failures += m.contacts.vf.size() != w.contacts.vf.size() || m.contacts.ee.size() != w.contacts.ee.size();
        for (std::size_t i = 0; i < std::min(m.contacts.vf.size(), w.contacts.vf.size()); ++i)
          failures += m.contacts.vf[i].first != w.contacts.vf[i].first || m.contacts.vf[i].second != w.contacts.vf[i].second ||
                      m.contacts.vf[i].toi != w.contacts.vf[i].toi;
        for (std::size_t i = 0; i < std::min(m.contacts.ee.size(), w.contacts.ee.size()); ++i)
          failures += m.contacts.ee[i].first != w.contacts.ee[i].first || m.contacts.ee[i].second != w.contacts.ee[i].second ||
                      m.contacts.ee[i].toi != w.contacts.ee[i].toi;
      } else {
        failures += !m.contacts.vf.empty();
      }
    }
    std::printf("rank %d of %d: %d differences from one GPU over %zu steps\n", rank, ranks, failures, steps.size());
  }
  ncclCommDestroy(comm);
  return failures == 0 ? 0 : 1;
}
}  // namespace

TEST_CASE("MultiGpuPipeline with one process per GPU (ncclCommInitRank) equals one GPU", "[multi_gpu][processes]") {
  if (device_count() < 2) {
    WARN("SKIPPED: needs two CUDA devices");
    return;
  }
  ncclUniqueId id;
  LWSCCD_NCCL_CHECK(ncclGetUniqueId(&id));
  const std::string id_file = "lwsccd_nccl_id_" + std::to_string(::getpid());
  {
    std::ofstream out(id_file, std::ios::binary);
    out.write(reinterpret_cast<const char*>(&id), sizeof id);
  }
  char self[4096] = {};
  REQUIRE(::readlink("/proc/self/exe", self, sizeof self - 1) > 0);
  std::vector<pid_t> children;
  for (int rank = 0; rank < 2; ++rank) {
    const std::string spec = "--rank=" + std::to_string(rank) + ":2:" + id_file;
    char* args[] = {self, const_cast<char*>(spec.c_str()), nullptr};
    pid_t pid = 0;
    REQUIRE(posix_spawn(&pid, self, nullptr, nullptr, args, environ) == 0);
    children.push_back(pid);
  }
  for (pid_t pid : children) {
    int status = 0;
    REQUIRE(::waitpid(pid, &status, 0) == pid);
    CHECK(WIFEXITED(status));
    CHECK(WEXITSTATUS(status) == 0);
  }
  std::remove(id_file.c_str());
}

int main(int argc, char* argv[]) {
  // A rank of the one-process-per-GPU case: --rank=R:N:FILE.
  if (argc == 2 && std::strncmp(argv[1], "--rank=", 7) == 0) {
    int rank = 0, ranks = 0, used = 0;
    if (std::sscanf(argv[1] + 7, "%d:%d:%n", &rank, &ranks, &used) < 2) return 2;
    try {
      return run_rank(rank, ranks, argv[1] + 7 + used);
    } catch (const std::exception& e) {
      std::printf("rank %d: %s\n", rank, e.what());
      return 1;
    }
  }
  const int devices = device_count();
  if (devices == 0) {
    std::printf("SKIPPED: no CUDA device; the multi-GPU tests were compiled but not run\n");
    return LWSCCD_SKIP_CODE;
  }
  int nccl_version = 0;
  ncclGetVersion(&nccl_version);
  std::printf("multi-GPU tests on %d CUDA device(s), NCCL %d\n", devices, nccl_version);
  return Catch::Session().run(argc, argv);
}
