#!/usr/bin/env python3
"""Scheduler comparison chart from lwsccd-bench-traverse's JSON.

usage: plot_traverse.py bench_traverse.json out.png
Grouped bars of the median traversal time (log scale) per scene and BV, for each scheduler started
from the root and from the front, plus Karras's independent traversal (root only).
"""
import json
import sys

try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:
    sys.exit("matplotlib is missing: apt-get install python3-matplotlib (or pip install matplotlib)")


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    rows = json.load(open(sys.argv[1]))
    gpu = rows[0]["gpu"] if rows else "?"
    series = [("static", "root"), ("gproximity", "root"), ("lazy-steal", "root"), ("karras", "root"),
              ("static", "front"), ("gproximity", "front"), ("lazy-steal", "front")]
    colors = {"static": "#4c72b0", "gproximity": "#dd8452", "lazy-steal": "#55a868", "karras": "#8c8c8c"}
    groups = []
    for r in rows:
        key = (r["scene"], r["bv"])
        if "horse" not in r["scene"] and key not in groups:
            groups.append(key)
    fig, ax = plt.subplots(figsize=(13, 5.5))
    width = 0.8 / len(series)
    for i, (scheduler, start) in enumerate(series):
        xs, ys = [], []
        for g, (scene, bv) in enumerate(groups):
            match = [r for r in rows if r["scene"] == scene and r["bv"] == bv and r["scheduler"] == scheduler and r["start"] == start]
            if match:
                xs.append(g + (i - len(series) / 2 + 0.5) * width)
                ys.append(match[0]["median_ms"])
        ax.bar(xs, ys, width, color=colors[scheduler], hatch="//" if start == "front" else None, edgecolor="white",
               label=f"{scheduler} ({'from the front' if start == 'front' else 'from the root'})")
    ax.set_yscale("log")
    ax.set_xticks(range(len(groups)))
    ax.set_xticklabels([f"{scene}\n{bv}" for scene, bv in groups])
    ax.set_ylabel("median traversal time (ms, log)")
    ax.set_title(f"BVTT self-collision traversal per scheduler ({gpu}, CUDA events)")
    ax.grid(axis="y", which="both", alpha=0.3)
    ax.legend(ncol=4, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.15))
    fig.tight_layout()
    fig.savefig(sys.argv[2], dpi=110)


if __name__ == "__main__":
    main()
