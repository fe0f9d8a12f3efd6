"""The built-in scene: a cloth dropped folded onto a rigid ball."""

from __future__ import annotations

from typing import List, Tuple

import numpy as np

from . import _lwsccd


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
