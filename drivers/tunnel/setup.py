"""The ``tunnel`` section of a rig config, and opening the tunnel it describes.

Example (see ``deploy/tunnel-*.yaml``)::

    tunnel:
      driver: ascii            # ascii | modbus | simulated
      port: /dev/ttyUSB0       # device path or pyserial URL
      baudrate: 9600
      safety: {max_speed_mps: 12, max_ramp_mps2: 0.5, keepalive_s: 1, watchdog_s: 5}
      ascii: {set_command: "SET {value:.2f}"}
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, TypedDict

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.typed_yaml import from_mapping, load_yaml
from flagtrack.drivers.tunnel.ascii import AsciiProtocol, AsciiTunnel
from flagtrack.drivers.tunnel.base import TunnelLink
from flagtrack.drivers.tunnel.modbus import ModbusMap, ModbusTunnel
from flagtrack.drivers.tunnel.safe import SafeTunnel, SafetyParams
from flagtrack.drivers.tunnel.sim_model import SimParams

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TunnelConfig:
    """How to reach the wind tunnel and its limits.

    Attributes:
        driver: ``ascii`` (line protocol), ``modbus`` (RTU drive) or ``simulated`` (an in-process
            simulated tunnel on a pty, speaking ``sim.protocol``, driven through the same driver).
        port: device path (``/dev/ttyUSB0``, a udev name) or pyserial URL (ascii only).
        baudrate, parity, stopbits, bytesize: serial frame format.
        timeout_s: reply timeout of one exchange, s.
        safety: bounds, ramp, readback check, keep-alive (:class:`SafetyParams`).
        ascii: commands and replies of the line protocol.
        modbus: register map of the drive.
        sim: the simulated tunnel (driver ``simulated``, and ``flagtrack tunnel sim``).
    """

    driver: Literal["ascii", "modbus", "simulated"] = "simulated"
    port: str = ""
    baudrate: int = 9600
    parity: Literal["N", "E", "O"] = "N"
    stopbits: int = 1
    bytesize: int = 8
    timeout_s: float = 0.5
    safety: SafetyParams = field(default_factory=SafetyParams)
    ascii: AsciiProtocol = field(default_factory=AsciiProtocol)
    modbus: ModbusMap = field(default_factory=ModbusMap)
    sim: SimParams = field(default_factory=SimParams)

    def __post_init__(self) -> None:
        if self.driver != "simulated" and not self.port:
            raise ValueError(f"driver {self.driver!r} needs a port")
        if self.timeout_s <= 0:
            raise ValueError("timeout_s must be positive")
        if not 50 <= self.baudrate <= 4_000_000:  # (-9600 and 1e30 passed to pyserial)
            raise ValueError(f"baudrate must be 50 to 4000000, got {self.baudrate}")
        if self.driver == "simulated" and self.safety.keepalive_s > self.sim.watchdog_s / 2:
            raise ValueError("safety.keepalive_s must be at most half of sim.watchdog_s")


def load_tunnel_config(path: str | Path, section: str = "tunnel") -> TunnelConfig:
    """Read the ``section`` of the YAML file ``path`` as a :class:`TunnelConfig`.

    Raises:
        ConfigError: unreadable file, missing section, or a bad value (naming key and file).
    """
    data = load_yaml(path)
    if section not in data:
        raise ConfigError("section is missing", key=section, path=str(path))
    return from_mapping(TunnelConfig, data[section], path=str(path), key=section)


class _SerialSettings(TypedDict):
    """The serial line's settings, as both protocol drivers' ``open`` take them."""

    baudrate: int
    timeout_s: float
    parity: str
    stopbits: int
    bytesize: int


def open_link(cfg: TunnelConfig, protocol: str, port: str) -> TunnelLink:
    """Open the protocol driver (``ascii`` or ``modbus``) of ``cfg`` on ``port``."""
    serial_kwargs: _SerialSettings = {"baudrate": cfg.baudrate, "timeout_s": cfg.timeout_s, "parity": cfg.parity,
                     "stopbits": cfg.stopbits, "bytesize": cfg.bytesize}  # fmt: skip
    if protocol == "modbus":
        return ModbusTunnel.open(port, cfg.modbus, **serial_kwargs)
    return AsciiTunnel.open(port, cfg.ascii, **serial_kwargs)


def open_tunnel(cfg: TunnelConfig) -> SafeTunnel:
    """Open the tunnel of ``cfg`` behind the safety layer (not started: use ``with``).

    For driver ``simulated`` a :class:`~flagtrack.drivers.tunnel.simulated.SimulatedTunnel` is
    started first (it is ``tunnel.simulator``, closed with the tunnel) and driven through the
    real serial driver of its protocol, so the whole chain runs with no hardware.

    Raises:
        DriverError: the port cannot be opened.
    """
    if cfg.driver != "simulated":
        return SafeTunnel(open_link(cfg, cfg.driver, cfg.port), cfg.safety)
    from flagtrack.drivers.tunnel.simulated import SimulatedTunnel  # simulation only when asked for

    sim = SimulatedTunnel(cfg.sim, cfg.modbus).start()
    try:
        tunnel = SafeTunnel(open_link(cfg, cfg.sim.protocol, sim.port), cfg.safety)
    except BaseException:
        sim.close()
        raise
    tunnel.simulator = sim
    tunnel.add_closer(sim.close)
    return tunnel
