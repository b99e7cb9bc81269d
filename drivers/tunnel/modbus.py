"""A variable-frequency drive over Modbus RTU (pymodbus 3.x), register map from YAML.

The only module that imports pymodbus (lazily, in :meth:`ModbusTunnel.open`): its client API
changed across 3.x releases (``slave=`` became ``device_id=``), so every call goes through
:meth:`ModbusTunnel._call`. Written against pymodbus 3.16.

Speed and drive frequency: ``speed_mps = mps_per_hz * frequency_hz`` (a calibration of the
tunnel), ``frequency_hz = counts * hz_per_count`` on the wire.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

from flagtrack.daemon.errors import DriverError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ModbusMap:
    """Register map of one drive (config ``tunnel.modbus``); addresses are 0-based PDU addresses.

    Attributes:
        device_id: Modbus slave address of the drive.
        setpoint_register: holding register of the frequency set-point.
        setpoint_hz_per_count: Hz per count of the set-point register.
        control: ``register`` (a control word) or ``coil`` (one run/stop coil).
        control_address: address of the control word or coil.
        run_value, stop_value: control word values for run and stop (``register`` control only).
        readback_register: register of the output frequency.
        readback_kind: ``input`` or ``holding`` register.
        readback_hz_per_count: Hz per count of the readback register.
        fault_register: register holding the fault code (0 = healthy), or ``null``.
        fault_kind: ``input`` or ``holding`` register.
        fault_codes: texts of known fault codes (others are reported as ``fault code N``).
        mps_per_hz: tunnel speed per drive frequency, m/s per Hz (calibrated on the rig).
        max_hz: the drive is never asked for more than this, Hz.
    """

    device_id: int = 1
    setpoint_register: int = 1
    setpoint_hz_per_count: float = 0.01
    control: Literal["register", "coil"] = "register"
    control_address: int = 0
    run_value: int = 1
    stop_value: int = 0
    readback_register: int = 16
    readback_kind: Literal["input", "holding"] = "input"
    readback_hz_per_count: float = 0.01
    fault_register: int | None = 17
    fault_kind: Literal["input", "holding"] = "input"
    fault_codes: dict[int, str] = field(default_factory=dict)
    mps_per_hz: float = 0.25
    max_hz: float = 60.0

    def __post_init__(self) -> None:
        if not 0 <= self.device_id <= 247:
            raise ValueError("device_id must be in 0..247")
        for name in ("setpoint_hz_per_count", "readback_hz_per_count", "mps_per_hz", "max_hz"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive")
        for name in ("setpoint_register", "control_address", "readback_register", "run_value", "stop_value"):
            if not 0 <= getattr(self, name) <= 0xFFFF:
                raise ValueError(f"{name} must be in 0..65535")

    def speed_to_counts(self, speed_mps: float) -> int:
        """Set-point counts for ``speed_mps``; ValueError beyond ``max_hz`` or 16 bits."""
        hz = speed_mps / self.mps_per_hz
        counts = round(hz / self.setpoint_hz_per_count)
        if hz < 0 or hz > self.max_hz + 1e-9 or counts > 0xFFFF:
            raise ValueError(f"{speed_mps:g} m/s is {hz:g} Hz, outside the drive's 0..{self.max_hz:g} Hz")
        return counts

    def counts_to_speed(self, counts: int) -> float:
        """Speed in m/s of a readback register value."""
        return counts * self.readback_hz_per_count * self.mps_per_hz


class ModbusTunnel:
    """The :class:`~flagtrack.drivers.tunnel.base.TunnelLink` of a Modbus RTU drive.

    Args:
        client: a connected ``pymodbus.client.ModbusSerialClient``.
        modbus_map: the register map.
        device: port name for errors.
    """

    def __init__(self, client: Any, modbus_map: ModbusMap, device: str) -> None:
        from pymodbus.exceptions import ModbusException

        self.client = client
        self.map = modbus_map
        self.device = device
        self._modbus_exception = ModbusException

    @classmethod
    def open(
        cls,
        port: str,
        modbus_map: ModbusMap = ModbusMap(),
        *,
        baudrate: int = 19200,
        timeout_s: float = 0.5,
        parity: str = "N",
        stopbits: int = 1,
        bytesize: int = 8,
    ) -> ModbusTunnel:
        """Open ``port`` and connect a pymodbus RTU client (one retry per request)."""
        from pymodbus.client import ModbusSerialClient

        client = ModbusSerialClient(
            port=port, baudrate=baudrate, timeout=timeout_s, retries=1,
            parity=parity, stopbits=stopbits, bytesize=bytesize,
        )  # fmt: skip
        if not client.connect():
            raise DriverError("cannot open the serial port of the Modbus drive", device=port)
        return cls(client, modbus_map, port)

    def write_setpoint_mps(self, speed_mps: float) -> None:
        """Write the frequency set-point; when ``speed_mps > 0`` also command run."""
        try:
            counts = self.map.speed_to_counts(speed_mps)
        except ValueError as exc:
            raise DriverError(str(exc), device=self.device) from exc
        self._call("write set-point", self.client.write_register, self.map.setpoint_register, counts)
        if speed_mps > 0:
            self._write_control(run=True)

    def read_speed_mps(self) -> float:
        """Read the output frequency, converted to m/s."""
        return self.map.counts_to_speed(self._read(self.map.readback_kind, self.map.readback_register))

    def stop(self) -> None:
        """Set-point zero, then the stop command."""
        self._call("write set-point", self.client.write_register, self.map.setpoint_register, 0)
        self._write_control(run=False)

    def keep_alive(self) -> None:
        """A readback request (any valid request resets a drive's communication timeout)."""
        self.read_speed_mps()

    def read_fault(self) -> str | None:
        """Fault text from the fault register (``None`` when 0 or when there is no register)."""
        if self.map.fault_register is None:
            return None
        code = self._read(self.map.fault_kind, self.map.fault_register)
        return None if code == 0 else self.map.fault_codes.get(code, f"fault code {code}")

    def close(self) -> None:
        """Close the port."""
        self.client.close()

    def _write_control(self, *, run: bool) -> None:
        if self.map.control == "coil":
            self._call("write run coil", self.client.write_coil, self.map.control_address, run)
        else:
            value = self.map.run_value if run else self.map.stop_value
            self._call("write control word", self.client.write_register, self.map.control_address, value)

    def _read(self, kind: str, address: int) -> int:
        reader = self.client.read_input_registers if kind == "input" else self.client.read_holding_registers
        response = self._call(f"read {kind} register {address}", reader, address, count=1)
        return int(response.registers[0])

    def _call(self, what: str, method: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        """Run one pymodbus request; DriverError (naming the port) on no reply or an exception reply."""
        try:
            response = method(*args, device_id=self.map.device_id, **kwargs)
        except self._modbus_exception as exc:
            raise DriverError(
                f"{what}: no valid reply from drive {self.map.device_id} ({exc})", device=self.device
            ) from exc
        if response.isError():
            code = getattr(response, "exception_code", "?")
            raise DriverError(f"{what}: drive {self.map.device_id} answered exception {code}", device=self.device)
        return response
