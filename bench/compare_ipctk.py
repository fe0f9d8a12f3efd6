#!/usr/bin/env python3
"""ipc-toolkit (PyPI `ipctk`, optional) and lwsccd.ipc measured side by side on the shared scenes:
the whole `compute_collision_free_stepsize` call of each. ipctk: each CPU broad phase, then Tight
Inclusion CCD at tolerance 1e-6, on the machine's cores or on the thread counts given. lwsccd.ipc
(when the lwsccd package is installed): the CPU backend on every core and the GPU where there is
one, a first call (a new pipeline) and steady calls (the pipeline it keeps), and the number of
colliding pairs lwsccd reports for the step (mode contacts). Where the Python package is not
built (a machine with another Python), --lwsccd-bench takes lwsccd's rows from the C++ benchmark
instead (lwsccd-bench-pipeline --sweep default on the CPU backend and the GPU: the same step in
mode contacts, host to host, first and steady; the step size is lwsccd.ipc's rule applied to its
earliest TOI). --count-pairs also counts the pairs ipctk's narrow phase finds colliding (one
Python call per candidate: scenes of at most --count-limit candidates). Prints a table and, with
--json, writes one row per measurement: medians of --reps calls, the step returned.

    python3 bench/compare_ipctk.py ../shared/data [--reps 3] [--threads 16,2] [--json FILE]
                                   [--lwsccd-bench build/bench/lwsccd-bench-pipeline] [--count-pairs]
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
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


def measure_lwsccd(lwsccd, scene, v0, v1, faces, reps):
    """lwsccd.ipc's call on each backend: the first (a new pipeline) and steady ones (medians)."""
    rows = []
    edges = np.unique(np.sort(np.vstack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1), axis=0)
    mesh = (v0, edges, faces)
    for device in ["cpu"] + (["gpu"] if lwsccd.gpu_available() else []):
        lwsccd.ipc.clear_cache()
        start = time.perf_counter()
        step = lwsccd.ipc.compute_collision_free_stepsize(mesh, v0, v1, device=device)
        first_ms = 1e3 * (time.perf_counter() - start)
        times = []
        for _ in range(reps):
            start = time.perf_counter()
            step = lwsccd.ipc.compute_collision_free_stepsize(mesh, v0, v1, device=device)
            times.append(1e3 * (time.perf_counter() - start))
        r = lwsccd.Pipeline(faces, device=device).step(v0, v1)
        row = dict(scene=scene, broad_phase=f"lwsccd {device}", threads=os.cpu_count() if device == "cpu" else 0,
                   median_ms=statistics.median(times), min_ms=min(times), times_ms=times, first_ms=first_ms, step=step,
                   colliding_pairs=len(r.vertex_face) + len(r.edge_edge), earliest_toi=r.earliest_toi,
                   gpu=lwsccd.gpu_name() if device == "gpu" else "", cores=os.cpu_count())
        rows.append(row)
        print(f"{scene:20s} {row['broad_phase']:14s} {row['threads']:7d} {row['median_ms']:10.1f} {row['min_ms']:10.1f} "
              f"{step:12.7g}  (first call {first_ms:.1f} ms; {row['colliding_pairs']} colliding pairs, earliest "
              f"contact {r.earliest_toi:.7g})", flush=True)
    return rows


# lwsccd.ipc's step: this fraction of the certified earliest TOI (ipctk's conservative rescaling).
IPC_RESCALING = 0.8


def measure_lwsccd_bench(bench, data, scene_names, reps):
    """lwsccd's rows from the C++ benchmark: its default sweep on the CPU backend (every core) and
    on the GPU when there is one; the first step of a new pipeline and the steady steps' median."""
    rows = []
    for device in ("cpu", "gpu"):
        with tempfile.TemporaryDirectory() as tmp:
            out = os.path.join(tmp, "rows.json")
            run = subprocess.run([bench, "--device", device, "--sweep", "default", "--reps", str(reps), "--data", data,
                                  "--json", out], capture_output=True, text=True)
            if run.returncode == 77:  # no GPU
                continue
            if run.returncode != 0:
                raise RuntimeError(f"{bench} --device {device}: exit {run.returncode}: {run.stderr.strip()[-400:]}")
            with open(out) as f:
                bench_rows = json.load(f)
        for scene in scene_names:
            got = {r["step"]: r for r in bench_rows if r["scene"] == scene and r["sweep"] == "default"}
            if "first" not in got or "steady" not in got:
                continue
            steady = got.get("kept", got["steady"])  # (GPU: the loop that keeps its result)
            row = dict(scene=scene, broad_phase=f"lwsccd {device}", threads=steady["threads"],
                       median_ms=steady["total_ms"], min_ms=min(steady["step_total_ms"]), times_ms=steady["step_total_ms"],
                       first_ms=got["first"]["total_ms"], step=IPC_RESCALING * steady["earliest_toi"],
                       colliding_pairs=steady["contacts"], earliest_toi=steady["earliest_toi"],
                       gpu=steady["device"] if device == "gpu" else "", cores=os.cpu_count(), source=os.path.basename(bench))
            rows.append(row)
            print(f"{scene:20s} {row['broad_phase']:14s} {row['threads']:7d} {row['median_ms']:10.1f} {row['min_ms']:10.1f} "
                  f"{row['step']:12.7g}  (first step {row['first_ms']:.1f} ms; {row['colliding_pairs']} colliding pairs, "
                  f"earliest contact {row['earliest_toi']:.7g}; C++ benchmark)", flush=True)
    return rows


def ipctk_colliding_pairs(ipctk, mesh, v0, v1, limit):
    """The candidates ipctk's LBVH finds and how many of them its narrow phase (Tight Inclusion,
    tolerance 1e-6) calls colliding; None where there are more than `limit` candidates."""
    candidates = ipctk.Candidates()
    candidates.build(mesh, v0, v1, broad_phase=ipctk.LBVH())
    lists = [candidates.vv_candidates, candidates.ev_candidates, candidates.ee_candidates, candidates.fv_candidates]
    total = sum(len(c) for c in lists)
    if total > limit:
        return total, None
    ccd = ipctk.TightInclusionCCD(tolerance=1e-6)
    colliding = 0
    for group in lists:
        for c in group:
            hit, _ = c.ccd(c.dof(v0, mesh.edges, mesh.faces), c.dof(v1, mesh.edges, mesh.faces), narrow_phase_ccd=ccd)
            colliding += bool(hit)
    return total, colliding


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("data", help="the shared data folder (scenes/ in it)")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--threads", default="", help="comma-separated thread counts (default: ipctk's, every core)")
    ap.add_argument("--json", default="")
    ap.add_argument("--lwsccd-bench", default="", help="lwsccd-bench-pipeline: lwsccd's rows from the C++ benchmark")
    ap.add_argument("--count-pairs", action="store_true", help="count ipctk's colliding pairs (LBVH candidates)")
    ap.add_argument("--count-limit", type=int, default=300000, help="count only scenes with at most this many candidates")
    args = ap.parse_args()
    try:
        import ipctk
    except ImportError:
        ipctk = None
        print("compare_ipctk.py: ipctk is not installed (pip install ipctk): lwsccd only", file=sys.stderr)
    try:
        import lwsccd
    except ImportError:
        lwsccd = None
        print("compare_ipctk.py: the lwsccd package is not installed (pip install .): ipctk only", file=sys.stderr)
    if ipctk is None and lwsccd is None and not args.lwsccd_bench:
        return 77
    threads = [int(t) for t in args.threads.split(",") if t] or ([ipctk.get_num_threads()] if ipctk else [])
    broad_phases = {"LBVH": ipctk.LBVH, "SweepAndPrune": ipctk.SweepAndPrune, "HashGrid": ipctk.HashGrid,
                    "SpatialHash": ipctk.SpatialHash} if ipctk else {}
    rows = []
    print(f"ipctk {ipctk.__version__ if ipctk else '(absent)'}, {os.cpu_count()} logical cores"
          f"{', GPU ' + lwsccd.gpu_name() if lwsccd and lwsccd.gpu_available() else ''}; whole "
          f"compute_collision_free_stepsize calls, medians of {args.reps}")
    print(f"{'scene':20s} {'broad phase':14s} {'threads':>7s} {'ms':>10s} {'min ms':>10s} {'step':>12s}")
    if args.lwsccd_bench:
        rows += measure_lwsccd_bench(args.lwsccd_bench, args.data, SCENES, args.reps)
    for scene in SCENES:
        folder = os.path.join(args.data, "scenes", scene, "frames")
        frames = sorted(os.listdir(folder))[:2]
        v0, faces = read_ply(os.path.join(folder, frames[0]))
        v1, faces1 = read_ply(os.path.join(folder, frames[1]))
        assert np.array_equal(faces, faces1), "both frames have one topology"
        if lwsccd:
            rows += measure_lwsccd(lwsccd, scene, v0, v1, faces, args.reps)
        if not ipctk:
            continue
        edges = ipctk.edges(faces)
        mesh = ipctk.CollisionMesh(v0, edges, faces)
        v0, v1 = np.asfortranarray(v0), np.asfortranarray(v1)
        if args.count_pairs:
            candidates, colliding = ipctk_colliding_pairs(ipctk, mesh, v0, v1, args.count_limit)
            rows.append(dict(scene=scene, broad_phase="LBVH", candidates=candidates, colliding_pairs=colliding,
                             ipctk=ipctk.__version__))
            print(f"{scene:20s} ipctk LBVH: {candidates} candidates, "
                  f"{colliding if colliding is not None else 'not counted (over --count-limit)'} colliding", flush=True)
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
        # Where and when: the CPU, the date, the commit (LWSCCD_COMMIT where there is no checkout).
        cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")), "?") \
            if os.path.exists("/proc/cpuinfo") else "?"
        commit = os.environ.get("LWSCCD_COMMIT") or subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
            cwd=os.path.dirname(os.path.abspath(__file__))).stdout.strip() or "?"
        for row in rows:
            row.update(cpu=cpu, cores=os.cpu_count(), date=time.strftime("%Y-%m-%d", time.gmtime()), commit=commit)
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
