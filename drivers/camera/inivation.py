"""iniVation cameras (DVXplorer, DAVIS346, ...) through dv-processing (``pip install -e '.[inivation]'``).

dv-processing 2.x opens a camera with ``dv.io.camera.open(serial)`` and gives decoded event
batches (``getNextEventBatch`` -> EventStore, Unix-time µs) and trigger batches, not EVT bytes:
they are converted to EVENT_DTYPE directly, with times relative to the camera's timestamp offset
(its clock zero, reported in the settings), and published as EVT 3.0 packets. ROI (crop area),
DVXplorer contrast thresholds and readout rate, DAVIS346 coarse/fine biases and the external
signal detector come from ``camera.hardware`` and are read back from the camera. dv-processing's
camera capture reports no drops, so this adapter reports none.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from datetime import timedelta
from typing import Any

import numpy as np

from flagtrack.daemon.core.events import EVENT_DTYPE, TRIGGER_DTYPE, empty_events, empty_triggers
from flagtrack.daemon.errors import ConfigError, DriverError
from flagtrack.daemon.typed_yaml import from_mapping
from flagtrack.drivers.camera.base import CameraData, CameraInfo
from flagtrack.drivers.camera.hardware import (
    KEY,
    Roi,
    StallWatch,
    call_or_none,
    check_serial,
    device_label,
    import_sdk,
    plain,
)

log = logging.getLogger(__name__)

INSTALL_HINT = "pip install -e '.[inivation]' in flagtrack's folder (installs dv-processing from PyPI)"
POLL_INTERVAL_S = 0.001
TRIGGERS = {
    "EXTERNAL_SIGNAL_RISING_EDGE": (0, 1),
    "EXTERNAL_SIGNAL_FALLING_EDGE": (0, 0),
    "EXTERNAL_SIGNAL_PULSE": (0, 1),
    "EXTERNAL_GENERATOR_RISING_EDGE": (1, 1),
    "EXTERNAL_GENERATOR_FALLING_EDGE": (1, 0),
}
"""dv TriggerType name -> (channel, edge), as the AEDAT4 reader maps them."""
YAML_BOOLEANS = {True: "On", False: "Off"}
"""DAVIS346 bias names that YAML 1.1 turns into booleans when unquoted."""


@dataclass(frozen=True)
class InivationConfig:
    """``camera.hardware`` of ``adapter: inivation``.

    Attributes:
        serial: serial number ("": the first iniVation camera found; a number YAML read unquoted is refused).
        roi: event crop area.
        contrast_threshold_on, contrast_threshold_off: DVXplorer contrast thresholds (None: default).
        readout_fps: DVXplorer event readout rate, a ``ReadoutFPS`` name (``VARIABLE_15000``, ...).
        davis_biases: DAVIS346 bias name (``On``, ``Off``, ``Diff``, ``Refractory``, ...) -> [coarse, fine]
            (unquoted On / Off, which YAML reads as true / false, are taken back as names).
        trigger_in: run the external signal detector on both edges (None: untouched).
        stall_timeout_s: raise "camera stopped delivering data" after this long without any event (0: never).
    """

    serial: str | int = ""
    roi: Roi | None = None
    contrast_threshold_on: int | None = None
    contrast_threshold_off: int | None = None
    readout_fps: str | None = None
    davis_biases: dict[Any, tuple[int, int]] = field(default_factory=dict)
    trigger_in: bool | None = None
    stall_timeout_s: float = 5.0

    def __post_init__(self) -> None:
        check_serial(self.serial)
        if self.stall_timeout_s < 0:
            raise ConfigError("must be >= 0 (0: never)", key=f"{KEY}.stall_timeout_s")
        names = {}
        for name, value in self.davis_biases.items():  # YAML 1.1 reads unquoted On / Off as true / false
            name = YAML_BOOLEANS.get(name, name) if isinstance(name, bool) else name
            if not isinstance(name, str):
                raise ConfigError(f"bias names are text, got {name!r}", key=f"{KEY}.davis_biases")
            names[name] = value
        object.__setattr__(self, "davis_biases", names)


def check_config(hardware: dict[str, Any], path: str | None = None) -> InivationConfig:
    """``camera.hardware`` checked as far as it can be without the device (when a rig is loaded).

    Keys, types, the ROI's form and the DAVIS coarse / fine ranges (3 and 8 bits); the bias names,
    the readout rate and whether the ROI fits the sensor are checked when the camera opens.

    Raises:
        ConfigError: naming ``camera.hardware.<key>`` and the rig file ``path``.
    """
    cfg = from_mapping(InivationConfig, hardware, path=path, key=KEY)
    for name, (coarse, fine) in cfg.davis_biases.items():
        if not (0 <= coarse <= 7 and 0 <= fine <= 255):
            raise ConfigError(
                f"[coarse, fine] must be in [0..7, 0..255], got [{coarse}, {fine}]",
                key=f"{KEY}.davis_biases.{name}",
                path=path,
            )
    return cfg


def open_from_config(hardware: dict[str, Any]) -> InivationCamera:
    """The camera ``camera.hardware`` describes (checked here; dv-processing is imported by ``open``).

    Raises:
        ConfigError: unknown key or wrong type, naming ``camera.hardware.<key>``.
    """
    return InivationCamera(from_mapping(InivationConfig, hardware, key=KEY))


class InivationCamera:
    """A :class:`~flagtrack.drivers.camera.base.Camera` reading an iniVation camera through dv-processing."""

    def __init__(self, cfg: InivationConfig) -> None:
        self.cfg = cfg
        self.label = device_label(cfg.serial)
        self._camera: Any = None
        self._offset_us = 0
        self._triggers_on = False
        self._stall = StallWatch(cfg.stall_timeout_s, self.label)

    def open(self) -> CameraInfo:
        dv = import_sdk("dv_processing", "inivation", INSTALL_HINT)
        cameras = getattr(getattr(dv, "io", None), "camera", None)
        if cameras is None or not hasattr(cameras, "open"):
            raise DriverError(
                f"this dv-processing has no dv.io.camera.open (2.0 or newer is needed): {INSTALL_HINT}",
                device=self.label,
            )
        try:
            camera = cameras.open(self.cfg.serial) if self.cfg.serial else cameras.open()
        except Exception as exc:
            seen = ", ".join(str(getattr(d, "serialNumber", d)) for d in (call_or_none(cameras, "discover") or []))
            raise DriverError(
                f"cannot open the camera: {exc} (connected: {seen or 'none'}; check the USB cable and the udev rules)",
                device=self.label,
            ) from exc
        serial = str(call_or_none(camera, "getSerialNumber") or self.cfg.serial)
        self.label = device_label(serial)
        resolution = call_or_none(camera, "getEventResolution")
        if not resolution:
            raise DriverError("the camera has no event stream", device=self.label)
        width, height = int(resolution[0]), int(resolution[1])
        settings = self._apply(camera, width, height)
        offset = call_or_none(camera, "getTimestampOffset")
        self._offset_us = offset // timedelta(microseconds=1) if isinstance(offset, timedelta) else int(offset or 0)
        settings.update(
            {
                "driver": "dv-processing",
                "serial": serial,
                "camera": call_or_none(camera, "getCameraName"),
                "firmware": call_or_none(camera, "getFirmwareVersion"),
                "logic_version": call_or_none(camera, "getLogicVersion"),
                "connection": call_or_none(camera, "getConnectionSpeed"),
                "timestamp_offset_us": self._offset_us,
            }
        )
        self._triggers_on = bool(call_or_none(camera, "isTriggerStreamAvailable"))
        self._camera = camera
        self._stall = StallWatch(self.cfg.stall_timeout_s, self.label)
        settings = plain(settings)
        log.info("%s: %dx%d, settings %s", self.label, width, height, settings)
        return CameraInfo("inivation", width, height, "evt3", serial=serial, settings=settings)

    def read(self, timeout_s: float) -> CameraData | None:
        if self._camera is None:
            raise DriverError("camera is not open", device=self.label)
        deadline = time.monotonic() + max(timeout_s, 0.0)
        while True:
            try:
                store = self._camera.getNextEventBatch()
                triggers = self._camera.getNextTriggerBatch() if self._triggers_on else None
                running = store is not None or self._camera.isRunning()
            except Exception as exc:
                raise DriverError(f"camera failed or was unplugged: {exc}", device=self.label) from exc
            if not running:
                raise DriverError("the camera stopped running (unplugged?)", device=self.label)
            events = self._events(store) if store is not None else empty_events()
            trig = self._triggers(triggers) if triggers else empty_triggers()
            if len(events) or len(trig):
                self._stall.fed()
                return CameraData(events, trig, time.time_ns())
            if time.monotonic() >= deadline:
                self._stall.check()
                return None
            time.sleep(POLL_INTERVAL_S)

    def close(self) -> None:
        self._camera = None  # dv-processing releases the device when the object is collected

    def _events(self, store: Any) -> np.ndarray:
        t = np.asarray(store.timestamps(), dtype=np.int64)
        events = np.empty(len(t), dtype=EVENT_DTYPE)
        if len(t):
            xy = np.asarray(store.coordinates())
            events["t"] = t - self._offset_us
            events["x"] = xy[:, 0]
            events["y"] = xy[:, 1]
            events["p"] = np.asarray(store.polarities()) != 0
        return events

    def _triggers(self, batch: Any) -> np.ndarray:
        kept = [
            (int(tr.timestamp) - self._offset_us, *TRIGGERS[tr.type.name])
            for tr in batch
            if getattr(tr.type, "name", "") in TRIGGERS
        ]
        return np.array(kept, dtype=TRIGGER_DTYPE) if kept else empty_triggers()

    def _apply(self, camera: Any, width: int, height: int) -> dict[str, Any]:
        """Apply the configured settings; return them as read back from the camera."""
        cfg = self.cfg
        out: dict[str, Any] = {}
        if cfg.roi is not None:
            r = cfg.roi.on_sensor(width, height)
            _set(camera, "setCropArea", "roi", (r.x, r.y, r.width, r.height))
        area = call_or_none(camera, "getCropArea")
        out["roi"] = dict(zip(("x", "y", "width", "height"), map(int, area))) if area is not None else None
        for polarity in ("on", "off"):
            value = getattr(cfg, f"contrast_threshold_{polarity}")
            method = f"ContrastThreshold{polarity.capitalize()}"
            if value is not None:
                _set(camera, f"set{method}", f"contrast_threshold_{polarity}", value)
            out[f"contrast_threshold_{polarity}"] = call_or_none(camera, f"get{method}")
        if cfg.readout_fps is not None:
            _set(camera, "setReadoutFPS", "readout_fps", _member(camera, "ReadoutFPS", cfg.readout_fps, "readout_fps"))
        out["readout_fps"] = call_or_none(camera, "getReadoutFPS")
        for name, (coarse, fine) in cfg.davis_biases.items():
            bias = _member(camera, "Davis346BiasCF", name, f"davis_biases.{name}")
            _set(camera, "setDavis346BiasCoarseFine", f"davis_biases.{name}", bias, coarse, fine)
        if cfg.davis_biases:
            out["davis_biases"] = {
                name: list(camera.getDavis346BiasCoarseFine(camera.Davis346BiasCF.__members__[name]))
                for name in cfg.davis_biases
            }
        if cfg.trigger_in is not None:
            if cfg.trigger_in:
                _set(camera, "setDetectorRisingEdges", "trigger_in", True)
                _set(camera, "setDetectorFallingEdges", "trigger_in", True)
            _set(camera, "setDetectorRunning", "trigger_in", cfg.trigger_in)
        out["trigger_in"] = call_or_none(camera, "isDetectorRunning")
        return out


def _set(camera: Any, method: str, key: str, *args: Any) -> None:
    """Call a setter; a camera without it, or refusing the value, is a ConfigError naming the key."""
    fn = getattr(camera, method, None)
    if fn is None:
        name = call_or_none(camera, "getCameraName") or type(camera).__name__
        raise ConfigError(f"{name} has no such setting ({method})", key=f"{KEY}.{key}")
    try:
        fn(*args)
    except Exception as exc:
        raise ConfigError(f"the camera refused {args}: {exc}", key=f"{KEY}.{key}") from exc


def _member(camera: Any, enum_name: str, name: str, key: str) -> Any:
    """A member of one of the camera class's enums (``ReadoutFPS``, ``Davis346BiasCF``) by name."""
    enum = getattr(camera, enum_name, None)
    members = getattr(enum, "__members__", {}) if enum is not None else {}
    if name not in members:
        known = ", ".join(members) if members else f"none: this camera has no {enum_name}"
        raise ConfigError(f"unknown value {name!r} (known: {known})", key=f"{KEY}.{key}")
    return members[name]
