"""The rig config: one YAML file describing the bus, the camera, the tracker, the recorder, the viewer,
the tunnel, the supervisor and the point sensor, read once and checked before anything opens.

Example (see ``deploy/rig-*.yaml``)::

    rig: lab1                     # namespace flagtrack/lab1 unless bus.namespace says otherwise
    bus: {listen: ["tcp/127.0.0.1:7447"]}
    camera: {id: cam0, adapter: simulated, simulated: {speed_mps: 6}}
    tracker: {root: [150, 240], length: 300, tau_s: 0.0003}
    recorder: {directory: recordings}
    viewer: {sink: rrd, rrd_path: live.rrd}
    services: [camera, tracker, recorder, viewer]
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.schema import Keys
from flagtrack.daemon.security.acl import access_control
from flagtrack.daemon.security.config import REDACTED
from flagtrack.daemon.security.names import identifier_problem
from flagtrack.daemon.services.camera import CameraStreamConfig
from flagtrack.daemon.services.recorder import RecorderConfig, recording_base
from flagtrack.daemon.services.supervisor.section import SupervisorConfig
from flagtrack.daemon.services.tracker import TrackerServiceConfig
from flagtrack.daemon.services.viewer import ViewerConfig, effective_sink
from flagtrack.daemon.tracking.section import TrackingConfig
from flagtrack.daemon.tracking.setup import resolve_calibration
from flagtrack.daemon.transport import BusConfig
from flagtrack.daemon.typed_yaml import (
    from_mapping,
    load_yaml,
    require_file,
    require_folder,
    require_output_file,
    to_mapping,
)
from flagtrack.drivers.camera.replay import ReplayConfig
from flagtrack.drivers.camera.simulated import SimulatedCameraConfig
from flagtrack.drivers.sensor.setup import SensorConfig
from flagtrack.drivers.tunnel.setup import TunnelConfig

SERVICE_NAMES = ("camera", "tracker", "recorder", "viewer", "supervisor", "sensor")
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
        if self.packet_us < 1 or self.max_packet_events < 1 or self.rate_interval_s <= 0:
            raise ValueError("packet_us, max_packet_events and rate_interval_s must be positive")


@dataclass(frozen=True)
class RigConfig:
    """Everything a rig runs with (YAML sections of the same names)."""

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
    services: tuple[str, ...] = ("camera", "tracker", "recorder", "viewer")
    path: str | None = None

    def __post_init__(self) -> None:
        unknown = [name for name in self.services if name not in SERVICE_NAMES]
        if unknown:
            raise ValueError(f"unknown service {unknown[0]!r} in services (known: {', '.join(SERVICE_NAMES)})")
        for key, value in self.identifiers().items():  # each becomes part of file names or bus keys
            problem = identifier_problem(value, "the name")
            if problem is not None:
                raise ConfigError(problem, key=key)
        if "supervisor" in self.services and self.tunnel is None:
            raise ValueError("the supervisor needs a 'tunnel:' section (driver: simulated for no hardware)")
        if "sensor" in self.services and self.sensor is None:
            raise ValueError("the sensor service needs a 'sensor:' section (driver: simulated for no hardware)")

    def identifiers(self) -> dict[str, str]:
        """The names of this rig that become parts of file names or keys, by their key."""
        names = {"rig": self.rig, "camera.id": self.camera.id}
        if self.sensor is not None:
            names["sensor.id"] = self.sensor.id
        if self.supervisor.run_name is not None:
            names["supervisor.run_name"] = self.supervisor.run_name
        return names

    @property
    def bus_config(self) -> BusConfig:
        """The bus section, with the namespace ``flagtrack/<rig>`` unless it is given, and the rig's
        access-control rules when ``bus.security.acl`` is on (:meth:`bus_config_for` also names the
        identity of a process that runs one service)."""
        if self.bus is None:
            return BusConfig(namespace=f"flagtrack/{self.rig}")
        security = self.bus.security
        if security is None or not security.acl:
            return self.bus
        sensors = (self.sensor.id,) if self.sensor is not None else ()
        rules = access_control(Keys(self.bus.namespace), security, (self.camera.id,), sensors)
        return dataclasses.replace(self.bus, access_control=rules)

    def bus_config_for(self, services: Sequence[str], identity: str | None = None) -> BusConfig:
        """:attr:`bus_config` for a process running ``services``: on a secured bus it presents
        ``identity``, else ``bus.security.identity``, else the one service it runs (``flagtrack
        camera`` presents ``camera``); ``flagtrack router`` presents ``router``."""
        cfg = self.bus_config
        security = cfg.security
        if security is None or security.tls is None:
            return cfg
        chosen = identity or security.identity or (services[0] if len(services) == 1 else None)
        if chosen is None or chosen == security.identity:
            return cfg
        return dataclasses.replace(cfg, security=dataclasses.replace(security, identity=chosen))

    def snapshot(self) -> dict[str, Any]:
        """The whole effective config as plain values (stored beside recordings and in run logs),
        with the bus password replaced by ``<redacted>`` (files are named, never read into it)."""
        mapping = to_mapping(self)
        security = (mapping.get("bus") or {}).get("security") or {}
        if security.get("password") is not None:
            security["password"] = REDACTED
        return mapping


def load_rig(path: str | Path, services: Sequence[str] | None = None) -> RigConfig:
    """Read and check a rig config; every error names the key and the file.

    Args:
        path: the YAML file.
        services: the services whose files, folders and camera settings are checked (:func:`check_rig`);
            default: the rig's own ``services:``; ``()`` for a caller that checks after changing the rig.

    Raises:
        ConfigError: unreadable file, unknown key, bad value, a missing input file, an output folder
            that cannot be made, a camera setting no camera of the adapter takes.
    """
    data = load_yaml(path)
    if "path" in data:
        raise ConfigError("reserved key", key="path", path=str(path))
    bus = data.get("bus") or {}
    if isinstance(bus, dict) and "access_control" in bus:
        raise ConfigError("made from the rig by bus.security.acl: true, not written", key="bus.access_control")
    security = bus.get("security") if isinstance(bus, dict) else None
    password = security.get("password") if isinstance(security, dict) else None
    if password is not None and not isinstance(password, str):  # (the type error would print it)
        raise ConfigError("must be text: quote it", key="bus.security.password", path=str(path))
    if isinstance(bus, dict) and "namespace" not in bus:
        rig_name = data.get("rig", "default")
        problem = identifier_problem(rig_name, "the name")
        if problem is not None:  # it makes the namespace: name the key the user wrote
            raise ConfigError(problem, key="rig", path=str(path))
        data = {**data, "bus": {**bus, "namespace": f"flagtrack/{rig_name}"}}
    rig = from_mapping(RigConfig, {**data, "path": str(path)}, path=str(path))
    rig = dataclasses.replace(rig, tracker=resolve_calibration(rig.tracker, Path(path).parent))
    check_rig(rig, rig.services if services is None else services)
    return rig


def check_rig(rig: RigConfig, services: Sequence[str]) -> None:
    """Check what ``services`` need of ``rig`` that a file or a setting can say, opening and creating nothing.

    Input files must exist (``camera.replay.path``, ``tracker.calibration``); output folders must
    exist or be creatable (``recorder.directory`` and ``path``, the ``.rrd`` file's, ``supervisor.runs_dir``);
    a hardware camera's settings are checked as far as they can be without the device (bias names,
    ROI form); what only the device can tell (an ROI that fits its sensor) is checked when ``up``
    opens it, before anything else (:func:`flagtrack.daemon.rig.build.open_hardware_camera`).

    Raises:
        ConfigError: naming the key and the rig file.
    """
    where = rig.path
    if "camera" in services:
        if rig.camera.adapter == "replay" and rig.camera.replay is not None:
            require_file(rig.camera.replay.path, key="camera.replay.path", path=where)
        if rig.camera.adapter in HARDWARE_ADAPTERS:
            module = importlib.import_module(f"flagtrack.drivers.camera.{rig.camera.adapter}")
            module.check_config(rig.camera.hardware, path=where)
    if {"tracker", "recorder"} & set(services) and rig.tracker.calibration is not None:  # the recorder's files name it
        require_file(rig.tracker.calibration, key="tracker.calibration", path=where)
    if "recorder" in services:
        require_folder(rig.recorder.directory, key="recorder.directory", path=where)
        if rig.recorder.path:
            require_folder(
                recording_base(rig.recorder.directory, rig.recorder.path).parent, key="recorder.path", path=where
            )
    if "viewer" in services and viewer_writes_file(rig.viewer):
        require_output_file(rig.viewer.rrd_path, key="viewer.rrd_path", path=where)
    if "supervisor" in services:
        require_folder(rig.supervisor.runs_dir, key="supervisor.runs_dir", path=where)


def viewer_writes_file(cfg: ViewerConfig) -> bool:
    """Whether the viewer writes ``rrd_path``: sink ``rrd``, or ``auto`` with no display to show a window on."""
    return effective_sink(cfg) == "rrd"
