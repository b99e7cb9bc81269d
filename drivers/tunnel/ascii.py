"""A fan controller that speaks a line protocol (commands and replies configurable in YAML).

The default protocol (documented in docs/tunnel.md; the simulated tunnel speaks it)::

    SET 5.00   -> OK            set-point, m/s
    GET?       -> SPD 4.98      measured speed, m/s
    STOP       -> OK            set-point zero, fan off
    PING       -> PONG          keep-alive (resets the controller's watchdog)
    FLT?       -> FLT NONE      fault text (NONE when healthy)
    any        -> ERR <text>    the controller refused the command

Commands are ``str.format`` templates (``{value}`` is the set-point in controller units,
``units_per_mps`` times the speed); replies are regular expressions matched against the whole
line. A reply of ``null`` means the controller does not answer that command.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from flagtrack.daemon.errors import DriverError
from flagtrack.drivers.serial.adapter import SerialAdapter
from flagtrack.drivers.serial.lines import NUMBER, compile_pattern


@dataclass(frozen=True)
class AsciiProtocol:
    """Commands and reply patterns of a line-protocol controller (config ``tunnel.ascii``).

    Attributes:
        eol: line terminator, both ways.
        units_per_mps: controller units per m/s for set-point and readback (1: m/s).
        set_command, query_command, stop_command, ping_command, fault_command: command templates
            (``fault_command: null`` when the controller has none; ``ping_command: null`` makes
            the keep-alive a speed query).
        set_reply, stop_reply, ping_reply: expected replies (regex; ``null``: none is sent).
        query_reply: regex with a group ``value``, the speed in controller units.
        fault_reply: regex with a group ``text``; texts in ``no_fault`` mean healthy.
        error_reply: regex with a group ``text`` for refusals.
        echo: the controller (or an RS-485 adapter) echoes each command line before replying.
    """

    eol: str = "\n"
    units_per_mps: float = 1.0
    set_command: str = "SET {value:.2f}"
    set_reply: str | None = "OK"
    query_command: str = "GET?"
    query_reply: str = rf"SPD (?P<value>{NUMBER})"
    stop_command: str = "STOP"
    stop_reply: str | None = "OK"
    ping_command: str | None = "PING"
    ping_reply: str | None = "PONG"
    fault_command: str | None = "FLT?"
    fault_reply: str = r"FLT (?P<text>.*)"
    no_fault: tuple[str, ...] = ("NONE", "0", "")
    error_reply: str = r"ERR (?P<text>.*)"
    echo: bool = False

    def __post_init__(self) -> None:
        if not self.eol or not self.eol.isascii():
            raise ValueError("eol must be a non-empty ASCII string")
        if self.units_per_mps <= 0:
            raise ValueError("units_per_mps must be positive")
        try:
            self.set_command.format(value=1.0)
        except (KeyError, IndexError, ValueError) as exc:
            raise ValueError(f"set_command {self.set_command!r} must format with {{value}}: {exc}") from None
        for name, group in (("query_reply", "value"), ("fault_reply", "text"), ("error_reply", "text")):
            if group not in compile_pattern(name, getattr(self, name)).groupindex:
                raise ValueError(f"{name} must have a named group (?P<{group}>...)")
        for name in ("set_reply", "stop_reply", "ping_reply"):
            if getattr(self, name) is not None:
                compile_pattern(name, getattr(self, name))


class AsciiTunnel:
    """The :class:`~flagtrack.drivers.tunnel.base.TunnelLink` of a line-protocol controller.

    Args:
        adapter: the serial line (owns the bytes).
        protocol: what the lines mean.
    """

    def __init__(self, adapter: SerialAdapter, protocol: AsciiProtocol = AsciiProtocol()) -> None:
        self.adapter = adapter
        self.protocol = protocol
        self.device = adapter.device
        self._error = re.compile(protocol.error_reply)

    @classmethod
    def open(
        cls, port: str, protocol: AsciiProtocol = AsciiProtocol(), *, baudrate: int = 9600, timeout_s: float = 0.5,
        parity: str = "N", stopbits: int = 1, bytesize: int = 8,
    ) -> AsciiTunnel:  # fmt: skip
        """Open ``port`` (device path or pyserial URL) with ``protocol``."""
        adapter = SerialAdapter(
            port, baudrate, timeout_s, protocol.eol.encode("ascii"),
            parity=parity, stopbits=stopbits, bytesize=bytesize,
        )  # fmt: skip
        return cls(adapter, protocol)

    def write_setpoint_mps(self, speed_mps: float) -> None:
        """``SET <value>``."""
        value = speed_mps * self.protocol.units_per_mps
        self._command(self.protocol.set_command.format(value=value), self.protocol.set_reply)

    def read_speed_mps(self) -> float:
        """``GET?`` -> speed, m/s."""
        match = self._ask(self.protocol.query_command, self.protocol.query_reply)
        try:
            return float(match.group("value")) / self.protocol.units_per_mps
        except ValueError as exc:
            raise DriverError(f"speed {match.group('value')!r} is not a number", device=self.device) from exc

    def stop(self) -> None:
        """``STOP``."""
        self._command(self.protocol.stop_command, self.protocol.stop_reply)

    def keep_alive(self) -> None:
        """``PING`` (or a speed query when the protocol has no ping)."""
        if self.protocol.ping_command is None:
            self.read_speed_mps()
        else:
            self._command(self.protocol.ping_command, self.protocol.ping_reply)

    def read_fault(self) -> str | None:
        """``FLT?`` -> fault text, ``None`` when healthy or when the protocol has no fault query."""
        if self.protocol.fault_command is None:
            return None
        match = self._ask(self.protocol.fault_command, self.protocol.fault_reply)
        text = match.group("text").strip()
        return None if text in self.protocol.no_fault else text

    def close(self) -> None:
        """Close the port."""
        self.adapter.close()

    def _command(self, command: str, reply: str | None) -> None:
        """Send ``command``; check its reply unless the protocol says none is sent."""
        if reply is None:
            self._send(command)
        else:
            self._ask(command, reply)

    def _ask(self, command: str, reply: str) -> re.Match[str]:
        """Send ``command``; return the match of its reply line against ``reply``."""
        self._send(command)
        line = self.adapter.read_line()
        error = self._error.fullmatch(line)
        if error:
            raise DriverError(f"controller refused {command!r}: {error.group('text')}", device=self.device)
        match = re.fullmatch(reply, line)
        if match is None:
            raise DriverError(f"unexpected reply {line!r} to {command!r} (expected /{reply}/)", device=self.device)
        return match

    def _send(self, command: str) -> None:
        self.adapter.write_line(command)
        if self.protocol.echo:
            echoed = self.adapter.read_line()
            if echoed != command:
                raise DriverError(f"expected the echo of {command!r}, got {echoed!r}", device=self.device)
