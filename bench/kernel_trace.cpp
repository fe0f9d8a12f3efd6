// lwsccd — a kernel timeline of any CUDA program: a CUPTI injection library that records every
// kernel, memcpy and memset with its start and end (GPU clock, ns) and its stream, one line each,
// tab-separated, to $LWSCCD_TRACE_OUT (default lwsccd_trace.tsv), when the program exits:
//
//   CUDA_INJECTION64_PATH=build/bench/liblwsccd-kernel-trace.so LWSCCD_TRACE_OUT=trace.tsv \
//     build/examples/lwsccd-ccd SCENE --steps 6
//   python3 bench/kernel_timeline.py trace.tsv
//
// Lines: K start end stream grid block name (a kernel), C start end stream bytes copy-kind
// (a memcpy), S start end stream bytes (a memset). Unlike Nsight Compute it leaves the
// kernels running concurrently, so it shows where streams overlap and where the GPU waits for
// the host (gaps). With LWSCCD_TRACE_API=1 it also records the host's CUDA runtime calls, A start
// end thread name (the same clock), which show what the host was doing in such a gap. The
// driver loads it and calls InitializeInjection before the program's first CUDA call.
#include <cupti.h>

#include <cstdio>
#include <cstdlib>
#include <mutex>

namespace {

FILE* trace_file = nullptr;
std::mutex trace_mutex;

void check(CUptiResult r, const char* what) {
  if (r == CUPTI_SUCCESS) return;
  const char* text = nullptr;
  cuptiGetResultString(r, &text);
  std::fprintf(stderr, "lwsccd-kernel-trace: %s failed: %s\n", what, text ? text : "unknown CUPTI error");
}

void CUPTIAPI buffer_requested(uint8_t** buffer, size_t* size, size_t* max_records) {
  *size = std::size_t(8) << 20;
  *buffer = static_cast<uint8_t*>(std::aligned_alloc(8, *size));
  *max_records = 0;
}

void CUPTIAPI buffer_completed(CUcontext, uint32_t, uint8_t* buffer, size_t, size_t valid) {
  std::lock_guard<std::mutex> lock(trace_mutex);
  CUpti_Activity* record = nullptr;
  while (trace_file && cuptiActivityGetNextRecord(buffer, valid, &record) == CUPTI_SUCCESS) {
    switch (record->kind) {
      case CUPTI_ACTIVITY_KIND_CONCURRENT_KERNEL:
      case CUPTI_ACTIVITY_KIND_KERNEL: {
        const auto* k = reinterpret_cast<const CUpti_ActivityKernel10*>(record);
        std::fprintf(trace_file, "K\t%llu\t%llu\t%u\t%d,%d,%d\t%d\t%s\n", static_cast<unsigned long long>(k->start),
                     static_cast<unsigned long long>(k->end), k->streamId, k->gridX, k->gridY, k->gridZ, k->blockX, k->name);
        break;
      }
      case CUPTI_ACTIVITY_KIND_MEMCPY: {
        const auto* m = reinterpret_cast<const CUpti_ActivityMemcpy6*>(record);
        std::fprintf(trace_file, "C\t%llu\t%llu\t%u\t%llu\t%d\n", static_cast<unsigned long long>(m->start),
                     static_cast<unsigned long long>(m->end), m->streamId, static_cast<unsigned long long>(m->bytes),
                     static_cast<int>(m->copyKind));
        break;
      }
      case CUPTI_ACTIVITY_KIND_MEMSET: {
        const auto* m = reinterpret_cast<const CUpti_ActivityMemset4*>(record);
        std::fprintf(trace_file, "S\t%llu\t%llu\t%u\t%llu\n", static_cast<unsigned long long>(m->start),
                     static_cast<unsigned long long>(m->end), m->streamId, static_cast<unsigned long long>(m->bytes));
        break;
      }
      case CUPTI_ACTIVITY_KIND_RUNTIME: {
        const auto* a = reinterpret_cast<const CUpti_ActivityAPI*>(record);
        const char* name = nullptr;
        if (cuptiGetCallbackName(CUPTI_CB_DOMAIN_RUNTIME_API, a->cbid, &name) != CUPTI_SUCCESS || !name) name = "?";
        std::fprintf(trace_file, "A\t%llu\t%llu\t%u\t%s\n", static_cast<unsigned long long>(a->start),
                     static_cast<unsigned long long>(a->end), a->threadId, name);
        break;
      }
      default:
        break;
    }
  }
  std::free(buffer);
}

void flush_at_exit() {
  check(cuptiActivityFlushAll(1), "cuptiActivityFlushAll");
  std::lock_guard<std::mutex> lock(trace_mutex);
  if (trace_file) std::fclose(trace_file);
  trace_file = nullptr;
}

}  // namespace

extern "C" int InitializeInjection() {
  const char* path = std::getenv("LWSCCD_TRACE_OUT");
  trace_file = std::fopen(path ? path : "lwsccd_trace.tsv", "w");
  if (!trace_file) {
    std::fprintf(stderr, "lwsccd-kernel-trace: cannot write %s\n", path ? path : "lwsccd_trace.tsv");
    return 0;
  }
  check(cuptiActivityRegisterCallbacks(buffer_requested, buffer_completed), "cuptiActivityRegisterCallbacks");
  check(cuptiActivityEnable(CUPTI_ACTIVITY_KIND_CONCURRENT_KERNEL), "cuptiActivityEnable(kernels)");
  check(cuptiActivityEnable(CUPTI_ACTIVITY_KIND_MEMCPY), "cuptiActivityEnable(memcpy)");
  check(cuptiActivityEnable(CUPTI_ACTIVITY_KIND_MEMSET), "cuptiActivityEnable(memset)");
  const char* api = std::getenv("LWSCCD_TRACE_API");
  if (api && api[0] == '1') check(cuptiActivityEnable(CUPTI_ACTIVITY_KIND_RUNTIME), "cuptiActivityEnable(runtime)");
  std::atexit(flush_at_exit);
  return 1;
}
