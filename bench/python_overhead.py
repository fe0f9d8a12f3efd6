"""Python overhead per step on the GPU: wall time of Pipeline.step seen from Python against the
step's own time (stats["total_ms"], measured inside the library), for host arrays, device arrays
(PyTorch) and device arrays with results left on the device. Medians over repeated steady steps of
one scene step (positions x0 -> x1 stepped again and again: the front-tracked steady state).

    python bench/python_overhead.py SCENE_DIR [--reps 20]
"""
import argparse
import statistics
import time

import lwsccd


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("scene")
    parser.add_argument("--reps", type=int, default=20)
    args = parser.parse_args()
    import torch

    faces, x0, x1 = lwsccd.load_scene(args.scene)
    print(f"device: {lwsccd.gpu_name()}; scene {args.scene}: {len(faces)} triangles; medians of {args.reps} steady steps")
    d0, d1 = torch.from_numpy(x0).cuda(), torch.from_numpy(x1).cuda()
    for label, inputs, kw in (("host arrays", (x0, x1), {}), ("device arrays", (d0, d1), {}),
                              ("device arrays, results on device", (d0, d1), {"on_device": True})):
        ccd = lwsccd.Pipeline(faces, num_vertices=len(x0), device="gpu")
        for _ in range(3):
            ccd.step(*inputs, **kw)  # first step (build, sizing) and warm-up
        wall, inside = [], []
        for _ in range(args.reps):
            torch.cuda.synchronize()
            t = time.perf_counter()
            r = ccd.step(*inputs, **kw)
            wall.append((time.perf_counter() - t) * 1e3)
            inside.append(r.stats["total_ms"])
        w, s = statistics.median(wall), statistics.median(inside)
        print(f"{label:34s} wall {w:8.3f} ms  step {s:8.3f} ms  Python overhead {w - s:6.3f} ms = {100 * (w - s) / s:5.1f}%")


if __name__ == "__main__":
    main()
