"""One owner per run: an exclusive ``flock`` on ``RUN_DIR/.lock``, holding who owns it.

The lock lives as long as the holder's open file (a killed holder releases it at once: the file
left behind locks nothing and the next owner takes it over). The file says who holds it (pid, host,
command line, since when), so a second supervisor is refused with one line naming the holder. An
orderly end (:meth:`RunLock.release`) removes the file, so a finished run folder holds none.

Removing a lock file races with a process that opened it just before: that process would lock the
removed file while a third makes a new one. So an owner checks, once it holds the ``flock``, that
the path still names the file it locked, and starts again if not.
"""

from __future__ import annotations

import fcntl
import json
import logging
import os
import socket
import time
from pathlib import Path
from types import TracebackType
from typing import IO

from flagtrack.daemon.errors import ConfigError

log = logging.getLogger(__name__)

LOCK_FILE = ".lock"
_ATTEMPTS, _RETRY_S = 5, 0.02  # an exclusive lock is tried this often, this far apart, before refusing


class RunLock:
    """The lock of one run folder; :meth:`acquire` it, :meth:`release` it (or use ``with``)."""

    def __init__(self, run_dir: Path, handle: IO[str]) -> None:
        self.run_dir = run_dir
        self._handle = handle

    @classmethod
    def acquire(cls, run_dir: str | Path, command: str) -> RunLock:
        """Lock ``run_dir`` (made if missing) for this process, ``command`` being what it runs.

        Raises:
            ConfigError: another process holds the run (the message names it), or the lock file
                cannot be made.
        """
        run_dir = Path(run_dir)
        path = run_dir / LOCK_FILE
        while True:  # again when the file was removed (an orderly end) between open and flock
            handle = _open_locked(run_dir, path)
            if _names(path, handle):
                break
            handle.close()
        handle.seek(0)
        handle.truncate()
        holder = {"pid": os.getpid(), "host": socket.gethostname(), "command": command, "since_unix": time.time()}
        handle.write(json.dumps(holder) + "\n")
        handle.flush()
        return cls(run_dir, handle)

    def release(self) -> None:
        """Remove the lock file and unlock (idempotent): the run is free, its folder holds no lock."""
        if not self._handle.closed:
            path = self.run_dir / LOCK_FILE
            try:
                if _names(path, self._handle):
                    path.unlink(missing_ok=True)  # still locked: whoever opens it now finds it removed
            except OSError as exc:  # a folder gone read-only: closing still frees the run
                log.warning("%s: left in place (%s); the run is free all the same", path, exc.strerror or exc)
            finally:
                self._handle.close()

    def __enter__(self) -> RunLock:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.release()


def held_by(run_dir: str | Path) -> str | None:
    """Who holds ``run_dir`` now (as :func:`describe_holder` says), or None when nobody does; nothing
    is made or changed (a command asks before it opens the rig; :meth:`RunLock.acquire` is the lock)."""
    try:
        handle = open(Path(run_dir) / LOCK_FILE, encoding="utf-8")  # noqa: SIM115 - closed below
    except OSError:
        return None  # no lock file: nobody holds it (or acquire will say why it cannot lock it)
    with handle:
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError:
            return describe_holder(handle.read())
        fcntl.flock(handle.fileno(), fcntl.LOCK_UN)
    return None


def _open_locked(run_dir: Path, path: Path) -> IO[str]:
    """``path`` opened (made if missing) and ``flock``-ed, or ConfigError naming its holder."""
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        handle = open(path, "a+", encoding="utf-8")  # noqa: SIM115 - closed by release()
    except OSError as exc:
        raise ConfigError(f"cannot lock the run folder: {exc.strerror or exc}", path=str(path)) from exc
    for attempt in range(_ATTEMPTS):  # (a moment: a probe of held_by may hold it shared)
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            break
        except OSError:
            if attempt + 1 < _ATTEMPTS:
                time.sleep(_RETRY_S)
    else:
        handle.seek(0)
        holder = describe_holder(handle.read())
        handle.close()
        raise ConfigError(f"the run is in use by {holder}; not started", path=str(run_dir)) from None
    return handle


def _names(path: Path, handle: IO[str]) -> bool:
    """Whether ``path`` is still the file ``handle`` has open (not removed or replaced)."""
    try:
        here, there = os.stat(path), os.fstat(handle.fileno())
    except FileNotFoundError:
        return False
    return (here.st_dev, here.st_ino) == (there.st_dev, there.st_ino)


def describe_holder(text: str) -> str:
    """``pid 12 on host lab1 (flagtrack supervisor -c rig.yaml) since 2026-11-25 18:02:11 UTC`` from the
    lock file's text (``another process`` when it cannot be read)."""
    try:
        holder = json.loads(text)
        since = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(float(holder["since_unix"])))
        return f"pid {int(holder['pid'])} on host {holder['host']} ({str(holder['command'])[:120]}) since {since}"
    except (ValueError, KeyError, TypeError):
        return "another process"
