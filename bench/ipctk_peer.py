#!/usr/bin/env python3
"""ipc-toolkit (PyPI `ipctk`, optional) measured on the shared scenes, as a CPU peer of lwsccd's
CPU backend: the whole `compute_collision_free_stepsize` call (its broad phase, then Tight
Inclusion CCD at tolerance 1e-6) for each CPU broad phase, on the machine's cores or on the
thread counts given. Prints a table and, with --json, writes one row per (scene, broad phase,
threads): medians of --reps calls, the step it returns.

    python3 bench/ipctk_peer.py ../shared/data [--reps 3] [--threads 16,2] [--json FILE]

lwsccd's side of the comparison: lwsccd-bench-pipeline --device cpu --sweep threads.
"""
import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

SCENES = ("cloth-ball", "armadillo-rollers", "cloth-funnel")


def read_ply(path):
    """Vertices (n, 3) float64 and triangles (m, 3) int64 of a binary or ASCII PLY of triangles."""
    with open(path, "rb") as f:
        header = []
        while True:
            line = f.readline().decode("ascii").strip()
            header.append(line)
            if line == "end_header":
                break
        body = f.read()
    fmt = next(h.split()[1] for h in header if h.startswith("format"))
    counts, props, current = {}, {"vertex": []}, None
    for h in header:
        parts = h.split()
        if parts[0] == "element":
            current = parts[1]
            counts[current] = int(parts[2])
            props.setdefault(current, [])
        elif parts[0] == "property" and current == "vertex":
            props["vertex"].append(parts[1])
    nv, nf = counts["vertex"], counts["face"]
    if fmt == "ascii":
        rows = body.decode("ascii").split("\n")
        v = np.array([list(map(float, r.split()[:3])) for r in rows[:nv]], dtype=np.float64)
        f = np.array([list(map(int, r.split()[1:4])) for r in rows[nv:nv + nf]], dtype=np.int64)
        return v, f
    end = ">" if fmt == "binary_big_endian" else "<"
    sizes = {"float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
    vtype = np.dtype([(f"p{i}", end + sizes[t]) for i, t in enumerate(props["vertex"])])
    verts = np.frombuffer(body, dtype=vtype, count=nv)
    v = np.stack([verts["p0"], verts["p1"], verts["p2"]], axis=1).astype(np.float64)
    ftype = np.dtype([("n", "u1"), ("v", end + "i4", (3,))])  # every face a triangle (checked)
    faces = np.frombuffer(body, dtype=ftype, count=nf, offset=nv * vtype.itemsize)
    if np.any(faces["n"] != 3):
        raise ValueError(f"{path}: a face that is not a triangle")
    return v, faces["v"].astype(np.int64)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("data", help="the shared data folder (scenes/ in it)")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--threads", default="", help="comma-separated thread counts (default: ipctk's, every core)")
    ap.add_argument("--json", default="")
    args = ap.parse_args()
    try:
        import ipctk
    except ImportError:
        print("ipctk_peer.py: ipctk is not installed (pip install ipctk): nothing to measure", file=sys.stderr)
        return 77
    threads = [int(t) for t in args.threads.split(",") if t] or [ipctk.get_num_threads()]
    broad_phases = {"LBVH": ipctk.LBVH, "SweepAndPrune": ipctk.SweepAndPrune, "HashGrid": ipctk.HashGrid,
                    "SpatialHash": ipctk.SpatialHash}
    rows = []
    print(f"ipctk {ipctk.__version__}, {os.cpu_count()} logical cores; whole compute_collision_free_stepsize calls, "
          f"medians of {args.reps}")
    print(f"{'scene':20s} {'broad phase':14s} {'threads':>7s} {'ms':>10s} {'min ms':>10s} {'step':>12s}")
    for scene in SCENES:
        folder = os.path.join(args.data, "scenes", scene, "frames")
        frames = sorted(os.listdir(folder))[:2]
        v0, faces = read_ply(os.path.join(folder, frames[0]))
        v1, faces1 = read_ply(os.path.join(folder, frames[1]))
        assert np.array_equal(faces, faces1), "both frames have one topology"
        edges = ipctk.edges(faces)
        mesh = ipctk.CollisionMesh(v0, edges, faces)
        v0, v1 = np.asfortranarray(v0), np.asfortranarray(v1)
        for n in threads:
            ipctk.set_num_threads(n)
            for name, make in broad_phases.items():
                times, step = [], None
                for _ in range(args.reps):
                    start = time.perf_counter()
                    step = ipctk.compute_collision_free_stepsize(
                        mesh, v0, v1, broad_phase=make(), narrow_phase_ccd=ipctk.TightInclusionCCD(tolerance=1e-6))
                    times.append(1e3 * (time.perf_counter() - start))
                row = dict(scene=scene, broad_phase=name, threads=n, median_ms=statistics.median(times),
                           min_ms=min(times), times_ms=times, step=step, ipctk=ipctk.__version__, cores=os.cpu_count())
                rows.append(row)
                print(f"{scene:20s} {name:14s} {n:7d} {row['median_ms']:10.1f} {row['min_ms']:10.1f} {step:12.7g}",
                      flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
