// lwsccd-bench-multi-gpu: the built-in scene's steady step on one GPU (gpu::CcdPipeline) and split
// over 1, 2, ... GPUs (gpu::MultiGpuPipeline), from positions already on the first GPU, with the
// contacts left there (the device-resident step: the split's broadcast of the positions and its
// gathering of the contacts are counted). Every configuration runs the same steps of the scene;
// the first `--warm` steps are not timed. Rows: medians and p10/p90 of the timed steps, the stages
// of the slowest GPU, each GPU's busy time and memory, front entries moved; the contacts and
// earliest TOI of every step are checked against the one-GPU pipeline's.
#include <cuda_runtime.h>

#include <chrono>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "lwsccd/multi_gpu.cuh"
#include "lwsccd/simulation/simulation.hpp"

namespace {

struct Row {
  std::string config;
  std::size_t triangles = 0, gpus = 0;
  std::vector<double> step_ms, refit_ms, traverse_ms, features_ms, narrow_ms;
  std::vector<std::vector<double>> busy_ms;  // per GPU
  std::vector<double> peak_mib;              // per GPU, last step
  std::vector<double> positions_ms, share_step_ms, exchange_ms, gather_ms, rebalance_ms, moved;  // the split's host times
  std::size_t contacts = 0, differences = 0;
  double earliest = 1;
};

std::vector<double> parse_list(const std::string& text) {
  std::vector<double> out;
  std::size_t at = 0;
  while (at <= text.size()) {
    const std::size_t comma = text.find(',', at);
    const std::string item = text.substr(at, comma == std::string::npos ? std::string::npos : comma - at);
    if (!item.empty()) out.push_back(std::stod(item));
    if (comma == std::string::npos) break;
    at = comma + 1;
  }
  return out;
}

// A timed step's figures: the call's host time and the stages of `stats` (the slowest GPU's).
void record(Row& row, double ms, const lwsccd::StepStats& stats) {
  row.step_ms.push_back(ms);
  row.refit_ms.push_back(stats.refit_ms);
  row.traverse_ms.push_back(stats.traverse_ms);
  row.features_ms.push_back(stats.features_ms);
  row.narrow_ms.push_back(stats.narrow_ms);
}

double elapsed_ms(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - since).count();
}

}  // namespace

int main(int argc, char** argv) {
  using namespace lwsccd;
  const lwsccd_bench::BenchArgs args = lwsccd_bench::parse_bench_args(
      argc, argv, 10, {"--sizes=", "--gpus=", "--warm="},
      "usage: lwsccd-bench-multi-gpu [--sizes 1e6,1e7] [--gpus 1,2] [--warm N] [--reps N] [--json FILE]");
  int available = 0;
  if (cudaGetDeviceCount(&available) != cudaSuccess || available == 0) {
    std::printf("SKIPPED: no CUDA device\n");
    return 77;
  }
  try {
    const std::vector<double> sizes = parse_list(args.value("--sizes", "1e6,1e7"));
    std::vector<double> gpu_counts = parse_list(args.value("--gpus", "1,2"));
    const int warm = std::max(1, std::stoi(args.value("--warm", "3")));
    cudaDeviceProp prop{};
    LWSCCD_CUDA_CHECK(cudaGetDeviceProperties(&prop, 0));
    int nccl_version = 0;
    ncclGetVersion(&nccl_version);
    std::printf("%d x %s, NCCL %d; %d warm steps, %d timed\n", available, prop.name, nccl_version, warm, args.reps);
    std::vector<Row> rows;
    for (const double size : sizes) {
      ClothBallSimulation sim(static_cast<std::size_t>(size));
      sim.advance(30);
      std::vector<Step> steps;
      for (int s = 0; s < warm + args.reps; ++s) steps.push_back(sim.next_step());
      const std::size_t vertices = sim.mesh()->num_vertices();
      // The steps' positions on the first GPU, uploaded before each timed step.
      LWSCCD_CUDA_CHECK(cudaSetDevice(0));
      gpu::DeviceBuffer<Vec3d> x0(vertices), x1(vertices);
      auto place = [&](const Step& s) {
        LWSCCD_CUDA_CHECK(cudaSetDevice(0));
        LWSCCD_CUDA_CHECK(cudaMemcpy(x0.data(), s.x0.data(), vertices * sizeof(Vec3d), cudaMemcpyHostToDevice));
        LWSCCD_CUDA_CHECK(cudaMemcpy(x1.data(), s.x1.data(), vertices * sizeof(Vec3d), cudaMemcpyHostToDevice));
        LWSCCD_CUDA_CHECK(cudaDeviceSynchronize());
      };
      // The one-GPU pipeline: the reference (contacts per step) and the baseline row.
      std::vector<std::size_t> contacts(steps.size());
      std::vector<double> earliest(steps.size());
      {
        Row row{"one-gpu", static_cast<std::size_t>(sim.mesh()->num_faces()), 1};
        gpu::CcdPipeline<> one(sim.mesh(), sim.layout());
        for (std::size_t s = 0; s < steps.size(); ++s) {
          place(steps[s]);
          const auto start = std::chrono::steady_clock::now();
          const DeviceStepResult<double> r = one.step_on_device(x0.data(), x1.data());
          const double ms = elapsed_ms(start);
          contacts[s] = r.contacts.num_vf + r.contacts.num_ee;
          earliest[s] = r.contacts.earliest_toi;
          if (static_cast<int>(s) < warm) continue;
          record(row, ms, r.stats);
          row.busy_ms.resize(1);
          row.busy_ms[0].push_back(r.stats.traverse_ms + r.stats.features_ms + r.stats.narrow_ms);
          row.contacts = contacts[s];
          row.earliest = earliest[s];
        }
        row.peak_mib = {static_cast<double>(one.device_bytes()) / (1 << 20)};
        rows.push_back(row);
      }
      for (const double g : gpu_counts) {
        const int n = static_cast<int>(g);
        if (n > available) {
          std::printf("(%d GPUs asked, %d present: row skipped)\n", n, available);
          continue;
        }
        std::vector<int> devices;
        for (int d = 0; d < n; ++d) devices.push_back(d);
        Row row{"split", static_cast<std::size_t>(sim.mesh()->num_faces()), static_cast<std::size_t>(n)};
        gpu::MultiGpuPipeline<> split(sim.mesh(), sim.layout(), devices);
        for (std::size_t s = 0; s < steps.size(); ++s) {
          place(steps[s]);
          const auto start = std::chrono::steady_clock::now();
          const DeviceStepResult<double> r = split.step_on_device(x0.data(), x1.data());
          const double ms = elapsed_ms(start);
          row.differences += r.contacts.num_vf + r.contacts.num_ee != contacts[s] || r.contacts.earliest_toi != earliest[s];
          if (static_cast<int>(s) < warm) continue;
          record(row, ms, r.stats);
          row.busy_ms.resize(devices.size());
          for (std::size_t d = 0; d < devices.size(); ++d) {
            const StepStats& ds = split.device_stats()[d];
            row.busy_ms[d].push_back(ds.traverse_ms + ds.features_ms + ds.narrow_ms);
          }
          row.contacts = r.contacts.num_vf + r.contacts.num_ee;
          row.earliest = r.contacts.earliest_toi;
          const gpu::MultiGpuTimes& t = split.last_times();
          row.positions_ms.push_back(t.positions_ms);
          row.share_step_ms.push_back(t.share_step_ms);
          row.exchange_ms.push_back(t.exchange_ms);
          row.gather_ms.push_back(t.gather_ms);
          row.rebalance_ms.push_back(t.rebalance_ms);
          row.moved.push_back(static_cast<double>(split.last_moved_front_entries()));
        }
        for (const StepStats& ds : split.device_stats()) row.peak_mib.push_back(static_cast<double>(ds.peak_device_bytes) / (1 << 20));
        rows.push_back(row);
      }
    }
    using lwsccd_bench::median;
    using lwsccd_bench::percentile;
    std::printf("%-8s %10s %4s %9s %8s %8s %7s %9s %9s %9s  %-22s %-22s %9s %7s\n", "config", "triangles", "gpus", "step ms", "p10",
                "p90", "refit", "traverse", "features", "narrow", "busy ms per GPU", "MiB per GPU", "contacts", "diffs");
    for (const Row& r : rows) {
      std::string busy, mib;
      for (const auto& b : r.busy_ms) busy += std::to_string(median(b)).substr(0, 6) + " ";
      for (const double m : r.peak_mib) mib += std::to_string(static_cast<long>(m)) + " ";
      std::printf("%-8s %10zu %4zu %9.3f %8.3f %8.3f %7.3f %9.3f %9.3f %9.3f  %-22s %-22s %9zu %7zu\n", r.config.c_str(), r.triangles,
                  r.gpus, median(r.step_ms), percentile(r.step_ms, 0.1), percentile(r.step_ms, 0.9), median(r.refit_ms), median(r.traverse_ms),
                  median(r.features_ms), median(r.narrow_ms), busy.c_str(), mib.c_str(), r.contacts, r.differences);
      if (!r.share_step_ms.empty())
        std::printf("         host ms on the root's thread: positions %.3f, share's step %.3f, exchange %.3f, gather %.3f, "
                    "rebalance %.3f; front entries moved %.0f (median)\n",
                    median(r.positions_ms), median(r.share_step_ms), median(r.exchange_ms), median(r.gather_ms),
                    median(r.rebalance_ms), median(r.moved));
    }
    lwsccd_bench::write_json_rows(args.json, rows.size(), [&](std::size_t i) {
      const Row& r = rows[i];
      lwsccd_bench::Json busy = lwsccd_bench::Json::array();
      for (const auto& b : r.busy_ms) busy.push_back(median(b));
      return lwsccd_bench::Json{{"config", r.config},
                                {"gpu", prop.name},
                                {"triangles", r.triangles},
                                {"gpus", r.gpus},
                                {"step_ms", median(r.step_ms)},
                                {"step_p10_ms", percentile(r.step_ms, 0.1)},
                                {"step_p90_ms", percentile(r.step_ms, 0.9)},
                                {"refit_ms", median(r.refit_ms)},
                                {"traverse_ms", median(r.traverse_ms)},
                                {"features_ms", median(r.features_ms)},
                                {"narrow_ms", median(r.narrow_ms)},
                                {"busy_ms_per_gpu", busy},
                                {"device_mib_per_gpu", r.peak_mib},
                                {"contacts", r.contacts},
                                {"earliest_toi", r.earliest},
                                {"steps_differing_from_one_gpu", r.differences},
                                {"positions_ms", median(r.positions_ms)},
                                {"share_step_ms", median(r.share_step_ms)},
                                {"exchange_ms", median(r.exchange_ms)},
                                {"gather_ms", median(r.gather_ms)},
                                {"rebalance_ms", median(r.rebalance_ms)},
                                {"front_entries_moved", median(r.moved)},
                                {"reps", r.step_ms.size()}};
    });
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lwsccd-bench-multi-gpu: %s\n", e.what());
    return 1;
  }
  return 0;
}
