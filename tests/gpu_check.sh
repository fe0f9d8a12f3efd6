#!/usr/bin/env bash
# The GPU check a developer runs on a machine with a GPU, in one call:
#   1. every GPU test (lwsccd_tests_gpu, the data tests too where LWSCCD_DATA_DIR is set);
#   2. a differential fuzzing run (random scenes, every GPU policy combination against the oracle);
#   3. compute-sanitizer's memcheck, racecheck, synccheck and initcheck on the GPU tests.
# It prints one summary line per part and exits non-zero if any part failed; each part's whole
# output goes to a log file.
#
# Usage: tests/gpu_check.sh [PATH/TO/lwsccd_tests_gpu]   (default: build/tests/lwsccd_tests_gpu)
# Environment:
#   LWSCCD_DATA_DIR          the data folder (../shared/data); without it the data tests skip
#   LWSCCD_CHECK_LOGS        where the logs go (default: gpu-check-logs)
#   LWSCCD_CHECK_PARTS       which parts run (default "tests fuzz sanitizers")
#   LWSCCD_FUZZ_SEED         first seed of the fuzzing run (default 1; scene k uses seed + k)
#   LWSCCD_FUZZ_SCENES       scenes per GPU configuration (default 2000; 0 skips the part)
#   LWSCCD_FUZZ_PARTS_EVERY  the pipelines in parts run on every N-th seed only (default 1: every
#                            scene; they cost ~5x a scene's 24 whole pipelines)
#   LWSCCD_SANITIZE_TESTS    Catch2 test spec for the sanitizer runs (default "~[data]~[fuzz]~[large]":
#                            every kernel runs in the procedural tests, and the tools slow them
#                            10-100x; [large] cases have a small twin that the tools run instead)
#   LWSCCD_SANITIZE_TOOLS    which tools (default "memcheck racecheck synccheck initcheck")
#   LWSCCD_SANITIZE_TIMEOUT  seconds per tool before it is stopped and counted failed (default 1200)
set -uo pipefail

tests="${1:-build/tests/lwsccd_tests_gpu}"
logs="${LWSCCD_CHECK_LOGS:-gpu-check-logs}"
fuzz_scenes="${LWSCCD_FUZZ_SCENES:-2000}"
fuzz_seed="${LWSCCD_FUZZ_SEED:-1}"
sanitize_spec="${LWSCCD_SANITIZE_TESTS:-~[data]~[fuzz]~[large]}"
sanitize_tools="${LWSCCD_SANITIZE_TOOLS:-memcheck racecheck synccheck initcheck}"
sanitize_timeout="${LWSCCD_SANITIZE_TIMEOUT:-1200}"
parts=" ${LWSCCD_CHECK_PARTS:-tests fuzz sanitizers} "

if [ ! -x "$tests" ]; then
  echo "gpu_check: no test binary at '$tests' (build the target lwsccd_tests_gpu, or pass its path)" >&2
  exit 2
fi
mkdir -p "$logs"
failed=0

# Seconds since $1 (whole seconds, from date +%s).
since() { echo $(($(date +%s) - $1)); }

# Catch2's closing line ("All tests passed (...)" or "test cases: ... failed"), or the skip message.
catch_summary() {
  grep -E "^SKIPPED:|All tests passed|test cases:" "$1" | tail -1
}

echo "gpu_check: $tests on" \
  "$(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null || echo 'no nvidia-smi')"

# 1. Every GPU test.
if [[ "$parts" == *" tests "* ]]; then
  t0=$(date +%s)
  "$tests" >"$logs/tests.log" 2>&1
  rc=$?
  echo "tests: rc=$rc, $(since "$t0") s: $(catch_summary "$logs/tests.log")"
  [ "$rc" -eq 0 ] || failed=1
fi

# 2. Fuzzing (the hidden [.fuzz] case: every GPU configuration against the CPU oracle).
if [[ "$parts" == *" fuzz "* ]] && [ "$fuzz_scenes" -gt 0 ]; then
  t0=$(date +%s)
  LWSCCD_FUZZ_SEED="$fuzz_seed" LWSCCD_FUZZ_SCENES="$fuzz_scenes" "$tests" "[.fuzz]" >"$logs/fuzz.log" 2>&1
  rc=$?
  echo "fuzz: rc=$rc, $(since "$t0") s, seeds $fuzz_seed..$((fuzz_seed + fuzz_scenes - 1)):" \
    "$(grep -h "^fuzz" "$logs/fuzz.log" | tail -1) $(catch_summary "$logs/fuzz.log")"
  [ "$rc" -eq 0 ] || failed=1
fi

# 3. compute-sanitizer, one tool at a time.
sanitizer="$(command -v compute-sanitizer || ls /usr/local/cuda*/bin/compute-sanitizer 2>/dev/null | head -1)"
if [[ "$parts" != *" sanitizers "* ]]; then
  :
elif [ -z "$sanitizer" ]; then
  echo "sanitizer: compute-sanitizer not found: not run"
  failed=1
else
  for tool in $sanitize_tools; do
    extra=()
    case "$tool" in
      memcheck) extra=(--leak-check full) ;;
      racecheck) extra=(--racecheck-report hazard) ;;
    esac
    t0=$(date +%s)
    timeout "$sanitize_timeout" "$sanitizer" --tool "$tool" "${extra[@]}" --error-exitcode 99 \
      "$tests" "$sanitize_spec" >"$logs/$tool.log" 2>&1
    rc=$?
    # The tool's own count: "ERROR SUMMARY: N errors" (racecheck: "RACECHECK SUMMARY: ...").
    count="$(grep -hE "(ERROR|RACECHECK) SUMMARY" "$logs/$tool.log" | tail -1 | sed 's/^=* *//')"
    note=""
    [ "$rc" -eq 124 ] && note=" (stopped after ${sanitize_timeout} s)"
    echo "$tool: rc=$rc, $(since "$t0") s$note: ${count:-no summary line} | $(catch_summary "$logs/$tool.log")"
    [ "$rc" -eq 0 ] || failed=1
  done
fi

if [ "$failed" -eq 0 ]; then echo "gpu_check: all parts passed (logs in $logs)"; else echo "gpu_check: FAILED (logs in $logs)"; fi
exit "$failed"
