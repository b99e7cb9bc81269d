"""A point sensor read over Modbus RTU: one distance register (16 or 32 bits), scale and offset.

pymodbus 3.x (``ModbusSerialClient``, slave keyword ``device_id=`` as in 3.16), imported lazily
here only, as in :mod:`flagtrack.drivers.tunnel.modbus`. Samples are stamped by the host (the
middle of each exchange); each sample is one request, so the rate is bounded by the link
(about 200 Hz at 115200 baud, tens of Hz at 9600).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Literal

from flagtrack.daemon.errors import DriverError
from flagtrack.drivers.sensor.base import HostClock, SensorInfo, SensorReading
from flagtrack.drivers.sensor.poll import Poller, PollParams

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ModbusSensorMap:
    """Where the reading is (config ``sensor.modbus``); addresses are 0-based PDU addresses.

    Attributes:
        device_id: Modbus slave address of the sensor.
        register: first register of the reading.
        kind: ``input`` or ``holding`` register.
        words: 1 (16-bit) or 2 (32-bit) registers.
        word_order: ``big`` (high word first) or ``little`` (32-bit readings).
        signed: two's complement reading.
        scale, offset: reading = counts * scale + offset (sensor units).
        invalid_counts: raw values meaning "no reading" (out of range), e.g. [65535].
    """

    device_id: int = 1
    register: int = 0
    kind: Literal["input", "holding"] = "input"
    words: int = 1
    word_order: Literal["big", "little"] = "big"
    signed: bool = False
    scale: float = 0.01
    offset: float = 0.0
    invalid_counts: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if not 0 <= self.device_id <= 247 or not 0 <= self.register <= 0xFFFF:
            raise ValueError("device_id must be in 0..247 and register in 0..65535")
        if self.words not in (1, 2) or self.scale == 0:
            raise ValueError("words must be 1 or 2 and scale non-zero")

    def counts(self, registers: list[int]) -> int:
        """The raw reading of the register values (word order and sign applied)."""
        words = list(registers[: self.words])
        if self.words == 2 and self.word_order == "little":
            words.reverse()
        raw = words[0] if self.words == 1 else (words[0] << 16) | words[1]
        bits = 16 * self.words
        if self.signed and raw >= 1 << (bits - 1):
            raw -= 1 << bits
        return raw

    def value(self, registers: list[int]) -> float:
        """The reading in sensor units (NaN for an invalid count)."""
        raw = self.counts(registers)
        if raw in self.invalid_counts:
            return math.nan
        return raw * self.scale + self.offset


class ModbusSensor:
    """A :class:`~flagtrack.drivers.sensor.base.PointSensor` polling one register.

    Args:
        client: a connected ``pymodbus.client.ModbusSerialClient``.
        modbus_map: where the reading is.
        device: port name for errors.
        poll: sampling rate and failure handling.
        units: unit of the readings.
    """

    def __init__(
        self, client: Any, modbus_map: ModbusSensorMap, device: str, poll: PollParams = PollParams(), units: str = "mm"
    ) -> None:
        from pymodbus.exceptions import ModbusException

        self.client = client
        self.map = modbus_map
        self.device = device
        self.poll = poll
        self.units = units
        self._modbus_exception = ModbusException
        self._poller = Poller(self._exchange, poll, HostClock(), device)

    @classmethod
    def open_port(
        cls,
        port: str,
        modbus_map: ModbusSensorMap = ModbusSensorMap(),
        *,
        baudrate: int = 115200,
        timeout_s: float = 0.05,
        parity: str = "N",
        stopbits: int = 1,
        bytesize: int = 8,
        poll: PollParams = PollParams(),
        units: str = "mm",
    ) -> ModbusSensor:
        """Open ``port`` and connect a pymodbus RTU client (no retries: a late sample is a missing one)."""
        from pymodbus.client import ModbusSerialClient

        client = ModbusSerialClient(
            port=port,
            baudrate=baudrate,
            timeout=timeout_s,
            retries=0,
            parity=parity,
            stopbits=stopbits,
            bytesize=bytesize,
        )
        if not client.connect():
            raise DriverError("cannot open the serial port of the Modbus sensor", device=port)
        return cls(client, modbus_map, port, poll, units)

    def open(self) -> SensorInfo:
        return SensorInfo(
            "modbus",
            self.device,
            self.units,
            "host",
            self.poll.rate_hz,
            {"device_id": self.map.device_id, "register": self.map.register},
        )

    def read(self, timeout_s: float) -> SensorReading:
        return self._poller.read(timeout_s)

    def close(self) -> None:
        self.client.close()

    def _exchange(self) -> tuple[float, int | None]:
        reader = self.client.read_input_registers if self.map.kind == "input" else self.client.read_holding_registers
        try:
            response = reader(self.map.register, count=self.map.words, device_id=self.map.device_id)
        except self._modbus_exception as exc:
            raise DriverError(f"no valid reply from sensor {self.map.device_id} ({exc})", device=self.device) from exc
        if response.isError():
            code = getattr(response, "exception_code", "?")
            raise DriverError(f"sensor {self.map.device_id} answered exception {code}", device=self.device)
        return self.map.value(list(response.registers)), None
