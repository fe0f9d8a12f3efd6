#!/usr/bin/env python3
"""Writes docs/BENCHMARKS.md and its charts from a results folder (bench/run_benchmarks.sh calls it).

usage: benchmarks_page.py RESULTS_DIR PAGE.md

RESULTS_DIR holds one file per benchmark and device kind, as run_benchmarks.sh writes them:
  machine_<kind>.json    the machine, the build, the commit and the date of the measurement
  pipeline_<kind>.json   lwsccd-bench-pipeline --sweep default,methods,scaling
  traverse_<kind>.json   lwsccd-bench-traverse
  rays_<kind>.json       lwsccd-bench-rays
  bvh_<kind>.json        lwsccd-bench-bvh
  accuracy_cpu.json      lwsccd-accuracy (every method and precision on the query sets and scenes)
  pipeline_cpu.json      lwsccd-bench-pipeline --device cpu --sweep default (with machine_cpu.json)
  ipctk.json             bench/compare_ipctk.py --json (ipc-toolkit beside lwsccd; its rows name their machine)
The charts (<area>_<kind>.png) are written next to them. Every number on the page comes from
these files; the few lines of prose around a table compute theirs from the same rows.
"""
import json
import os
import sys
from collections import OrderedDict

try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:
    sys.exit("matplotlib is missing: apt-get install python3-matplotlib (or pip install matplotlib)")

STAGES = [("refit_ms", "refit / build"), ("traverse_ms", "traversal"), ("features_ms", "feature pairs"),
          ("narrow_ms", "narrow phase")]
SCENE_ORDER = ["cloth-funnel", "horse-gallop", "armadillo-rollers", "cloth-ball"]


# --- small helpers -------------------------------------------------------------------------------
def load(path):
    if not os.path.exists(path):
        return None
    with open(path) as f:
        return json.load(f)


def ms(x, digits=None):
    """A time in ms with about three significant digits."""
    if x is None:
        return "-"
    if digits is not None:
        return f"{x:.{digits}f}"
    if x >= 100:
        return f"{x:,.0f}"
    if x >= 10:
        return f"{x:.1f}"
    if x >= 1:
        return f"{x:.2f}"
    return f"{x:.3f}"


def us(x):
    """A time in microseconds with two or three significant digits."""
    if x is None:
        return "-"
    return f"{x:,.0f}" if x >= 100 else f"{x:.2g}"


def count(n):
    return "-" if n is None else f"{int(n):,}"


def table(header, rows, align=None):
    align = align or ["---"] + ["---:"] * (len(header) - 1)
    out = ["| " + " | ".join(header) + " |", "|" + "|".join(align) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def scene_key(name):
    base = name.split(" ")[0]
    if base.startswith("builtin-"):
        digits = "".join(c for c in base if c.isdigit())
        return (1, int(digits or 0))
    return (0, SCENE_ORDER.index(base) if base in SCENE_ORDER else len(SCENE_ORDER))


def builtin_label(scene, triangles):
    if not scene.startswith("builtin"):
        return scene
    for size, label in ((10_000_000, "10M"), (1_000_000, "1M"), (100_000, "100K"), (10_000, "10K"), (1_000, "1K")):
        if triangles >= 0.8 * size:
            return f"built-in {label}"
    return f"built-in {triangles}"


def save_chart(fig, out_dir, name, kind, alt):
    """Writes the chart as <name>_<kind>.png in out_dir; returns the page's lines that show it."""
    chart = f"{name}_{kind}.png"
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, chart), dpi=110)
    plt.close(fig)
    return ["", f"![{alt}](results/{chart})"]


# --- machine -------------------------------------------------------------------------------------
def machine_lines(m, what):
    if not m:
        return [f"*{what}: no machine file in the results folder.*"]
    b = m.get("build", {})
    lines = [f"| {what} | |", "|---|---|"]
    if m.get("gpu"):
        lines.append(f"| GPU | {m['gpu']} ({m.get('gpu_memory_mib', '?')} MiB), driver {m.get('driver', '?')}, "
                     f"CUDA runtime {m.get('cuda_runtime', '?')} |")
    lines.append(f"| CPU | {m.get('cpu', '?')}, {m.get('cores', '?')} cores |")
    if b:
        comp = f"{b.get('cxx_compiler', '?')}"
        if b.get("cuda_compiler"):
            comp += f"; nvcc {b['cuda_compiler']} (architectures {b.get('cuda_architectures', '?')})"
        flags = f"C++ `{b.get('flags', '').strip()}`"
        if b.get("cuda_flags"):
            flags += f", CUDA `{b['cuda_flags'].strip()}`"
        lines.append(f"| Build | {b.get('type', '?')}: {comp}; {flags} (the library adds `-ffp-contract=off`) |")
    lines.append(f"| Commit | `{m.get('commit', '?')}` |")
    lines.append(f"| Date | {m.get('date', '?')} |")
    return lines


# --- whole step ----------------------------------------------------------------------------------
def pipeline_rows(rows, sweep):
    return [r for r in rows if r["sweep"] == sweep]


def by_scene_step(rows):
    out = OrderedDict()
    for r in sorted(rows, key=lambda r: scene_key(r["scene"])):
        out.setdefault(r["scene"], {})[r["step"]] = r
    return out


def spread(r):
    if r.get("p10_total_ms") is None:
        return ms(r["total_ms"])
    return f"{ms(r['total_ms'])} ({ms(r['p10_total_ms'])}-{ms(r['p90_total_ms'])})"


def whole_step_section(rows, kind, out_dir, gpu):
    rows = pipeline_rows(rows, "default")
    if not rows:
        return ["*Not measured (no `default` sweep in the pipeline results).*"]
    scenes = by_scene_step(rows)
    body = []
    for scene, steps in scenes.items():
        first, steady, device = steps.get("first"), steps.get("steady"), steps.get("device")
        base = steady or first
        truth = "-"
        if base.get("false_negatives") is not None:
            truth = f"{base['false_negatives']} / {base['false_positives']}"
        stages = " / ".join(ms(base[k]) for k, _ in STAGES)
        label = builtin_label(scene, base["triangles"])
        if scene == "horse-gallop":
            label += f" ({base['steps_measured'] + 1} steps)"
        body.append([label, count(base["triangles"]), ms(first["total_ms"]) if first else "-",
                     spread(steady) if steady else "-", spread(device) if device else "-", stages,
                     count(base["feature_pairs"]), count(base["contacts"]), truth,
                     ms(base["peak_device_bytes"] / 2**20, 0) if base.get("peak_device_bytes") else "-"])
    header = ["scene", "triangles", "first ms", "steady ms, host to host (p10-p90)", "steady ms, device-resident (p10-p90)",
              "steady stages ms: refit / traversal / feature pairs / narrow", "feature pairs", "contacts", "FN / FP",
              "peak MiB"]
    lines = [table(header, body)]
    # The chart: per scene the first step, the steady step host to host and device-resident, by stage.
    fig, ax = plt.subplots(figsize=(max(6.5, 1.5 * len(scenes)), 4.5))
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    width = 0.27
    names = list(scenes)
    for offset, which, hatch in ((-width, "first", "//"), (0, "steady", None), (width, "device", "..")):
        bottom = [0.0] * len(names)
        for si, (key, label) in enumerate(STAGES):
            vals = [scenes[n][which][key] if which in scenes[n] else 0.0 for n in names]
            ax.bar([i + offset for i in range(len(names))], vals, width, bottom=bottom, color=colors[si], hatch=hatch,
                   edgecolor="white", label=label if which == "steady" else None)
            bottom = [b + v for b, v in zip(bottom, vals)]
    ax.set_xticks(range(len(names)))
    ax.set_xticklabels([builtin_label(n, next(iter(scenes[n].values()))["triangles"]) for n in names], fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("ms (log)")
    ax.set_title(f"Stages per step: first (hatched), steady host to host, steady device-resident (dotted)\n{gpu}",
                 fontsize=9)
    ax.legend(fontsize=8)
    lines += save_chart(fig, out_dir, "pipeline_stages", kind, "stages per step")
    # What it teaches, from the rows.
    cb = scenes.get("cloth-ball", {})
    if "steady" in cb and "first" in cb:
        s, f = cb["steady"], cb["first"]
        dev = cb.get("device")
        share = 100.0 * s["narrow_ms"] / max(1e-9, s["refit_ms"] + s["traverse_ms"] + s["features_ms"] + s["narrow_ms"])
        lines += ["", f"On cloth-ball the first step takes {ms(f['total_ms'])} ms, {f['total_ms'] / (dev or s)['total_ms']:.1f}x "
                  f"the steady {'device-resident ' if dev else ''}step ({ms((dev or s)['total_ms'])} ms): it builds the BVH "
                  f"and traverses from the root, where a steady step refits and starts from the last step's front. "
                  f"The narrow phase is {share:.0f}% of the steady step's stages."]
    return lines


def cpu_section(rows, machine):
    rows = pipeline_rows(rows or [], "default")
    if not rows:
        return []
    scenes = by_scene_step(rows)
    body = []
    for scene, steps in scenes.items():
        first, steady = steps.get("first"), steps.get("steady")
        base = steady or first
        body.append([builtin_label(scene, base["triangles"]), count(base["triangles"]), ms(first["total_ms"]) if first else "-",
                     spread(steady) if steady else "-", " / ".join(ms(base[k]) for k, _ in STAGES),
                     count(base["contacts"])])
    cpu = machine.get("cpu", "?") if machine else "?"
    cores = machine.get("cores", "?") if machine else "?"
    return ["## The CPU backend", "",
            f"The same default sweep on the CPU backend ({cpu}, {cores} cores; `--device cpu`). It is also the oracle "
            "that every GPU test compares with, pair for pair.", "",
            table(["scene", "triangles", "first ms", "steady ms (p10-p90)", "steady stages ms", "contacts"], body), ""]


def ipctk_section(rows):
    """ipc-toolkit beside lwsccd (bench/compare_ipctk.py --json, ipctk.json): one machine, one run."""
    if not rows:
        return []
    timed = [r for r in rows if "median_ms" in r]
    if not timed:
        return []
    r0 = timed[0]
    scenes = [s for s in ("cloth-ball", "armadillo-rollers", "cloth-funnel") if any(r["scene"] == s for r in timed)]
    names = []
    for r in timed:
        if r["broad_phase"] not in names:
            names.append(r["broad_phase"])
    body = []
    for name in names:
        cells = []
        for scene in scenes:
            r = next((x for x in timed if x["scene"] == scene and x["broad_phase"] == name), None)
            if r is None:
                cells.append("-")
            elif name.startswith("lwsccd"):
                cells.append(f"{ms(r['first_ms'])} / {ms(r['median_ms'])}; step {r['step']:.6g}")
            else:
                cells.append(f"{ms(r['median_ms'])}; step {r['step']:.6g}")
        version = next((x["ipctk"] for x in timed if x.get("ipctk")), "")
        label = f"ipctk {version} {name} + Tight Inclusion" if not name.startswith("lwsccd") else \
            (name.replace("lwsccd cpu", "lwsccd, CPU backend").replace("lwsccd gpu", "lwsccd, GPU"))
        body.append([label] + cells)
    pairs = []
    for scene in scenes:
        counted = next((x for x in rows if x["scene"] == scene and "candidates" in x), None)
        ours = next((x for x in timed if x["scene"] == scene and x["broad_phase"].startswith("lwsccd")), None)
        text = f"{scene}: lwsccd {ours['colliding_pairs']:,}" if ours else f"{scene}:"
        if counted and counted.get("colliding_pairs") is not None:
            text += f", ipctk {counted['colliding_pairs']:,} (of its {counted['candidates']:,} LBVH candidates)"
        elif counted:
            text += f", ipctk not counted ({counted['candidates']:,} candidates, one Python call each)"
        pairs.append(text)
    gpu = next((x.get("gpu") for x in timed if x.get("gpu")), "")
    from_benchmark = any(x.get("source") for x in timed if x["broad_phase"].startswith("lwsccd"))
    lwsccd_text = ("lwsccd: the same step (mode contacts, host to host) as first step of a new pipeline / steady step of a "
                   "kept one (a line search's repeated calls), ms, and the step lwsccd.ipc returns (0.8 x the certified "
                   "earliest contact)." if from_benchmark else
                   "lwsccd: `lwsccd.ipc.compute_collision_free_stepsize`, the same question (mode earliest), as a first call "
                   "from scratch (a new pipeline: the mesh's checks and the pipeline's construction included) / steady calls "
                   "(the pipeline it keeps: a line search's repeated calls), median ms, and the step it returns (0.8 x the "
                   "certified earliest contact).")
    out = [f"ipc-toolkit (PyPI `ipctk`) and lwsccd on one machine ({r0.get('cpu', '?')}, {r0.get('cores', '?')} cores"
           + (f", {gpu}" if gpu else "") + f"; commit `{r0.get('commit', '?')}`, {r0.get('date', '?')}; "
           "`bench/compare_ipctk.py`). ipctk: the whole `compute_collision_free_stepsize` call on every core, median ms, "
           "and the step it returns. " + lwsccd_text, "",
           table(["", *scenes], body, ["---"] + ["---:"] * len(scenes)), ""]
    if pairs:
        out += ["Colliding pairs (lwsccd's are the scenes' exact ground truth, 0 false negatives and 0 false positives: "
                "Whole step per scene; ipctk's narrow phase at tolerance 1e-6, each LBVH candidate's `ccd`): "
                + "; ".join(pairs) + ".", ""]
    return out


# --- speed against accuracy ----------------------------------------------------------------------
METHOD_ORDER = ["certified", "filtered-inclusion", "inclusion", "cubic", "filter-only"]


def method_precisions(rows):
    """The rows' (method, precision) pairs in METHOD_ORDER, double before float."""
    return sorted({(r["method"], r["precision"]) for r in rows},
                  key=lambda mp: (METHOD_ORDER.index(mp[0]) if mp[0] in METHOD_ORDER else 9, mp[1] != "double"))


def accuracy_section(rows, accuracy, kind, out_dir, gpu):
    lines = []
    rows = [r for r in rows if r["sweep"] == "methods" and r["step"] == "steady"]
    if rows:
        scenes = sorted({r["scene"] for r in rows}, key=scene_key)
        combos = method_precisions(rows)
        cell = {(r["scene"], r["method"], r["precision"]): r for r in rows}
        body = []
        for m, p in combos:
            line = [f"{m} {p}"]
            for s in scenes:
                r = cell.get((s, m, p))
                if not r:
                    line.append("-")
                    continue
                fn = r.get("false_negatives")
                fn_text = f"**{fn}**" if fn else str(fn)
                line.append(f"{ms(r['total_ms'])} ({ms(r['narrow_ms'])}), {fn_text} / {r.get('false_positives')}")
            body.append(line)
        lines += [f"GPU ({gpu}), steady step, default broad phase; whole step ms (narrow phase ms), false negatives / "
                  "false positives against each scene's exact ground truth (a false negative in bold):", "",
                  table(["method, precision"] + scenes, body, ["---"] + ["---"] * len(scenes))]
        fig, ax = plt.subplots(figsize=(7, 4.5))
        markers = {"certified": "o", "filtered-inclusion": "s", "inclusion": "D", "cubic": "^"}
        method_color = {m: "C%d" % i for i, m in enumerate(METHOD_ORDER)}
        for m, p in combos:
            xs = [cell[(s, m, p)]["narrow_ms"] for s in scenes if (s, m, p) in cell]
            ys = [cell[(s, m, p)].get("false_negatives", 0) + cell[(s, m, p)].get("false_positives", 0)
                  for s in scenes if (s, m, p) in cell]
            c = method_color.get(m, "k")
            # double: filled; float: hollow
            ax.scatter(xs, ys, marker=markers.get(m, "x"), label=f"{m} {p}", s=40, edgecolors=c,
                       facecolors=c if p == "double" else "none")
        ax.set_xscale("log")
        ax.set_yscale("symlog", linthresh=1)
        ax.set_ylim(bottom=-0.3)
        ax.set_xlabel("narrow phase ms, steady step (log)")
        ax.set_ylabel("false negatives + false positives")
        ax.set_title(f"Speed against accuracy on the scenes with ground truth\n{gpu}", fontsize=9)
        ax.legend(fontsize=7, ncol=2)
        lines += save_chart(fig, out_dir, "accuracy", kind, "speed against accuracy")
    if accuracy:
        groups = [r for r in accuracy if r["kind"] == "group"]
        inputs = sorted({r["input"] for r in groups})
        combos = method_precisions(groups)
        cell = {(r["input"], r["method"], r["precision"]): r for r in groups}
        body = []
        for m, p in combos:
            line = [f"{m} {p}"]
            for i in inputs:
                r = cell.get((i, m, p))
                if not r:
                    line += ["-", "-"]
                    continue
                fn = r["false_negatives"]
                line += [f"{'**%d**' % fn if fn else 0} / {r['false_positives']}",
                         f"{us(r['median_us'])} / {us(r['max_us'])}"]
            body.append(line)
        header = ["method, precision"]
        for i in inputs:
            n = next(r["queries"] for r in groups if r["input"] == i)
            header += [f"{i} ({n:,} queries) FN / FP", "median / max µs"]
        cpu = accuracy[0].get("cpu", "?")
        lines += ["", f"One query at a time on one CPU core ({cpu}), `lwsccd-accuracy`: every method on the degenerate "
                  "query sets and on the scenes' candidate pairs (`filter-only` is the non-penetration filter alone; "
                  "`cubic` is the plain coplanarity solve, not conservative):", "",
                  table(header, body, ["---"] + ["---:"] * (len(header) - 1))]
    if not lines:
        return ["*Not measured (no `methods` sweep, no accuracy_cpu.json).*"]
    return lines


# --- schedulers ----------------------------------------------------------------------------------
SCHEDULERS = [("static", "root"), ("gproximity", "root"), ("lazy-steal", "root"), ("karras", "root"),
              ("static", "front"), ("gproximity", "front"), ("lazy-steal", "front")]


def schedulers_section(rows, kind, out_dir, gpu):
    if not rows:
        return ["*Not measured (no traverse results).*"]
    cell = {(r["scene"], r["bv"], r["scheduler"], r["start"]): r for r in rows}
    groups = sorted({(r["scene"], r["bv"]) for r in rows if r["start"] in ("root", "front")},
                    key=lambda g: (g[1], scene_key(g[0])))
    body = []
    for scene, bv in groups:
        line = [scene, bv]
        for sched, start in SCHEDULERS:
            r = cell.get((scene, bv, sched, start))
            line.append(ms(r["median_ms"]) if r else "-")
        r = cell.get((scene, bv, "lazy-steal", "root"))
        line.append(f"{r['busy_share']:.2f}" if r and r.get("busy_share", -1) >= 0 else "-")
        body.append(line)
    header = ["scene", "BV", "static, root", "gProximity, root", "lazy, root", "Karras, root", "static, front",
              "gProximity, front", "lazy, front", "lazy busy share (root)"]
    lines = [f"Median ms of {gpu} CUDA events per traversal (self-collision BVTT, float positions); from the root (a "
             "first step) and from the front the same traversal left (a steady step). Karras: one thread per leaf, "
             "independent traversal, the baseline.", "", table(header, body, ["---", "---"] + ["---:"] * (len(header) - 2))]
    tracked = [r for r in rows if r["start"] == "tracked"]
    if tracked:
        t = {(r["bv"], r["scheduler"]): r for r in tracked}
        bvs = sorted({r["bv"] for r in tracked})
        scheds = [s for s in ("static", "gproximity", "lazy-steal") if any((b, s) in t for b in bvs)]
        lines += ["", f"{tracked[0]['scene']}, each step from the last step's front (mean ms per step):", "",
                  table(["BV"] + scheds, [[b] + [ms(t[(b, s)]["median_ms"]) if (b, s) in t else "-" for s in scheds]
                                           for b in bvs])]
    variants = sorted({r["scheduler"] for r in rows} - {s for s, _ in SCHEDULERS})
    if variants:
        scenes = sorted({r["scene"] for r in rows if r["start"] == "root" and r["bv"].startswith("AABB")}, key=scene_key)
        body = []
        for v in ["lazy-steal"] + variants:
            line = [v]
            for s in scenes:
                a, b = cell.get((s, "AABB float", v, "root")), cell.get((s, "AABB float", v, "front"))
                line.append(f"{ms(a['median_ms']) if a else '-'} / {ms(b['median_ms']) if b else '-'}")
            body.append(line)
        lines += ["", "The lazy scheduler's knobs, one at a time (AABB; root / front ms; `lazy-steal` is the default, the "
                  "names say what each variant changes: docs/TRAVERSAL.md):", "",
                  table(["variant"] + scenes, body, ["---"] + ["---:"] * len(scenes))]
    # Chart: grouped bars per scene and BV.
    fig, ax = plt.subplots(figsize=(max(7, 1.4 * len(groups)), 4.5))
    width = 0.8 / len(SCHEDULERS)
    colors = {"static": "#4c72b0", "gproximity": "#dd8452", "lazy-steal": "#55a868", "karras": "#8c8c8c"}
    for k, (sched, start) in enumerate(SCHEDULERS):
        vals = [cell[(s, b, sched, start)]["median_ms"] if (s, b, sched, start) in cell else 0 for s, b in groups]
        ax.bar([i - 0.4 + (k + 0.5) * width for i in range(len(groups))], vals, width, color=colors[sched],
               hatch="//" if start == "front" else None, edgecolor="white", label=f"{sched}, {start}")
    ax.set_xticks(range(len(groups)))
    ax.set_xticklabels([f"{s}\n{b}" for s, b in groups], fontsize=7)
    ax.set_yscale("log")
    ax.set_ylabel("ms (log)")
    ax.set_title(f"Traversal from the root and from the front (hatched)\n{gpu}", fontsize=9)
    ax.legend(fontsize=7, ncol=2)
    lines += save_chart(fig, out_dir, "traverse", kind, "schedulers")
    return lines


# --- scaling -------------------------------------------------------------------------------------
def multi_gpu_section(rows):
    """The built-in scene split over several GPUs (lwsccd-bench-multi-gpu), against one GPU."""
    if not rows:
        return []
    m = rows[0]
    # (Rows written without their commit and date: MULTI_GPU.md names them.)
    when = (f"commit {m['commit']}, {m['date']}" if m.get("commit") and m.get("date")
            else "its commit and date in MULTI_GPU.md")
    lines = [f"The same scene split over GPUs (`gpu::MultiGpuPipeline`, [MULTI_GPU.md](MULTI_GPU.md)), device-resident "
             f"steps (positions on the first GPU, contacts left there): {m.get('machine', m.get('gpu', ''))}, {when}, "
             f"medians of {m.get('reps', '?')} steps:", ""]
    body = []
    one = {r["triangles"]: r["step_ms"] for r in rows if r["config"] == "one-gpu"}
    for r in rows:
        base = one.get(r["triangles"])
        speedup = f"{base / r['step_ms']:.2f}x" if base and r["config"] == "split" else "-"
        body.append([count(r["triangles"]), "one GPU" if r["config"] == "one-gpu" else f"split, {r['gpus']} GPU(s)",
                     f"{ms(r['step_ms'])} ({ms(r['step_p10_ms'])}-{ms(r['step_p90_ms'])})", speedup,
                     " / ".join(ms(b) for b in r["busy_ms_per_gpu"]),
                     " / ".join(count(int(v)) for v in r["device_mib_per_gpu"]), r["steps_differing_from_one_gpu"]])
    lines.append(table(["triangles", "pipeline", "step ms (p10-p90)", "speed-up", "busy ms per GPU", "MiB per GPU",
                        "steps differing from one GPU"], body))
    return lines


def scaling_section(rows, kind, out_dir, gpu):
    rows = [r for r in rows if r["sweep"] == "scaling"]
    if not rows:
        return ["*Not measured (no `scaling` sweep).*"]
    sizes = by_scene_step(rows)
    body = []
    for scene, steps in sizes.items():
        first, steady = steps.get("first"), steps.get("steady")
        base = steady or first
        body.append([count(base["triangles"]), ms(first["total_ms"]) if first else "-", spread(steady) if steady else "-",
                     " / ".join(ms(base[k]) for k, _ in STAGES), count(base["feature_pairs"]), count(base["contacts"]),
                     ms(base["peak_device_bytes"] / 2**20, 0) if base.get("peak_device_bytes") else "-"])
    lines = ["The built-in scene (a folded cloth dropped on a ball, simulated; no data needed) at each size, default "
             "policies, host to host:", "",
             table(["triangles", "first ms", "steady ms (p10-p90)", "steady stages ms: refit / traversal / feature pairs / narrow",
                    "feature pairs", "contacts", "peak MiB"], body)]
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    tri = [s["steady"]["triangles"] for s in sizes.values() if "steady" in s]
    for key, label in [("total_ms", "whole step")] + STAGES:
        ax.plot(tri, [s["steady"][key] for s in sizes.values() if "steady" in s], marker="o", label=label)
    ax.plot([s["first"]["triangles"] for s in sizes.values() if "first" in s],
            [s["first"]["total_ms"] for s in sizes.values() if "first" in s], marker="x", linestyle="--", label="first step")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("triangles")
    ax.set_ylabel("ms per steady step (log)")
    ax.set_title(f"Scaling with the number of triangles\n{gpu}", fontsize=9)
    ax.legend(fontsize=8)
    lines += save_chart(fig, out_dir, "scaling", kind, "scaling")
    return lines


# --- BVH -----------------------------------------------------------------------------------------
def bvh_section(rows):
    if not rows:
        return ["*Not measured (no bvh results).*"]
    cell = OrderedDict()
    for r in sorted(rows, key=lambda r: (r["faces"], r["bv"], r["backend"])):
        cell.setdefault((r["scene"], r["faces"], r["bv"], r["backend"]), {})[r["op"]] = r
    body = [[s, count(f), bv, be, ms(ops["build"]["median_ms"]) if "build" in ops else "-",
             ms(ops["refit"]["median_ms"]) if "refit" in ops else "-"] for (s, f, bv, be), ops in cell.items()]
    return [table(["scene", "faces", "BV", "backend", "build ms", "refit ms"], body, ["---", "---:", "---", "---", "---:", "---:"])]


# --- rays ----------------------------------------------------------------------------------------
def rays_section(rows, kind, out_dir, gpu):
    if not rows:
        return ["*Not measured (no rays results).*"]
    sets = list(OrderedDict.fromkeys(r["rays"] for r in rows))
    methods = list(OrderedDict.fromkeys(r["method"] for r in rows))
    cell = {(r["rays"], r["method"]): r for r in rows}
    body = []
    for m in methods:
        line = [m]
        for s in sets:
            r = cell.get((s, m))
            line.append(f"{r['mrays_per_s']:,.0f}{'' if r['same_hits'] else ' (hits differ!)'}" if r else "-")
        body.append(line)
    counts = [f"{s} ({cell[(s, methods[0])]['count']:,} rays)" if (s, methods[0]) in cell else s for s in sets]
    lines = [f"Millions of rays per second ({gpu}; closest hit against cloth-ball's triangles; every method's hits equal "
             "one thread per ray's):", "", table(["method"] + counts, body)]
    fig, ax = plt.subplots(figsize=(7, max(3.5, 0.3 * len(methods) * len(sets))))
    ypos = 0
    ticks, labels = [], []
    for si, s in enumerate(sets):
        for m in methods:
            if (s, m) in cell:
                ax.barh(ypos, cell[(s, m)]["mrays_per_s"], color="C%d" % si)
                ticks.append(ypos)
                labels.append(m)
                ypos += 1
        ypos += 1
    ax.set_yticks(ticks)
    ax.set_yticklabels(labels, fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel("Mrays/s")
    ax.set_title(f"Rays per second: {' | '.join(f'C{i}: {s}' for i, s in enumerate(sets))}\n{gpu}", fontsize=8)
    lines += save_chart(fig, out_dir, "rays", kind, "rays")
    return lines


# --- FP64 and FP32 instructions ------------------------------------------------------------------
def fp_section(rows, planned=None):
    if not rows:
        return ["*Not measured (no fp results: Nsight Compute's ncu was not found).*"]
    out = fp_table(rows, "Thread instructions of one steady step (all kernels; `bench/fp_instructions.py`: Nsight Compute, "
                   "`--steps 3` minus `--steps 1`, over two), per feature pair; where the pairs were decided (in FP32, "
                   "of them contacts whose time of impact's leaf pairs of floats proved (only on a GPU with little FP64, "
                   "or planned for one: NARROW_PHASE.md B17); contacts found in FP32 whose time of impact took an FP64 "
                   "tail; the rest, searched in FP64 or by the fallback); and the time the FP64 instructions alone would "
                   "take at 0.6e12 per second, a GPU of today's size that runs FP64 at 1/64 of FP32 (the RTX and L40 "
                   "classes):")
    if planned:
        label = planned[0].get("label", "")
        out += [""] + fp_table(planned, "The same, planned as for a GPU whose FP64 runs at 1/64 of its FP32 (`lwsccd-ccd "
                               "--fp64-ratio 64`: its searches in double a thread each, contacts' leaves in pairs of "
                               "floats; the same answers), counted on this GPU" + (f" ({label})" if label else "") + ":")
    return out


def fp_table(rows, caption):
    body = []
    for r in rows:
        d = r.get("decided") or {}
        pairs = r["feature_pairs"]
        tail = d.get("fp32_fp64_tail", 0) if d else 0
        share = f"{100.0 * (pairs - d['fp32'] - tail) / pairs:.2f}%" if d and pairs else "-"
        given = r["input"].replace(" --fp64-ratio 64", "")  # (the planned table says so once)
        label = given.split("/")[-1] if "/" in given else given.replace("--triangles ", "built-in ")
        in_pairs = d.get("fp32_float_pair_leaf") if d else None
        body.append([label, count(pairs), f"{r['fp64_per_pair']:.1f}", f"{r['fp32_per_pair']:.1f}",
                     count(d.get("fp32")) if d else "-", count(in_pairs) if in_pairs is not None else "-",
                     count(tail) if "fp32_fp64_tail" in d else "-", share, ms(r["fp64_ms_at_0.6T"])])
    return [caption, "",
            table(["scene", "feature pairs", "FP64 / pair", "FP32 / pair", "decided in FP32", "of them leaves in pairs of floats",
                   "contacts with an FP64 tail", "pairs searched in FP64", "FP64 ms at 0.6 T/s"], body)]


# --- the page ------------------------------------------------------------------------------------
def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    results, page = sys.argv[1], sys.argv[2]
    rel = os.path.relpath(results, os.path.dirname(os.path.abspath(page)))
    kinds = sorted(f[len("machine_"):-len(".json")] for f in os.listdir(results)
                   if f.startswith("machine_") and f.endswith(".json") and f != "machine_cpu.json")
    # The latest measurement is drawn in full; older ones (other GPU kinds) are named with their
    # files, so that the page shows one commit's figures.
    kinds.sort(key=lambda k: (load(os.path.join(results, f"machine_{k}.json")) or {}).get("date", ""), reverse=True)
    older, kinds = kinds[1:], kinds[:1]
    cpu_machine = load(os.path.join(results, "machine_cpu.json"))
    accuracy = load(os.path.join(results, "accuracy_cpu.json"))
    out = ["# Benchmarks", "",
           "Generated by `bash bench/run_benchmarks.sh` from the results in [results/](results/) (one JSON file per "
           "benchmark and machine kind, overwritten by each run; `--plot` redraws this page from a results folder "
           "measured elsewhere). Do not edit by hand: the design notes that explain these numbers are in "
           "[TRAVERSAL.md](TRAVERSAL.md), [NARROW_PHASE.md](NARROW_PHASE.md), [PIPELINE.md](PIPELINE.md), "
           "[BVH.md](BVH.md) and [RAYTRACING.md](RAYTRACING.md).", ""]
    if not kinds:
        out += ["*No GPU results in the results folder.*", ""]
    for kind in kinds:
        m = load(os.path.join(results, f"machine_{kind}.json"))
        gpu = m.get("gpu", kind)
        pipeline = load(os.path.join(results, f"pipeline_{kind}.json")) or []
        out += machine_lines(m, "Measured on") + [""]
        out += ["Every time is a median over repeated steps or traversals (p10-p90 in brackets where given), CUDA events "
                "for the stages, a host clock around the whole call. *Host to host*: positions in host memory, contacts "
                "sorted in host memory. *Device-resident*: positions already on the GPU, contacts left there "
                "(`step_on_device`). A *steady* step refits the BVH and starts from the last step's front; the *first* "
                "step of a new pipeline builds the BVH and traverses from the root. Default policies: AABB, lazy work "
                "stealing, the certified narrow phase in double precision, mode `contacts`.", ""]
        out += ["## Whole step per scene", ""] + whole_step_section(pipeline, kind, results, gpu) + [""]
        out += ["## Speed against accuracy", ""] + accuracy_section(pipeline, accuracy, kind, results, gpu) + [""]
        out += ["## FP64 and FP32 instructions", ""] + fp_section(load(os.path.join(results, f"fp_{kind}.json")),
                                                                 load(os.path.join(results, f"fp_planned_{kind}.json"))) + [""]
        out += ["## Schedulers", ""] + schedulers_section(load(os.path.join(results, f"traverse_{kind}.json")), kind,
                                                          results, gpu) + [""]
        out += ["## Scaling", ""] + scaling_section(pipeline, kind, results, gpu) + [""]
        for name in sorted(f for f in os.listdir(results) if f.startswith(f"multi_gpu_{kind}x") and f.endswith(".json")):
            out += multi_gpu_section(load(os.path.join(results, name))) + [""]
        out += ["## BVH build and refit", "", f"Median ms ({gpu}):", ""] + bvh_section(
            load(os.path.join(results, f"bvh_{kind}.json"))) + [""]
        out += ["## Rays", ""] + rays_section(load(os.path.join(results, f"rays_{kind}.json")), kind, results, gpu) + [""]
    if older:
        out += ["## Earlier GPU measurements", "",
                "Kept in [results/](results/) and not drawn here (each file names its benchmark):", ""]
        for kind in older:
            m = load(os.path.join(results, f"machine_{kind}.json")) or {}
            files = sorted(f for f in os.listdir(results) if f.endswith(".json") and (
                f == f"machine_{kind}.json" or any(f == f"{b}_{kind}.json" for b in ("pipeline", "traverse", "rays", "bvh", "fp"))))
            out += [f"- {m.get('gpu', kind)}, commit `{m.get('commit', '?')}`, {m.get('date', '?')}: " +
                    ", ".join(f"`{f}`" for f in files)]
        out += [""]
    out += cpu_section(load(os.path.join(results, "pipeline_cpu.json")), cpu_machine)
    if cpu_machine:
        out += machine_lines(cpu_machine, "CPU backend measured on") + [""]
    ipctk_rows = ipctk_section(load(os.path.join(results, "ipctk.json")))
    if ipctk_rows:
        out += ["## ipc-toolkit beside lwsccd", ""] + ipctk_rows
    out += ["## Reproducing", "",
            "```sh",
            "bash bench/run_benchmarks.sh                   # build, measure on this machine (GPU if present), write this page",
            "bash bench/run_benchmarks.sh --plot DIR        # this page and its charts from results measured elsewhere",
            "```", "",
            "The benchmarks read `../shared/data` (or `--data DIR`); without it only the built-in scene is measured.", ""]
    text = "\n".join(out).replace("](results/", f"]({rel}/")
    with open(page, "w") as f:
        f.write(text)
    print(f"wrote {page} and the charts in {results}")


if __name__ == "__main__":
    main()
