#!/usr/bin/env python3
"""Chart of lwsccd-accuracy results: median time per query against the false-negative and the
false-positive rate, one point per method x precision, for the totals over all query sets and
over all scenes.

usage: plot_accuracy.py RESULTS.json OUTPUT.png
"""
import json
import sys

ZERO_FLOOR = 1e-5  # rates of exactly 0 are drawn here (log axis) and labelled "0"


def main(argv):
    if len(argv) != 3 or argv[1] in ("-h", "--help"):
        print(__doc__.strip(), file=sys.stderr if len(argv) != 2 else sys.stdout)
        return 0 if len(argv) == 2 else 1
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.ticker import FixedLocator
    except ImportError:
        print(f"plot_accuracy.py needs matplotlib, which {sys.executable} cannot import: "
              "apt-get install python3-matplotlib (then run it with /usr/bin/python3), "
              "or python3 -m pip install matplotlib", file=sys.stderr)
        return 1

    with open(argv[1]) as f:
        rows = json.load(f)
    groups = [("all query sets", "query sets", "o"), ("all scenes", "scenes", "s")]
    series = []  # (group label, marker, method, precision, median us, fn rate, fp rate)
    for name, label, marker in groups:
        for r in rows:
            if r.get("kind") == "group" and r.get("input") == name:
                series.append((label, marker, r["method"], r["precision"], r["median_us"],
                               r.get("false_negative_rate"), r.get("false_positive_rate")))
    if not series:
        print(f"{argv[1]}: no 'all query sets' / 'all scenes' rows (kind 'group')", file=sys.stderr)
        return 1

    order = ["cubic", "inclusion", "filtered-inclusion", "filter-only"]
    methods = sorted({s[2] for s in series}, key=lambda m: order.index(m) if m in order else len(order))
    colors = dict(zip(methods, ["tab:red", "tab:blue", "tab:green", "tab:gray", "tab:purple", "tab:orange"]))
    # Inclusion and filtered inclusion often land on the same spot: big and small markers keep both visible.
    sizes = {"inclusion": 150, "filtered-inclusion": 45}
    cpu = rows[0].get("cpu", "?")

    fig, axes = plt.subplots(1, 2, figsize=(13, 5.8))
    for ax, which, what in ((axes[0], 0, "false-negative rate (missed / true pairs)"),
                            (axes[1], 1, "false-positive rate (false alarms / non-touching pairs)")):
        top = 1e-1
        for label, marker, method, precision, median, fnr, fpr in series:
            rate = (fnr, fpr)[which]
            if rate is None or median is None:
                continue
            y = rate if rate > 0 else ZERO_FLOOR
            top = max(top, y)
            c = colors[method]
            ax.scatter([median], [y], marker=marker, s=sizes.get(method, 80), color=c,
                       facecolors=c if precision == "double" else "none", linewidths=1.8, zorder=3)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("median time per query (µs, one CPU core, log)")
        ax.set_ylabel(what + ", log")
        ax.set_ylim(ZERO_FLOOR / 3, min(3.0, top * 3))
        decades = [e for e in range(-4, 1) if 10.0 ** e <= top * 3]
        ax.yaxis.set_major_locator(FixedLocator([ZERO_FLOOR] + [10.0 ** e for e in decades]))
        ax.yaxis.set_minor_locator(FixedLocator([]))
        ax.set_yticklabels(["0"] + [f"1e{e}" if e < 0 else "1" for e in decades])
        ax.axhline(ZERO_FLOOR * 3, color="black", linewidth=0.6, linestyle=":")
        ax.grid(True, which="major", alpha=0.3)
    axes[0].set_title("missed contacts vs time (bottom row: none missed)")
    axes[1].set_title("false alarms vs time")

    from matplotlib.lines import Line2D
    handles = [Line2D([], [], marker="o", linestyle="", color=colors[m], markersize=8, label=m) for m in methods]
    handles += [Line2D([], [], marker="o", linestyle="", color="black", markersize=8, label="double (filled)"),
                Line2D([], [], marker="o", linestyle="", color="black", markerfacecolor="none", markersize=8,
                       label="float (hollow)"),
                Line2D([], [], marker="o", linestyle="", color="black", markerfacecolor="none", markersize=8,
                       label="circle: all query sets"),
                Line2D([], [], marker="s", linestyle="", color="black", markerfacecolor="none", markersize=8,
                       label="square: all scenes")]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8, frameon=False)
    fig.suptitle(f"lwsccd narrow phase: median time per query against error rates, shared data ({cpu})",
                 fontsize=10)
    fig.tight_layout(rect=(0, 0.06, 1, 0.96))
    fig.savefig(argv[2], dpi=130)
    print(f"wrote {argv[2]}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
