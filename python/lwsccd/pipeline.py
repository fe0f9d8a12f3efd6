"""The CCD pipeline: one object per mesh topology, stepped with two position arrays."""

from __future__ import annotations

import os
from typing import Any, List, Optional, Sequence, Tuple

import numpy as np

from . import _lwsccd
from ._arrays import _cuda_address, _host_positions, _to_host
from ._device import gpu_available
from .results import EDGE_EDGE_DTYPE, VERTEX_FACE_DTYPE, DeviceStepResult, StepResult


class Pipeline:
    """Continuous collision detection for one triangle mesh topology, step after step.

    Args:
        faces: (F, 3) integer array of vertex indices.
        bodies: optional (F,) integer array, each face's body id. Pairs inside a body that does
            not self-collide are never tested (a rigid body), pairs across bodies always.
        self_collides: optional list of bools, one per body id (default: every body).
        bv: bounding volume of the swept triangles, "aabb" (default) or "obb".
        scheduler: GPU traversal load balancer: "lazy" (lazy work stealing, default),
            "gproximity" or "static". The CPU backend has its own.
        method: narrow phase: "certified" (default; a certified floating-point test, the
            inclusion search where it cannot decide), "filtered-inclusion", "inclusion"
            (conservative, slower), "cubic" (fast, can miss contacts).
        precision: narrow-phase scalar, "double" (default) or "float".
        mode: "contacts" (every colliding pair with its TOI), "earliest" (only the step's
            earliest TOI, what a line search needs; the pair lists stay empty) or "set" (the
            colliding pairs, TOIs unrefined lower bounds).
        min_separation: report pairs that come closer than this (0: contact).
        tolerance: time resolution of the TOIs (default 1e-6).
        max_iterations: narrow-phase work bound per pair; past it a pair counts as a contact.
        front_tracking: start each step's traversal from the last step's front (default True).
        rebuild_factor, front_growth_limit: when to rebuild the BVH / restart from the root
            (front_growth_limit 0: the backend's default, 1.5 on the CPU and 3 on the GPU).
        device_memory_budget: GPU bytes the pipeline may hold (0: no limit); a step that needs
            more runs in parts that fit, with the same contacts (RuntimeError only when even the
            mesh's own data does not fit).
        part_pairs: at most this many candidate triangle pairs go through the narrow phase
            together, the traversal running in parts of about as many (0: no limit); both
            devices, same contacts, less memory at once.
        threads: CPU backend: at most this many threads (0, the default: every core). The
            GPU backend ignores it.
        fp64_ratio: GPU backend: plan the narrow phase as for a GPU whose FP32 runs this many
            times its FP64 (0, the default: the device's own; e.g. 64 to run on an H100 what an
            RTX-class GPU runs); the same contacts. For measuring. From 8 on, both backends
            prove contacts' leaves in pairs of floats first (the same contacts; the counts'
            "float_pair_leaves" say how many).
        device: "auto" (the GPU when the package has it and a device is present, else the
            CPU), "gpu" or "cpu".
        devices: CUDA device ordinals to split each step over (e.g. [0, 1]: NCCL, one host
            thread per GPU, the same contacts as one GPU); one ordinal runs the pipeline on that
            device. Default policies only (aabb, lazy, certified, double) and no
            device_memory_budget or part_pairs; the first device reads device positions and
            holds device results. None (the default): the current CUDA device, as before.

    Raises:
        ValueError: bad faces (index out of range, repeated vertex), bodies, or parameters
            (devices: empty, repeated, not present, with device="cpu" or other policies).
        RuntimeError: device="gpu" (or devices=) without a GPU backend or device, devices=
            without NCCL in this build.
    """

    def __init__(
        self,
        faces: Any,
        bodies: Any = None,
        self_collides: Optional[Sequence[bool]] = None,
        *,
        num_vertices: Optional[int] = None,
        bv: str = "aabb",
        scheduler: str = "lazy",
        method: str = "certified",
        precision: str = "double",
        mode: str = "contacts",
        min_separation: float = 0.0,
        tolerance: float = 1e-6,
        max_iterations: int = 16384,
        front_tracking: bool = True,
        rebuild_factor: float = 1.5,
        front_growth_limit: float = 0.0,
        device_memory_budget: int = 0,
        part_pairs: int = 0,
        threads: int = 0,
        fp64_ratio: int = 0,
        device: str = "auto",
        devices: Optional[Sequence[int]] = None,
    ) -> None:
        f = np.asarray(faces)
        if f.dtype.kind not in "iu":
            raise TypeError(f"lwsccd.Pipeline: faces must be integers, got dtype {f.dtype}")
        if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] == 0:
            raise ValueError(f"lwsccd.Pipeline: faces must have shape (num_faces > 0, 3), got {f.shape}")
        f = np.ascontiguousarray(f, dtype=np.int64)
        if num_vertices is None:
            num_vertices = int(f.max()) + 1
        body_list: List[int] = []
        if bodies is not None:
            b = np.asarray(bodies)
            if b.dtype.kind not in "iu":
                raise TypeError(f"lwsccd.Pipeline: bodies must be integers, got dtype {b.dtype}")
            if b.ndim != 1:
                raise ValueError(f"lwsccd.Pipeline: bodies must have shape (num_faces,) = ({len(f)},), got {b.shape}")
            body_list = [int(v) for v in b]
        collides = [bool(v) for v in self_collides] if self_collides is not None else []
        device_list: List[int] = []
        if devices is not None:
            device_list = [int(d) for d in devices]
            if not device_list:
                raise ValueError("lwsccd.Pipeline: devices must name at least one CUDA device (or be None)")
        if device == "auto":
            device = "gpu" if device_list or gpu_available() else "cpu"
        self._core = _lwsccd.Pipeline(
            int(num_vertices), f, body_list, collides, bv, scheduler, method, precision, mode,
            float(min_separation), float(tolerance), int(max_iterations), bool(front_tracking),
            float(rebuild_factor), float(front_growth_limit), int(device_memory_budget),
            int(part_pairs), int(threads), int(fp64_ratio), device, device_list,
        )
        self.mode = mode

    @property
    def device(self) -> str:
        """The backend the pipeline runs on: "gpu" or "cpu"."""
        return self._core.backend

    @property
    def num_vertices(self) -> int:
        return int(self._core.num_vertices)

    @property
    def faces(self) -> np.ndarray:
        """(F, 3) int64 faces."""
        return self._core.faces

    @property
    def edges(self) -> np.ndarray:
        """(E, 2) int64 vertex pairs of the mesh's edges (lower index first): what
        ``StepResult.edge_edge`` indexes."""
        return self._core.edges

    def step(self, x0: Any, x1: Any, *, on_device: bool = False):
        """One step: every pair that comes into contact while the vertices move from x0 to x1.

        Args:
            x0, x1: (num_vertices, 3) positions at the step's start and end: NumPy arrays
                (float32 taken as it is; any other real dtype converted to float64), or CUDA
                arrays (float64 or float32, C-contiguous) that expose
                ``__cuda_array_interface__`` or DLPack, read in place (GPU backend). Float32
                positions are widened exactly, so the answers are certified for the float32
                values as given. Host arrays of two dtypes are both taken as float64; CUDA arrays
                must have one dtype.
            on_device: GPU backend: leave the contacts in device memory and return a
                :class:`DeviceStepResult` instead of a :class:`StepResult`.

        Raises:
            TypeError: a wrong dtype. ValueError: a wrong shape, NaN or infinite positions.
        """
        n = self.num_vertices
        a0, a1 = _cuda_address(x0, "x0", n), _cuda_address(x1, "x1", n)
        if (a0 is None) != (a1 is None):
            raise ValueError("lwsccd: x0 and x1 must both be host arrays or both CUDA arrays")
        if a0 is not None and a0[1] != a1[1]:
            raise TypeError("lwsccd: x0 and x1 must have the same dtype (both float64 or both float32)")
        if on_device:
            if a0 is None:
                raise ValueError("lwsccd: on_device=True needs x0 and x1 in device memory (CUDA arrays)")
            d = self._core.step_on_device(a0[0], a1[0], a0[1])
            return DeviceStepResult(d["vf_pairs"], d["vf_toi"], d["ee_pairs"], d["ee_toi"],
                                    float(d["earliest_toi"]), int(d["gave_up"]), d["stats"])
        if a0 is not None:
            d = self._core.step_from_device(a0[0], a1[0], a0[1])
        else:
            h0, h1 = _host_positions(x0, "x0", n), _host_positions(x1, "x1", n)
            if h0.dtype != h1.dtype:  # one float32, one float64: the float32 one widened (exactly)
                h0, h1 = h0.astype(np.float64, copy=False), h1.astype(np.float64, copy=False)
            d = (self._core.step_f32 if h0.dtype == np.float32 else self._core.step)(h0, h1)
        return StepResult(
            d["vf"].view(VERTEX_FACE_DTYPE),  # 24-byte records written by the extension
            d["ee"].view(EDGE_EDGE_DTYPE),
            float(d["earliest_toi"]),
            int(d["gave_up"]),
            d["stats"],
        )

    def restart_from_root(self) -> None:
        """The next step traverses the hierarchy from its root instead of from the last step's
        front. The answer is the same either way; on the shared scenes even a front from
        unrelated positions was faster than the root (docs/PIPELINE.md), so call it only where
        the last front is known to be far larger than the next step needs."""
        self._core.restart_from_root()

    def render(self, path: str, x0: Any, x1: Any, result: Optional[StepResult] = None, *,
               size: Tuple[int, int] = (800, 600)) -> str:
        """Writes a PNG picture of a step: the mesh at the step's earliest contact (t = 1 when
        nothing collides) with the triangles of its contacts in red, ray cast on the CPU by the
        library's own ray caster (no other dependency).

        Args:
            path: the PNG file to write (its folder must exist).
            x0, x1: the step's positions (host arrays; CUDA arrays are copied to the host).
            result: the StepResult of ``step(x0, x1)``; stepped now when None (which advances the
                pipeline's front like any step).
            size: (width, height) in pixels.

        Returns the path. Raises ValueError for bad sizes or arrays, RuntimeError when the file
        cannot be written.
        """
        n = self.num_vertices
        h0, h1 = (np.asarray(_to_host(x)) for x in (x0, x1))
        h0, h1 = _host_positions(h0, "x0", n), _host_positions(h1, "x1", n)
        if result is None:
            result = self.step(h0, h1)
        if not isinstance(result, StepResult):
            raise TypeError("lwsccd.Pipeline.render: result must be a StepResult (of step(x0, x1) on the host)")
        width, height = (int(v) for v in size)
        self._core.render(os.fspath(path), h0.astype(np.float64, copy=False), h1.astype(np.float64, copy=False),
                          np.ascontiguousarray(result.vertex_face, dtype=VERTEX_FACE_DTYPE).view(np.uint8),
                          np.ascontiguousarray(result.edge_edge, dtype=EDGE_EDGE_DTYPE).view(np.uint8),
                          float(result.earliest_toi), width, height)
        return os.fspath(path)

    def __repr__(self) -> str:
        return f"lwsccd.Pipeline({len(self.faces)} faces, {self.num_vertices} vertices, device={self.device!r}, mode={self.mode!r})"
