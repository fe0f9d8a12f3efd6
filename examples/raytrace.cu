// raytrace — the lazy-stealing scheduler reused for ray tracing: renders a mesh with primary rays
// and one shadow ray per hit, through the same traversal engine as collision detection
// (RayCastTask, no change to any scheduler), and writes a PNG.
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

#include "lwsccd/bvh.cuh"
#include "lwsccd/dataset.hpp"
#include "lwsccd/ray_task.hpp"
#include "lwsccd/scenes.hpp"
#include "lwsccd/traverse.cuh"
#include "lwsccd/traverse.hpp"
#include "png_writer.hpp"

using namespace lwsccd;

namespace {

struct View {
  int width = 800, height = 600;
  Vec3f eye, forward, right, up;
  Vec3f light;
};

View make_view(const std::vector<Vec3f>& x, int width, int height) {
  Aabbf box = Aabbf::empty();
  for (const auto& p : x) box.expand(p);
  const Vec3f c = box.center(), e = box.extent();
  const float r = 0.5f * norm(e);
  View v;
  v.width = width;
  v.height = height;
  v.eye = c + Vec3f{0.9f * r, -1.6f * r, 1.1f * r};
  v.forward = c - v.eye;
  v.forward *= 1.0f / norm(v.forward);
  v.right = cross(v.forward, Vec3f{0, 0, 1});
  v.right *= 1.0f / norm(v.right);
  v.up = cross(v.right, v.forward);
  v.light = c + Vec3f{-2.0f * r, -1.0f * r, 4.0f * r};
  return v;
}

std::vector<Ray> primary_rays(const View& v) {
  std::vector<Ray> rays;
  const float aspect = float(v.width) / float(v.height);
  for (int j = 0; j < v.height; ++j)
    for (int i = 0; i < v.width; ++i) {
      const float sx = (2.0f * (i + 0.5f) / v.width - 1.0f) * 0.6f * aspect, sy = (1.0f - 2.0f * (j + 0.5f) / v.height) * 0.6f;
      Vec3f d = v.forward + v.right * sx + v.up * sy;
      d *= 1.0f / norm(d);
      rays.push_back({v.eye, d, 1e30f});
    }
  return rays;
}

// Casts rays with Scheduler on the GPU, or on the CPU backend when `gpu` is false.
template <class Scheduler>
std::vector<std::uint64_t> cast(bool gpu, const BvhView<Aabbf>& gpu_bvh, const BvhView<Aabbf>& cpu_bvh,
                                const gpu::DeviceBuffer<Face>* d_faces, const gpu::DeviceBuffer<Vec3f>* d_x,
                                const TriangleMesh& mesh, const std::vector<Vec3f>& x, const std::vector<Ray>& rays,
                                bool any_hit) {
  std::vector<RayNode> seeds;
  for (index_t r = 0; r < static_cast<index_t>(rays.size()); ++r) seeds.push_back({r, 0});
  if (!gpu) {
    std::vector<std::uint64_t> best(rays.size(), kNoHit);
    RayCastTask task{cpu_bvh, mesh.faces().data(), x.data(), rays.data(), best.data(), any_hit};
    cpu::traverse(task, seeds, false, cpu::WorkStealingScheduler{});
    return best;
  }
  gpu::DeviceBuffer<Ray> d_rays;
  d_rays.upload(rays);
  gpu::DeviceBuffer<std::uint64_t> best;
  best.upload(std::vector<std::uint64_t>(rays.size(), kNoHit));
  gpu::DeviceBuffer<RayNode> d_seeds;
  d_seeds.upload(seeds);
  RayCastTask task{gpu_bvh, d_faces->data(), d_x->data(), d_rays.data(), best.data(), any_hit};
  gpu::TraversalOutput<RayCastTask> out;
  gpu::traverse<Scheduler>(task, d_seeds.data(), seeds.size(), out, false);
  return best.download();
}

template <class Scheduler>
std::vector<unsigned char> render(bool gpu, const View& view, const BvhView<Aabbf>& gpu_bvh, const BvhView<Aabbf>& cpu_bvh,
                                  const gpu::DeviceBuffer<Face>* d_faces, const gpu::DeviceBuffer<Vec3f>* d_x,
                                  const TriangleMesh& mesh, const std::vector<Vec3f>& x) {
  const std::vector<Ray> rays = primary_rays(view);
  const auto hits = cast<Scheduler>(gpu, gpu_bvh, cpu_bvh, d_faces, d_x, mesh, x, rays, false);
  // One shadow ray per hit, toward the light, started a little off the surface.
  std::vector<Ray> shadows;
  std::vector<std::size_t> owner;
  std::vector<Vec3f> normal(rays.size());
  for (std::size_t r = 0; r < rays.size(); ++r) {
    if (hits[r] == kNoHit) continue;
    const Face f = mesh.face(hit_triangle(hits[r]));
    Vec3f n = cross(x[f.v[1]] - x[f.v[0]], x[f.v[2]] - x[f.v[0]]);
    n *= 1.0f / norm(n);
    if (dot(n, rays[r].direction) > 0) n = -n;
    normal[r] = n;
    const Vec3f p = rays[r].origin + rays[r].direction * hit_t(hits[r]) + n * 1e-4f;
    Vec3f to_light = view.light - p;
    const float dist = norm(to_light);
    shadows.push_back({p, to_light * (1.0f / dist), dist});
    owner.push_back(r);
  }
  const auto blocked = cast<Scheduler>(gpu, gpu_bvh, cpu_bvh, d_faces, d_x, mesh, x, shadows, true);
  std::vector<unsigned char> rgb(rays.size() * 3);
  for (std::size_t r = 0; r < rays.size(); ++r) {  // background: a vertical gradient
    const float g = 0.75f - 0.35f * float(r / view.width) / view.height;
    rgb[3 * r] = static_cast<unsigned char>(255 * g * 0.85f);
    rgb[3 * r + 1] = static_cast<unsigned char>(255 * g * 0.9f);
    rgb[3 * r + 2] = static_cast<unsigned char>(255 * g);
  }
  for (std::size_t s = 0; s < shadows.size(); ++s) {
    const std::size_t r = owner[s];
    const float lambert = std::max(0.0f, dot(normal[r], shadows[s].direction));
    const float light = 0.18f + 0.82f * lambert * (blocked[s] == kNoHit ? 1.0f : 0.25f);
    rgb[3 * r] = static_cast<unsigned char>(255 * std::min(1.0f, light * 0.95f));
    rgb[3 * r + 1] = static_cast<unsigned char>(255 * std::min(1.0f, light * 0.72f));
    rgb[3 * r + 2] = static_cast<unsigned char>(255 * std::min(1.0f, light * 0.45f));
  }
  return rgb;
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
    const View view = make_view(x, width, height);
    std::printf("%d triangles, %dx%d, %s\n", mesh->num_faces(), width, height, gpu ? "GPU" : "CPU backend (no GPU)");
    std::vector<unsigned char> image;
    auto run = [&](const std::string& name) {
      if (name == "static") return render<gpu::StaticTaskList<>>(gpu, view, gbvh.view(), cbvh.view(), &d_faces, &d_x, *mesh, x);
      if (name == "gproximity")
        return render<gpu::GProximityBalancer<>>(gpu, view, gbvh.view(), cbvh.view(), &d_faces, &d_x, *mesh, x);
      return render<gpu::LazyStealScheduler<>>(gpu, view, gbvh.view(), cbvh.view(), &d_faces, &d_x, *mesh, x);
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
