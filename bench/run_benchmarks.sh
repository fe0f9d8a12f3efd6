#!/usr/bin/env bash
# Measures lwsccd on this machine and writes docs/BENCHMARKS.md from the results.
#
#   bash bench/run_benchmarks.sh [--only gpu|cpu] [--no-fp | --fp-only] [--build DIR] [--data DIR] [--results DIR] [--no-page]
#   bash bench/run_benchmarks.sh --plot [DIR]     # only the page and its charts, from results measured elsewhere
#
# It writes one file per benchmark and machine kind into the results folder (default docs/results),
# overwriting the last ones: <kind> is the GPU's short name (h100, h200, ...), or cpu.
#   GPU (where nvidia-smi sees one): machine_<kind>.json, pipeline_<kind>.json (whole step: default
#       policies per scene, methods x precision, scaling 1K..10M), traverse_<kind>.json (schedulers),
#       rays_<kind>.json, bvh_<kind>.json, multi_gpu_<kind>x<N>.json (two GPUs or more, NCCL),
#       fp_<kind>.json (FP64 and FP32 instructions of a steady
#       step per feature pair: bench/fp_instructions.py, where Nsight Compute's ncu is)
#   CPU: machine_cpu.json, accuracy_cpu.json (every narrow-phase method on the query sets and
#       scenes), pipeline_cpu.json (the CPU backend, default policies per scene)
# then bench/benchmarks_page.py draws the charts and writes the page (needs matplotlib).
# --no-fp leaves out the FP64/FP32 counts (Nsight Compute profiles lwsccd-ccd eight times: minutes);
# --fp-only measures only them (the GPU's other results and the CPU's are left as they are).
# The benchmarks are built in DIR (default build-bench) when they are not there yet; a machine
# without nvcc measures the CPU part only. The data comes from ../shared/data (or --data DIR).
# The commit recorded is `git rev-parse --short HEAD` (with "+changes" when the tree differs),
# or $LWSCCD_COMMIT where there is no git checkout (binaries built elsewhere).
set -euo pipefail
cd "$(dirname "$0")/.."

build="build-bench"
data=""
results="docs/results"
only=""
fp=1
fp_only=0
page=1
plot_only=0
while [ $# -gt 0 ]; do
  case "$1" in
    --plot) plot_only=1; if [ $# -gt 1 ] && [ "${2#--}" = "$2" ]; then results="$2"; shift; fi ;;
    --only) only="$2"; shift ;;
    --build) build="$2"; shift ;;
    --data) data="$2"; shift ;;
    --results) results="$2"; shift ;;
    --no-page) page=0 ;;
    --no-fp) fp=0 ;;
    --fp-only) fp_only=1 ;;
    -h|--help) sed -n '2,20p' "$0"; exit 0 ;;
    *) echo "run_benchmarks.sh: unknown argument '$1' (see --help)" >&2; exit 1 ;;
  esac
  shift
done
case "$only" in ""|gpu|cpu) ;; *) echo "run_benchmarks.sh: --only takes gpu or cpu, not '$only'" >&2; exit 1 ;; esac
if [ "$fp_only" = 1 ]; then
  [ "$fp" = 1 ] || { echo "run_benchmarks.sh: --fp-only and --no-fp exclude each other" >&2; exit 1; }
  [ "$only" != "cpu" ] || { echo "run_benchmarks.sh: --fp-only measures the GPU, not --only cpu" >&2; exit 1; }
  only="gpu"
fi

write_page() {
  if python3 -c "import matplotlib" 2>/dev/null; then
    python3 bench/benchmarks_page.py "$results" docs/BENCHMARKS.md
  else
    echo "run_benchmarks.sh: matplotlib is missing (apt-get install python3-matplotlib): results kept in $results;" \
         "write the page with: bash bench/run_benchmarks.sh --plot $results" >&2
  fi
}
if [ "$plot_only" = 1 ]; then
  [ -d "$results" ] || { echo "run_benchmarks.sh: no results folder $results" >&2; exit 1; }
  write_page
  exit 0
fi

# --- what is measured where
gpu_name=""
if [ "$only" != "cpu" ] && command -v nvidia-smi >/dev/null 2>&1; then
  gpu_name="$(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -n1 || true)"
fi
if [ "$only" = "gpu" ] && [ -z "$gpu_name" ]; then
  echo "run_benchmarks.sh: --only gpu, but nvidia-smi sees no GPU" >&2
  exit 1
fi
# The kind: the GPU's model in lower case (NVIDIA H100 80GB HBM3 -> h100, GeForce RTX 4090 -> rtx4090).
kind=""
if [ -n "$gpu_name" ]; then
  set -- $(echo "$gpu_name" | sed -E 's/NVIDIA|GeForce|Tesla|Quadro//g')
  kind="$(echo "$1" | tr 'A-Z' 'a-z')"
  case "$kind" in rtx|gtx) kind="$kind$(echo "${2:-}" | tr 'A-Z' 'a-z')" ;; esac
fi

# --- the benchmarks, built when missing
bin="$build/bench"
need=(lwsccd-bench-pipeline)
[ -n "$gpu_name" ] && [ ! -x "$build/examples/lwsccd-ccd" ] && build_ccd=1 || build_ccd=0
[ "$only" != "gpu" ] && need+=(lwsccd-accuracy)
[ -n "$gpu_name" ] && need+=(lwsccd-bench-traverse lwsccd-bench-rays lwsccd-bench-bvh)
missing=()
for t in "${need[@]}"; do [ -x "$bin/$t" ] || missing+=("$t"); done
if [ ${#missing[@]} -gt 0 ]; then
  cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DLWSCCD_BUILD_TESTS=OFF -DLWSCCD_BUILD_EXAMPLES=ON \
        -DLWSCCD_BUILD_BENCH=ON >/dev/null
  cmake --build "$build" -j"$(nproc)" --target "${missing[@]}"
fi
[ "$build_ccd" = 1 ] && cmake --build "$build" -j"$(nproc)" --target lwsccd-ccd
# Two GPUs or more: the split's benchmark, where the build found NCCL (no target otherwise).
if [ -n "$gpu_name" ] && [ "$(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | wc -l)" -ge 2 ] &&
   [ ! -x "$bin/lwsccd-bench-multi-gpu" ]; then
  cmake --build "$build" -j"$(nproc)" --target lwsccd-bench-multi-gpu 2>/dev/null ||
    echo "run_benchmarks.sh: no lwsccd-bench-multi-gpu (a build without NCCL): the split over GPUs not measured" >&2
fi
data_args=()
[ -n "$data" ] && data_args=(--data "$data")
mkdir -p "$results"

commit="${LWSCCD_COMMIT:-}"
if [ -z "$commit" ] && git rev-parse --short HEAD >/dev/null 2>&1; then
  commit="$(git rev-parse --short HEAD)"
  git diff --quiet HEAD -- include bench examples 2>/dev/null || commit="$commit+changes"
fi
# machine_<kind>.json: the machine, the build (bench/build_info.json, written by CMake), commit, date.
write_machine() {
  local file="$1" with_gpu="$2"
  python3 - "$file" "$with_gpu" "$bin/build_info.json" "${commit:-unknown}" <<'EOF'
import datetime, json, os, subprocess, sys
path, with_gpu, build_info, commit = sys.argv[1:5]
m = {"commit": commit, "date": datetime.date.today().isoformat()}
if with_gpu == "1":
    q = subprocess.run(["nvidia-smi", "--query-gpu=name,driver_version,memory.total", "--format=csv,noheader,nounits"],
                       capture_output=True, text=True).stdout.splitlines()[0].split(", ")
    m.update(gpu=q[0], driver=q[1], gpu_memory_mib=int(float(q[2])))
    head = subprocess.run(["nvidia-smi"], capture_output=True, text=True).stdout
    m["cuda_runtime"] = head.split("CUDA Version:")[1].split()[0] if "CUDA Version:" in head else "?"
cpu = "?"
with open("/proc/cpuinfo") as f:
    for line in f:
        if line.startswith("model name"):
            cpu = line.split(":", 1)[1].strip()
            break
m.update(cpu=cpu, cores=os.cpu_count())
if os.path.exists(build_info):
    with open(build_info) as f:
        m["build"] = json.load(f)
with open(path, "w") as f:
    json.dump(m, f, indent=1)
EOF
}

if [ -n "$gpu_name" ]; then
  echo "== GPU: $gpu_name (results *_$kind.json in $results)"
  if [ "$fp_only" = 0 ]; then
    write_machine "$results/machine_$kind.json" 1
    "$bin/lwsccd-bench-pipeline" --device gpu --sweep default,methods,scaling --reps 10 "${data_args[@]}" \
        --json "$results/pipeline_$kind.json"
    "$bin/lwsccd-bench-traverse" "${data_args[@]}" --json "$results/traverse_$kind.json"
    "$bin/lwsccd-bench-rays" "${data_args[@]}" --json "$results/rays_$kind.json"
    "$bin/lwsccd-bench-bvh" "${data_args[@]}" --json "$results/bvh_$kind.json"
    # The step split over GPUs, where there are two or more and the build has NCCL.
    gpus=$(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | wc -l)
    if [ "$gpus" -ge 2 ] && [ -x "$bin/lwsccd-bench-multi-gpu" ]; then
      "$bin/lwsccd-bench-multi-gpu" --sizes 1e6,1e7 --gpus "1,$gpus" --reps 11 --json "$results/multi_gpu_${kind}x$gpus.json"
    fi
  fi
  # FP64 and FP32 instructions of a steady step, per feature pair (Nsight Compute, where it is).
  ncu="$(command -v ncu || ls /usr/local/cuda*/bin/ncu 2>/dev/null | head -n1 || true)"
  ccd="$build/examples/lwsccd-ccd"
  if [ "$fp" = 0 ]; then
    echo "run_benchmarks.sh: --no-fp: FP64/FP32 instruction counts not measured" >&2
  elif [ -n "$ncu" ] && [ -x "$ccd" ]; then
    scenes="${data:-$(sed -n 's/^LWSCCD_DATA_DIR:PATH=//p' "$build/CMakeCache.txt" 2>/dev/null || true)}/scenes"
    python3 bench/fp_instructions.py --ncu "$ncu" --program "$ccd" --json "$results/fp_$kind.json" -- \
        "$scenes/cloth-ball" -- "$scenes/armadillo-rollers" -- "$scenes/cloth-funnel" -- --triangles 100000
    # The same, planned as for a GPU whose FP64 runs at 1/64 of its FP32 (the RTX and L40 classes).
    python3 bench/fp_instructions.py --ncu "$ncu" --program "$ccd" --json "$results/fp_planned_$kind.json" \
        --label "planned for a GPU with FP64 at 1/64 of FP32 (lwsccd-ccd --fp64-ratio 64)" -- \
        "$scenes/cloth-ball" --fp64-ratio 64 -- "$scenes/armadillo-rollers" --fp64-ratio 64 -- \
        "$scenes/cloth-funnel" --fp64-ratio 64 -- --triangles 100000 --fp64-ratio 64
  else
    echo "run_benchmarks.sh: no ncu or no $ccd: FP64/FP32 instruction counts not measured" >&2
  fi
fi
if [ "$only" != "gpu" ]; then
  echo "== CPU (results *_cpu.json in $results)"
  write_machine "$results/machine_cpu.json" 0
  # (no --data: the data folder the build was configured with, or $LWSCCD_DATA_DIR)
  "$bin/lwsccd-accuracy" ${data:+"$data"} --json "$results/accuracy_cpu.json"
  "$bin/lwsccd-bench-pipeline" --device cpu --sweep default --reps 3 "${data_args[@]}" --json "$results/pipeline_cpu.json"
fi
[ "$page" = 1 ] && write_page
exit 0
