"""Positions handed to a pipeline: NumPy arrays checked and made contiguous on the host (float32
kept as it is, any other real dtype made float64), CUDA arrays (``__cuda_array_interface__`` or
DLPack, float64 or float32) checked and read by their device address."""

from __future__ import annotations

from typing import Any, Optional, Tuple

import numpy as np

from . import _lwsccd


def _host_positions(x: Any, name: str, num_vertices: int) -> np.ndarray:
    """x as a C-contiguous (num_vertices, 3) NumPy array of float32 (when it is float32: the
    pipeline widens it exactly, so the answers are certified for those values) or float64 (any
    other real dtype), or a clear error."""
    a = np.asarray(x)
    if a.dtype.kind not in "fiu":
        raise TypeError(f"lwsccd: {name} must hold real numbers (float64 or float32), got dtype {a.dtype}")
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"lwsccd: {name} must have shape (num_vertices, 3) = ({num_vertices}, 3), got {a.shape}")
    if a.shape[0] != num_vertices:
        raise ValueError(f"lwsccd: {name} has {a.shape[0]} points for a mesh of {num_vertices} vertices")
    return np.ascontiguousarray(a, dtype=np.float32 if a.dtype == np.float32 else np.float64)


def _to_host(x: Any) -> Any:
    """A CUDA array's contents on the host (PyTorch, CuPy); other arrays unchanged."""
    if hasattr(x, "__cuda_array_interface__") or (hasattr(x, "__dlpack_device__") and int(x.__dlpack_device__()[0]) == 2):
        if hasattr(x, "get"):  # CuPy
            return x.get()
        if hasattr(x, "cpu"):  # PyTorch
            return x.cpu().numpy()
        return np.from_dlpack(x)
    return x


def _cuda_address(x: Any, name: str, num_vertices: int) -> Optional[Tuple[int, bool]]:
    """(device address, whether float32) of a CUDA array (float64 or float32, C-contiguous,
    (num_vertices, 3)), or None when x is not a CUDA array. Float32 is read in place and widened
    on the device (exactly: the answers are certified for those values)."""
    cai = getattr(x, "__cuda_array_interface__", None)
    if cai is not None:
        shape, typestr, strides = tuple(cai["shape"]), cai["typestr"], cai.get("strides")
        if typestr not in ("<f8", "=f8", "<f4", "=f4"):
            raise TypeError(f"lwsccd: {name} on the device must be float64 or float32, got typestr {typestr!r} (convert it first)")
        float32 = typestr.endswith("f4")
        if len(shape) != 2 or shape[1] != 3:
            raise ValueError(f"lwsccd: {name} must have shape ({num_vertices}, 3), got {shape}")
        if shape[0] != num_vertices:
            raise ValueError(f"lwsccd: {name} has {shape[0]} points for a mesh of {num_vertices} vertices")
        item = 4 if float32 else 8
        if strides is not None and tuple(strides) != (3 * item, item):
            raise ValueError(f"lwsccd: {name} on the device must be C-contiguous, got strides {tuple(strides)}")
        stream = cai.get("stream")
        if stream not in (None, 1, 2):  # a producer's own stream: its writes must be done
            _lwsccd_sync_stream(stream)
        return int(cai["data"][0]), float32
    if hasattr(x, "__dlpack__") and hasattr(x, "__dlpack_device__"):
        device_type, _ = x.__dlpack_device__()
        if int(device_type) != 2:  # kDLCUDA
            return None
        shape = tuple(getattr(x, "shape", ()))
        dtype = str(getattr(x, "dtype", ""))
        if "float64" not in dtype and "float32" not in dtype:
            raise TypeError(f"lwsccd: {name} on the device must be float64 or float32, got dtype {dtype} (convert it first)")
        if len(shape) != 2 or shape[1] != 3 or shape[0] != num_vertices:
            raise ValueError(f"lwsccd: {name} must have shape ({num_vertices}, 3), got {shape}")
        return int(_lwsccd.dlpack_address(x)), "float32" in dtype
    return None


def _lwsccd_sync_stream(stream: int) -> None:
    _lwsccd.synchronize_stream(int(stream))
