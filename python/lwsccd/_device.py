"""Which backends this build of the package has, and the GPU it sees."""

from __future__ import annotations

from . import _lwsccd


def built_with_gpu() -> bool:
    """True when this build of the package has the GPU backend compiled in."""
    return bool(_lwsccd.built_with_gpu())


def gpu_name() -> str:
    """The first CUDA device's name; "" when there is none or the package has no GPU backend."""
    return _lwsccd.gpu_name()


def release_cached_memory() -> None:
    """Frees the device memory that destroyed pipelines gave back and the process kept for later
    ones (a later pipeline on a mesh of the same size starts with it); nothing without a GPU."""
    _lwsccd.release_cached_memory()


def gpu_available() -> bool:
    """True when the GPU backend is compiled in and a CUDA device is present."""
    return built_with_gpu() and gpu_name() != ""


def built_with_nccl() -> bool:
    """True when this build can split a step over several GPUs (Pipeline(devices=[...]))."""
    return bool(_lwsccd.built_with_nccl())


def gpu_count() -> int:
    """The number of CUDA devices this build sees (0 without the GPU backend)."""
    return int(_lwsccd.gpu_count())
