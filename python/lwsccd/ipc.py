"""ipc-toolkit's CCD calls on lwsccd: a one-line switch for an IPC line search.

ipc-toolkit (PyPI ``ipctk``) asks two questions of a step from ``vertices_t0`` to
``vertices_t1`` of a :class:`ipctk.CollisionMesh`; these functions answer them with the same
names, arguments and meaning, on the GPU when there is one, else on the CPU::

    step = ipctk.compute_collision_free_stepsize(mesh, V0, V1)        # before
    step = lwsccd.ipc.compute_collision_free_stepsize(mesh, V0, V1)   # after

``mesh`` is an ``ipctk.CollisionMesh`` (read through its ``num_vertices``, ``edges`` and
``faces``; ipctk itself is not needed) or a tuple ``(V, E, F)`` of arrays. A pipeline is kept per
topology and settings, so a line search's repeated calls run at lwsccd's steady-state speed.

Differences from ipctk, all on the safe side:

- The step: lwsccd finds the step's earliest time of contact certified within ``tolerance``
  (a lower bound ``toi`` with ``exact - tolerance <= toi <= exact``) and returns
  ``conservative_rescaling * toi`` (1.0 when nothing touches). ipctk (1.6.1, Tight Inclusion)
  counts a pair as colliding once it comes within ``min(0.2 * its initial distance, 1e-4)`` of
  ``min_distance`` (with the default rescaling 0.8), and rescales only where that time is below
  1e-6, so its step is earlier: on the dataset's cloth-funnel step ipctk returns 0.0293,
  lwsccd 0.0362 (0.8 x 0.045232), the exact earliest contact being at 0.0452322. Both are
  collision free; ipctk's also keeps every pair a little apart.
- ``is_step_collision_free`` likewise: False where a pair comes within ``min_distance``
  (contact) during the step, where ipctk already says False for a pair that comes within its
  effective distance above.
- ``broad_phase`` is accepted and ignored (lwsccd has its own); ``narrow_phase_ccd``'s
  ``tolerance`` and ``conservative_rescaling`` are read where it has them (ipctk's
  ``TightInclusionCCD``), the keyword arguments of the same names win. Its ``max_iterations``
  counts Tight Inclusion's iterations, not lwsccd's narrow-phase work, and is not read.
- Triangle meshes only: a mesh with codimensional edges (in no face) or vertices (in no face)
  is refused with a ValueError rather than checked in part.
"""

from __future__ import annotations

from typing import Any, List, NamedTuple, Optional, Tuple

import numpy as np

from ._device import release_cached_memory
from .pipeline import Pipeline

__all__ = ["compute_collision_free_stepsize", "is_step_collision_free", "clear_cache"]

#: ipctk's defaults (TightInclusionCCD): the CCD tolerance and the step's conservative rescaling.
DEFAULT_TOLERANCE = 1e-6
DEFAULT_CONSERVATIVE_RESCALING = 0.8
DEFAULT_MAX_ITERATIONS = 16384


class _Kept(NamedTuple):
    """A pipeline kept for a topology and settings, with copies of the arrays it was made from."""

    faces: np.ndarray
    edges: np.ndarray
    settings: tuple
    pipeline: Pipeline


_CACHE: List[_Kept] = []  # the most recently used last
_CACHE_SIZE = 4


def clear_cache() -> None:
    """Drops the pipelines kept for earlier meshes and frees their device memory."""
    _CACHE.clear()
    release_cached_memory()


def _arrays(mesh: Any) -> Tuple[np.ndarray, np.ndarray, int]:
    """(faces, edges, num_vertices) of an ipctk.CollisionMesh or a (V, E, F) tuple, as given."""
    if isinstance(mesh, (tuple, list)):
        if len(mesh) != 3:
            raise ValueError(f"lwsccd.ipc: a mesh given as arrays is (V, E, F), got {len(mesh)} items")
        v = np.asarray(mesh[0])
        if v.ndim != 2:
            raise ValueError(f"lwsccd.ipc: V must have shape (num_vertices, 3), got {v.shape}")
        return np.asarray(mesh[2]), np.asarray(mesh[1]), v.shape[0]
    if all(hasattr(mesh, name) for name in ("faces", "edges", "num_vertices")):
        dim = getattr(mesh, "dim", 3)
        if int(dim) != 3:
            raise ValueError(f"lwsccd.ipc: lwsccd checks 3D meshes, this CollisionMesh is {dim}D")
        for name in ("num_codim_edges", "num_codim_vertices"):
            if int(getattr(mesh, name, 0)) > 0:
                raise ValueError(f"lwsccd.ipc: the mesh has {int(getattr(mesh, name))} codimensional "
                                 f"{name.split('_')[-1]}: lwsccd checks triangle meshes only")
        return np.asarray(mesh.faces), np.asarray(mesh.edges), int(mesh.num_vertices)
    raise TypeError("lwsccd.ipc: mesh must be an ipctk.CollisionMesh (or any object with faces, edges and "
                    f"num_vertices) or a tuple (V, E, F), got {type(mesh).__name__}")


def _check_faces(f: np.ndarray, e: np.ndarray, num_vertices: int) -> Tuple[np.ndarray, np.ndarray]:
    """The faces and edges as int64, after checking their types, shapes and the faces' indices."""
    if f.dtype.kind not in "iu" or (e.size and e.dtype.kind not in "iu"):
        raise TypeError(f"lwsccd.ipc: faces and edges must be integers, got {f.dtype} and {e.dtype}")
    if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] == 0:
        raise ValueError(f"lwsccd.ipc: faces must have shape (num_faces > 0, 3), got {f.shape}")
    if f.min() < 0 or f.max() >= num_vertices:
        raise ValueError(f"lwsccd.ipc: a face index is outside [0, {num_vertices})")
    if e.size and (e.ndim != 2 or e.shape[1] != 2):
        raise ValueError(f"lwsccd.ipc: edges must have shape (num_edges, 2), got {e.shape}")
    edges = np.ascontiguousarray(e, dtype=np.int64).reshape(-1, 2) if e.size else np.zeros((0, 2), dtype=np.int64)
    return np.ascontiguousarray(f, dtype=np.int64), edges


def _check_triangle_mesh(p: Pipeline, edges: np.ndarray) -> None:
    """Refuses codimensional elements, which ipctk would check and lwsccd does not: edges in no face
    and vertices in no face (counted by the pipeline's own mesh, on all cores)."""
    loose_edges, loose_vertices = p._core.count_loose(edges)
    if loose_edges:
        raise ValueError(f"lwsccd.ipc: {loose_edges} edges belong to no face (codimensional): lwsccd checks triangle "
                         "meshes only")
    if loose_vertices:
        raise ValueError(f"lwsccd.ipc: {loose_vertices} vertices belong to no face (codimensional points): "
                         "lwsccd checks triangle meshes only")


def _setting(explicit: Optional[float], ccd: Any, name: str, default: float) -> float:
    if explicit is not None:
        return explicit
    if ccd is not None and hasattr(ccd, name):
        return getattr(ccd, name)
    return default


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.dtype == b.dtype and bool(np.array_equal(a, b))


def _pipeline(mesh: Any, mode: str, min_distance: float, tolerance: float, max_iterations: int, device: str) -> Pipeline:
    faces, edges, num_vertices = _arrays(mesh)
    settings = (num_vertices, mode, float(min_distance), float(tolerance), int(max_iterations), device)
    # A line search asks many times of one topology: its pipeline is found again by comparing the
    # arrays with the copies kept (memory compares: ~0.5 ms for 92 K triangles, where a SHA-1 of
    # them took 6 ms a call), and the topology is checked once, when the pipeline is made.
    for i in range(len(_CACHE) - 1, -1, -1):
        kept = _CACHE[i]
        if kept.settings == settings and _same(faces, kept.faces) and _same(edges, kept.edges):
            _CACHE.append(_CACHE.pop(i))
            return kept.pipeline
    f, e = _check_faces(faces, edges, num_vertices)
    p = Pipeline(f, num_vertices=num_vertices, mode=mode, min_separation=float(min_distance),
                 tolerance=float(tolerance), max_iterations=int(max_iterations), device=device)
    _check_triangle_mesh(p, e)
    _CACHE.append(_Kept(np.array(faces, copy=True), np.array(edges, copy=True), settings, p))
    del _CACHE[:-_CACHE_SIZE]
    return p


def _iterations(max_iterations: Optional[int]) -> int:
    n = DEFAULT_MAX_ITERATIONS if max_iterations is None else int(max_iterations)
    if not 1 <= n < 2**31:
        raise ValueError(f"lwsccd.ipc: max_iterations must be in [1, 2**31), got {max_iterations}")
    return n


def _check_distance(min_distance: float) -> float:
    d = float(min_distance)
    if not np.isfinite(d) or d < 0:
        raise ValueError(f"lwsccd.ipc: min_distance must be finite and >= 0, got {min_distance}")
    return d


def compute_collision_free_stepsize(mesh: Any, vertices_t0: Any, vertices_t1: Any, min_distance: float = 0.0,
                                    broad_phase: Any = None, narrow_phase_ccd: Any = None, *,
                                    tolerance: Optional[float] = None, max_iterations: Optional[int] = None,
                                    conservative_rescaling: Optional[float] = None, device: str = "auto") -> float:
    """A step size in [0, 1] that is collision free, as ipctk's function of the same name.

    Args:
        mesh: an ``ipctk.CollisionMesh`` or a tuple ``(V, E, F)``.
        vertices_t0, vertices_t1: (num_vertices, 3) positions at the step's start (assumed
            intersection free) and end.
        min_distance: no two elements may come closer than this.
        broad_phase: ignored (lwsccd's own).
        narrow_phase_ccd: read for ``tolerance`` and ``conservative_rescaling`` where it has
            them (ipctk's ``TightInclusionCCD``).
        tolerance: the time resolution of the certified earliest contact (default 1e-6).
        max_iterations: lwsccd's narrow-phase work bound per pair (default 16384; a pair past it
            counts as a contact at the time it had excluded).
        conservative_rescaling: the step returned is this times the earliest contact's certified
            lower bound (default 0.8, ipctk's), in (0, 1].
        device: "auto", "gpu" or "cpu".

    Returns:
        1.0 when nothing comes within ``min_distance`` during the step, else
        ``conservative_rescaling * toi`` with ``toi`` no later than the exact earliest contact and
        at most ``tolerance`` before it.
    """
    scale = float(_setting(conservative_rescaling, narrow_phase_ccd, "conservative_rescaling", DEFAULT_CONSERVATIVE_RESCALING))
    if not 0 < scale <= 1:
        raise ValueError(f"lwsccd.ipc: conservative_rescaling must be in (0, 1], got {scale}")
    tol = float(_setting(tolerance, narrow_phase_ccd, "tolerance", DEFAULT_TOLERANCE))
    iters = _iterations(max_iterations)
    p = _pipeline(mesh, "earliest", _check_distance(min_distance), tol, iters, device)
    toi = p.step(vertices_t0, vertices_t1).earliest_toi
    return 1.0 if toi >= 1.0 else scale * toi


def is_step_collision_free(mesh: Any, vertices_t0: Any, vertices_t1: Any, min_distance: float = 0.0,
                           broad_phase: Any = None, narrow_phase_ccd: Any = None, *,
                           tolerance: Optional[float] = None, max_iterations: Optional[int] = None,
                           device: str = "auto") -> bool:
    """Whether no two elements come within ``min_distance`` while the vertices move from
    ``vertices_t0`` to ``vertices_t1`` (t in [0, 1]), as ipctk's function of the same name.
    Conservative: a pair that comes within the tolerance of contact counts as a collision.
    Arguments as :func:`compute_collision_free_stepsize`."""
    tol = float(_setting(tolerance, narrow_phase_ccd, "tolerance", DEFAULT_TOLERANCE))
    p = _pipeline(mesh, "set", _check_distance(min_distance), tol, _iterations(max_iterations), device)
    r = p.step(vertices_t0, vertices_t1)
    return len(r.vertex_face) == 0 and len(r.edge_edge) == 0
