"""The cores this process may use: the default of ``--workers`` and the bound its size check warns
above. Nothing here imports torch, so the command line's parser can ask it."""

from __future__ import annotations

import os


def usable_cores() -> int:
    """The cores this process may run on: its CPU affinity where the platform has one (``taskset``, a
    container's or a batch scheduler's cpuset; a CPU quota is not seen), else the machine's count, and
    at least 1."""
    if hasattr(os, "sched_getaffinity"):  # Linux; not macOS or Windows
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1
