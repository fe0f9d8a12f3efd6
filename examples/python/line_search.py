"""A few steps of a toy simulation that uses lwsccd's earliest time of impact as a line-search
bound: a sheet falls under gravity onto a tilted rigid plate, and each step moves only as far as
it can without any contact (a fraction of the earliest TOI), the way an implicit solver bounds its
line search to stay intersection-free.

    python examples/python/line_search.py [--device auto|cpu|gpu] [--steps N] [--resolution R]

Runs on the CPU backend anywhere; on the GPU when the package has it and a device is present.
"""
import argparse

import numpy as np

import lwsccd


def grid(n, size, z, tilt=0.0):
    """An n x n grid of vertices (size x size) at height z, tilted about the x axis, and its faces."""
    u = np.linspace(-size / 2, size / 2, n)
    xs, ys = np.meshgrid(u, u, indexing="ij")
    vertices = np.stack([xs.ravel(), ys.ravel(), z + np.tan(tilt) * ys.ravel()], axis=1)
    faces = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            faces += [(a, b, c), (a, c, d)]
    return vertices, np.array(faces)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="auto", choices=["auto", "cpu", "gpu"])
    parser.add_argument("--steps", type=int, default=12)
    parser.add_argument("--resolution", type=int, default=40)
    args = parser.parse_args()

    sheet, sheet_faces = grid(args.resolution, 1.0, 0.3)
    plate, plate_faces = grid(8, 1.6, 0.0, tilt=0.2)
    x = np.vstack([sheet, plate])
    faces = np.vstack([sheet_faces, plate_faces + len(sheet)])
    bodies = np.r_[np.zeros(len(sheet_faces), int), np.ones(len(plate_faces), int)]
    # The sheet self-collides; the plate is rigid (its own pairs are never tested).
    ccd = lwsccd.Pipeline(faces, bodies=bodies, self_collides=[True, False], mode="earliest", device=args.device)
    print(f"{ccd}: {len(sheet)} sheet vertices, plate rigid")

    velocity = np.zeros_like(x)
    gravity, dt, moving = np.array([0.0, 0.0, -9.81]), 1.0 / 30, slice(0, len(sheet))
    for step in range(args.steps):
        velocity[moving] += gravity * dt
        proposed = x + velocity * dt
        r = ccd.step(x, proposed)
        # Line search: take the whole step if nothing collides, else stop short of the first contact.
        alpha = 1.0 if r.earliest_toi >= 1.0 else 0.8 * r.earliest_toi
        x = x + alpha * (proposed - x)
        if alpha < 1.0:
            velocity[moving] = 0.0  # a crude response: the sheet stops where it would touch
        print(f"step {step:2d}: earliest TOI {r.earliest_toi:.6f}  step taken {alpha:5.3f}  "
              f"lowest sheet point z = {x[moving, 2].min():+.4f}  ({r.stats['total_ms']:.2f} ms)")


if __name__ == "__main__":
    main()
