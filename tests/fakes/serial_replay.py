"""Replay a serial device's side of a protocol, in the manner of pymeasure's ``expected_protocol``.

The driver under test talks to a pyserial ``loop://`` port (:class:`ReplayPort`) whose writes are
checked against the expected requests, pair by pair, and whose reads give the paired responses::

    with expected_protocol([(b"GET?\\n", b"SPD 4.98\\n")]) as replay:
        tunnel = AsciiTunnel(SerialAdapter("loop://", port_obj=replay.open_port()))
        assert tunnel.read_speed_mps() == 4.98
    # leaving the block: every pair was used, or the test fails naming the first one that was not

A write that is not the next expected request fails at once (AssertionError naming the pair and both
byte strings) and again when the block ends, should the driver have swallowed the first failure. A
response of ``None`` (or ``b""``) means the device does not answer that request.

A driver that opens its port by name (pymodbus's client does) is given :attr:`SerialReplay.url`,
``replay://N``: pyserial's ``serial_for_url`` opens it with the driver's own settings through the
handler module :mod:`tests.fakes.protocol_replay` (pyserial's documented way to add URL schemes).
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from urllib.parse import urlsplit

import serial
from serial.serialutil import SerialException, iterbytes, to_bytes
from serial.urlhandler import protocol_loop

Pair = tuple[bytes, bytes | None]

HANDLER_PACKAGE = "tests.fakes"  # holds protocol_replay, the handler of replay:// URLs
if HANDLER_PACKAGE not in serial.protocol_handler_packages:
    serial.protocol_handler_packages.append(HANDLER_PACKAGE)

_OPEN: dict[str, SerialReplay] = {}  # replay:// name -> script
_NAMES = itertools.count(1)


class ReplayError(AssertionError):
    """The driver's bytes differ from the expected protocol."""


class SerialReplay:
    """The expected protocol: (request, response) pairs, used in order.

    Args:
        pairs: what the driver must write, and what the device answers (``None``: no answer).
    """

    def __init__(self, pairs: Sequence[Pair]) -> None:
        self.pairs = [(bytes(request), bytes(response or b"")) for request, response in pairs]
        self.used = 0  # pairs whose request has been written in full
        self.failure: str | None = None
        self._pending = b""  # the start of the next request, written so far
        self._lock = threading.Lock()
        self._ports: list[ReplayPort] = []
        self.name = str(next(_NAMES))
        _OPEN[self.name] = self

    @property
    def url(self) -> str:
        """The pyserial URL of this replay, for drivers that open a port by name."""
        return f"replay://{self.name}"

    def open_port(self, timeout_s: float = 0.1) -> ReplayPort:
        """An open port speaking this replay (reads time out after ``timeout_s``), as a driver opening
        :attr:`url` gets it."""
        return serial.serial_for_url(self.url, timeout=timeout_s, write_timeout=timeout_s)

    def bind(self, port: ReplayPort) -> None:
        self._ports.append(port)

    def device_sends(self, data: bytes) -> None:
        """Bytes the device sends unasked, now (a reply that comes too late, a line it streams)."""
        for port in self._ports:
            port.receive(data)

    def written(self, data: bytes) -> bytes:
        """Check ``data`` (written by the driver) against the next requests; return their responses."""
        with self._lock:
            if self.failure is not None:
                raise ReplayError(self.failure)
            self._pending += data
            out = b""
            while self._pending:
                if self.used == len(self.pairs):
                    self._fail(f"after all {len(self.pairs)} pairs, the driver wrote {_show(self._pending)}")
                request, response = self.pairs[self.used]
                if request.startswith(self._pending) and len(self._pending) < len(request):
                    break  # the rest of the request is still to come
                if not self._pending.startswith(request):
                    self._fail(
                        f"pair {self.used}: the driver wrote {_show(self._pending[: len(request)])}, "
                        f"expected {_show(request)}"
                    )
                self._pending = self._pending[len(request) :]
                self.used += 1
                out += response
            return out

    def _fail(self, message: str) -> None:
        self.failure = message
        raise ReplayError(message)

    def verify(self) -> None:
        """Raise ReplayError unless every pair was used, in order, and nothing else was written."""
        if self.failure is not None:
            raise ReplayError(self.failure)
        if self._pending:
            request = self.pairs[self.used][0]
            raise ReplayError(f"pair {self.used}: the driver wrote only {_show(self._pending)} of {_show(request)}")
        if self.used < len(self.pairs):
            raise ReplayError(
                f"pair {self.used} of {len(self.pairs)} not used: the driver never wrote "
                f"{_show(self.pairs[self.used][0])}"
            )

    def close(self) -> None:
        """Forget the URL and close the ports the driver left open."""
        _OPEN.pop(self.name, None)
        for port in self._ports:
            port.close()


class ReplayPort(protocol_loop.Serial):
    """pyserial's ``loop://`` port, except that what is written is checked by a :class:`SerialReplay`
    and its responses (not the written bytes) come back to the reader."""

    replay: SerialReplay | None = None

    def from_url(self, url: str) -> None:
        parts = urlsplit(url)
        if parts.scheme != "replay" or parts.netloc not in _OPEN:
            raise SerialException(f"{url!r} is no open replay (expected replay://N of a SerialReplay)")
        self.replay = _OPEN[parts.netloc]
        self.replay.bind(self)

    def write(self, data: bytes) -> int:
        if not self.is_open or self.replay is None:
            raise serial.PortNotOpenError()
        data = to_bytes(data)
        self.receive(self.replay.written(data))
        return len(data)

    def receive(self, data: bytes) -> None:
        """Put ``data`` in the receive queue at once (the loop's own write would pace it at the baud rate)."""
        if self.is_open:
            for byte in iterbytes(data):
                self.queue.put_nowait(byte)


def _show(data: bytes) -> str:
    """``repr(data)``, and its hex digits when it is not text (a Modbus frame)."""
    text = all(32 <= byte < 127 or byte in b"\r\n\t" for byte in data)
    return repr(data) if text else f"{data!r} ({data.hex(' ')})"


@contextmanager
def expected_protocol(pairs: Sequence[Pair]) -> Iterator[SerialReplay]:
    """A :class:`SerialReplay` of ``pairs``; checks at the end of the block that every pair was used."""
    replay = SerialReplay(pairs)
    try:
        yield replay
    except Exception as exc:
        if replay.failure is not None and not isinstance(exc, ReplayError):
            raise ReplayError(replay.failure) from exc  # what the driver made of the mismatch is secondary
        raise
    finally:
        replay.close()
    replay.verify()
