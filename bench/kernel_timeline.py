#!/usr/bin/env python3
"""A step's kernel timeline from bench/kernel_trace.cpp's trace (lwsccd-ccd or any program).

usage: kernel_timeline.py TRACE.tsv [--step K] [--all]

Steps are cut where the positions go to the device (a host-to-device copy of at least
--min-bytes, two per step: x0 and x1), as lwsccd-ccd's host-to-host steps do; a step ends with
its last kernel. For step K (default the one before the last; negative counts from the end) it
prints each kernel's start relative to the step's first activity, its duration and stream (us;
--all adds copies and memsets), then the time no activity ran (the GPU waiting for the host) and
per stream the time busy and the span from its first start to its last end. With --api it lists
the host's runtime calls among them (a trace taken with LWSCCD_TRACE_API=1).
"""
import argparse
import re


def short_name(name):
    """A kernel's name without namespaces, template arguments and parameters (mangled or not)."""
    if name.startswith("_ZN"):  # nested name: length-prefixed identifiers up to the template arguments
        ids, i = [], 3
        while i < len(name) and name[i].isdigit():
            j = i
            while name[j].isdigit():
                j += 1
            n = int(name[i:j])
            ids.append(name[j:j + n])
            i = j + n
        if ids:
            return ids[-1]
    return re.sub(r"<.*", "", name.split("(")[0]).split("::")[-1].replace("void ", "").strip()


def load(path, api=False):
    """The trace's GPU activities (kernels, copies, memsets) sorted by start; with api, the host's
    runtime calls too (kind "A", their thread id in "stream")."""
    records = []
    with open(path) as f:
        for line in f:
            fields = line.rstrip("\n").split("\t")
            kind, start, end, stream = fields[0], int(fields[1]), int(fields[2]), int(fields[3])
            if kind == "A":
                if not api:
                    continue
                label = fields[4]
            elif kind == "K":
                label = short_name(fields[6])
            elif kind == "C":
                label = "memcpy " + {"1": "HtoD", "2": "DtoH", "8": "DtoD"}.get(fields[5], fields[5]) + " " + fields[4] + " B"
            else:
                label = "memset " + fields[4] + " B"
            records.append({"kind": kind, "start": start, "end": end, "stream": stream, "label": label,
                            "upload": kind == "C" and fields[5] == "1" and int(fields[4])})
    records.sort(key=lambda r: r["start"])
    return records


def steps(records, min_bytes):
    starts = [i for i, r in enumerate(records) if r["upload"] and r["upload"] >= min_bytes][::2]
    return [records[s:(starts[k + 1] if k + 1 < len(starts) else len(records))] for k, s in enumerate(starts)]


def main():
    p = argparse.ArgumentParser()
    p.add_argument("trace")
    p.add_argument("--step", type=int, default=-2)
    p.add_argument("--min-bytes", type=int, default=4096)
    p.add_argument("--all", action="store_true", help="list memsets and copies too")
    p.add_argument("--api", action="store_true", help="list the host's CUDA runtime calls too (traced with LWSCCD_TRACE_API=1)")
    a = p.parse_args()
    all_steps = steps(load(a.trace, a.api), a.min_bytes)
    if not all_steps:
        raise SystemExit("kernel_timeline.py: no step found (no host-to-device copies of positions)")
    print("steps (us):", " ".join(f"{(s[-1]['end'] - s[0]['start']) / 1e3:.1f}" for s in all_steps))
    if not -len(all_steps) <= a.step < len(all_steps):
        raise SystemExit(f"kernel_timeline.py: --step {a.step}: the trace holds {len(all_steps)} steps")
    step = all_steps[a.step]
    last_kernel = max(i for i, r in enumerate(step) if r["kind"] == "K") if any(r["kind"] == "K" for r in step) else 0
    step = step[:last_kernel + 1]  # (what follows the last kernel is the host's: results read and checked)
    t0 = step[0]["start"]
    idle, reach, streams = 0, t0, {}
    for r in step:
        if r["kind"] == "A":
            print(f"{(r['start'] - t0) / 1e3:9.1f} {(r['end'] - r['start']) / 1e3:8.1f}  host  {r['label']}")
            continue
        idle += max(0, r["start"] - reach)
        reach = max(reach, r["end"])
        s = streams.setdefault(r["stream"], [0, r["start"], r["end"], 0])
        s[0] += r["end"] - r["start"]
        s[2] = max(s[2], r["end"])
        s[3] += 1
        if a.all or r["kind"] == "K":
            print(f"{(r['start'] - t0) / 1e3:9.1f} {(r['end'] - r['start']) / 1e3:8.1f}  s{r['stream']:<4} {r['label']}")
    print(f"step {a.step}, its upload to its last kernel: {(reach - t0) / 1e3:.1f} us, nothing running {idle / 1e3:.1f} us")
    for k, (busy, first, last, n) in sorted(streams.items()):
        print(f"  stream {k}: {n} activities, busy {busy / 1e3:.1f} us over {(last - first) / 1e3:.1f} us")


if __name__ == "__main__":
    main()
