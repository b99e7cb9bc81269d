"""The folders a batch writes into: one batch at a time in each, and what a killed batch left removed."""

from __future__ import annotations

import fcntl
import glob
import logging
import os
from collections.abc import Iterable
from pathlib import Path
from types import TracebackType

from flagtrack.daemon.errors import ConfigError

log = logging.getLogger(__name__)

LOCK_NAME = ".flagtrack-batch.lock"


class FolderLock:
    """An exclusive ``flock`` on ``FOLDER/.flagtrack-batch.lock`` while a batch writes into ``folder``.

    The lock goes with the process (a killed batch holds none), so finding another batch's lock means
    that batch is running; its unfinished temporary files must then be left alone.

    Raises:
        ConfigError: another batch holds the lock (on entering).
    """

    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder)
        self._fd: int | None = None

    def __enter__(self) -> FolderLock:
        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / LOCK_NAME
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise ConfigError(
                f"another flagtrack batch is writing into {self.folder} (it holds {path}): wait for it, "
                "or give another output folder",
                key="-o",
            ) from None
        except OSError as exc:  # a file system without locks (ENOLCK, EOPNOTSUPP: some FUSE mounts)
            log.warning("%s: cannot lock (%s): make sure one batch at a time writes here", path, exc.strerror)
        self._fd = fd
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self._fd is not None:
            os.close(self._fd)  # releases the lock; the empty file stays (removing it would race a waiter)
            self._fd = None


def remove_partial_outputs(outputs: Iterable[Path]) -> list[Path]:
    """Remove the temporary files an interrupted batch left beside ``outputs`` (call with the folder locked).

    An atomic centreline file is written as ``.<name>.<12 hex>.tmp`` in the output's folder and renamed
    at its end (:class:`~flagtrack.drivers.formats.centreline.CentrelineSink`); one still there belongs
    to a process that was killed. Returns the files removed.
    """
    removed = []
    for output in outputs:
        for leftover in output.parent.glob(f".{glob.escape(output.name)}.*.tmp"):
            leftover.unlink(missing_ok=True)
            removed.append(leftover)
    return removed
