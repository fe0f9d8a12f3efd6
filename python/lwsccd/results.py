"""What a step returns: its contacts as structured arrays on the host (StepResult) or as CUDA
arrays left on the device (DeviceStepResult)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict

import numpy as np


#: One vertex-face contact: the vertex, the face (indices into the mesh) and the time of impact.
VERTEX_FACE_DTYPE = np.dtype([("vertex", np.int64), ("face", np.int64), ("toi", np.float64)])
#: One edge-edge contact: two edges (indices into :attr:`Pipeline.edges`) and the time of impact.
EDGE_EDGE_DTYPE = np.dtype([("edge_a", np.int64), ("edge_b", np.int64), ("toi", np.float64)])


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
