// raytrace — the lazy-stealing scheduler reused for ray tracing: renders a mesh with primary rays
// and one shadow ray per hit, through the same traversal engine as collision detection
// (no change to any scheduler), and writes a PNG. The lazy scheduler takes walks (RayWalkTask: an
// item walks its ray up to 64 nodes down before it hands the rest back), the static list and
// gProximity one node per item (RayCastTask).
//
//   lwsccd-raytrace [SCENE_DIR | MESH.ply|.obj] [--out image.png] [--size WxH]
//                   [--scheduler lazy|static|gproximity|all]
// With "all" it renders with every scheduler and checks that the images are identical.
// Without a GPU it renders on the CPU backend (work stealing).
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "lwsccd/bvh/bvh.cuh"
#include "lwsccd/io/dataset.hpp"
#include "lwsccd/io/render.hpp"
#include "lwsccd/simulation/scenes.hpp"
#include "lwsccd/traversal/cpu_traverse.hpp"
#include "lwsccd/traversal/ray_task.hpp"
#include "lwsccd/traverse.cuh"

using namespace lwsccd;

namespace {

// Casts rays with Scheduler on the GPU (items of Task: RayCastTask or RayWalkTask), or on the CPU
// backend when `gpu` is false.
template <class Scheduler, class Task>
std::vector<std::uint64_t> cast(bool gpu, const BvhView<Aabbf>& gpu_bvh, const BvhView<Aabbf>& cpu_bvh,
                                const gpu::DeviceBuffer<Face>* d_faces, const gpu::DeviceBuffer<Vec3f>* d_x,
                                const TriangleMesh& mesh, const std::vector<Vec3f>& x, const std::vector<Ray>& rays,
                                bool any_hit) {
  if (!gpu) return cpu::cast_rays(cpu_bvh, mesh, x, rays, any_hit);
  std::vector<RayNode> seeds;
  for (index_t r = 0; r < static_cast<index_t>(rays.size()); ++r) seeds.push_back({r, 0});
  gpu::DeviceBuffer<Ray> d_rays;
  d_rays.upload(rays);
  gpu::DeviceBuffer<std::uint64_t> best;
  best.upload(std::vector<std::uint64_t>(rays.size(), kNoHit));
  gpu::DeviceBuffer<RayNode> d_seeds;
  d_seeds.upload(seeds);
  Task task;
  static_cast<RayCastTask&>(task) = RayCastTask{gpu_bvh, d_faces->data(), d_x->data(), d_rays.data(), best.data(), any_hit};
  gpu::DeviceBuffer<Vec3f> inverse;  // each ray's 1 / direction once, not per visited node
  inverse.upload(inverse_directions(rays));
  task.inverse = inverse.data();
  gpu::TraversalOutput<Task> out;
  gpu::traverse<Scheduler>(task, d_seeds.data(), seeds.size(), out, false);
  return best.download();
}

template <class Scheduler, class Task = RayCastTask>
std::vector<unsigned char> render(bool gpu, const RenderView& view, const BvhView<Aabbf>& gpu_bvh, const BvhView<Aabbf>& cpu_bvh,
                                  const gpu::DeviceBuffer<Face>* d_faces, const gpu::DeviceBuffer<Vec3f>* d_x,
                                  const TriangleMesh& mesh, const std::vector<Vec3f>& x) {
  const std::vector<Ray> rays = primary_rays(view);
  const auto hits = cast<Scheduler, Task>(gpu, gpu_bvh, cpu_bvh, d_faces, d_x, mesh, x, rays, false);
  const ShadowRays shadows = shadow_rays(view, mesh, x, rays, hits);
  return shade(view, shadows, cast<Scheduler, Task>(gpu, gpu_bvh, cpu_bvh, d_faces, d_x, mesh, x, shadows.rays, true));
}

}  // namespace

int main(int argc, char** argv) {
  std::string input, out_path = "raytrace.png", scheduler = "lazy";
  int width = 800, height = 600;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--out" && i + 1 < argc) out_path = argv[++i];
    else if (a == "--scheduler" && i + 1 < argc) scheduler = argv[++i];
    else if (a == "--size" && i + 1 < argc) {
      if (std::sscanf(argv[++i], "%dx%d", &width, &height) != 2 || width < 1 || height < 1 || width > 16384 || height > 16384) {
        std::fprintf(stderr, "lwsccd-raytrace: --size expects WxH, e.g. 1920x1080\n");
        return 1;
      }
    } else if (a == "-h" || a == "--help") {
      std::printf("usage: lwsccd-raytrace [SCENE_DIR | MESH.ply|.obj] [--out image.png] [--size WxH] "
                  "[--scheduler lazy|static|gproximity|all]\n");
      return 0;
    } else if (!a.empty() && a[0] == '-') {
      std::fprintf(stderr, "lwsccd-raytrace: unknown option %s (see --help)\n", a.c_str());
      return 1;
    } else {
      input = a;
    }
  }
  if (scheduler != "lazy" && scheduler != "static" && scheduler != "gproximity" && scheduler != "all") {
    std::fprintf(stderr, "lwsccd-raytrace: --scheduler expects lazy, static, gproximity or all\n");
    return 1;
  }
  try {
    std::shared_ptr<const TriangleMesh> mesh;
    std::vector<Vec3d> positions;
    if (input.empty()) {
      const MultiBodyStep s = make_cloth_ball_scene(60000);
      mesh = s.step.mesh, positions = s.step.x0;
    } else if (std::filesystem::is_directory(std::filesystem::path(input) / "frames")) {
      const Scene s = load_scene(input);
      mesh = s.step.mesh, positions = s.step.x0;
    } else {
      const Step s = load_step(input, input);
      mesh = s.mesh, positions = s.x0;
    }
    std::vector<Vec3f> x(positions.size());
    for (std::size_t v = 0; v < x.size(); ++v) x[v] = positions[v].cast<float>();
    int devices = 0;
    const bool gpu = cudaGetDeviceCount(&devices) == cudaSuccess && devices > 0;
    const cpu::Bvh<Aabbf> cbvh(*mesh, x, x);
    gpu::Bvh<Aabbf> gbvh;
    gpu::DeviceBuffer<Face> d_faces;
    gpu::DeviceBuffer<Vec3f> d_x;
    if (gpu) {
      gpu::DeviceStep<float> step(*mesh, positions, positions);
      gbvh.build(step);
      d_faces.upload(mesh->faces());
      d_x.upload(x);
    }
    const RenderView view = frame_view(x, width, height);
    std::printf("%d triangles, %dx%d, %s\n", mesh->num_faces(), width, height, gpu ? "GPU" : "CPU backend (no GPU)");
    std::vector<unsigned char> image;
    auto run = [&](const std::string& name) {
      if (name == "static") return render<gpu::StaticTaskList>(gpu, view, gbvh.view(), cbvh.view(), &d_faces, &d_x, *mesh, x);
      if (name == "gproximity")
        return render<gpu::GProximityBalancer>(gpu, view, gbvh.view(), cbvh.view(), &d_faces, &d_x, *mesh, x);
      return render<gpu::RayWalkLazySteal, RayWalkTask<>>(gpu, view, gbvh.view(), cbvh.view(), &d_faces, &d_x, *mesh, x);
    };
    if (scheduler == "all") {
      image = run("lazy");
      for (const char* other : {"static", "gproximity"}) {
        const bool same = run(other) == image;
        std::printf("%s: %s\n", other, same ? "identical image" : "DIFFERENT image");
        if (!same) return 2;
      }
    } else {
      image = run(scheduler);
    }
    if (!png::write_rgb(out_path, width, height, image)) {
      std::fprintf(stderr, "lwsccd-raytrace: cannot write %s\n", out_path.c_str());
      return 1;
    }
    std::printf("wrote %s\n", out_path.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lwsccd-raytrace: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
