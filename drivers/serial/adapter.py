"""The bytes of a line-oriented serial link: one ``_send`` / ``_recv`` pair that logs at DEBUG.

Opens anything pyserial opens: a device path (``/dev/ttyUSB0``), a pseudo-terminal of the
simulated tunnel (``/dev/pts/5``), or a URL (``loop://``, ``socket://host:port``, ``rfc2217://``).
Every failure is a :class:`DriverError` naming the port. A device path is opened exclusively
(pyserial's ``exclusive``: an advisory ``flock``): a second owner is refused with a line naming the
holder, so two programs never drive one tunnel.
"""

from __future__ import annotations

import errno
import logging
import os
import time

import serial

from flagtrack.daemon.errors import DriverError, PortInUseError
from flagtrack.drivers.serial.holder import port_holders

log = logging.getLogger(__name__)

try:  # pyserial's POSIX port flushes and configures through termios, whose errors are not OSErrors
    import termios

    _LINK_ERRORS: tuple[type[BaseException], ...] = (serial.SerialException, OSError, termios.error)
except ImportError:  # pragma: no cover - not POSIX
    _LINK_ERRORS = (serial.SerialException, OSError)


class SerialAdapter:
    """A serial port read and written in lines.

    Args:
        port: device path or pyserial URL.
        baudrate: bits per second.
        timeout_s: how long to wait for a whole reply line, s.
        eol: line terminator sent after each command and expected after each reply.
        port_obj: an already-open pyserial port (tests); ``port`` then only names it.
        parity, stopbits, bytesize: frame format (``N``/``E``/``O``, 1 or 2, 7 or 8).
    """

    def __init__(
        self,
        port: str,
        baudrate: int = 9600,
        timeout_s: float = 0.5,
        eol: bytes = b"\n",
        port_obj: serial.SerialBase | None = None,
        *,
        parity: str = "N",
        stopbits: int = 1,
        bytesize: int = 8,
    ) -> None:
        self.device = port
        self.eol = eol
        self.timeout_s = timeout_s
        self.last_sent_ns = 0  # wall time of the last write's flush, ns
        if port_obj is not None:
            self.serial = port_obj
            return
        exclusive = {} if "://" in port else {"exclusive": True}
        try:
            self.serial = serial.serial_for_url(
                port, baudrate=baudrate, timeout=timeout_s, write_timeout=timeout_s,
                parity=parity, stopbits=stopbits, bytesize=bytesize, **exclusive,
            )  # fmt: skip
        except (serial.SerialException, OSError, ValueError) as exc:
            if "exclusively lock" in str(exc):
                holders = "; ".join(port_holders(port)) or "a process this user cannot see"
                raise PortInUseError(f"port in use, held by {holders}; not opened", device=port) from exc
            raise DriverError(f"cannot open serial port: {_why_not_opened(exc)}", device=port) from exc

    def _send(self, data: bytes) -> None:
        """Write ``data`` as is (after dropping unread input, so replies stay aligned)."""
        log.debug("%s <- %r", self.device, data)
        try:
            self.serial.reset_input_buffer()
            self.serial.write(data)
            self.serial.flush()
            self.last_sent_ns = time.time_ns()  # (the latency of a control loop ends here)
        except _LINK_ERRORS as exc:  # a pty whose other end closed: EIO from tcflush
            raise DriverError(f"write failed: {exc}", device=self.device) from exc

    def _recv(self) -> bytes:
        """Read one line (terminator removed); DriverError when none arrives within the timeout."""
        try:
            data = self.serial.read_until(self.eol)
        except _LINK_ERRORS as exc:
            raise DriverError(f"read failed: {exc}", device=self.device) from exc
        log.debug("%s -> %r", self.device, data)
        if not data.endswith(self.eol):
            got = f" (got {data!r})" if data else ""
            raise DriverError(f"no reply within {self.timeout_s:g} s{got}", device=self.device)
        return data[: -len(self.eol)]

    def write_line(self, line: str) -> None:
        """Send ``line`` followed by the terminator."""
        self._send(line.encode("ascii") + self.eol)

    def read_line(self) -> str:
        """Receive one reply line as text (stripped of surrounding white space)."""
        data = self._recv()
        try:
            return data.decode("ascii").strip()
        except UnicodeDecodeError as exc:
            raise DriverError(f"reply is not ASCII: {data!r}", device=self.device) from exc

    def close(self) -> None:
        """Close the port (idempotent)."""
        try:
            self.serial.close()
        except _LINK_ERRORS as exc:  # pragma: no cover - closing a dead port
            log.debug("%s: close failed: %s", self.device, exc)


def _why_not_opened(exc: BaseException) -> str:
    """Why a port did not open, in a few words (pyserial's own text repeats the port and the errno)."""
    code = getattr(exc, "errno", None)
    if code == errno.ENOENT:
        return "no such device (is it plugged in? docs/first-day.md: the udev rule names it)"
    if code in (errno.EACCES, errno.EPERM):
        return "permission denied (the user must be in the 'dialout' group: docs/first-day.md)"
    if isinstance(code, int):
        return os.strerror(code).lower()
    if "Could not configure port" in str(exc):
        return "not a serial port (it does not take a serial port's settings)"
    return str(exc)
