"""The device side of a pseudo-terminal pair: what a simulated serial device (tunnel, sensor) talks through.

The client side (:attr:`PtyLink.port`, e.g. ``/dev/pts/7``) is a raw byte pipe like a serial port
(no echo, no line editing), opened by the driver under test with pyserial.
"""

from __future__ import annotations

import errno
import fcntl
import logging
import os
import select
import time
import tty

log = logging.getLogger(__name__)


class PtyLink:
    """A raw pty pair; the simulator reads and writes the master side without blocking."""

    def __init__(self) -> None:
        self._master_fd, self._slave_fd = os.openpty()
        tty.setraw(self._slave_fd)
        flags = fcntl.fcntl(self._master_fd, fcntl.F_GETFL)
        fcntl.fcntl(self._master_fd, fcntl.F_SETFL, flags | os.O_NONBLOCK)
        self.port = os.ttyname(self._slave_fd)
        self.dropped_writes = 0

    def wait_readable(self, timeout_s: float) -> bool | None:
        """True when bytes wait, False after ``timeout_s``; None once the link is closed."""
        try:
            ready, _, _ = select.select([self._master_fd], [], [], timeout_s)
        except (OSError, ValueError):
            return None
        return bool(ready)

    def read(self, idle_s: float) -> bytes:
        """The bytes waiting (b"" if none); on a read error, wait ``idle_s`` and return b""."""
        try:
            return os.read(self._master_fd, 4096)
        except BlockingIOError:
            return b""
        except OSError as exc:  # EIO: no client has the slave open (we keep one, so rare)
            if exc.errno != errno.EIO:
                log.warning("simulated device on %s: read failed: %s", self.port, exc)
            time.sleep(idle_s)
            return b""

    def write(self, data: bytes) -> None:
        """Send ``data`` to the client; counted in :attr:`dropped_writes` when it cannot be sent."""
        try:
            os.write(self._master_fd, data)
        except OSError:  # nobody reads the other side and its buffer is full
            self.dropped_writes += 1

    def close(self) -> None:
        """Close both ends (idempotent)."""
        for fd in (self._master_fd, self._slave_fd):
            try:
                os.close(fd)
            except OSError:
                pass
        self._master_fd = self._slave_fd = -1
