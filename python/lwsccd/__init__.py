"""lwsccd: continuous collision detection (CCD) for deforming triangle meshes, on the GPU or the CPU.

A :class:`Pipeline` is made once for a mesh's topology (its faces) and then asked, step after
step, which vertex-face and edge-edge pairs come into contact while every vertex moves on a
straight line from ``x0`` to ``x1``, and when (the time of impact, TOI, in [0, 1])::

    import numpy as np, lwsccd
    sim = lwsccd.ClothBallSimulation(20000)           # the built-in scene: a cloth on a ball
    ccd = lwsccd.Pipeline(sim.faces, bodies=sim.face_body, self_collides=sim.body_self_collides)
    x0, x1 = sim.next_step()
    r = ccd.step(x0, x1)
    r.vertex_face["toi"], r.edge_edge, r.earliest_toi, r.stats["total_ms"]

The answer is conservative: no contact is ever missed (the certified narrow phase, the default),
and the GPU and CPU backends give the same pairs with bit-identical TOIs. Positions may come from
NumPy (host) or, on the GPU backend, from any CUDA array that exposes ``__cuda_array_interface__``
or DLPack (PyTorch, CuPy, JAX, Numba) without a host copy; ``step(..., on_device=True)`` leaves
the contacts in device memory as DLPack-capable arrays.

:mod:`lwsccd.ipc` answers ipc-toolkit's CCD calls (``compute_collision_free_stepsize``,
``is_step_collision_free``) with the same arguments.
"""

from __future__ import annotations

from . import ipc
from ._device import built_with_gpu, built_with_nccl, gpu_available, gpu_count, gpu_name, release_cached_memory
from .io import load_mesh, load_scene, load_sequence, load_step
from .pipeline import Pipeline
from .results import EDGE_EDGE_DTYPE, VERTEX_FACE_DTYPE, DeviceStepResult, StepResult
from .simulation import ClothBallSimulation

__all__ = [
    "Pipeline",
    "StepResult",
    "DeviceStepResult",
    "ClothBallSimulation",
    "VERTEX_FACE_DTYPE",
    "EDGE_EDGE_DTYPE",
    "gpu_available",
    "gpu_name",
    "built_with_gpu",
    "built_with_nccl",
    "gpu_count",
    "release_cached_memory",
    "load_mesh",
    "load_step",
    "load_scene",
    "load_sequence",
    "ipc",
]

__version__ = "0.1.0"
