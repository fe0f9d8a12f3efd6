#!/usr/bin/env bash
# Regenerates docs/results/pipeline_*.json and the charts of docs/BENCHMARKS.md.
#
#   bash bench/run_benchmarks.sh [BUILD_DIR]        # measure (GPU if present) and plot
#   bash bench/run_benchmarks.sh --plot FILE.json   # only plot (where the numbers came from elsewhere)
#
# BUILD_DIR (default build-bench) is configured and built here if it has no benchmark yet.
set -euo pipefail
cd "$(dirname "$0")/.."
plot() {
  python3 bench/plot_pipeline.py "$1" docs/results
  echo "charts written to docs/results/pipeline_*.png"
}
if [ "${1:-}" = "--plot" ]; then
  plot "$2"
  exit 0
fi
build="${1:-build-bench}"
if [ ! -x "$build/bench/lwsccd-bench-pipeline" ]; then
  cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DLWSCCD_BUILD_TESTS=OFF >/dev/null
  cmake --build "$build" -j"$(nproc)" --target lwsccd-bench-pipeline
fi
out="docs/results/pipeline.json"
"$build/bench/lwsccd-bench-pipeline" --sweep all --reps 5 --json "$out" | tee docs/results/pipeline.txt
plot "$out"
