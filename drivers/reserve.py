"""Room kept on a disk for the last writes after it filled up (standard library only).

The HDF5 library flushes what it holds when its file closes: with no room left that close fails
(h5py then prints a traceback per object as they are freed, and the process may crash). A recording
part therefore holds a hidden file of :data:`RESERVE_BYTES` next to its recording, given back just
before its files close, so the centreline file and the sidecar close whole; a sweep's run log keeps
one for its last records. A process killed outright leaves its reserve behind (hidden, and replaced
by the next one made at the same path).
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

RESERVE_BYTES = 2 * 1024 * 1024
"""Room kept for closing a part that records centrelines (its HDF5 file), bytes."""

RESERVE_BYTES_RAW_ONLY = 64 * 1024
"""Room kept for closing a part without centrelines (its sidecar), bytes."""


class DiskReserve:
    """A file of ``size`` bytes at ``path`` (allocated on the disk, not sparse), removed by :meth:`release`."""

    def __init__(self, path: Path, size: int) -> None:
        self.path = path
        self.size = size
        self.held = False

    def take(self) -> None:
        """Allocate the room (a leftover file of a crashed run, or a link, at ``path`` is replaced).

        Raises:
            OSError: the disk has not that much room (nothing is left at ``path``).
        """
        self.path.unlink(missing_ok=True)  # (a symbolic link: the link goes, never its target)
        fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o600)
        try:
            _allocate(fd, self.size)
        except OSError:
            os.close(fd)
            self.path.unlink(missing_ok=True)
            raise
        os.close(fd)
        self.held = True

    def release(self) -> None:
        """Give the room back to the disk (idempotent; never raises)."""
        if self.held:
            self.held = False
            with contextlib.suppress(OSError):
                self.path.unlink()


def _allocate(fd: int, size: int) -> None:
    """Make the file's ``size`` bytes take room on the disk (zeros written where posix_fallocate is missing)."""
    if hasattr(os, "posix_fallocate"):
        os.posix_fallocate(fd, 0, size)
        return
    block = bytes(64 * 1024)
    for start in range(0, size, len(block)):
        os.write(fd, block[: min(len(block), size - start)])
