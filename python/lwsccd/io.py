"""Mesh files (OBJ, PLY), two-frame steps, scene folders and sequences of frames, read into
NumPy arrays."""

from __future__ import annotations

import errno
import os
from typing import List, Tuple

import numpy as np

from . import _lwsccd


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
