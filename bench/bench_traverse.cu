// lwsccd-bench-traverse — BVTT self-collision traversal time per scheduler x BV (CUDA events,
// medians) on the real scenes (from the root and from the recorded front) and over every step of
// horse-gallop with front tracking; BVTT nodes, front sizes, candidate pairs, and the lazy
// scheduler's per-block busy/idle cycles. With --timeline DIR, instead: the lazy scheduler's
// per-block timelines (TraversalOutput::record_timeline) as CSV files, for bench/plot_timeline.py.
#include <algorithm>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "bench_gpu.cuh"
#include "lwsccd/bvh/bvh.cuh"
#include "lwsccd/io/dataset.hpp"
#include "lwsccd/traversal/bvtt.hpp"
#include "lwsccd/traversal/independent_traversal.cuh"
#include "lwsccd/traverse.cuh"

using namespace lwsccd;

namespace {

// Scheduler policies measured or tested beside the defaults (knobs overridden by name).
struct Lazy128Threads : gpu::LazyStealScheduler {
  static constexpr int kBlockThreads = 128;
  static constexpr int kSharedStack = 1024;
  static constexpr int kPopSize = 256;
  static constexpr int kPushThreshold = 512;
  static constexpr int kSeedsPerBlock = 128;
};
struct Lazy256Threads4PerSm : gpu::LazyStealScheduler {
  static constexpr int kBlockThreads = 256;
  static constexpr int kSharedStack = 2048;
  static constexpr int kPopSize = 256;
  static constexpr int kPushThreshold = 512;
  static constexpr int kBlocksPerSm = 4;
};
struct LazySeeds0 : gpu::LazyStealScheduler {
  static constexpr int kSeedsPerBlock = 0;
};
struct LazySeeds1 : gpu::LazyStealScheduler {
  static constexpr int kSeedsPerBlock = 1;
};
struct LazySeeds1Pop256 : gpu::LazyStealScheduler {
  static constexpr int kPopSize = 256;
  static constexpr int kPushThreshold = 256;
  static constexpr int kSeedsPerBlock = 1;
};
struct LazySleep4k : gpu::LazyStealScheduler {
  static constexpr int kMaxBackoffNs = 4096;
};
struct LazySleep16k : gpu::LazyStealScheduler {
  static constexpr int kMaxBackoffNs = 16384;
};
struct LazyLock4 : gpu::LazyStealScheduler {
  static constexpr int kStealLockAttempts = 4;
};
struct LazyLock64 : gpu::LazyStealScheduler {
  static constexpr int kStealLockAttempts = 64;
};
struct Plain : gpu::LazyStealScheduler {
  static constexpr int kStealLockAttempts = 0;
  static constexpr bool kRandomVictim = false;
  static constexpr int kFlatStartPerBlock = 0;
  static constexpr int kShareWhenHungry = 0;
};
struct NoFit : gpu::LazyStealScheduler {
  static constexpr bool kFitBlocksPerSm = false;
};

struct Row {
  std::string scene, scheduler, bv, start;
  double median_ms, p10_ms, p90_ms;
  std::size_t nodes, pairs, front;
  double busy_share = -1;  ///< lazy scheduler: busy / (busy + idle) over all blocks, else -1
  unsigned long long steals = 0, failed_steals = 0;  ///< lazy scheduler, summed over the blocks (last run)
};

// A scene's BVTT self-collision task on the GPU (float positions) and the buffers it points to.
template <class BV>
struct DeviceScene {
  gpu::DeviceStep<float> step;
  gpu::Bvh<BV> bvh;
  gpu::DeviceBuffer<Face> faces;
  gpu::DeviceBuffer<NodePair> root;
  template <class Positions>
  DeviceScene(const TriangleMesh& mesh, const Positions& x0, const Positions& x1) : step(mesh, x0, x1) {
    bvh.build(step);
    faces.upload(mesh.faces());
    root.upload(std::vector<NodePair>{NodePair{0, 0}});
  }
  SelfCollisionTask<BV> task() const { return {bvh.view(), LeafFilter{nullptr, nullptr, faces.data(), true}}; }
};

// The lazy scheduler's per-block activity of the last run, summed into the row.
template <class Task>
void add_activity(const gpu::TraversalOutput<Task>& out, bool lazy, Row& row) {
  if (!lazy) return;
  unsigned long long busy = 0, idle = 0;
  for (const gpu::BlockActivity& a : out.download_block_activity()) {
    busy += a.busy_cycles, idle += a.idle_cycles;
    row.steals += a.steals, row.failed_steals += a.failed_steals;
  }
  row.busy_share = busy + idle ? double(busy) / double(busy + idle) : -1;
}

template <class Scheduler, class BV>
void scene_rows(const char* scheduler, const char* bv_name, const std::string& name, const Step& step, int reps,
                std::vector<Row>& rows) {
  using Task = SelfCollisionTask<BV>;
  const DeviceScene<BV> scene(*step.mesh, step.x0, step.x1);
  const Task task = scene.task();
  gpu::TraversalOutput<Task> out;
  auto from_root = [&] { gpu::traverse<Scheduler>(task, scene.root.data(), 1, out, true); };
  from_root();
  const auto ms = lwsccd_bench::time_with_events(reps, from_root);
  const bool lazy = std::string(scheduler).rfind("lazy", 0) == 0;
  rows.push_back({name, scheduler, bv_name, "root", lwsccd_bench::median(ms), lwsccd_bench::percentile(ms, 0.1),
                  lwsccd_bench::percentile(ms, 0.9), out.stats().items_processed, out.num_results(), out.num_front()});
  add_activity(out, lazy, rows.back());
  // From the front of the same step (the refit of an unchanged step keeps it valid).
  gpu::DeviceBuffer<NodePair> front(out.num_front());
  LWSCCD_CUDA_CHECK(cudaMemcpy(front.data(), out.front(), out.num_front() * sizeof(NodePair), cudaMemcpyDeviceToDevice));
  const std::size_t front_size = out.num_front();
  auto from_front = [&] { gpu::traverse<Scheduler>(task, front.data(), front_size, out, true); };
  from_front();
  const auto ms_front = lwsccd_bench::time_with_events(reps, from_front);
  rows.push_back({name, scheduler, bv_name, "front", lwsccd_bench::median(ms_front), lwsccd_bench::percentile(ms_front, 0.1),
                  lwsccd_bench::percentile(ms_front, 0.9), out.stats().items_processed, out.num_results(), out.num_front()});
  add_activity(out, lazy, rows.back());
}

// Karras's independent traversal: one thread per leaf from the root (it keeps no front).
template <class BV>
void independent_rows(const char* bv_name, const std::string& name, const Step& step, int reps, std::vector<Row>& rows) {
  using Task = SelfCollisionTask<BV>;
  const DeviceScene<BV> scene(*step.mesh, step.x0, step.x1);
  const Task task = scene.task();
  gpu::TraversalOutput<Task> out;
  auto run = [&] { gpu::independent_self_traversal(task, out); };
  run();
  const auto ms = lwsccd_bench::time_with_events(reps, run);
  rows.push_back({name, "karras", bv_name, "root", lwsccd_bench::median(ms), lwsccd_bench::percentile(ms, 0.1),
                  lwsccd_bench::percentile(ms, 0.9), out.stats().items_processed, out.num_results(), 0});
}

template <class Scheduler, class BV>
void sequence_rows(const char* scheduler, const char* bv_name, const Sequence& seq, std::vector<Row>& rows) {
  using Task = SelfCollisionTask<BV>;
  DeviceScene<BV> scene(*seq.mesh(), seq.frame(0), seq.frame(1));
  gpu::DeviceStep<float>& dstep = scene.step;
  gpu::Bvh<BV>& bvh = scene.bvh;
  const Task task = scene.task();
  gpu::TraversalOutput<Task> out;
  FrontTracker tracker;
  gpu::DeviceBuffer<NodePair> seeds;
  std::vector<double> ms;
  std::size_t nodes = 0, pairs = 0, front = 0;
  for (std::size_t s = 0; s < seq.num_steps(); ++s) {
    if (s > 0) {
      dstep.set_positions(seq.frame(s), seq.frame(s + 1));
      bvh.refit(dstep);
    }
    const auto& host_seeds = tracker.seeds(bvh.generation());
    seeds.upload(host_seeds);
    const auto t = lwsccd_bench::time_with_events(1, [&] { gpu::traverse<Scheduler>(task, seeds.data(), host_seeds.size(), out, true); });
    if (s > 0) ms.push_back(t[0]);  // the first step is a cold start from the root
    nodes += out.stats().items_processed;
    pairs += out.num_results();
    front = out.num_front();
    tracker.update(out.download_front());
  }
  double sum = 0;
  for (double x : ms) sum += x;
  rows.push_back({"horse-gallop (mean of 46 steps)", scheduler, bv_name, "tracked", sum / ms.size(),
                  lwsccd_bench::percentile(ms, 0.1), lwsccd_bench::percentile(ms, 0.9), nodes / seq.num_steps(),
                  pairs / seq.num_steps(), front});
}

// The default lazy scheduler with another kFlatStartPerBlock (0: no flat start).
template <int kPerBlock>
struct FlatFrom : gpu::LazyStealScheduler {
  static constexpr int kFlatStartPerBlock = kPerBlock;
};
template <int kAbove>
struct Hungry : gpu::LazyStealScheduler {
  static constexpr int kShareWhenHungry = kAbove;
};

// Variants of the lazy scheduler's occupancy and batch knobs (AABB only: the knobs do not depend
// on the BV), beside its defaults.
template <class BV>
void lazy_variants(const char* bv_name, const std::string& name, const Step& step, int reps, std::vector<Row>& rows) {
  if (std::string(bv_name) != "AABB float") return;
  // Smaller blocks (128 threads, 2 blocks per SM, batches of 256), and two neighbours of the default shape.
  scene_rows<Lazy128Threads, BV>("lazy-128t", bv_name, name, step, reps, rows);
  scene_rows<Lazy256Threads4PerSm, BV>("lazy-256t-4sm", bv_name, name, step, reps, rows);
  scene_rows<LazySeeds0, BV>("lazy-seeds0", bv_name, name, step, reps, rows);
  scene_rows<LazySeeds1, BV>("lazy-seeds1", bv_name, name, step, reps, rows);
  scene_rows<LazySeeds1Pop256, BV>("lazy-seeds1-p256", bv_name, name, step, reps, rows);
  // The idle blocks' sleep between searches doubling up to 4 us, and up to 16 us (default: 256 ns).
  scene_rows<LazySleep4k, BV>("lazy-sleep4k", bv_name, name, step, reps, rows);
  scene_rows<LazySleep16k, BV>("lazy-sleep16k", bv_name, name, step, reps, rows);
  // Thieves trying a victim's lock 4 or 64 times before they look again (default 16).
  scene_rows<LazyLock4, BV>("lazy-lock4", bv_name, name, step, reps, rows);
  scene_rows<LazyLock64, BV>("lazy-lock64", bv_name, name, step, reps, rows);
  // A flat first launch for starts of at least 128 or 2,048 items per block (default 512).
  scene_rows<FlatFrom<128>, BV>("lazy-flat128", bv_name, name, step, reps, rows);
  scene_rows<FlatFrom<2048>, BV>("lazy-flat2048", bv_name, name, step, reps, rows);
  // Sharing the older half when the deque is empty and a block is searching, above 256 or 768
  // items (default: above 512, half of kPushThreshold; lazy-share-off below: only above 1,024).
  scene_rows<Hungry<256>, BV>("lazy-hungry256", bv_name, name, step, reps, rows);
  scene_rows<Hungry<768>, BV>("lazy-hungry768", bv_name, name, step, reps, rows);
}

template <class BV>
void all_schedulers(const char* bv_name, const std::vector<std::pair<std::string, Step>>& scenes, const Sequence& horse,
                    int reps, std::vector<Row>& rows) {
  for (const auto& [name, step] : scenes) {
    scene_rows<gpu::StaticTaskList, BV>("static", bv_name, name, step, reps, rows);
    scene_rows<gpu::GProximityBalancer, BV>("gproximity", bv_name, name, step, reps, rows);
    scene_rows<gpu::LazyStealScheduler, BV>("lazy-steal", bv_name, name, step, reps, rows);
    scene_rows<FlatFrom<0>, BV>("lazy-flat0", bv_name, name, step, reps, rows);
    lazy_variants<BV>(bv_name, name, step, reps, rows);
    scene_rows<Hungry<0>, BV>("lazy-share-off", bv_name, name, step, reps, rows);  // no sharing on demand
    independent_rows<BV>(bv_name, name, step, reps, rows);
  }
  // The plain lazy scheduler (a thief takes from the fullest victim and waits for its lock; no
  // flat start, no sharing on demand: the variants of each refinement alone are above), and the
  // kernel left to the compiler's register choice (OBB: 113, so one block per SM) instead of
  // compiled to fit the default's two.
  for (const auto& [name, step] : scenes) {
    scene_rows<Plain, BV>("lazy-plain", bv_name, name, step, reps, rows);
    scene_rows<NoFit, BV>("lazy-nofit", bv_name, name, step, reps, rows);
  }
  sequence_rows<NoFit, BV>("lazy-nofit", bv_name, horse, rows);
  sequence_rows<Plain, BV>("lazy-plain", bv_name, horse, rows);
  sequence_rows<gpu::StaticTaskList, BV>("static", bv_name, horse, rows);
  sequence_rows<gpu::GProximityBalancer, BV>("gproximity", bv_name, horse, rows);
  sequence_rows<gpu::LazyStealScheduler, BV>("lazy-steal", bv_name, horse, rows);
  sequence_rows<FlatFrom<0>, BV>("lazy-flat0", bv_name, horse, rows);
  sequence_rows<Hungry<0>, BV>("lazy-share-off", bv_name, horse, rows);
  if (std::string(bv_name) == "AABB float") {
    sequence_rows<FlatFrom<128>, BV>("lazy-flat128", bv_name, horse, rows);
    sequence_rows<FlatFrom<2048>, BV>("lazy-flat2048", bv_name, horse, rows);
    sequence_rows<Lazy128Threads, BV>("lazy-128t", bv_name, horse, rows);
  }
}

// One recorded traversal per scene and start (AABB float, the lazy scheduler's defaults, after a
// warm-up): DIR/timeline_<scene>_<start>.csv with a row per event (block, time in ns from the
// launch's first event, phase, items), and a summary line each.
void write_timelines(const std::string& dir, const std::vector<std::pair<std::string, Step>>& scenes) {
  using Task = SelfCollisionTask<Aabbf>;
  for (const auto& [name, step] : scenes) {
    const DeviceScene<Aabbf> scene(*step.mesh, step.x0, step.x1);
    const Task task = scene.task();
    const NodePair* root = scene.root.data();
    gpu::TraversalOutput<Task> out;
    gpu::traverse<gpu::LazyStealScheduler>(task, root, 1, out, true);  // warm-up, and the front
    const std::vector<NodePair> front = out.download_front();
    gpu::DeviceBuffer<NodePair> d_front;
    d_front.upload(front);
    out.record_timeline(1 << 16);
    for (const char* start : {"root", "front"}) {
      const bool from_root = std::string(start) == "root";
      gpu::traverse<gpu::LazyStealScheduler>(task, from_root ? root : d_front.data(), from_root ? 1 : front.size(), out, true);
      const std::vector<gpu::BlockTimeline> timeline = out.download_timeline();
      if (timeline.empty()) {  // the flat launch ended every item: no lazy launch to show
        std::printf("%-18s %-5s: no lazy launch (the flat launch ended all %zu start items)\n", name.c_str(), start,
                    out.stats().flat_start_items);
        continue;
      }
      unsigned long long first = ~0ull, last = 0, working = 0, dropped = 0, steals = 0;
      for (const auto& b : timeline) {
        dropped += b.recorded - b.events.size();
        for (std::size_t k = 0; k < b.events.size(); ++k) {
          first = std::min(first, b.events[k].time_ns);
          last = std::max(last, b.events[k].time_ns);
          steals += b.events[k].phase == gpu::BlockPhase::steal;
          const bool works = b.events[k].phase == gpu::BlockPhase::own || b.events[k].phase == gpu::BlockPhase::steal;
          if (works && k + 1 < b.events.size()) working += b.events[k + 1].time_ns - b.events[k].time_ns;
        }
      }
      const std::string path = dir + "/timeline_" + name + "_" + start + ".csv";
      std::FILE* f = std::fopen(path.c_str(), "w");
      if (!f) throw std::runtime_error("cannot write " + path);
      std::fprintf(f, "block,time_ns,phase,items\n");
      static const char* phases[] = {"seek", "own", "steal", "done"};
      for (std::size_t b = 0; b < timeline.size(); ++b)
        for (const auto& e : timeline[b].events)
          std::fprintf(f, "%zu,%llu,%s,%u\n", b, e.time_ns - first, phases[static_cast<int>(e.phase)], e.items);
      std::fclose(f);
      const double span = last > first ? double(last - first) : 1.0;
      std::printf("%-18s %-5s: %zu blocks, lazy kernel %.1f us (first to last event), working %.1f%% of block time, %llu "
                  "steals, %llu events dropped -> %s\n", name.c_str(), start, timeline.size(), span / 1e3,
                  100.0 * double(working) / (span * double(timeline.size())), steals, dropped, path.c_str());
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  const lwsccd_bench::BenchArgs args =
      lwsccd_bench::parse_bench_args(argc, argv, 11, {"--timeline="},
                                     "usage: lwsccd-bench-traverse [--data DIR] [--reps N] [--json FILE] [--timeline DIR]");
  cudaDeviceProp prop{};
  if (!lwsccd_bench::first_gpu(prop, "lwsccd-bench-traverse")) return 77;
  try {
    const std::string dir = lwsccd_bench::data_dir(args.data, LWSCCD_BENCH_DATA_DIR);
    std::vector<std::pair<std::string, Step>> scenes;
    for (const char* name : {"cloth-ball", "cloth-funnel", "armadillo-rollers"})
      scenes.emplace_back(name, load_scene(dir + "/scenes/" + name).step);
    for (const auto& [flag, value] : args.values)
      if (flag == "--timeline") {
        std::printf("GPU: %s; lazy stealing timelines (AABB float, default knobs)\n", prop.name);
        write_timelines(value, scenes);
        return 0;
      }
    const Sequence horse = load_sequence(dir + "/sequences/horse-gallop");
    std::vector<Row> rows;
    all_schedulers<Aabbf>("AABB float", scenes, horse, args.reps, rows);
    all_schedulers<Obbf>("OBB float", scenes, horse, args.reps, rows);
    std::printf("GPU: %s (sm_%d%d); BVTT self-collision traversal (adjacent pairs skipped), CUDA events, median of %d runs\n",
                prop.name, prop.major, prop.minor, args.reps);
    std::printf("%-32s %-11s %-11s %-7s %10s %21s %11s %10s %10s %6s %8s %8s\n", "scene", "scheduler", "bv", "start", "median ms",
                "p10 - p90 ms", "BVTT nodes", "pairs", "front", "busy", "steals", "failed");
    for (const Row& r : rows)
      std::printf("%-32s %-11s %-11s %-7s %10.3f %10.3f - %8.3f %11zu %10zu %10zu %6.2f %8llu %8llu\n", r.scene.c_str(),
                  r.scheduler.c_str(), r.bv.c_str(), r.start.c_str(), r.median_ms, r.p10_ms, r.p90_ms, r.nodes, r.pairs,
                  r.front, r.busy_share, r.steals, r.failed_steals);
    lwsccd_bench::write_json_rows(args.json, rows.size(), [&](std::size_t i) {
      const Row& r = rows[i];
      return lwsccd_bench::Json{{"gpu", prop.name}, {"scene", r.scene}, {"scheduler", r.scheduler}, {"bv", r.bv},
                                {"start", r.start}, {"median_ms", r.median_ms}, {"p10_ms", r.p10_ms}, {"p90_ms", r.p90_ms},
                                {"bvtt_nodes", r.nodes}, {"pairs", r.pairs}, {"front", r.front}, {"busy_share", r.busy_share},
                                {"steals", r.steals}, {"failed_steals", r.failed_steals}};
    });
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lwsccd-bench-traverse: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
