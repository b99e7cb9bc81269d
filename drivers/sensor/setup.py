"""The ``sensor:`` section of a rig config, and opening the sensor it describes.

Example (see ``deploy/rig-sensor-*.yaml`` and docs/sensor.md)::

    sensor:
      id: om70
      driver: ascii              # ascii | modbus | simulated
      port: /dev/ttyUSB1
      baudrate: 115200
      units: mm
      poll: {rate_hz: 1000}
      ascii: {mode: stream}
      beam: {x_over_l: 0.73, units_per_reading: 0.001, zero_reading: 100.0, direction: -1}
      sync: {mode: auto}
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

from flagtrack.daemon.core.pointsensor import BeamParams
from flagtrack.daemon.core.sync import SyncParams
from flagtrack.daemon.errors import ConfigError
from flagtrack.drivers.sensor.ascii import AsciiSensorProtocol
from flagtrack.drivers.sensor.base import PointSensor
from flagtrack.drivers.sensor.modbus import ModbusSensorMap
from flagtrack.drivers.sensor.poll import PollParams
from flagtrack.drivers.sensor.twin import TwinSensorParams


@dataclass(frozen=True)
class SensorConfig:
    """A point sensor: how to reach it, where it looks, how its clock is put on the camera's.

    Attributes:
        id: sensor name in key expressions.
        driver: ``ascii`` (line protocol), ``modbus`` (RTU register) or ``simulated`` (reads the
            digital twin; needs the simulated camera in the same process).
        port: device path or pyserial URL (ascii, modbus).
        baudrate, parity, stopbits, bytesize: serial frame format.
        timeout_s: reply timeout of one exchange, s.
        units: unit of the readings.
        poll: rate and failure handling (``poll.rate_hz`` is also the expected rate of a stream).
        ascii: the line protocol (driver ``ascii``).
        modbus: the register (driver ``modbus``).
        simulated: the twin-reading sensor (driver ``simulated``).
        beam: beam position (x/L) and reading -> lateral displacement mapping.
        sync: clock synchronisation with the camera.
        publish_interval_s: samples are published in batches this often.
        reopen_s: wait before reopening a sensor that failed or went silent.
    """

    id: str = "sensor0"
    driver: Literal["ascii", "modbus", "simulated"] = "simulated"
    port: str = ""
    baudrate: int = 115200
    parity: Literal["N", "E", "O"] = "N"
    stopbits: int = 1
    bytesize: int = 8
    timeout_s: float = 0.05
    units: str = "mm"
    poll: PollParams = field(default_factory=PollParams)
    ascii: AsciiSensorProtocol = field(default_factory=AsciiSensorProtocol)
    modbus: ModbusSensorMap = field(default_factory=ModbusSensorMap)
    simulated: TwinSensorParams = field(default_factory=TwinSensorParams)
    beam: BeamParams = field(default_factory=BeamParams)
    sync: SyncParams = field(default_factory=SyncParams)
    publish_interval_s: float = 0.05
    reopen_s: float = 1.0

    def __post_init__(self) -> None:
        if self.driver != "simulated" and not self.port:
            raise ValueError(f"driver {self.driver!r} needs a port")
        if not self.id or "/" in self.id or " " in self.id:
            raise ValueError(f"sensor id {self.id!r} must be one word")
        if self.timeout_s <= 0 or self.publish_interval_s <= 0 or self.reopen_s < 0:
            raise ValueError("timeout_s and publish_interval_s must be positive, reopen_s >= 0")

    @property
    def rate_hz(self) -> float:
        """Nominal sample rate."""
        return self.simulated.rate_hz if self.driver == "simulated" else self.poll.rate_hz


def open_sensor(cfg: SensorConfig, camera: Any = None, rig_path: str | None = None) -> PointSensor:
    """Open the sensor of ``cfg`` (not started: call ``open()``).

    Args:
        cfg: the section.
        camera: the in-process simulated camera (driver ``simulated`` only).
        rig_path: the rig file, for error messages.

    Raises:
        ConfigError: a simulated sensor without a simulated camera in this process.
        DriverError: the port cannot be opened.
    """
    if cfg.driver == "simulated":
        if camera is None or not hasattr(camera, "truth"):
            raise ConfigError(
                "the simulated sensor reads the simulated camera's flag: run the camera (adapter "
                "'simulated') in the same process",
                key="sensor.driver",
                path=rig_path,
            )
        from flagtrack.drivers.sensor.twin import TwinSensor

        return TwinSensor(cfg.simulated, cfg.beam, camera, cfg.units)
    if cfg.driver == "modbus":
        from flagtrack.drivers.sensor.modbus import ModbusSensor

        return ModbusSensor.open_port(
            cfg.port,
            cfg.modbus,
            baudrate=cfg.baudrate,
            timeout_s=cfg.timeout_s,
            parity=cfg.parity,
            stopbits=cfg.stopbits,
            bytesize=cfg.bytesize,
            poll=cfg.poll,
            units=cfg.units,
        )
    from flagtrack.drivers.sensor.ascii import AsciiSensor
    from flagtrack.drivers.serial.adapter import SerialAdapter

    adapter = SerialAdapter(
        cfg.port,
        cfg.baudrate,
        cfg.timeout_s,
        cfg.ascii.eol.encode("ascii"),
        parity=cfg.parity,
        stopbits=cfg.stopbits,
        bytesize=cfg.bytesize,
    )
    return AsciiSensor(adapter, cfg.ascii, cfg.poll, cfg.units)
