"""An IPC-style time stepper whose line search takes its step bound from lwsccd instead of
ipc-toolkit: one line changes.

A sheet falls onto a fixed plate. Each time step minimises inertia + gravity (+ ipc-toolkit's
barrier potential when ``ipctk`` is installed) by gradient steps; every step's line search
starts from the largest collision-free step, then halves until the energy decreases::

    alpha = ipctk.compute_collision_free_stepsize(mesh, x, x + dx)    # ipc-toolkit
    alpha = lwsccd.ipc.compute_collision_free_stepsize(mesh, x, x + dx)  # lwsccd (this example)

    python examples/python/ipc_line_search.py [--device auto|cpu|gpu] [--steps N] [--resolution R]

Without ipctk the mesh is passed as (V, E, F) arrays and the energy has no barrier (the line
search's bound alone keeps the sheet off the plate).
"""
import argparse

import numpy as np

import lwsccd

try:
    import ipctk
except ImportError:
    ipctk = None


def grid(n, size, z):
    """An n x n grid of vertices (size x size) at height z, and its triangles."""
    u = np.linspace(-size / 2, size / 2, n)
    xs, ys = np.meshgrid(u, u, indexing="ij")
    vertices = np.stack([xs.ravel(), ys.ravel(), np.full(n * n, z)], axis=1)
    faces = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            faces += [(a, b, c), (a, c, d)]
    return vertices, np.array(faces, dtype=np.int32)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="auto", choices=["auto", "cpu", "gpu"])
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--resolution", type=int, default=20)
    args = parser.parse_args()

    sheet, sheet_faces = grid(args.resolution, 1.0, 0.05)
    plate, plate_faces = grid(6, 1.6, 0.0)
    x = np.vstack([sheet, plate])
    faces = np.vstack([sheet_faces, plate_faces + len(sheet)]).astype(np.int32)
    edges = np.unique(np.sort(np.vstack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1), axis=0)
    moving = np.arange(len(sheet))
    dt, mass, gravity, dhat = 1.0 / 30, 1.0 / len(sheet), np.array([0.0, 0.0, -9.81]), 1e-2
    if ipctk is not None:
        mesh = ipctk.CollisionMesh(np.asfortranarray(x), np.asfortranarray(edges, dtype=np.int32), np.asfortranarray(faces))
        barrier = ipctk.BarrierPotential(dhat, 1e4)  # stiffness: enough to hold the sheet up
    else:
        mesh = (x, edges, faces)
    print(f"{len(x)} vertices, {len(faces)} faces; barrier: {'ipctk' if ipctk is not None else 'none (ipctk not installed)'}")

    velocity = np.zeros_like(x)
    for step in range(args.steps):
        predicted = x.copy()
        predicted[moving] += dt * velocity[moving] + dt * dt * gravity

        def energy(y):
            e = 0.5 * mass / (dt * dt) * float(np.sum((y[moving] - predicted[moving]) ** 2))
            if ipctk is not None:
                collisions = ipctk.NormalCollisions()
                collisions.build(mesh, np.asfortranarray(y), dhat)
                e += barrier(collisions, mesh, np.asfortranarray(y))
            return e

        start, y, bounds = x.copy(), x.copy(), []
        for _ in range(5):  # a few gradient steps toward the prediction
            # Newton's direction for the inertia term, the barrier's gradient scaled alike.
            dx = np.zeros_like(y)
            dx[moving] = predicted[moving] - y[moving]
            if ipctk is not None:
                collisions = ipctk.NormalCollisions()
                collisions.build(mesh, np.asfortranarray(y), dhat)
                grad = np.asarray(barrier.gradient(collisions, mesh, np.asfortranarray(y))).reshape(-1, 3)
                dx[moving] -= (dt * dt / mass) * grad[moving]
            # The one line an ipc-toolkit user changes:
            alpha = lwsccd.ipc.compute_collision_free_stepsize(mesh, y, y + dx, device=args.device)
            bounds.append(alpha)
            e0 = energy(y)
            while alpha > 1e-8 and energy(y + alpha * dx) > e0:
                alpha *= 0.5
            y = y + alpha * dx
        velocity = (y - start) / dt
        x = y
        print(f"step {step:2d}: step bounds {' '.join(f'{b:.3f}' for b in bounds)}, lowest sheet point "
              f"z = {x[moving, 2].min():+.5f}")


if __name__ == "__main__":
    main()
