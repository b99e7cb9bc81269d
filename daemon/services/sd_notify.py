"""systemd's notify protocol from the services' own loops: READY, WATCHDOG, STATUS, STOPPING.

Each service calls :func:`beat` from the loop that does its work. The process tells systemd it is
ready once every service of the group has beaten once, and pings the watchdog (``WATCHDOG=1``, every
half of ``$WATCHDOG_USEC``) only when every service has beaten since the last ping, so one hung loop
stops the pings and systemd (``WatchdogSec``) kills and restarts the process. Messages go to
``$NOTIFY_SOCKET`` (a path, or ``@name`` in the abstract namespace) as single datagrams; without it
(a terminal, a test) everything here is a no-op.

Written with the socket module (about 30 lines) rather than a dependency: the PyPI ``sdnotify`` is
unmaintained and ``systemd-python`` needs libsystemd's headers to build.
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence

log = logging.getLogger(__name__)

STATUS_INTERVAL_S = 5.0  # STATUS= at most this often when systemd does not ask for watchdog pings


def notify_address(env: Mapping[str, str] = os.environ) -> str | bytes | None:
    """The socket address of ``$NOTIFY_SOCKET`` (abstract names start with ``@``), or None."""
    name = env.get("NOTIFY_SOCKET", "")
    if not name:
        return None
    if name.startswith("@"):
        return b"\0" + name[1:].encode()
    return name if name.startswith("/") else None  # vsock and other schemes: not for a lab PC


def watchdog_interval_s(env: Mapping[str, str] = os.environ) -> float | None:
    """Half of ``$WATCHDOG_USEC`` (systemd's advice), if it is meant for this process; else None."""
    usec, pid = env.get("WATCHDOG_USEC", ""), env.get("WATCHDOG_PID", "")
    if not (usec.isascii() and usec.isdigit()) or int(usec) == 0 or (pid and pid != str(os.getpid())):
        return None
    return int(usec) / 2e6


class Notifier:
    """Sends datagrams to systemd's notify socket; a no-op without one. Never raises."""

    def __init__(self, address: str | bytes | None) -> None:
        self.address = address
        self.sent = 0
        self._sock: socket.socket | None = None
        if address is not None:
            self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.setblocking(False)

    def send(self, message: str) -> bool:
        """Send one notification (``KEY=value`` lines); False if there is nowhere to send it or it failed."""
        if self._sock is None or self.address is None:
            return False
        try:
            self._sock.sendto(message.encode(), self.address)
        except OSError as exc:  # systemd gone or its queue full: the service goes on; systemd decides
            log.debug("sd_notify: %s", exc)
            return False
        self.sent += 1
        return True

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None


class Watchdog:
    """READY once every service has beaten, then a ping whenever all have beaten again.

    Args:
        names: the services whose loops must beat.
        send: where messages go (:meth:`Notifier.send`).
        interval_s: the ping period (half of ``WatchdogSec``), or None for no pings (STATUS only).
        clock: monotonic seconds.
    """

    def __init__(
        self,
        names: Sequence[str],
        send: Callable[[str], object],
        interval_s: float | None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.names = list(dict.fromkeys(names))
        self.send = send
        self.interval_s = interval_s
        self.clock = clock
        self.ready = False
        self.stopped = False
        self.pings = 0
        self._status: dict[str, str] = {}
        self._fresh: set[str] = set()
        self._last_s = -float("inf")
        self._lock = threading.Lock()

    def beat(self, name: str, status: str = "") -> None:
        """Service ``name``'s loop is alive (``status``: its figures, for ``systemctl status``)."""
        with self._lock:
            if self.stopped or name not in self.names:
                return
            self._fresh.add(name)
            if status:
                self._status[name] = status
            if len(self._fresh) < len(self.names):
                return
            now = self.clock()
            period = self.interval_s if self.interval_s is not None else STATUS_INTERVAL_S
            if self.ready and now - self._last_s < period:
                return
            lines = [] if self.ready else ["READY=1"]
            if self.interval_s is not None:
                lines.append("WATCHDOG=1")
            text = "; ".join(f"{n}: {self._status[n]}" for n in self.names if n in self._status)
            if text:
                lines.append(f"STATUS={text}")
            self.send("\n".join(lines))
            self.ready, self._last_s, self.pings = True, now, self.pings + (self.interval_s is not None)
            self._fresh.clear()

    def awaits(self, name: str) -> bool:
        """Whether the next ping needs a new beat of ``name`` (its last beat has been pinged for)."""
        with self._lock:
            return name in self.names and name not in self._fresh

    def retire(self, name: str) -> None:
        """Service ``name`` has ended (its work done): the others' beats alone keep the pings going."""
        with self._lock:
            if name in self.names:
                self.names.remove(name)
                self._fresh.discard(name)
                self._status.pop(name, None)

    def stopping(self) -> None:
        """Say the process is stopping (``STOPPING=1``); no more pings after this."""
        with self._lock:
            if not self.stopped:
                self.stopped = True
                self.send("STOPPING=1")


_current: Watchdog | None = None


def beat(name: str, status: str = "") -> None:
    """Tell the process's watchdog that service ``name``'s loop is alive; a no-op outside a runner."""
    watchdog = _current
    if watchdog is not None:
        watchdog.beat(name, status)


def retire(name: str) -> None:
    """Service ``name`` of this process has ended; a no-op outside a runner."""
    watchdog = _current
    if watchdog is not None:
        watchdog.retire(name)


@contextlib.contextmanager
def watching(names: Sequence[str], env: Mapping[str, str] = os.environ) -> Iterator[Watchdog | None]:
    """While inside, :func:`beat` of these services reaches systemd (None: no ``$NOTIFY_SOCKET``);
    ``STOPPING=1`` on the way out (or sooner, :meth:`Watchdog.stopping`)."""
    global _current
    address = notify_address(env)
    if address is None:
        yield None
        return
    notifier = Notifier(address)
    watchdog = Watchdog(names, notifier.send, watchdog_interval_s(env))
    previous, _current = _current, watchdog
    try:
        yield watchdog
    finally:
        _current = previous
        watchdog.stopping()
        notifier.close()
