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
"""

from __future__ import annotations

import errno
import os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import _lwsccd

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
    "load_mesh",
    "load_step",
    "load_scene",
    "load_sequence",
]

__version__ = "0.1.0"

#: One vertex-face contact: the vertex, the face (indices into the mesh) and the time of impact.
VERTEX_FACE_DTYPE = np.dtype([("vertex", np.int64), ("face", np.int64), ("toi", np.float64)])
#: One edge-edge contact: two edges (indices into :attr:`Pipeline.edges`) and the time of impact.
EDGE_EDGE_DTYPE = np.dtype([("edge_a", np.int64), ("edge_b", np.int64), ("toi", np.float64)])


def built_with_gpu() -> bool:
    """True when this build of the package has the GPU backend compiled in."""
    return bool(_lwsccd.built_with_gpu())


def gpu_name() -> str:
    """The first CUDA device's name; "" when there is none or the package has no GPU backend."""
    return _lwsccd.gpu_name()


def gpu_available() -> bool:
    """True when the GPU backend is compiled in and a CUDA device is present."""
    return built_with_gpu() and gpu_name() != ""


@dataclass
class StepResult:
    """One step's contacts, on the host.

    Attributes:
        vertex_face: structured array of :data:`VERTEX_FACE_DTYPE` (vertex, face, toi), sorted by
            (vertex, face); empty in mode "earliest".
        edge_edge: structured array of :data:`EDGE_EDGE_DTYPE` (edge_a, edge_b, toi), edge_a <
            edge_b, sorted; edges index :attr:`Pipeline.edges`. Empty in mode "earliest".
        earliest_toi: the step's earliest time of impact (a lower bound within the tolerance);
            1.0 when nothing collides.
        gave_up: pairs counted as contacts because they hit the work bound (max_iterations).
        stats: per-stage times (ms) and counts of the step (refit, traversal, feature pairs,
            narrow phase, peak device memory, ...).
    """

    vertex_face: np.ndarray
    edge_edge: np.ndarray
    earliest_toi: float
    gave_up: int
    stats: Dict[str, Any] = field(repr=False)

    @property
    def num_contacts(self) -> int:
        return len(self.vertex_face) + len(self.edge_edge)

    def __repr__(self) -> str:
        return (f"StepResult({len(self.vertex_face)} vertex-face and {len(self.edge_edge)} edge-edge contacts, "
                f"earliest_toi={self.earliest_toi!r}, gave_up={self.gave_up}, {self.stats.get('total_ms', 0):.3f} ms)")


@dataclass
class DeviceStepResult:
    """One step's contacts left in device memory (``Pipeline.step(..., on_device=True)``).

    The four arrays are new CUDA arrays owned by this object, exposing DLPack
    (``torch.from_dlpack(r.vf_pairs)``, ``cupy.from_dlpack(...)``): ``vf_pairs`` (n, 2) int64
    (vertex, face), ``vf_toi`` (n,) float64, ``ee_pairs`` (m, 2) int64 (edge, edge), ``ee_toi``.
    """

    vf_pairs: Any
    vf_toi: Any
    ee_pairs: Any
    ee_toi: Any
    earliest_toi: float
    gave_up: int
    stats: Dict[str, Any] = field(repr=False)


def _host_positions(x: Any, name: str, num_vertices: int) -> np.ndarray:
    """x as a C-contiguous float64 (num_vertices, 3) NumPy array, or a clear error."""
    a = np.asarray(x)
    if a.dtype.kind not in "fiu":
        raise TypeError(f"lwsccd: {name} must hold real numbers (float64 preferred), got dtype {a.dtype}")
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"lwsccd: {name} must have shape (num_vertices, 3) = ({num_vertices}, 3), got {a.shape}")
    if a.shape[0] != num_vertices:
        raise ValueError(f"lwsccd: {name} has {a.shape[0]} points for a mesh of {num_vertices} vertices")
    return np.ascontiguousarray(a, dtype=np.float64)


def _to_host(x: Any) -> Any:
    """A CUDA array's contents on the host (PyTorch, CuPy); other arrays unchanged."""
    if hasattr(x, "__cuda_array_interface__") or (hasattr(x, "__dlpack_device__") and int(x.__dlpack_device__()[0]) == 2):
        if hasattr(x, "get"):  # CuPy
            return x.get()
        if hasattr(x, "cpu"):  # PyTorch
            return x.cpu().numpy()
        return np.from_dlpack(x)
    return x


def _cuda_address(x: Any, name: str, num_vertices: int) -> Optional[int]:
    """The device address of a CUDA array (float64, C-contiguous, (num_vertices, 3)), or None
    when x is not a CUDA array."""
    cai = getattr(x, "__cuda_array_interface__", None)
    if cai is not None:
        shape, typestr, strides = tuple(cai["shape"]), cai["typestr"], cai.get("strides")
        if typestr not in ("<f8", "=f8"):
            raise TypeError(f"lwsccd: {name} on the device must be float64, got typestr {typestr!r} (convert it first)")
        if len(shape) != 2 or shape[1] != 3:
            raise ValueError(f"lwsccd: {name} must have shape ({num_vertices}, 3), got {shape}")
        if shape[0] != num_vertices:
            raise ValueError(f"lwsccd: {name} has {shape[0]} points for a mesh of {num_vertices} vertices")
        if strides is not None and tuple(strides) != (24, 8):
            raise ValueError(f"lwsccd: {name} on the device must be C-contiguous, got strides {tuple(strides)}")
        stream = cai.get("stream")
        if stream not in (None, 1, 2):  # a producer's own stream: its writes must be done
            _lwsccd_sync_stream(stream)
        return int(cai["data"][0])
    if hasattr(x, "__dlpack__") and hasattr(x, "__dlpack_device__"):
        device_type, _ = x.__dlpack_device__()
        if int(device_type) != 2:  # kDLCUDA
            return None
        shape = tuple(getattr(x, "shape", ()))
        dtype = str(getattr(x, "dtype", ""))
        if "float64" not in dtype:
            raise TypeError(f"lwsccd: {name} on the device must be float64, got dtype {dtype} (convert it first)")
        if len(shape) != 2 or shape[1] != 3 or shape[0] != num_vertices:
            raise ValueError(f"lwsccd: {name} must have shape ({num_vertices}, 3), got {shape}")
        return int(_lwsccd.dlpack_address(x))
    return None


def _lwsccd_sync_stream(stream: int) -> None:
    _lwsccd.synchronize_stream(int(stream))


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
        device: "auto" (the GPU when the package has it and a device is present, else the
            CPU), "gpu" or "cpu".

    Raises:
        ValueError: bad faces (index out of range, repeated vertex), bodies, or parameters.
        RuntimeError: device="gpu" without a GPU backend or device.
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
        device: str = "auto",
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
        if device == "auto":
            device = "gpu" if gpu_available() else "cpu"
        self._core = _lwsccd.Pipeline(
            int(num_vertices), f, body_list, collides, bv, scheduler, method, precision, mode,
            float(min_separation), float(tolerance), int(max_iterations), bool(front_tracking),
            float(rebuild_factor), float(front_growth_limit), int(device_memory_budget),
            int(part_pairs), device,
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
            x0, x1: (num_vertices, 3) positions at the step's start and end: NumPy arrays (any
                real dtype, converted to float64), or CUDA arrays (float64, C-contiguous) that
                expose ``__cuda_array_interface__`` or DLPack, read in place (GPU backend).
            on_device: GPU backend: leave the contacts in device memory and return a
                :class:`DeviceStepResult` instead of a :class:`StepResult`.

        Raises:
            TypeError: a wrong dtype. ValueError: a wrong shape, NaN or infinite positions.
        """
        n = self.num_vertices
        a0, a1 = _cuda_address(x0, "x0", n), _cuda_address(x1, "x1", n)
        if (a0 is None) != (a1 is None):
            raise ValueError("lwsccd: x0 and x1 must both be host arrays or both CUDA arrays")
        if on_device:
            if a0 is None:
                raise ValueError("lwsccd: on_device=True needs x0 and x1 in device memory (CUDA arrays)")
            d = self._core.step_on_device(a0, a1)
            return DeviceStepResult(d["vf_pairs"], d["vf_toi"], d["ee_pairs"], d["ee_toi"],
                                    float(d["earliest_toi"]), int(d["gave_up"]), d["stats"])
        if a0 is not None:
            d = self._core.step_from_device(a0, a1)
        else:
            d = self._core.step(_host_positions(x0, "x0", n), _host_positions(x1, "x1", n))
        return StepResult(
            d["vf"].view(VERTEX_FACE_DTYPE),  # 24-byte records written by the extension
            d["ee"].view(EDGE_EDGE_DTYPE),
            float(d["earliest_toi"]),
            int(d["gave_up"]),
            d["stats"],
        )

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
        self._core.render(os.fspath(path), h0, h1,
                          np.ascontiguousarray(result.vertex_face, dtype=VERTEX_FACE_DTYPE).view(np.uint8),
                          np.ascontiguousarray(result.edge_edge, dtype=EDGE_EDGE_DTYPE).view(np.uint8),
                          float(result.earliest_toi), width, height)
        return os.fspath(path)

    def __repr__(self) -> str:
        return f"lwsccd.Pipeline({len(self.faces)} faces, {self.num_vertices} vertices, device={self.device!r}, mode={self.mode!r})"


class ClothBallSimulation:
    """The built-in scene: a cloth dropped folded onto a ball (the main program's default).

    ``target_triangles`` sets the cloth's resolution; body 0 is the cloth (self-colliding),
    body 1 the ball (rigid). The simulation starts at ``first_frame`` (default 30, as the main
    program: the folded cloth is landing on the ball). ``next_step()`` returns (x0, x1) for the
    next CCD step.
    """

    def __init__(self, target_triangles: int = 20000, first_frame: int = 30) -> None:
        if int(target_triangles) < 64:
            raise ValueError(f"lwsccd.ClothBallSimulation: target_triangles must be at least 64, got {target_triangles}")
        if int(first_frame) < 0:
            raise ValueError(f"lwsccd.ClothBallSimulation: first_frame must be >= 0, got {first_frame}")
        self._sim = _lwsccd.ClothBallSimulation(int(target_triangles))
        if first_frame:
            self._sim.advance(int(first_frame))
        self.faces: np.ndarray = self._sim.faces
        self.face_body: np.ndarray = self._sim.face_body
        self.body_self_collides: List[bool] = list(self._sim.body_self_collides)

    def next_step(self) -> Tuple[np.ndarray, np.ndarray]:
        d = self._sim.next_step()
        return d["x0"], d["x1"]


def _existing(path: str, folder: bool = False) -> str:
    path = os.fspath(path)
    if not (os.path.isdir(path) if folder else os.path.isfile(path)):
        raise FileNotFoundError(errno.ENOENT, f"lwsccd: no such {'folder' if folder else 'file'}", path)
    return path


def load_mesh(path: str) -> Tuple[np.ndarray, np.ndarray]:
    """Reads an OBJ or PLY mesh: (vertices (V, 3) float64, faces (F, 3) int64). Polygons are
    triangulated. Raises FileNotFoundError, or ValueError naming the file, line and problem."""
    d = _lwsccd.load_frame(_existing(path))
    return d["vertices"], d["faces"]


def load_step(path_t0: str, path_t1: str) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two frames of one topology as a step: (faces, x0, x1)."""
    d = _lwsccd.load_step(_existing(path_t0), _existing(path_t1))
    return d["faces"], d["x0"], d["x1"]


def load_scene(folder: str) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A scene folder (frames/ with two frames, as the dataset's scenes): (faces, x0, x1)."""
    d = _lwsccd.load_scene(_existing(folder, folder=True))
    return d["faces"], d["x0"], d["x1"]


def load_sequence(folder: str) -> Tuple[np.ndarray, List[np.ndarray]]:
    """Every OBJ/PLY frame of a folder, in name order, of one topology: (faces, [positions])."""
    d = _lwsccd.load_sequence(_existing(folder, folder=True))
    return d["faces"], list(d["frames"])
