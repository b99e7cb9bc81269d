"""Build the services a rig config asks for, checking everything before anything opens."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from flagtrack.daemon.errors import ConfigError, DriverError, FlagtrackError
from flagtrack.daemon.rig.config import HARDWARE_ADAPTERS, CameraConfig, RigConfig
from flagtrack.daemon.services.camera import CameraService
from flagtrack.daemon.services.recorder import RecorderService
from flagtrack.daemon.services.runner import Service
from flagtrack.daemon.services.tracker import TrackerService
from flagtrack.daemon.tracking.setup import TrackingSetup, processing_attrs, tracking_setup
from flagtrack.daemon.transport import Bus
from flagtrack.daemon.typed_yaml import with_path
from flagtrack.drivers.camera.base import Camera, CameraInfo
from flagtrack.drivers.tunnel.base import WindTunnel

if TYPE_CHECKING:
    from flagtrack.daemon.services.supervisor.service import SupervisorService

log = logging.getLogger(__name__)


def open_camera(
    cfg: CameraConfig, speed_source: Callable[[], float] | None = None, rig_path: str | None = None
) -> Camera:
    """The camera adapter the ``camera:`` section names (hardware SDKs are imported only here)."""
    if cfg.adapter == "replay":
        from flagtrack.drivers.camera.replay import ReplayCamera

        assert cfg.replay is not None  # checked by CameraConfig
        return ReplayCamera(cfg.replay)
    if cfg.adapter == "simulated":
        from flagtrack.drivers.camera.simulated import SimulatedCamera

        return SimulatedCamera(cfg.simulated, speed_source)
    import importlib

    module = importlib.import_module(f"flagtrack.drivers.camera.{cfg.adapter}")
    try:
        return module.open_from_config(cfg.hardware)
    except ConfigError as exc:
        if exc.path is None and rig_path is not None:
            raise with_path(exc, rig_path) from exc
        raise


class OpenedCamera:
    """A camera opened ahead of its service: the service's ``open`` gets what the device said then
    (``handed_over`` from then on: the service closes it)."""

    def __init__(self, camera: Camera, info: CameraInfo) -> None:
        self.camera = camera
        self._info: CameraInfo | None = info
        self.handed_over = False

    def open(self) -> CameraInfo:
        info, self._info = self._info, None
        self.handed_over = True
        return info if info is not None else self.camera.open()

    def read(self, timeout_s: float) -> Any:
        return self.camera.read(timeout_s)

    def close(self) -> None:
        self._info = None
        self.camera.close()

    def __getattr__(self, name: str) -> Any:  # the adapter's own attributes (dropped_packets, ...)
        if name == "camera":
            raise AttributeError(name)
        return getattr(self.camera, name)


def open_hardware_camera(rig: RigConfig) -> OpenedCamera | None:
    """Open the rig's hardware camera now, before the bus and the other services (None for replay or simulated).

    What only the device can check (a bias its model lacks, a value it refuses, an ROI that does
    not fit its sensor) then stops the rig with one error naming the key and the rig file, before
    anything else has opened; the camera service takes the open device as it is.

    Raises:
        ConfigError: a setting the device refuses (key and rig file named).
        DriverError: the camera is missing, busy or fails.
    """
    if rig.camera.adapter not in HARDWARE_ADAPTERS:
        return None
    camera = open_camera(rig.camera, rig_path=rig.path)
    try:
        info = camera.open()
    except ConfigError as exc:
        raise with_path(exc, rig.path) from exc
    except FlagtrackError:
        raise
    except Exception as exc:  # an SDK's own exception: still one line for the user
        raise DriverError(
            f"cannot open the camera ({type(exc).__name__}: {exc})", device=f"camera adapter '{rig.camera.adapter}'"
        ) from exc
    return OpenedCamera(camera, info)


class BusSpeedSource:
    """The wind speed as the supervisor publishes it (for a simulated camera in another process)."""

    def __init__(self, bus: Bus) -> None:
        from flagtrack.daemon.schema import TunnelState

        self._sub = bus.subscribe(bus.keys.tunnel_state(), TunnelState, capacity=100, ring=True)
        self._speed_mps = 0.0

    def __call__(self) -> float:
        while (msg := self._sub.recv(timeout_s=0)) is not None:
            if msg.speed_mps >= 0:
                self._speed_mps = msg.speed_mps
        return self._speed_mps


def build_services(
    rig: RigConfig,
    bus: Bus,
    names: Sequence[str],
    *,
    exit_at_end_of_stream: bool = False,
    resume_dir: Path | None = None,
    tracker: TrackingSetup | None = None,
    camera: Camera | None = None,
) -> list[Service]:
    """Instantiate the named services of ``rig`` on ``bus`` (subscribers before the camera).

    A simulated camera reads the wind speed from the simulated tunnel when the supervisor runs in
    this process, else from the tunnel state on the bus. A simulated point sensor reads the
    simulated camera's flag, so both must run in this process. ``tracker``: the rig's
    :func:`~flagtrack.daemon.tracking.setup.tracking_setup`, if the caller already made it; ``camera``: the camera, if the caller opened
    it (:func:`open_hardware_camera`).
    """
    setup = (tracker or tracking_setup(rig.tracker, path=rig.path)) if "tracker" in names else None
    services: list[Service] = []
    speed_source: Callable[[], float] | None = None
    if "supervisor" in names:
        from flagtrack.drivers.tunnel.setup import open_tunnel

        assert rig.tunnel is not None  # checked by RigConfig
        tunnel = open_tunnel(rig.tunnel)
        simulator = getattr(tunnel, "simulator", None)
        if simulator is not None:
            speed_source = lambda: float(simulator.speed_mps)  # noqa: E731
        services.append(build_supervisor(rig, bus, tunnel, resume_dir))
    elif "camera" in names and rig.camera.adapter == "simulated" and rig.tunnel is not None:
        speed_source = BusSpeedSource(bus)
    if "recorder" in names:
        services.append(
            RecorderService(
                bus,
                replace(  # commands may name recordings in its folder and where the sweep's points go
                    rig.recorder,
                    camera_id=rig.camera.id,
                    allowed_dirs=(
                        *rig.recorder.allowed_dirs,
                        rig.supervisor.runs_dir,
                        *([resume_dir] if resume_dir else []),
                    ),
                ),
                rig.snapshot(),
                centreline_attrs=setup.attrs if setup else processing_attrs(rig.tracker),
                exit_at_end_of_stream=exit_at_end_of_stream,
            )
        )
    if "tracker" in names:
        assert setup is not None
        cfg = replace(
            rig.tracker_service,
            camera_id=rig.camera.id,
            exit_at_end_of_stream=exit_at_end_of_stream or rig.tracker_service.exit_at_end_of_stream,
        )
        services.append(TrackerService(bus, cfg, setup.factory, setup.units))
    if "viewer" in names:
        from flagtrack.daemon.services.viewer import ViewerService  # rerun: only where a viewer runs

        services.append(
            ViewerService(bus, replace(rig.viewer, camera_id=rig.camera.id), exit_after_final=exit_at_end_of_stream)
        )
    if "camera" not in names:
        camera = None
    elif camera is None:
        camera = open_camera(rig.camera, speed_source, rig.path)
    if "sensor" in names:
        services.append(sensor_service(rig, bus, camera))
    if camera is not None:
        services.append(CameraService(bus, rig.camera, camera))
    return services


def build_supervisor(rig: RigConfig, bus: Bus, tunnel: WindTunnel, resume_dir: Path | None = None) -> SupervisorService:
    """The supervisor of ``rig``, with its opened (not started) tunnel."""
    from flagtrack.daemon.services.supervisor.service import FlagGeometry, SupervisorService  # SciPy: here only

    tracker = rig.tracker
    flag = FlagGeometry(float(tracker.length or 1.0), tuple(tracker.root or (0.0, 0.0)), float(tracker.direction_deg))
    return SupervisorService(bus, rig.supervisor, tunnel, rig.camera.id, flag, rig.snapshot(), resume_dir, rig.sensor)


def sensor_service(rig: RigConfig, bus: Bus, camera: Camera | None) -> Service:
    """The point-sensor service of the ``sensor:`` section (a simulated one reads ``camera``'s twin).

    Raises:
        ConfigError: a simulated sensor without the simulated camera in this process.
    """
    from flagtrack.daemon.services.sensor import SensorService
    from flagtrack.drivers.sensor.setup import open_sensor

    cfg = rig.sensor
    if cfg is None:
        raise ConfigError("the sensor service needs a 'sensor:' section", key="sensor", path=rig.path)
    if cfg.driver == "simulated" and not hasattr(camera, "truth"):
        raise ConfigError(
            "the simulated sensor reads the simulated camera's flag: run the camera (adapter "
            "'simulated') in the same process",
            key="sensor.driver",
            path=rig.path,
        )
    return SensorService(bus, cfg, lambda: open_sensor(cfg, camera, rig.path))
