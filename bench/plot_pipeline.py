#!/usr/bin/env python3
"""Charts of lwsccd-bench-pipeline's JSON rows (docs/BENCHMARKS.md explains them).

usage: plot_pipeline.py RESULTS.json OUT_DIR
"""
import json
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

STAGES = [("refit_ms", "refit / build"), ("traverse_ms", "traversal"), ("features_ms", "feature pairs"),
          ("narrow_ms", "narrow phase")]
DEFAULT = {"bv": "aabb", "scheduler": "lazy", "method": "filtered-inclusion", "precision": "double"}


def is_default(r):
    return all(r[k] == v for k, v in DEFAULT.items()) or (r["scheduler"] == "cpu-work-stealing" and all(
        r[k] == v for k, v in DEFAULT.items() if k != "scheduler"))


def device_of(rows):
    return rows[0]["device"] if rows else "?"


def stages_chart(rows, out):
    # One bar per scene: the default policies, steady state (the first step hatched beside it).
    picked = {}
    for r in rows:
        if is_default(r) and r["sweep"] in ("schedulers", "scaling"):
            picked[(r["scene"], r["step"])] = r
    scenes = sorted({s for s, _ in picked}, key=lambda s: picked.get((s, "steady"), picked.get((s, "first")))["triangles"])
    fig, ax = plt.subplots(figsize=(max(6, 1.3 * len(scenes)), 4.5))
    width = 0.38
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for offset, step, hatch in ((-width / 2, "first", "//"), (width / 2, "steady", None)):
        bottom = [0.0] * len(scenes)
        for si, (key, label) in enumerate(STAGES + [("other", "transfers + host")]):
            vals = []
            for s in scenes:
                r = picked.get((s, step))
                if r is None:
                    vals.append(0.0)
                elif key == "other":
                    vals.append(max(0.0, r["total_ms"] - sum(r[k] for k, _ in STAGES)))
                else:
                    vals.append(r[key])
            ax.bar([i + offset for i in range(len(scenes))], vals, width, bottom=bottom, color=colors[si % len(colors)],
                   hatch=hatch, edgecolor="white" if hatch else None,
                   label=label if step == "steady" else None)
            bottom = [b + v for b, v in zip(bottom, vals)]
    ax.set_xticks(range(len(scenes)))
    ax.set_xticklabels(scenes, rotation=20, ha="right")
    ax.set_yscale("log")
    ax.set_ylabel("ms per step (log)")
    ax.set_title(f"Per-stage time, first step (hatched) and steady state\n{device_of(rows)}, AABB, lazy stealing, "
                 "filtered inclusion, double")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(f"{out}/pipeline_stages.png", dpi=120)


def schedulers_chart(rows, out):
    sel = [r for r in rows if r["sweep"] == "schedulers" and r["step"] == "steady" and r["method"] == "filtered-inclusion"]
    scenes = sorted({r["scene"] for r in sel}, key=lambda s: next(r["triangles"] for r in sel if r["scene"] == s))
    combos = sorted({(r["bv"], r["precision"], r["scheduler"]) for r in sel})
    if not scenes:
        return
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.8))
    for ax, key, title in ((axes[0], "traverse_ms", "traversal (from the front)"), (axes[1], "total_ms", "whole step")):
        width = 0.8 / max(1, len(combos))
        palette = plt.cm.tab20.colors  # 20 distinct colours: one per combination
        for ci, combo in enumerate(combos):
            vals = []
            for s in scenes:
                match = [r for r in sel if r["scene"] == s and (r["bv"], r["precision"], r["scheduler"]) == combo]
                vals.append(match[0][key] if match else 0.0)
            ax.bar([i - 0.4 + (ci + 0.5) * width for i in range(len(scenes))], vals, width,
                   color=palette[ci % len(palette)], label=f"{combo[2]} / {combo[0]} / {combo[1]}")
        ax.set_xticks(range(len(scenes)))
        ax.set_xticklabels(scenes, rotation=20, ha="right")
        ax.set_yscale("log")
        ax.set_ylabel("ms (log), median of steady steps")
        ax.set_title(title)
    axes[1].legend(fontsize=7, ncol=2)
    fig.suptitle(f"Schedulers x bounding volumes x precision, {device_of(rows)}")
    fig.tight_layout()
    fig.savefig(f"{out}/pipeline_schedulers.png", dpi=120)


def accuracy_chart(rows, out):
    # Every method in mode contacts (sweep methods), and the other modes that report pairs (set;
    # earliest reports only a time) from the modes sweep.
    sel = [r for r in rows if r["step"] == "steady" and "false_negatives" in r and
           (r["sweep"] == "methods" or (r["sweep"] == "modes" and r.get("mode", "contacts") != "contacts"))]
    for r in sel:
        r["label"] = r["method"] if r.get("mode", "contacts") == "contacts" else f'{r["method"]}/{r["mode"]}'
    scenes = sorted({r["scene"] for r in sel})
    if not scenes:
        return
    fig, axes = plt.subplots(1, len(scenes), figsize=(5 * len(scenes), 4.2), squeeze=False)
    markers = {"certified": "D", "certified/set": "P", "filtered-inclusion": "o", "inclusion": "s", "cubic": "^"}
    colors = {"double": "tab:blue", "float": "tab:orange"}
    for ax, scene in zip(axes[0], scenes):
        for r in (r for r in sel if r["scene"] == scene):
            for value, fill in ((r["false_negatives"], True), (r["false_positives"], False)):
                ax.scatter(r["total_ms"], value, marker=markers.get(r["label"], "x"),
                           facecolors=colors[r["precision"]] if fill else "none", edgecolors=colors[r["precision"]], s=60)
        ax.set_xscale("log")
        ax.set_yscale("symlog", linthresh=1)
        ax.set_ylim(bottom=-0.5)
        ax.set_xlabel("ms per step (log)")
        ax.set_ylabel("false negatives (filled) / positives (hollow)")
        ax.set_title(scene)
    handles = [plt.Line2D([], [], marker=m, linestyle="", color="gray", label=k) for k, m in markers.items()]
    handles += [plt.Line2D([], [], marker="o", linestyle="", color=c, label=k) for k, c in colors.items()]
    axes[0][-1].legend(handles=handles, fontsize=8)
    fig.suptitle(f"Speed against accuracy of the narrow-phase methods (ground truth), {device_of(rows)}")
    fig.tight_layout()
    fig.savefig(f"{out}/pipeline_accuracy.png", dpi=120)


def scaling_chart(rows, out):
    sel = sorted((r for r in rows if r["sweep"] == "scaling" and r["step"] == "steady"), key=lambda r: r["triangles"])
    if not sel:
        return
    fig, ax = plt.subplots(figsize=(6.5, 4.8))
    xs = [r["triangles"] for r in sel]
    ax.plot(xs, [r["total_ms"] for r in sel], "k-o", label="whole step")
    for key, label in STAGES:
        ax.plot(xs, [max(r[key], 1e-3) for r in sel], "--.", label=label)
    ax.axhline(100, color="red", lw=0.8, ls=":", label="target at 10M: 100 ms")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("triangles (built-in cloth on a ball)")
    ax.set_ylabel("ms per step, steady (log)")
    ax.set_title(f"Scaling with scene size, {device_of(rows)}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(f"{out}/pipeline_scaling.png", dpi=120)


def memory_chart(rows, out):
    picked = {}
    for r in rows:
        if is_default(r) and r["step"] == "steady" and r["peak_device_bytes"] > 0:
            picked[r["scene"]] = r
    if not picked:
        return
    scenes = sorted(picked, key=lambda s: picked[s]["triangles"])
    fig, ax = plt.subplots(figsize=(max(6, 1.2 * len(scenes)), 4.2))
    vals = [picked[s]["peak_device_bytes"] / 2**20 for s in scenes]
    ax.bar(range(len(scenes)), vals)
    for i, v in enumerate(vals):
        ax.text(i, v, f"{v:.0f}", ha="center", va="bottom", fontsize=8)
    ax.set_xticks(range(len(scenes)))
    ax.set_xticklabels([f"{s}\n{picked[s]['triangles']:,} tri" for s in scenes], rotation=20, ha="right", fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("peak device memory, MiB (log)")
    ax.set_title(f"Peak device memory of a step (library allocations), {device_of(rows)}")
    fig.tight_layout()
    fig.savefig(f"{out}/pipeline_memory.png", dpi=120)


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    rows = []
    for path in sys.argv[1].split(","):
        with open(path) as f:
            rows += json.load(f)
    out = sys.argv[2]
    for chart in (stages_chart, schedulers_chart, accuracy_chart, scaling_chart, memory_chart):
        chart(rows, out)


if __name__ == "__main__":
    main()
