#!/usr/bin/env python3
"""Timeline chart of the lazy work-stealing scheduler from lwsccd-bench-traverse --timeline.

usage: plot_timeline.py out.png "title" timeline_A.csv [timeline_B.csv ...]
One panel per CSV (rows: block, time_ns, phase, items): every persistent block is a line over
time, coloured by what it does - working on items from its own deque, working on stolen items,
or looking for work (its deque, then steals, then waiting for others) - until it finds none left.
"""
import csv
import os
import sys

try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch
except ImportError:
    sys.exit("matplotlib is missing: apt-get install python3-matplotlib (or pip install matplotlib)")

COLORS = {"own": "#2b8a3e", "steal": "#e8590c", "seek": "#ced4da"}
LABELS = {"own": "working (own deque)", "steal": "working (stolen batch)", "seek": "looking for work / waiting"}


def read_spans(path):
    """Per block, the (start_us, length_us, phase) spans between consecutive events."""
    events = {}
    with open(path) as f:
        for row in csv.DictReader(f):
            events.setdefault(int(row["block"]), []).append((int(row["time_ns"]) / 1e3, row["phase"]))
    spans, end = {}, 0.0
    for block, ev in events.items():
        ev.sort()
        spans[block] = [(t0, t1 - t0, phase) for (t0, phase), (t1, _) in zip(ev, ev[1:]) if phase != "done"]
        end = max(end, ev[-1][0])
    return spans, end


def share(spans, end):
    """Fraction of all blocks' time (from 0 to the last event) spent working."""
    work = sum(length for s in spans.values() for (_, length, phase) in s if phase in ("own", "steal"))
    return work / (end * len(spans)) if spans and end > 0 else 0.0


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    out, title, paths = sys.argv[1], sys.argv[2], sys.argv[3:]
    fig, axes = plt.subplots(len(paths), 1, figsize=(11, 2.6 * len(paths)), squeeze=False)
    for ax, path in zip(axes[:, 0], paths):
        spans, end = read_spans(path)
        for phase in ("seek", "own", "steal"):
            for block, s in spans.items():
                bars = [(t, length) for (t, length, p) in s if p == phase]
                if bars:
                    ax.broken_barh(bars, (block - 0.4, 0.8), facecolors=COLORS[phase], linewidth=0)
        name = os.path.basename(path)[len("timeline_"):-len(".csv")]
        ax.set_title(f"{name}: {len(spans)} blocks, {end:.0f} us, working {100 * share(spans, end):.0f}% of block time",
                     fontsize=9)
        ax.set_xlim(0, end * 1.01)
        ax.set_ylim(-1, len(spans))
        ax.set_ylabel("block")
    axes[-1, 0].set_xlabel("time since the lazy kernel's first event (us)")
    handles = [Patch(color=COLORS[p], label=LABELS[p]) for p in ("own", "steal", "seek")]
    fig.legend(handles=handles, loc="upper right", fontsize=8, ncol=3)
    fig.suptitle(title, fontsize=10, x=0.01, ha="left")
    fig.tight_layout(rect=(0, 0, 1, 0.96))
    fig.savefig(out, dpi=110)


if __name__ == "__main__":
    main()
