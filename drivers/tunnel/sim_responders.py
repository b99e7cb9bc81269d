"""What the simulated tunnel answers: the default ASCII protocol and a Modbus RTU drive.

A responder takes the bytes received since the last call and returns the bytes to send back,
acting on a :class:`~flagtrack.drivers.tunnel.sim_model.TunnelModel`. Only valid commands feed
the model's watchdog.
"""

from __future__ import annotations

import logging
from typing import Protocol

from flagtrack.drivers.serial import modbus_rtu as rtu
from flagtrack.drivers.serial.lines import split_lines
from flagtrack.drivers.tunnel.modbus import ModbusMap
from flagtrack.drivers.tunnel.sim_model import WATCHDOG_FAULT, TunnelModel

log = logging.getLogger(__name__)

WATCHDOG_FAULT_CODE = 1  # fault register value of the simulated drive after a watchdog trip
OTHER_FAULT_CODE = 2


class Responder(Protocol):
    """Turns received bytes into reply bytes."""

    def feed(self, data: bytes, now_s: float) -> bytes:
        """Consume ``data`` received at ``now_s``; return what to send back (may be empty)."""
        ...


class AsciiResponder:
    """The default line protocol of docs/tunnel.md (``SET``, ``GET?``, ``STOP``, ``PING``, ``FLT?``)."""

    def __init__(self, model: TunnelModel) -> None:
        self.model = model
        self._buffer = b""

    def feed(self, data: bytes, now_s: float) -> bytes:
        lines, self._buffer, overflow = split_lines(self._buffer + data)
        out = [self.answer(line, now_s).encode("ascii") + b"\n" for line in lines]
        if overflow:
            out.append(b"ERR line too long\n")
        return b"".join(out)

    def answer(self, line: str, now_s: float) -> str:
        """The reply line to one command line."""
        words = line.split()
        command, args = words[0].upper(), words[1:]
        model = self.model
        if command == "SET" and len(args) == 1:
            try:
                model.set_setpoint(float(args[0]))
            except ValueError:
                return f"ERR bad set-point {args[0]!r} (0..{model.params.max_speed_mps:g} m/s)"
            reply = "OK"
        elif command == "GET?" and not args:
            reply = f"SPD {model.speed_mps:.3f}"
        elif command == "STOP" and not args:
            model.stop()
            reply = "OK"
        elif command == "PING" and not args:
            reply = "PONG"
        elif command == "FLT?" and not args:
            reply = f"FLT {model.fault or 'NONE'}"
        else:
            return f"ERR unknown command {line!r}"
        model.touch(now_s)
        return reply


class ModbusResponder:
    """A variable-frequency drive with the register map ``modbus_map`` (RTU framing).

    Frames addressed to another device are ignored; broadcasts (id 0) are acted on silently.
    A partial frame left for more than ``gap_s`` is dropped (resynchronisation).
    """

    def __init__(self, model: TunnelModel, modbus_map: ModbusMap = ModbusMap(), gap_s: float = 0.05) -> None:
        self.model = model
        self.map = modbus_map
        self.gap_s = gap_s
        self._buffer = b""
        self._last_rx_s = 0.0
        self._setpoint_counts = round(model.setpoint_mps / modbus_map.mps_per_hz / modbus_map.setpoint_hz_per_count)

    def feed(self, data: bytes, now_s: float) -> bytes:
        if self._buffer and now_s - self._last_rx_s > self.gap_s:
            self._buffer = b""
        if data:
            self._buffer += data
            self._last_rx_s = now_s
        frames, self._buffer = rtu.split_frames(self._buffer)
        out = []
        for frame in frames:
            reply = self._answer(frame, now_s)
            if reply is None:  # a bad frame: resynchronise, dropping what follows it
                self._buffer = b""
                break
            out.append(reply)
        return b"".join(out)

    def _answer(self, frame: bytes, now_s: float) -> bytes | None:
        """The reply to one frame (may be empty); None for a frame that does not parse."""
        try:
            request = rtu.parse_request(frame)
        except ValueError as exc:
            log.debug("simulated drive: dropped frame %r: %s", frame, exc)
            return None
        if request.device_id not in (0, self.map.device_id):
            return b""
        reply, valid = self._execute(request)
        if valid:
            self.model.touch(now_s)
        return b"" if request.device_id == 0 else reply

    def _execute(self, req: rtu.Request) -> tuple[bytes, bool]:
        """Reply frame and whether the request was valid (feeds the watchdog)."""
        fn = req.function
        if fn in (rtu.READ_HOLDING, rtu.READ_INPUT, rtu.READ_COILS):
            values = [self._read(fn, req.address + i) for i in range(req.count)]
            if any(v is None for v in values) or not 1 <= req.count <= 125:
                return rtu.exception_response(req.device_id, fn, rtu.ILLEGAL_ADDRESS), False
            return rtu.read_response(req, [int(v) for v in values if v is not None]), True
        if fn in (rtu.WRITE_REGISTER, rtu.WRITE_REGISTERS, rtu.WRITE_COIL):
            for i, value in enumerate(req.values):
                code = self._write(fn, req.address + i, value)
                if code:
                    return rtu.exception_response(req.device_id, fn, code), False
            return rtu.write_response(req), True
        return rtu.exception_response(req.device_id, fn, rtu.ILLEGAL_FUNCTION), False

    def _read(self, function: int, address: int) -> int | None:
        m, model = self.map, self.model
        kind = {rtu.READ_HOLDING: "holding", rtu.READ_INPUT: "input", rtu.READ_COILS: "coil"}[function]
        if kind == "coil":
            return int(model.running) if m.control == "coil" and address == m.control_address else None
        if kind == m.readback_kind and address == m.readback_register:
            return min(0xFFFF, round(model.speed_mps / m.mps_per_hz / m.readback_hz_per_count))
        if kind == m.fault_kind and address == m.fault_register:
            if model.fault is None:
                return 0
            return WATCHDOG_FAULT_CODE if model.fault == WATCHDOG_FAULT else OTHER_FAULT_CODE
        if kind == "holding" and address == m.setpoint_register:
            return self._setpoint_counts
        if kind == "holding" and m.control == "register" and address == m.control_address:
            return m.run_value if model.running else m.stop_value
        return None

    def _write(self, function: int, address: int, value: int) -> int:
        """Apply one write; return 0 or a Modbus exception code."""
        m, model = self.map, self.model
        if function == rtu.WRITE_COIL:
            if m.control != "coil" or address != m.control_address:
                return rtu.ILLEGAL_ADDRESS
            model.set_running(bool(value))
            return 0
        if address == m.setpoint_register:
            speed_mps = value * m.setpoint_hz_per_count * m.mps_per_hz
            try:
                model.set_setpoint(speed_mps, run=None)
            except ValueError:
                return rtu.ILLEGAL_VALUE
            self._setpoint_counts = value
            return 0
        if m.control == "register" and address == m.control_address:
            if value not in (m.run_value, m.stop_value):
                return rtu.ILLEGAL_VALUE
            model.set_running(value == m.run_value)
            return 0
        return rtu.ILLEGAL_ADDRESS
