// lwsccd-bench-rays — rays per second of RayCastTask with each scheduler against the standard
// approach (one thread per ray with its own stack), for coherent primary rays and incoherent
// random rays, closest hit, on cloth-ball (or the built-in scene). CUDA events, medians; every
// variant's hits are checked equal to the one-thread-per-ray kernel's.
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "bench_gpu.cuh"
#include "lwsccd/bvh/bvh.cuh"
#include "lwsccd/io/dataset.hpp"
#include "lwsccd/simulation/scenes.hpp"
#include "lwsccd/traversal/ray_task.hpp"
#include "lwsccd/traverse.cuh"

using namespace lwsccd;

namespace {

// Scheduler policies measured or tested beside the defaults (knobs overridden by name).
struct NoFit : gpu::LazyStealScheduler {
  static constexpr bool kFitBlocksPerSm = false;
};
struct WalkNeverHungry : gpu::RayWalkLazySteal {
  static constexpr int kShareWhenHungry = 0;
};
struct StaticDeepStack : gpu::StaticTaskList {
  static constexpr int kSharedStack = 4096;
};
struct Lazy256 : gpu::LazyStealScheduler {
  static constexpr int kBlockThreads = 256;
  static constexpr int kPushThreshold = 2048;
  static constexpr int kBlocksPerSm = 4;
};
struct NoFlat256 : Lazy256 {
  static constexpr int kFlatStartPerBlock = 0;
};
struct NoFit256 : Lazy256 {
  static constexpr bool kFitBlocksPerSm = false;
};
struct Lazy128 : gpu::LazyStealScheduler {
  static constexpr int kBlockThreads = 128;
  static constexpr int kSharedStack = 2048;
  static constexpr int kPopSize = 256;
  static constexpr int kBlocksPerSm = 8;
};
struct Lazy64 : gpu::LazyStealScheduler {
  static constexpr int kBlockThreads = 64;
  static constexpr int kSharedStack = 1024;
  static constexpr int kPopSize = 128;
  static constexpr int kPushThreshold = 512;
  static constexpr int kBlocksPerSm = 16;
};
struct Lazy64Deep : gpu::LazyStealScheduler {
  static constexpr int kBlockThreads = 64;
  static constexpr int kSharedStack = 2048;
  static constexpr int kPopSize = 256;
  static constexpr int kBlocksPerSm = 12;
};
struct Lazy64Deeper : gpu::LazyStealScheduler {
  static constexpr int kBlockThreads = 64;
  static constexpr int kPushThreshold = 2048;
  static constexpr int kBlocksPerSm = 6;
};

// The standard approach: one thread per ray, a per-thread stack, near child first.
__global__ void ray_per_thread_kernel(BvhView<Aabbf> bvh, const Face* faces, const Vec3f* x, const Ray* rays, int n,
                                      std::uint64_t* best) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const Ray r = rays[i];
  const Vec3f inv{1.0f / r.direction.x, 1.0f / r.direction.y, 1.0f / r.direction.z};
  std::uint64_t hit = kNoHit;
  index_t stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const index_t node = stack[--top];
    const float limit = hit == kNoHit ? r.t_max : hit_t(hit);
    if (!(detail::ray_box_entry(r, inv, bvh.bvs[node], limit) <= limit)) continue;
    if (bvh.is_leaf(node)) {
      const index_t tri = bvh.primitive(node);
      const Face f = faces[tri];
      const float t = detail::ray_triangle(r, x[f.v[0]], x[f.v[1]], x[f.v[2]]);
      if (t <= limit) {
        const std::uint64_t key = hit_key(t, tri);
        hit = key < hit ? key : hit;
      }
      continue;
    }
    const index_t l = bvh.left[node], rr = bvh.right[node];
    const float tl = detail::ray_box_entry(r, inv, bvh.bvs[l], limit), tr = detail::ray_box_entry(r, inv, bvh.bvs[rr], limit);
    if (tl <= tr) {  // push the far child first
      stack[top++] = rr;
      stack[top++] = l;
    } else {
      stack[top++] = l;
      stack[top++] = rr;
    }
  }
  best[i] = hit;
}

// One thread per ray with the walk RayWalkTask's items use (detail::walk_ray: children tested
// before they are pushed, pending nodes kept with their entry distances), unbounded: the standard
// approach with the same inner loop, so that the walk rows compare schedulers, not loops.
struct CountOverflow {
  unsigned* overflows;
  __device__ void operator()(index_t) { atomicAdd(overflows, 1u); }
};
__global__ void ray_walk_per_thread_kernel(BvhView<Aabbf> bvh, const Face* faces, const Vec3f* x, const Ray* rays,
                                           const Vec3f* inverse, int n, std::uint64_t* best, unsigned* overflows) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const Ray r = rays[i];
  std::uint64_t hit = kNoHit;
  CountOverflow spill{overflows};
  if (detail::ray_box_entry(r, inverse[i], bvh.bvs[0], r.t_max) <= r.t_max)
    detail::walk_ray<64>(bvh, faces, x, r, inverse[i], 0, hit, false, -1, spill);
  best[i] = hit;
}

std::vector<Ray> camera_rays(const std::vector<Vec3f>& x, int w, int h) {
  Aabbf box = Aabbf::empty();
  for (const auto& p : x) box.expand(p);
  const Vec3f c = box.center();
  const float r = 0.5f * norm(box.extent());
  const Vec3f eye = c + Vec3f{0.9f * r, -1.6f * r, 1.1f * r};
  Vec3f fwd = c - eye;
  fwd *= 1.0f / norm(fwd);
  Vec3f right = cross(fwd, Vec3f{0, 0, 1});
  right *= 1.0f / norm(right);
  const Vec3f up = cross(right, fwd);
  std::vector<Ray> rays;
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      Vec3f d = fwd + right * ((2.0f * (i + 0.5f) / w - 1.0f) * 0.6f * w / h) + up * ((1.0f - 2.0f * (j + 0.5f) / h) * 0.6f);
      d *= 1.0f / norm(d);
      rays.push_back({eye, d, 1e30f});
    }
  return rays;
}

std::vector<Ray> random_rays(const std::vector<Vec3f>& x, std::size_t n) {
  Aabbf box = Aabbf::empty();
  for (const auto& p : x) box.expand(p);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0, 1), d(-1, 1);
  std::vector<Ray> rays;
  for (std::size_t k = 0; k < n; ++k) {
    const Vec3f o{box.lo.x + u(rng) * (box.hi.x - box.lo.x), box.lo.y + u(rng) * (box.hi.y - box.lo.y),
                  box.lo.z + u(rng) * (box.hi.z - box.lo.z)};
    Vec3f dir{d(rng), d(rng), d(rng)};
    dir *= 1.0f / norm(dir);
    rays.push_back({o, dir, 1e30f});
  }
  return rays;
}

struct Row {
  std::string rays, method;
  std::size_t count;
  double median_ms;
  bool same;
  std::size_t items = 0, flat_items = 0;  ///< scheduler rows: items processed (all, by the flat start)
  double busy_share = -1;                 ///< lazy stealing: busy / (busy + idle) over its blocks
};

template <class Scheduler, class Task = RayCastTask>
Row scheduler_row(const std::string& name, const std::string& kind, const Task& task_template, const gpu::DeviceBuffer<Ray>& rays,
                  gpu::DeviceBuffer<std::uint64_t>& best, const gpu::DeviceBuffer<RayNode>& seeds,
                  const std::vector<std::uint64_t>& reference, int reps) {
  Task task = task_template;
  task.rays = rays.data();
  task.best = best.data();
  gpu::TraversalOutput<Task> out;
  auto run = [&] {
    LWSCCD_CUDA_CHECK(cudaMemset(best.data(), 0xff, rays.size() * sizeof(std::uint64_t)));
    gpu::traverse<Scheduler>(task, seeds.data(), seeds.size(), out, false);
  };
  run();
  const auto ms = lwsccd_bench::time_with_events(reps, run);
  Row row{kind, name, rays.size(), lwsccd_bench::median(ms), best.download() == reference};
  row.items = out.stats().items_processed;
  row.flat_items = out.stats().flat_start_items;
  unsigned long long busy = 0, idle = 0;
  for (const gpu::BlockActivity& a : out.download_block_activity()) {
    busy += a.busy_cycles;
    idle += a.idle_cycles;
  }
  if (busy + idle) row.busy_share = double(busy) / double(busy + idle);
  return row;
}

// RayWalkTask<StackSize> (visit budget `budget`) with Scheduler.
template <class Scheduler, int StackSize>
Row walk_row(const std::string& name, const std::string& kind, const RayCastTask& base, int budget,
             const gpu::DeviceBuffer<Ray>& rays, gpu::DeviceBuffer<std::uint64_t>& best, const gpu::DeviceBuffer<RayNode>& seeds,
             const std::vector<std::uint64_t>& reference, int reps) {
  RayWalkTask<StackSize> walk;
  static_cast<RayCastTask&>(walk) = base;
  walk.visit_budget = budget;
  return scheduler_row<Scheduler>(name, kind, walk, rays, best, seeds, reference, reps);
}

}  // namespace

int main(int argc, char** argv) {
  const lwsccd_bench::BenchArgs args =
      lwsccd_bench::parse_bench_args(argc, argv, 5, {"--walks"},
                                     "usage: lwsccd-bench-rays [--data DIR] [--reps N] [--json FILE] [--walks]");
  cudaDeviceProp prop{};
  if (!lwsccd_bench::first_gpu(prop, "lwsccd-bench-rays")) return 77;
  try {
    const std::string dir = lwsccd_bench::data_dir(args.data, LWSCCD_BENCH_DATA_DIR);
    const Scene scene = load_scene(dir + "/scenes/cloth-ball");
    const TriangleMesh& mesh = *scene.step.mesh;
    std::vector<Vec3f> x(scene.step.x0.size());
    for (std::size_t v = 0; v < x.size(); ++v) x[v] = scene.step.x0[v].cast<float>();
    gpu::DeviceStep<float> step(mesh, scene.step.x0, scene.step.x0);
    gpu::Bvh<Aabbf> bvh;
    bvh.build(step);
    gpu::DeviceBuffer<Face> faces;
    faces.upload(mesh.faces());
    gpu::DeviceBuffer<Vec3f> dx;
    dx.upload(x);
    std::vector<Row> rows;
    for (const std::string kind : {"primary 1920x1080 (coherent)", "random (incoherent)"}) {
      const std::vector<Ray> host_rays = kind[0] == 'p' ? camera_rays(x, 1920, 1080) : random_rays(x, 1920 * 1080);
      gpu::DeviceBuffer<Ray> rays;
      rays.upload(host_rays);
      gpu::DeviceBuffer<std::uint64_t> best(host_rays.size());
      const int n = static_cast<int>(host_rays.size());
      auto baseline = [&] {
        ray_per_thread_kernel<<<(n + 127) / 128, 128>>>(bvh.view(), faces.data(), dx.data(), rays.data(), n, best.data());
        LWSCCD_CUDA_CHECK_LAUNCH();
      };
      baseline();
      const auto ms = lwsccd_bench::time_with_events(args.reps, baseline);
      const std::vector<std::uint64_t> reference = best.download();
      rows.push_back({kind, "one thread per ray", host_rays.size(), lwsccd_bench::median(ms), true});
      std::vector<RayNode> host_seeds;
      for (index_t r = 0; r < n; ++r) host_seeds.push_back({r, 0});
      gpu::DeviceBuffer<RayNode> seeds;
      seeds.upload(host_seeds);
      const RayCastTask task{bvh.view(), faces.data(), dx.data(), nullptr, nullptr, false};
      rows.push_back(scheduler_row<gpu::StaticTaskList>("static task list", kind, task, rays, best, seeds, reference, args.reps));
      rows.push_back(scheduler_row<gpu::GProximityBalancer>("gProximity", kind, task, rays, best, seeds, reference, args.reps));
      rows.push_back(scheduler_row<gpu::LazyStealScheduler>("lazy stealing", kind, task, rays, best, seeds, reference, args.reps));
      // The kernel left to the compiler's register choice (94: one 512-thread block per SM)
      // instead of compiled to fit the default's two (64).
      rows.push_back(scheduler_row<NoFit>("lazy stealing (no fit)", kind, task, rays, best, seeds, reference, args.reps));
      // Each ray's inverse direction stored once (RayCastTask::inverse), not divided for per item.
      gpu::DeviceBuffer<Vec3f> inverse;
      inverse.upload(inverse_directions(host_rays));
      RayCastTask with_inverse = task;
      with_inverse.inverse = inverse.data();
      rows.push_back(scheduler_row<gpu::LazyStealScheduler>("lazy, inverses stored", kind, with_inverse, rays, best, seeds,
                                                              reference, args.reps));
      rows.push_back(scheduler_row<gpu::StaticTaskList>("static, inverses stored", kind, with_inverse, rays, best, seeds,
                                                          reference, args.reps));
      // Walks (RayWalkTask): an item takes a ray `budget` nodes down before it hands the rest back.
      gpu::DeviceBuffer<unsigned> overflows;
      overflows.upload(std::vector<unsigned>{0});
      auto walk_baseline = [&] {
        ray_walk_per_thread_kernel<<<(n + 127) / 128, 128>>>(bvh.view(), faces.data(), dx.data(), rays.data(), inverse.data(), n,
                                                             best.data(), overflows.data());
        LWSCCD_CUDA_CHECK_LAUNCH();
      };
      walk_baseline();
      const auto walk_ms = lwsccd_bench::time_with_events(args.reps, walk_baseline);
      rows.push_back({kind, "one thread per ray, walk", host_rays.size(), lwsccd_bench::median(walk_ms),
                      best.download() == reference && overflows.download()[0] == 0});
      // Walks with the defaults: RayWalkTask<> (a stack of 14 nodes), gpu::RayWalkLazySteal.
      for (const int budget : {32, 64, 128, 0})
        rows.push_back(walk_row<gpu::RayWalkLazySteal, 14>(budget ? "lazy, walks of " + std::to_string(budget) : "lazy, whole rays",
                                                           kind, with_inverse, budget, rays, best, seeds, reference, args.reps));
      // RayWalkLazySteal without sharing on demand.
      rows.push_back(walk_row<WalkNeverHungry, 14>("lazy, walks of 64, share off", kind, with_inverse, 64, rays, best, seeds,
                                                   reference, args.reps));
      rows.push_back(walk_row<StaticDeepStack, 14>("static, walks of 32", kind, with_inverse, 32, rays, best, seeds,
                                                                 reference, args.reps));
      if (args.has("--walks")) {  // the variants weighed for RayWalkTask's defaults (docs/RAYTRACING.md)
        rows.push_back(walk_row<NoFlat256, 6>("lazy no flat start, walks of 16", kind, with_inverse, 16, rays, best, seeds, reference,
                                           args.reps));
        rows.push_back(walk_row<NoFit256, 6>("lazy no fit, walks of 16", kind, with_inverse, 16, rays, best, seeds, reference,
                                          args.reps));
        for (const int budget : {8, 16, 32}) {
          const std::string b = std::to_string(budget);
          rows.push_back(walk_row<Lazy256, 6>("lazy 256x4, walks of " + b, kind, with_inverse, budget, rays, best, seeds,
                                              reference, args.reps));
          rows.push_back(walk_row<Lazy128, 6>("lazy 128x8, walks of " + b, kind, with_inverse, budget, rays, best, seeds,
                                              reference, args.reps));
          rows.push_back(walk_row<Lazy64, 6>("lazy 64x16, walks of " + b, kind, with_inverse, budget, rays, best, seeds,
                                             reference, args.reps));
          rows.push_back(walk_row<gpu::RayWalkLazySteal, 14>("lazy 128x6, stack 14, walks of " + b, kind, with_inverse, budget, rays, best,
                                                   seeds, reference, args.reps));
          rows.push_back(walk_row<Lazy64Deep, 14>("lazy 64x12, stack 14, walks of " + b, kind, with_inverse, budget, rays, best,
                                                  seeds, reference, args.reps));
          rows.push_back(walk_row<Lazy64Deeper, 30>("lazy 64x6, stack 30, walks of " + b, kind, with_inverse, budget, rays, best,
                                                    seeds, reference, args.reps));
        }
        for (const int budget : {48, 96, 256})
          rows.push_back(walk_row<gpu::RayWalkLazySteal, 14>("lazy, walks of " + std::to_string(budget), kind, with_inverse, budget,
                                                             rays, best, seeds, reference, args.reps));
        rows.push_back(walk_row<gpu::RayWalkLazySteal, 14>("lazy 128x6, stack 14, whole rays", kind, with_inverse, 0, rays, best, seeds,
                                                 reference, args.reps));
        rows.push_back(walk_row<Lazy64Deeper, 30>("lazy 64x6, stack 30, whole rays", kind, with_inverse, 0, rays, best, seeds,
                                                  reference, args.reps));
      }
    }
    std::printf("GPU: %s; cloth-ball (92,230 triangles), closest hit, CUDA events, median of %d runs\n", prop.name, args.reps);
    std::printf("%-30s %-36s %10s %10s %12s %11s %11s %6s %s\n", "rays", "method", "count", "ms", "Mrays/s", "items", "flat items",
                "busy", "hits = per-thread");
    for (const Row& r : rows)
      std::printf("%-30s %-36s %10zu %10.3f %12.1f %11zu %11zu %6.3f %s\n", r.rays.c_str(), r.method.c_str(), r.count, r.median_ms,
                  r.count / r.median_ms / 1e3, r.items, r.flat_items, r.busy_share, r.same ? "yes" : "NO");
    lwsccd_bench::write_json_rows(args.json, rows.size(), [&](std::size_t i) {
      const Row& r = rows[i];
      return lwsccd_bench::Json{{"gpu", prop.name}, {"rays", r.rays}, {"method", r.method}, {"count", r.count},
                                {"median_ms", r.median_ms}, {"mrays_per_s", r.count / r.median_ms / 1e3}, {"same_hits", r.same},
                                {"items", r.items}, {"flat_start_items", r.flat_items}, {"busy_share", r.busy_share}};
    });
    for (const Row& r : rows)
      if (!r.same) return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lwsccd-bench-rays: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
