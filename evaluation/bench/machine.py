"""What a benchmark's figures depend on besides the code: library versions, CPUs,
threads."""

from __future__ import annotations

import os

__all__ = ["cpu_count", "mujoco_version", "os_threads", "torch_threads"]


def mujoco_version() -> str:
    """The MuJoCo version in use."""
    import mujoco

    return str(mujoco.__version__)


def cpu_count() -> int | None:
    """CPUs of the machine (None when unknown)."""
    return os.cpu_count()


def os_threads() -> int | None:
    """Threads of this process (native ones too, e.g. the BLAS pool); None off Linux."""
    try:
        return len(os.listdir("/proc/self/task"))
    except OSError:
        return None


def torch_threads(threads: int | None = None) -> int:
    """torch's CPU thread count, after setting it to ``threads`` when given."""
    import torch

    if threads is not None:
        torch.set_num_threads(threads)
    return int(torch.get_num_threads())
