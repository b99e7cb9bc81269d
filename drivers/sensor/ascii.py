"""A point sensor speaking a line protocol, polled (request/response) or streaming (config in YAML).

Default protocol (the simulated device speaks it; docs/sensor.md)::

    M?        -> D 152.307          poll: one reading, sensor units
    START     -> OK                 stream: then one line per sample ...
                 D 1234567 152.307     sensor-clock time (µs) and reading
                 T 1300000             a trigger pulse on the sensor clock
                 D 1234567 -----       no reading (out of range): a missing sample
    STOP      -> OK

Replies are regular expressions matched against the whole line: ``reply`` needs a group ``value``
and may have a group ``t`` (sensor clock, ``time_us_per_count`` µs per count). ``clock`` says
which time the samples carry: ``sensor`` (the ``t`` group; a line without it is a missing sample)
or ``host`` (stamped on arrival); ``auto`` is ``sensor`` in stream mode, ``host`` in poll mode.
``trigger_reply`` (group ``t``) reports sync pulses;
``invalid_reply`` marks a line as a missing sample; ``error_reply`` (group ``text``) a refusal.
"""

from __future__ import annotations

import logging
import math
import re
import time
from dataclasses import dataclass
from typing import Literal

from flagtrack.daemon.errors import DriverError
from flagtrack.drivers.sensor.base import HostClock, SensorInfo, SensorReading, reading
from flagtrack.drivers.sensor.poll import Poller, PollParams
from flagtrack.drivers.serial.adapter import SerialAdapter
from flagtrack.drivers.serial.lines import NUMBER, compile_pattern

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class AsciiSensorProtocol:
    """Commands and replies of a line-protocol sensor (config ``sensor.ascii``).

    Attributes:
        mode: ``poll`` (one request per sample) or ``stream`` (the sensor sends lines by itself).
        eol: line terminator, both ways.
        request: poll command.
        start_command, start_reply: sent at open in stream mode (``null``: none) and its reply.
        stop_command: sent at close in stream mode (``null``: none).
        reply: a sample line; group ``value`` (number), optional group ``t`` (sensor clock counts).
        trigger_reply: a trigger-pulse line, group ``t`` (``null``: the sensor reports none).
        invalid_reply: a line meaning "no reading" (a missing sample; optional group ``t``).
        error_reply: a refusal, group ``text``.
        clock: ``auto``, ``sensor`` or ``host`` (see the module docstring).
        time_us_per_count: µs per count of the ``t`` groups.
        time_wrap_counts: the sensor's counter wraps after this many counts (``null``: never).
        scale, offset: reading = value * scale + offset (sensor units).
        echo: the device (or an RS-485 adapter) echoes each command line.
    """

    mode: Literal["poll", "stream"] = "poll"
    eol: str = "\n"
    request: str = "M?"
    start_command: str | None = "START"
    start_reply: str | None = "OK"
    stop_command: str | None = "STOP"
    reply: str = rf"D (?:(?P<t>\d+) )?(?P<value>{NUMBER})"
    trigger_reply: str | None = r"T (?P<t>\d+)"
    invalid_reply: str = r"D (?:(?P<t>\d+) )?-+"
    error_reply: str = r"ERR (?P<text>.*)"
    clock: Literal["auto", "sensor", "host"] = "auto"
    time_us_per_count: float = 1.0
    time_wrap_counts: int | None = None
    scale: float = 1.0
    offset: float = 0.0
    echo: bool = False

    def __post_init__(self) -> None:
        if not self.eol or not self.eol.isascii():
            raise ValueError("eol must be a non-empty ASCII string")
        if "value" not in compile_pattern("reply", self.reply).groupindex:
            raise ValueError("reply must have a named group (?P<value>...)")
        trigger = self.trigger_reply
        if trigger is not None and "t" not in compile_pattern("trigger_reply", trigger).groupindex:
            raise ValueError("trigger_reply must have a named group (?P<t>...)")
        if "text" not in compile_pattern("error_reply", self.error_reply).groupindex:
            raise ValueError("error_reply must have a named group (?P<text>...)")
        compile_pattern("invalid_reply", self.invalid_reply)
        if self.time_us_per_count <= 0 or self.scale == 0:
            raise ValueError("time_us_per_count must be positive and scale non-zero")
        if self.stamps_time and "t" not in re.compile(self.reply).groupindex:
            raise ValueError("clock 'sensor' needs a group (?P<t>...) in reply")

    @property
    def stamps_time(self) -> bool:
        """True when samples carry the sensor's time (group ``t``), False when the host stamps them."""
        return self.clock == "sensor" or (self.clock == "auto" and self.mode == "stream")


class LineParser:
    """Turns reply lines into samples, trigger pulses or refusals (protocol ``p``)."""

    def __init__(self, p: AsciiSensorProtocol) -> None:
        self.p = p
        self._sensor_clock = p.stamps_time
        self._reply, self._invalid = re.compile(p.reply), re.compile(p.invalid_reply)
        self._trigger = re.compile(p.trigger_reply) if p.trigger_reply else None
        self._error = re.compile(p.error_reply)
        self._last_counts: int | None = None
        self._wraps = 0

    def parse(self, line: str) -> tuple[str, float, int | None]:
        """``(kind, value, t_us)``: kind ``sample`` (value NaN = no reading; ``t_us`` None when the host
        stamps), ``untimed`` (a sample without the sensor time the protocol promised), ``trigger``,
        ``error`` or ``other``."""
        if (m := self._invalid.fullmatch(line)) is not None:
            return self._sample(math.nan, m)
        if (m := self._reply.fullmatch(line)) is not None:
            return self._sample(float(m.group("value")) * self.p.scale + self.p.offset, m)
        if self._trigger is not None and (m := self._trigger.fullmatch(line)) is not None:
            return "trigger", math.nan, self._time(m)
        if self._error.fullmatch(line) is not None:
            return "error", math.nan, None
        return "other", math.nan, None

    def _sample(self, value: float, match: re.Match[str]) -> tuple[str, float, int | None]:
        if not self._sensor_clock:
            return "sample", value, None
        t_us = self._time(match)
        return ("sample", value, t_us) if t_us is not None else ("untimed", math.nan, None)

    def _time(self, match: re.Match[str]) -> int | None:
        raw = match.groupdict().get("t")
        if raw is None:
            return None
        counts = int(raw)
        wrap = self.p.time_wrap_counts
        if wrap is not None and self._last_counts is not None and counts < self._last_counts - wrap // 2:
            self._wraps += 1
        self._last_counts = counts
        return round((counts + self._wraps * (wrap or 0)) * self.p.time_us_per_count)


class AsciiSensor:
    """A :class:`~flagtrack.drivers.sensor.base.PointSensor` over a line protocol.

    Args:
        adapter: the serial line (owns the bytes).
        protocol: what the lines mean.
        poll: sampling rate and failure handling (``rate_hz`` is the expected rate in stream mode).
        units: unit of the readings.
    """

    def __init__(
        self,
        adapter: SerialAdapter,
        protocol: AsciiSensorProtocol = AsciiSensorProtocol(),
        poll: PollParams = PollParams(),
        units: str = "mm",
    ) -> None:
        self.adapter = adapter
        self.protocol = protocol
        self.poll = poll
        self.units = units
        self.device = adapter.device
        self.clock = HostClock()
        self.parser = LineParser(protocol)
        self._poller = Poller(self._exchange, poll, self.clock, self.device, sensor_clock=protocol.stamps_time)
        self._buffer = b""
        self._last_line_s = time.monotonic()
        self._last_stamp_us: int | None = None

    def open(self) -> SensorInfo:
        if self.protocol.mode == "stream" and self.protocol.start_command is not None:
            self._command(self.protocol.start_command, self.protocol.start_reply)
        self._last_line_s = time.monotonic()
        return SensorInfo(
            "ascii",
            self.device,
            self.units,
            "sensor" if self.protocol.stamps_time else "host",
            self.poll.rate_hz,
            {"mode": self.protocol.mode},
        )

    def read(self, timeout_s: float) -> SensorReading:
        if self.protocol.mode == "poll":
            return self._poller.read(timeout_s)
        return self._read_stream(timeout_s)

    def close(self) -> None:
        try:
            if self.protocol.mode == "stream" and self.protocol.stop_command is not None:
                self.adapter.write_line(self.protocol.stop_command)
        except DriverError as exc:
            log.debug("%s: stop command failed: %s", self.device, exc)
        finally:
            self.adapter.close()

    # -- poll --------------------------------------------------------------------------------

    def _exchange(self) -> tuple[float, int | None]:
        self.adapter.write_line(self.protocol.request)
        line = self._reply_line()
        kind, value, t_us = self.parser.parse(line)
        if kind == "sample":
            return value, t_us
        raise DriverError(f"unexpected reply {line!r} to {self.protocol.request!r}", device=self.device)

    def _reply_line(self) -> str:
        line = self.adapter.read_line()
        if self.protocol.echo:
            line = self.adapter.read_line()
        return line

    def _command(self, command: str, expected: str | None) -> None:
        """Send a command and, unless ``expected`` is None, wait for that reply (sample lines skipped)."""
        self.adapter.write_line(command)
        if expected is None:
            return
        pattern = re.compile(expected)
        deadline = time.monotonic() + max(self.adapter.timeout_s, 0.1)
        while time.monotonic() < deadline:
            line = self.adapter.read_line()
            if pattern.fullmatch(line):
                return
            if self.parser.parse(line)[0] == "error":
                raise DriverError(f"{command!r} refused: {line!r}", device=self.device)
        raise DriverError(f"no {expected!r} reply to {command!r}", device=self.device)

    # -- stream ------------------------------------------------------------------------------

    def _read_stream(self, timeout_s: float) -> SensorReading:
        silent_s = time.monotonic() - self._last_line_s
        if silent_s > self.poll.fail_after_s:
            self._last_line_s = time.monotonic()
            raise DriverError(f"the stream has been silent for {silent_s:.1f} s", device=self.device)
        lines = self._lines(max(0.0, min(timeout_s, self.poll.batch_s)))
        now_us = self.clock.now_us()
        samples: list[tuple[int | None, float]] = []
        triggers: list[int] = []
        untimed = 0
        for line in lines:
            kind, value, t_us = self.parser.parse(line)
            if kind == "sample":
                samples.append((t_us, value))
            elif kind == "untimed":
                untimed += 1
            elif kind == "trigger" and t_us is not None:
                triggers.append(t_us)
        if samples:
            self._last_line_s = time.monotonic()
        t_out, v_out, missing = self._stamp(samples, now_us)
        return reading(t_out, v_out, triggers, missing + untimed)

    def _stamp(self, samples: list[tuple[int | None, float]], now_us: int) -> tuple[list[int], list[float], int]:
        """Sample times (the sensor's, or the arrival time spread back at the nominal rate) and the
        missing count (NaN readings, and gaps longer than 1.5 periods)."""
        period_us = 1e6 / self.poll.rate_hz
        n = len(samples)
        times = [t if t is not None else round(now_us - (n - 1 - i) * period_us) for i, (t, _) in enumerate(samples)]
        values = [v for _, v in samples]
        missing = sum(math.isnan(v) for v in values)
        previous = self._last_stamp_us
        for t in times:
            if previous is not None and t - previous > 1.5 * period_us:
                missing += round((t - previous) / period_us) - 1
            previous = t
        self._last_stamp_us = previous
        return times, values, missing

    def _lines(self, budget_s: float) -> list[str]:
        """Complete lines received within ``budget_s`` (partial ones kept for the next call)."""
        port = self.adapter.serial
        eol = self.protocol.eol.encode("ascii")
        deadline = time.monotonic() + budget_s
        try:
            while True:
                port.timeout = max(0.0, deadline - time.monotonic())
                chunk = port.read(max(1, port.in_waiting))
                if chunk:
                    log.debug("%s -> %r", self.device, chunk)
                    self._buffer += chunk
                if eol in self._buffer or time.monotonic() >= deadline:
                    break
        except OSError as exc:
            raise DriverError(f"read failed: {exc}", device=self.device) from exc
        *complete, self._buffer = self._buffer.split(eol)
        if len(self._buffer) > 4096:
            self._buffer = b""
        return [raw.decode("ascii", errors="replace").strip() for raw in complete if raw.strip()]
