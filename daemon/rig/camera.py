"""The camera adapter of a rig: made from the ``camera:`` section, and a hardware camera opened ahead
of everything else (what only the device can refuse stops the rig with one line first)."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable
from typing import Any

from flagtrack.daemon.errors import ConfigError, DriverError, FlagtrackError
from flagtrack.daemon.rig.camera_auto import resolve_auto
from flagtrack.daemon.rig.sections import HARDWARE_ADAPTERS, CameraConfig, RigSections
from flagtrack.daemon.transport import Bus, Subscription
from flagtrack.daemon.typed_yaml import with_path
from flagtrack.drivers.camera.base import Camera, CameraInfo

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


def open_hardware_camera(rig: RigSections, *, check_root: bool = True) -> OpenedCamera | None:
    """Open the rig's hardware camera now, before the bus and the other services (None for replay or simulated).

    What only the device can check (a bias its model lacks, a value it refuses, an ROI that does
    not fit its sensor) then stops the rig with one error naming the key and the rig file, before
    anything else has opened; the camera service takes the open device as it is. ``roi: auto`` and
    the rate limiter's ``auto`` are worked out first (:mod:`.camera_auto`); what they set, and why,
    is logged and goes in the camera's settings under ``auto``.

    Raises:
        ConfigError: a setting the device refuses (key and rig file named).
        DriverError: the camera is missing, busy or fails.
    """
    if rig.camera.adapter not in HARDWARE_ADAPTERS:
        return None
    auto = resolve_auto(rig)  # roi: auto and the rate limiter's auto, from the tracker section
    camera = open_camera(dataclasses.replace(rig.camera, hardware=auto.hardware), rig_path=rig.path)
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
    try:  # the sensor's size is known now: a root off it tracks nothing (check_root False: aim, which sets it up)
        if check_root:
            from flagtrack.daemon.tracking.setup import refuse_tracker_off_sensor

            refuse_tracker_off_sensor(
                rig.tracker, info.width, info.height, sensor=f"camera {info.serial}", path=rig.path
            )
    except FlagtrackError:
        camera.close()
        raise
    for key, why in auto.why.items():
        log.info("camera %s: %s.%s auto: %s", rig.camera.id, "camera.hardware", key, why)
    if auto.why:  # the status message says what was set and why
        info = dataclasses.replace(info, settings={**info.settings, "auto": dict(auto.why)})
    return OpenedCamera(camera, info)


class BusSpeedSource:
    """The wind speed as the supervisor publishes it (for a simulated camera in another process), and
    ``own_mps`` (the camera's own setting) until a tunnel state arrives: a rig without a running
    supervisor (``flagtrack up`` beside ``flagtrack tunnel set``) shows the flag at that speed, as
    ``flagtrack config check`` says. It subscribes to the tunnel state at its first call, in the
    camera's loop."""

    def __init__(self, bus: Bus, own_mps: float = 0.0) -> None:
        self._bus = bus
        self._sub: Subscription | None = None
        self._speed_mps = own_mps

    def __call__(self) -> float:
        if self._sub is None:
            from flagtrack.daemon.schema import TunnelState

            self._sub = self._bus.subscribe(self._bus.keys.tunnel_state(), TunnelState, capacity=100, ring=True)
        while (msg := self._sub.recv(timeout_s=0)) is not None:
            if msg.speed_mps >= 0:
                self._speed_mps = msg.speed_mps
        return self._speed_mps
