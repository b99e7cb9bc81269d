"""Process-wide settings, applied once by ``flagtrack``'s ``main`` before a command runs."""

from __future__ import annotations

import ctypes
import os
import sys

_SWITCH_INTERVAL_S = 0.0005
# glibc mallopt parameters: M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD (the largest it takes, 32 MB)
_MALLOC_SETTINGS = ((-1, 256 << 20), (-2, 16 << 20), (-3, 32 << 20))


def keep_freed_memory() -> bool:
    """Ask glibc's allocator to keep freed memory for reuse rather than hand it back to the OS at once.

    Live services allocate and free the same few arrays for every packet; glibc's defaults return
    freed memory early and map growing arrays afresh, so each packet page-faults again (figures in
    docs/live.md). The heap then keeps up to 256 MB free for reuse. Returns whether the settings took
    (False without glibc, or when the user set glibc's allocator through ``MALLOC_*`` or
    ``GLIBC_TUNABLES``: nothing changes).
    """
    if any(name.startswith("MALLOC_") for name in os.environ) or "glibc.malloc" in os.environ.get("GLIBC_TUNABLES", ""):
        return False
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    return all(mallopt(param, value) == 1 for param, value in _MALLOC_SETTINGS)


def tune_process() -> None:
    """Settings that the live services need and every command can live with.

    Zenoh delivers on its own threads, which need the GIL to queue a message; with Python's default
    5 ms switch interval a busy service thread would hold messages back for up to 5 ms. Freed memory
    is kept for reuse (:func:`keep_freed_memory`).
    """
    sys.setswitchinterval(min(sys.getswitchinterval(), _SWITCH_INTERVAL_S))
    keep_freed_memory()
