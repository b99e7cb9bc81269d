"""Pinning a benchmark to one core (the targets are per core), for the block of a ``with``."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def one_core(enabled: bool = True) -> Iterator[bool]:
    """Pin this process, and the processes it starts, to its last allowed core inside the block.

    Yields whether it pinned (not where ``enabled`` is false or the OS has no affinity call); the
    previous affinity is restored on leaving.
    """
    pin = enabled and hasattr(os, "sched_setaffinity")
    cores = os.sched_getaffinity(0) if pin else set()
    try:
        if pin:
            os.sched_setaffinity(0, {max(cores)})
        yield pin
    finally:
        if pin:
            os.sched_setaffinity(0, cores)
