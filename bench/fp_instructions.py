#!/usr/bin/env python3
"""FP64 and FP32 instructions of a steady CCD step, counted by Nsight Compute over every kernel.

usage: fp_instructions.py [--program lwsccd-ccd] [--ncu ncu] [--json OUT] [--label TEXT] -- INPUT [lwsccd-ccd options]

For each run it profiles lwsccd-ccd twice on the GPU, with --steps 1 and with --steps 3, and takes
the difference over two: the instructions of one steady step (refit, traversal from the front,
feature pairs, narrow phase), without the first step's BVH build and traversal from the root.
Metrics (thread instructions executed, predicated on):
  FP64: smsp__sass_thread_inst_executed_op_{dadd,dmul,dfma}_pred_on.sum
  FP32: smsp__sass_thread_inst_executed_op_{fadd,fmul,ffma}_pred_on.sum
It reports them per feature pair of the step, and the time the FP64 part alone would take at
0.6e12 FP64 instructions per second (a GPU of today's size that runs FP64 at 1/64 of FP32, as the
RTX and L40 classes do). Several inputs: separate them with '--', e.g.
  fp_instructions.py --json fp.json -- ../shared/data/scenes/cloth-ball -- --triangles 100000
lwsccd-ccd's options follow an input: '--fp64-ratio 64' counts the path a GPU with FP64 at 1/64 of
FP32 takes (its searches in double a thread each) on a GPU with more FP64, e.g. an H100.
"""
import argparse
import csv
import io
import json
import subprocess
import sys

FP64 = ["dadd", "dmul", "dfma"]
FP32 = ["fadd", "fmul", "ffma"]
METRIC = "smsp__sass_thread_inst_executed_op_{}_pred_on.sum"
FP64_RATE = 0.6e12  # FP64 instructions per second of an FP64-1/64 GPU
DURATION = "gpu__time_duration.sum"


def short_name(name):
    """A kernel's name without its template arguments and parameters."""
    name = name.split("(")[0].split("<")[0]
    return name.split("::")[-1].strip()


def profile(ncu, program, args, steps):
    """Sums of the metrics over every kernel of one run, per kernel name too, and the run's JSON output."""
    metrics = ",".join([METRIC.format(op) for op in FP64 + FP32] + [DURATION])
    log = f"/tmp/lwsccd_fp_{steps}.csv"
    cmd = [ncu, "--csv", "--page", "raw", "--clock-control", "none", "--metrics", metrics, "--log-file", log, program] + args + \
          ["--steps", str(steps), "--device", "gpu", "--json"]
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(f"fp_instructions.py: {' '.join(cmd)} failed ({run.returncode}):\n{run.stderr[-2000:]}")
    out = json.loads(run.stdout)
    with open(log) as f:
        text = f.read()
    rows = list(csv.reader(io.StringIO(text[text.index('"ID"'):])))
    header = rows[0]
    sums = {op: 0.0 for op in FP64 + FP32}
    per_kernel = {}
    kernels = 0
    name_col = header.index("Kernel Name")
    for r in rows[2:]:  # (row 1: units)
        if len(r) != len(header):
            continue
        kernels += 1
        k = per_kernel.setdefault(short_name(r[name_col]), {"fp64": 0.0, "fp32": 0.0, "ns": 0.0, "launches": 0})
        k["launches"] += 1
        for op in FP64 + FP32:
            v = r[header.index(METRIC.format(op))].replace(",", "")
            x = float(v) if v not in ("", "n/a") else 0.0
            sums[op] += x
            k["fp64" if op in FP64 else "fp32"] += x
        v = r[header.index(DURATION)].replace(",", "")
        k["ns"] += float(v) if v not in ("", "n/a") else 0.0
    return sums, kernels, out, per_kernel


def main():
    argv = sys.argv[1:]
    if "--" not in argv:
        sys.exit(__doc__)
    cut = argv.index("--")
    p = argparse.ArgumentParser()
    p.add_argument("--program", default="build/examples/lwsccd-ccd")
    p.add_argument("--ncu", default="ncu")
    p.add_argument("--json", default="")
    p.add_argument("--label", default="")
    opts = p.parse_args(argv[:cut])
    inputs, current = [], []
    for a in argv[cut + 1:]:
        if a == "--":
            inputs.append(current)
            current = []
        else:
            current.append(a)
    inputs.append(current)
    results = []
    print(f"{'input':<46} {'feature pairs':>13} {'FP64/pair':>10} {'FP32/pair':>10} {'FP64 G':>8} {'FP32 G':>8} "
          f"{'FP64 ms @0.6T/s':>15}")
    for args in inputs:
        one, k1, out1, per1 = profile(opts.ncu, opts.program, args, 1)
        three, k3, out3, per3 = profile(opts.ncu, opts.program, args, 3)
        # Per kernel, one steady step: (three steps - one step) / 2.
        per_kernel = {}
        for name, k in per3.items():
            b = per1.get(name, {"fp64": 0.0, "fp32": 0.0, "ns": 0.0, "launches": 0})
            per_kernel[name] = {key: (k[key] - b[key]) / 2 for key in k}
        steady = {op: (three[op] - one[op]) / 2 for op in FP64 + FP32}
        step = out3["steps"][-1]
        pairs = step["vf_pairs"] + step["ee_pairs"]
        fp64 = sum(steady[op] for op in FP64)
        fp32 = sum(steady[op] for op in FP32)
        row = {"label": opts.label, "input": " ".join(args), "gpu_program": out3.get("backend", "?"),
               "precision": out3.get("precision"), "method": out3.get("method"), "feature_pairs": pairs,
               "fp64_per_pair": fp64 / max(1, pairs), "fp32_per_pair": fp32 / max(1, pairs), "fp64": fp64, "fp32": fp32,
               "fp64_ms_at_0.6T": 1e3 * fp64 / FP64_RATE, "by_op": steady, "kernels_one_step": k1,
               "kernels_three_steps": k3, "narrow_ms": step["ms"]["narrow"], "certified": step.get("certified"),
               "decided": step.get("decided"), "per_kernel": per_kernel}
        results.append(row)
        print(f"{row['input'][:46]:<46} {pairs:>13,} {row['fp64_per_pair']:>10.1f} {row['fp32_per_pair']:>10.1f} "
              f"{fp64 / 1e9:>8.3f} {fp32 / 1e9:>8.3f} {row['fp64_ms_at_0.6T']:>15.2f}")
        top = sorted(per_kernel.items(), key=lambda kv: -kv[1]["ns"])[:8]
        for name, k in top:
            print(f"    {name[:44]:<44} {k['ns'] / 1e3:>9.1f} us {k['fp64'] / max(1, pairs):>8.1f} FP64/pair "
                  f"{k['fp32'] / max(1, pairs):>8.1f} FP32/pair  x{k['launches']:g}")
    if opts.json:
        with open(opts.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
