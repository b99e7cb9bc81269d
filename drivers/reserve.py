"""Room kept on a disk for the last writes after it filled up (standard library only).

The HDF5 library flushes what it holds when its file closes: with no room left that close fails
(h5py then prints a traceback per object as they are freed, and the process may crash). A recording
part therefore holds a hidden file of :data:`RESERVE_BYTES` next to its recording, given back just
before its files close, so the centreline file and the sidecar close whole; a sweep's run log keeps
one for its last records. A reserve is held open under an exclusive ``flock`` while it is taken: a
process killed outright leaves its file behind unlocked, and :func:`remove_stale_reserves` (run
where a new part starts) removes it.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from pathlib import Path

RESERVE_BYTES = 2 * 1024 * 1024
"""Room kept for closing a part that records centrelines (its HDF5 file), bytes."""

RESERVE_BYTES_RAW_ONLY = 64 * 1024
"""Room kept for closing a part without centrelines (its sidecar), bytes."""


class DiskReserve:
    """A file of ``size`` bytes at ``path`` (allocated on the disk, not sparse), held open and locked
    until :meth:`release` removes it."""

    def __init__(self, path: Path, size: int) -> None:
        self.path = path
        self.size = size
        self._fd: int | None = None

    def take(self) -> None:
        """Allocate the room (a leftover file of a crashed run, or a link, at ``path`` is replaced).

        Raises:
            OSError: the disk has not that much room (nothing is left at ``path``).
        """
        self.path.unlink(missing_ok=True)  # (a symbolic link: the link goes, never its target)
        fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)  # (held while open: the file is not stale)
            _allocate(fd, self.size)
        except OSError:
            os.close(fd)
            self.path.unlink(missing_ok=True)
            raise
        self._fd = fd

    def release(self) -> None:
        """Give the room back to the disk (idempotent; never raises)."""
        fd, self._fd = self._fd, None
        if fd is None:
            return
        with contextlib.suppress(OSError):
            if _names(self.path, fd):  # (not another process's file made since at the same path)
                self.path.unlink()
        os.close(fd)

    def leave(self) -> None:
        """Close the file and keep it on the disk, unlocked, for a later process (idempotent)."""
        fd, self._fd = self._fd, None
        if fd is not None:
            os.close(fd)


def remove_stale_reserves(folder: Path) -> list[Path]:
    """Remove the reserves in ``folder`` that no process holds (left by one killed outright); returns them."""
    removed = []
    for path in sorted(folder.glob(".*.reserve")):
        try:
            fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
        except OSError:  # gone meanwhile, a link, unreadable: not ours to judge
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            if _names(path, fd):
                path.unlink()
                removed.append(path)
        except OSError:  # held by a live process (or gone meanwhile)
            pass
        finally:
            os.close(fd)
    return removed


def _names(path: Path, fd: int) -> bool:
    """Whether ``path`` still names the file open as ``fd``."""
    try:
        here, held = path.lstat(), os.fstat(fd)
    except OSError:
        return False
    return (here.st_dev, here.st_ino) == (held.st_dev, held.st_ino)


def _allocate(fd: int, size: int) -> None:
    """Make the file's ``size`` bytes take room on the disk (zeros written where posix_fallocate is missing)."""
    if hasattr(os, "posix_fallocate"):
        os.posix_fallocate(fd, 0, size)
        return
    block = bytes(64 * 1024)
    for start in range(0, size, len(block)):
        os.write(fd, block[: min(len(block), size - start)])
