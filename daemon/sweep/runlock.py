"""One owner per run: an exclusive ``flock`` on ``RUN_DIR/.lock``, holding who owns it.

The lock lives as long as the holder's open file (a killed holder releases it at once: no stale
lock to clean up). The file says who holds it (pid, host, command line, since when), so a second
supervisor is refused with one line naming the holder.
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
import time
from pathlib import Path
from types import TracebackType
from typing import IO

from flagtrack.daemon.errors import ConfigError

LOCK_FILE = ".lock"


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
        try:
            run_dir.mkdir(parents=True, exist_ok=True)
            handle = open(path, "a+", encoding="utf-8")  # noqa: SIM115 - closed by release()
        except OSError as exc:
            raise ConfigError(f"cannot lock the run folder: {exc.strerror or exc}", path=str(path)) from exc
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.seek(0)
            holder = describe_holder(handle.read())
            handle.close()
            raise ConfigError(f"the run is in use by {holder}; not started", path=str(run_dir)) from None
        handle.seek(0)
        handle.truncate()
        holder = {"pid": os.getpid(), "host": socket.gethostname(), "command": command, "since_unix": time.time()}
        handle.write(json.dumps(holder) + "\n")
        handle.flush()
        return cls(run_dir, handle)

    def release(self) -> None:
        """Unlock (idempotent); the file stays, saying who held it last."""
        if not self._handle.closed:
            self._handle.close()

    def __enter__(self) -> RunLock:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.release()


def describe_holder(text: str) -> str:
    """``pid 12 on host lab1 (flagtrack supervisor -c rig.yaml) since 2026-11-25 18:02:11 UTC`` from the
    lock file's text (``another process`` when it cannot be read)."""
    try:
        holder = json.loads(text)
        since = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(float(holder["since_unix"])))
        return f"pid {int(holder['pid'])} on host {holder['host']} ({str(holder['command'])[:120]}) since {since}"
    except (ValueError, KeyError, TypeError):
        return "another process"
