"""A simulated point sensor on a real pseudo-terminal: the ASCII protocol (poll or stream) or a Modbus RTU slave.

Like :class:`~flagtrack.drivers.tunnel.simulated.SimulatedTunnel`, it opens a pty pair
(:class:`~flagtrack.drivers.serial.pty_link.PtyLink`), gives the client side's path as
:attr:`SimulatedSensorDevice.port` and answers from a thread; lines and Modbus RTU frames are split
as the simulated tunnel splits them. The reading comes from ``signal(t_us)``
on the device's own clock (µs since start plus ``clock_offset_us``). Faults for tests:
``inject(mute=True)`` (nothing answered or sent), ``inject(out_of_range=True)`` (every reading invalid).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from types import TracebackType
from typing import Literal

from flagtrack.drivers.sensor.modbus import ModbusSensorMap
from flagtrack.drivers.serial import modbus_rtu as rtu
from flagtrack.drivers.serial.lines import split_lines
from flagtrack.drivers.serial.pty_link import PtyLink

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DeviceParams:
    """The simulated device.

    Attributes:
        protocol: ``ascii`` (docs/sensor.md default protocol) or ``modbus``.
        rate_hz: samples per second in stream mode.
        trigger_period_ms: stream mode: a ``T <t>`` line every period on the device clock (0: none).
        clock_offset_us: the device clock at start, µs.
        modbus: register map (protocol ``modbus``).
        tick_s: how often the serving thread wakes up.
    """

    protocol: Literal["ascii", "modbus"] = "ascii"
    rate_hz: float = 1000.0
    trigger_period_ms: float = 0.0
    clock_offset_us: int = 0
    modbus: ModbusSensorMap = field(default_factory=ModbusSensorMap)
    tick_s: float = 0.002


class SimulatedSensorDevice:
    """A simulated sensor answering on a pseudo-terminal from a background thread.

    Args:
        params: protocol and timing.
        signal: the reading (sensor units, NaN = out of range) at a device-clock time (µs).
    """

    def __init__(
        self, params: DeviceParams = DeviceParams(), signal: Callable[[int], float] = lambda t_us: 100.0
    ) -> None:
        self.params = params
        self.signal = signal
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._mute = False
        self._out_of_range = False
        self._streaming = False
        self._buffer = b""
        self._next_sample_us = 0.0  # float: the sample period need not be whole microseconds
        self._next_pulse_us = 0.0
        self.requests = 0
        self._mono0_ns = time.monotonic_ns()
        self._link = PtyLink()
        self.port = self._link.port
        self._thread = threading.Thread(target=self._serve, name=f"simulated sensor {self.port}", daemon=True)

    def now_us(self) -> int:
        """The device clock, µs."""
        return (time.monotonic_ns() - self._mono0_ns) // 1000 + self.params.clock_offset_us

    def start(self) -> SimulatedSensorDevice:
        """Start answering; return self."""
        if not self._thread.is_alive():
            self._thread.start()
        return self

    def inject(self, *, mute: bool | None = None, out_of_range: bool | None = None) -> None:
        """Switch faults on or off (``None`` leaves one unchanged)."""
        with self._lock:
            if mute is not None:
                self._mute = mute
            if out_of_range is not None:
                self._out_of_range = out_of_range

    def close(self) -> None:
        """Stop the thread and close both ends of the pty (idempotent)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        self._link.close()

    def __enter__(self) -> SimulatedSensorDevice:
        return self.start()

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

    # -- serving -----------------------------------------------------------------------------

    def _serve(self) -> None:
        while not self._stop.is_set():
            ready = self._link.wait_readable(self.params.tick_s)
            if ready is None:
                return
            data = self._link.read(self.params.tick_s) if ready else b""
            with self._lock:
                if self._mute:
                    self._buffer = b""
                    self._next_sample_us = self._next_pulse_us = 0
                    continue
                out = self._modbus(data) if self.params.protocol == "modbus" else self._ascii(data)
                if self._streaming:
                    out += self._stream_lines()
            if out:
                self._link.write(out)

    def _reading(self, t_us: int) -> float:
        value = self.signal(t_us)
        return math.nan if self._out_of_range else value

    def _ascii(self, data: bytes) -> bytes:
        lines, self._buffer, _ = split_lines(self._buffer + data)  # an overlong line is dropped silently
        self.requests += len(lines)
        return b"".join(self._answer(line).encode("ascii") + b"\n" for line in lines)

    def _answer(self, line: str) -> str:
        command = line.upper()
        if command == "M?":
            value = self._reading(self.now_us())
            return "D -----" if math.isnan(value) else f"D {value:.4f}"
        if command == "START":
            self._streaming = True
            now = self.now_us()
            self._next_sample_us, self._next_pulse_us = now, now
            return "OK"
        if command == "STOP":
            self._streaming = False
            return "OK"
        return f"ERR unknown command {line!r}"

    def _stream_lines(self) -> bytes:
        now = self.now_us()
        period_us = 1e6 / self.params.rate_hz
        lines = []
        if self._next_sample_us == 0:
            self._next_sample_us = self._next_pulse_us = now
        while self._next_sample_us <= now:
            t = round(self._next_sample_us)
            value = self._reading(t)
            lines.append(f"D {t} -----" if math.isnan(value) else f"D {t} {value:.4f}")
            self._next_sample_us += period_us
        if self.params.trigger_period_ms > 0:
            while self._next_pulse_us <= now:
                lines.append(f"T {round(self._next_pulse_us)}")
                self._next_pulse_us += self.params.trigger_period_ms * 1000
        return "".join(line + "\n" for line in lines).encode("ascii")

    def _modbus(self, data: bytes) -> bytes:
        frames, self._buffer = rtu.split_frames(self._buffer + data)
        out = []
        for frame in frames:
            try:
                request = rtu.parse_request(frame)
            except ValueError:  # a bad frame: resynchronise, dropping what follows it
                self._buffer = b""
                break
            if request.device_id != self.params.modbus.device_id:
                continue
            self.requests += 1
            out.append(self._registers(request))
        return b"".join(out)

    def _registers(self, request: rtu.Request) -> bytes:
        m = self.params.modbus
        kind = {rtu.READ_INPUT: "input", rtu.READ_HOLDING: "holding"}.get(request.function)
        if kind is None:
            return rtu.exception_response(request.device_id, request.function, rtu.ILLEGAL_FUNCTION)
        if kind != m.kind or request.address != m.register or request.count != m.words:
            return rtu.exception_response(request.device_id, request.function, rtu.ILLEGAL_ADDRESS)
        value = self._reading(self.now_us())
        if math.isnan(value):
            counts = m.invalid_counts[0] if m.invalid_counts else (1 << (16 * m.words)) - 1
        else:
            counts = round((value - m.offset) / m.scale) % (1 << (16 * m.words))
        words = [counts] if m.words == 1 else [counts >> 16, counts & 0xFFFF]
        if m.word_order == "little":
            words.reverse()
        return rtu.read_response(request, words)
