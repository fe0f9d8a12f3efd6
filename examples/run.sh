#!/usr/bin/env bash
# Builds and runs the main program, lwsccd-ccd, on a fresh Debian machine: installs what it
# needs, builds only that program, then runs it with the arguments given (none: the built-in
# scene, no data needed): on the GPU when there is one, else on the CPU backend; see README.md.
set -euo pipefail
cd "$(dirname "$0")/.."
packages=(cmake g++ make ccache nlohmann-json3-dev libtbb-dev)
missing=()
for p in "${packages[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
if [ ${#missing[@]} -gt 0 ]; then
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${missing[@]}"
fi
# The GPU backend is built when there is a GPU to run it and nvcc to build it; otherwise the
# program is the CPU backend alone (and builds in a fraction of the time).
cuda=OFF
if nvidia-smi -L >/dev/null 2>&1 && { command -v nvcc >/dev/null 2>&1 || [ -x /usr/local/cuda/bin/nvcc ]; }; then
  cuda=ON
  command -v nvcc >/dev/null 2>&1 || export PATH="/usr/local/cuda/bin:$PATH"
fi
echo "lwsccd: building lwsccd-ccd (GPU backend: $cuda)" >&2
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DLWSCCD_ENABLE_CUDA=$cuda -DLWSCCD_BUILD_TESTS=OFF -DLWSCCD_BUILD_BENCH=OFF >/dev/null
cmake --build build -j"$(nproc)" --target lwsccd-ccd
exec ./build/examples/lwsccd-ccd "$@"
