"""The sections of a rig file, as the services read them: the camera, the tracker, the recorder, the
viewer, the tunnel, the supervisor, the point sensor and the bus (:class:`RigSections`).

:class:`~flagtrack.daemon.rig.config.RigConfig` is these sections checked against the service table
(which services there are, the sections each needs) with the bus's access-control rules made from
it; the table's steps read the sections through this class, below the table.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.security.config import REDACTED
from flagtrack.daemon.security.names import identifier_problem
from flagtrack.daemon.services.camera import CameraStreamConfig
from flagtrack.daemon.services.flagstate_section import FlagStateConfig
from flagtrack.daemon.services.recorder import RecorderConfig
from flagtrack.daemon.services.supervisor.section import SupervisorConfig
from flagtrack.daemon.services.tracker import TrackerServiceConfig
from flagtrack.daemon.services.viewer import ViewerConfig, effective_sink
from flagtrack.daemon.tracking.section import TrackingConfig
from flagtrack.daemon.transport import BusConfig
from flagtrack.daemon.typed_yaml import to_mapping
from flagtrack.drivers.camera.replay import ReplayConfig
from flagtrack.drivers.camera.simulated import SimulatedCameraConfig
from flagtrack.drivers.sensor.setup import SensorConfig
from flagtrack.drivers.tunnel.setup import TunnelConfig

HARDWARE_ADAPTERS = ("prophesee", "metavision", "inivation")


@dataclass(frozen=True)
class CameraConfig(CameraStreamConfig):
    """The ``camera:`` section: the adapter, and how its stream is cut (the camera service's own fields).

    Attributes:
        adapter: ``replay`` (a file), ``simulated`` (digital twin), ``prophesee``, ``metavision``, ``inivation``.
        replay, simulated: settings of those adapters.
        hardware: settings of a hardware adapter (see docs/cameras.md), passed to it as they are.
    """

    adapter: Literal["replay", "simulated", "prophesee", "metavision", "inivation"] = "simulated"
    replay: ReplayConfig | None = None
    simulated: SimulatedCameraConfig = field(default_factory=SimulatedCameraConfig)
    hardware: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.adapter == "replay" and self.replay is None:
            raise ValueError("adapter 'replay' needs a 'replay:' section with a path")
        if self.packet_us < 1 or self.max_packet_events < 1 or self.rate_interval_s <= 0 or self.max_packet_us < 1:
            raise ValueError("packet_us, max_packet_events, max_packet_us and rate_interval_s must be positive")
        if self.min_packet_events < 0:
            raise ValueError("min_packet_events must be 0 or more")


@dataclass(frozen=True)
class RigSections:
    """Everything a rig runs with (YAML sections of the same names), each section checked on its own."""

    rig: str = "default"
    bus: BusConfig | None = None
    camera: CameraConfig = field(default_factory=CameraConfig)
    tracker: TrackingConfig = field(default_factory=TrackingConfig)
    tracker_service: TrackerServiceConfig = field(default_factory=TrackerServiceConfig)
    recorder: RecorderConfig = field(default_factory=RecorderConfig)
    viewer: ViewerConfig = field(default_factory=ViewerConfig)
    tunnel: TunnelConfig | None = None
    supervisor: SupervisorConfig = field(default_factory=SupervisorConfig)
    sensor: SensorConfig | None = None
    flag_state: FlagStateConfig = field(default_factory=FlagStateConfig)
    services: tuple[str, ...] = ("camera", "tracker", "recorder", "viewer")
    path: str | None = None

    def __post_init__(self) -> None:
        for key, value in self.identifiers().items():  # each becomes part of file names or bus keys
            problem = identifier_problem(value, "the name")
            if problem is not None:
                raise ConfigError(problem, key=key)
        law_timeout_s = self.supervisor.control.law_timeout_s
        if self.tunnel is not None and law_timeout_s * 2 > self.tunnel.safety.loop_timeout_s:
            raise ConfigError(  # (the loop waits up to law_timeout_s for the law: the keep-alive must outlast it)
                f"{law_timeout_s:g} s must be at most half of tunnel.safety.loop_timeout_s "
                f"({self.tunnel.safety.loop_timeout_s:g} s)",
                key="supervisor.control.law_timeout_s",
            )

    def identifiers(self) -> dict[str, str]:
        """The names of this rig that become parts of file names or keys, by their key."""
        names = {"rig": self.rig, "camera.id": self.camera.id}
        if self.sensor is not None:
            names["sensor.id"] = self.sensor.id
        if self.supervisor.run_name is not None:
            names["supervisor.run_name"] = self.supervisor.run_name
        return names

    def snapshot(self) -> dict[str, Any]:
        """The whole effective config as plain values (stored beside recordings and in run logs),
        with the bus password replaced by ``<redacted>`` (files are named, never read into it)."""
        mapping = to_mapping(self)
        security = (mapping.get("bus") or {}).get("security") or {}
        if security.get("password") is not None:
            security["password"] = REDACTED
        return mapping


def viewer_writes_file(cfg: ViewerConfig) -> bool:
    """Whether the viewer writes ``rrd_path``: sink ``rrd``, or ``auto`` with no display to show a window on."""
    return effective_sink(cfg) == "rrd"
