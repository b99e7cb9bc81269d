"""Prophesee-sensor cameras (EVK4, EVK3 HD, CenturyArks SilkyEvCam VGA, ...) through ``neuromorphic-drivers``.

neuromorphic-drivers (PyPI, ``pip install -e '.[prophesee]'``) talks USB directly (no
OpenEB needed). The camera is opened in raw mode: it yields the sensor's EVT 3.0 bytes, which are
handed to the camera service as they are (it cuts them into packets: docs/formats.md). Biases, ROI (row/column masks), the rate limiter and the external trigger
input come from ``camera.hardware`` of the rig config and are applied with
``update_configuration``; the library cannot read registers back, so the settings reported in
:class:`CameraInfo` are the ones applied, after clamping each bias to the bounds the device
reports (``biases_bounds()``), as the device does.

What the library drops is reported with the data (``CameraData.drops``): USB packets its host ring
had no room for (``RawRingStatus.dropped_packets`` rising, or ``overflow_indices`` marking holes),
and the backlog this adapter clears (``clear_backlog``) when the host falls more than
``max_backlog_packets`` behind.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from flagtrack.daemon.errors import ConfigError, DriverError
from flagtrack.daemon.typed_yaml import from_mapping
from flagtrack.drivers.camera.base import CameraData, CameraInfo, DeviceDrop
from flagtrack.drivers.camera.hardware import (
    KEY,
    RawStream,
    Roi,
    StallWatch,
    call_or_none,
    check_serial,
    device_label,
    import_sdk,
    plain,
    sdk_version,
)

log = logging.getLogger(__name__)

INSTALL_HINT = "pip install -e '.[prophesee]' in flagtrack's folder (installs neuromorphic-drivers from PyPI)"
ITERATOR_TIMEOUT_S = 0.02
"""How long one step of the device iterator waits for data (reads loop over steps until their timeout)."""
RING_FULL = "neuromorphic-drivers dropped USB packets: the host's ring was full (the host fell behind)"
BACKLOG_CLEARED = "backlog cleared: the host fell more than camera.hardware.max_backlog_packets USB packets behind"


@dataclass(frozen=True)
class RateLimiterConfig:
    """The sensor's event rate limiter: at most ``maximum_events_per_period`` per ``reference_period_us``."""

    reference_period_us: int
    maximum_events_per_period: int

    def __post_init__(self) -> None:
        if not 1 <= self.reference_period_us <= 0xFFFF:
            raise ConfigError("must be in 1..65535", key=f"{KEY}.rate_limiter.reference_period_us")
        if not 1 <= self.maximum_events_per_period <= 0xFFFFFFFF:
            raise ConfigError("must be in 1..4294967295", key=f"{KEY}.rate_limiter.maximum_events_per_period")


@dataclass(frozen=True)
class PropheseeConfig:
    """``camera.hardware`` of ``adapter: prophesee``.

    Attributes:
        serial: serial number of the camera to open (None: the first Prophesee-sensor camera found; a
            number YAML read from an unquoted serial is refused with a hint to quote it).
        biases: bias name -> value, names as neuromorphic-drivers spells them for the model
            (EVK4: ``diff_on``, ``diff_off``, ``fo``, ``hpf``, ``refr``, ...); others keep their defaults.
        roi: region of interest (pixels outside it are masked by row/column masks).
        rate_limiter: the sensor's rate limiter (None: off).
        trigger_in: enable the external trigger input (None: the library's default).
        encoding: the raw stream's encoding; ``auto`` is EVT 3.0, which neuromorphic-drivers
            configures on every Prophesee-sensor camera.
        stall_timeout_s: raise "camera stopped delivering data" after this long without any byte (0: never).
        max_backlog_packets: when more USB packets than this wait in the host's ring, drop them all
            (``clear_backlog``) to catch up with the camera, reported as a drop (None: never).
    """

    serial: str | int | None = None
    biases: dict[str, int] = field(default_factory=dict)
    roi: Roi | None = None
    rate_limiter: RateLimiterConfig | None = None
    trigger_in: bool | None = None
    encoding: Literal["auto", "evt3", "evt2", "evt21"] = "auto"
    stall_timeout_s: float = 5.0
    max_backlog_packets: int | None = None

    def __post_init__(self) -> None:
        check_serial(self.serial)
        if self.stall_timeout_s < 0:
            raise ConfigError("must be >= 0 (0: never)", key=f"{KEY}.stall_timeout_s")
        if self.max_backlog_packets is not None and self.max_backlog_packets < 1:
            raise ConfigError("must be >= 1 (omit it: never clear)", key=f"{KEY}.max_backlog_packets")


MODEL_BIASES = {
    "Prophesee EVK4": (
        "pr",
        "fo",
        "hpf",
        "diff_on",
        "diff",
        "diff_off",
        "inv",
        "refr",
        "reqpuy",
        "reqpux",
        "sendreqpdy",
        "unknown_1",
        "unknown_2",
    ),
    "Prophesee EVK3 HD": ("pr", "fo_p", "fo_n", "hpf", "diff_on", "diff", "diff_off", "refr", "reqpuy", "blk"),
    "CenturyArks VGA": ("diff_on", "diff", "diff_off", "fo", "hpf", "pr", "refr"),
}
"""Bias names of each model, as neuromorphic-drivers (0.18) spells them (docs/cameras.md)."""
KNOWN_BIASES = tuple(dict.fromkeys(name for names in MODEL_BIASES.values() for name in names))


def check_config(hardware: dict[str, Any], path: str | None = None) -> PropheseeConfig:
    """``camera.hardware`` checked as far as it can be without the device (when a rig is loaded).

    Keys, types, the ROI's form and each bias name against the names of every known model; whether
    the model in hand has that bias and whether the ROI fits its sensor are checked when it opens.

    Raises:
        ConfigError: naming ``camera.hardware.<key>`` and the rig file ``path``.
    """
    cfg = from_mapping(PropheseeConfig, hardware, path=path, key=KEY)
    for name in cfg.biases:
        if name not in KNOWN_BIASES:
            raise ConfigError(
                f"no Prophesee-sensor camera has a bias {name!r} (known: {', '.join(KNOWN_BIASES)})",
                key=f"{KEY}.biases.{name}",
                path=path,
            )
    return cfg


def open_from_config(hardware: dict[str, Any]) -> PropheseeCamera:
    """The camera ``camera.hardware`` describes (checked here; the SDK is imported by ``open``).

    Raises:
        ConfigError: unknown key or wrong type, naming ``camera.hardware.<key>``.
    """
    return PropheseeCamera(from_mapping(PropheseeConfig, hardware, key=KEY))


class PropheseeCamera:
    """A :class:`~flagtrack.drivers.camera.base.Camera` reading a Prophesee-sensor camera (neuromorphic-drivers)."""

    def __init__(self, cfg: PropheseeConfig) -> None:
        self.cfg = cfg
        self.label = device_label(cfg.serial)
        self._device: Any = None
        self._stream: RawStream | None = None
        self._stall = StallWatch(cfg.stall_timeout_s, self.label)
        self.dropped_packets = 0  # the library's count, as last reported
        self._drops: list[DeviceDrop] = []  # not yet handed over with data

    def open(self) -> CameraInfo:
        nd = import_sdk("neuromorphic_drivers", "prophesee", INSTALL_HINT)
        listed = self._find(nd)
        serial = listed.serial or self.cfg.serial
        self.label = device_label(serial)
        module = getattr(nd, listed.name.name.lower(), None)
        if module is None or not hasattr(module, "Configuration"):
            raise DriverError(f"{listed.name.value} is not supported by this neuromorphic-drivers", device=self.label)
        try:
            device = nd.open(serial=serial, raw=True, iterator_timeout=ITERATOR_TIMEOUT_S)
        except Exception as exc:
            raise DriverError(f"cannot open {listed.name.value}: {exc}", device=self.label) from exc
        try:
            bounds = call_or_none(device, "biases_bounds")
            configuration, clamped = build_configuration(module, self.cfg, bounds, listed.name.value)
            device.update_configuration(configuration)
            properties = device.properties()
            encoding = "evt3" if self.cfg.encoding == "auto" else self.cfg.encoding
            self._stream = RawStream(encoding, int(properties.width), int(properties.height), device=self.label)
            settings = self._settings(nd, device, listed, configuration, bounds, clamped)
        except BaseException:
            _close(device)
            raise
        self._device = device
        self._stall = StallWatch(self.cfg.stall_timeout_s, self.label)
        log.info(
            "%s: %s %dx%d, settings %s", self.label, listed.name.value, properties.width, properties.height, settings
        )
        return CameraInfo(
            "prophesee",
            int(properties.width),
            int(properties.height),
            self._stream.published,
            serial=str(serial or ""),
            settings=settings,
        )

    def read(self, timeout_s: float) -> CameraData | None:
        if self._device is None or self._stream is None:
            raise DriverError("camera is not open", device=self.label)
        deadline = time.monotonic() + max(timeout_s, 0.0)
        while True:
            try:
                status, packet = next(self._device)
            except StopIteration:
                raise DriverError("the camera's stream ended", device=self.label) from None
            except Exception as exc:
                raise DriverError(f"camera failed or was unplugged: {exc}", device=self.label) from exc
            self._note_drops(status)
            if packet:
                self._stall.fed()
                data = self._stream.take(packet)
                drops, self._drops = tuple(self._drops), []
                self._clear_backlog(status)  # reported with the next data
                return replace(data, drops=drops + data.drops) if drops else data
            if time.monotonic() >= deadline:
                self._stall.check()
                return None

    def close(self) -> None:
        device, self._device = self._device, None
        if device is not None:
            _close(device)

    def _find(self, nd: Any) -> Any:
        """The listed device to open: the one with the configured serial, else the first Prophesee one."""
        try:
            devices = list(nd.list_devices())
        except Exception as exc:
            raise DriverError(f"cannot list USB devices: {exc}", device=self.label) from exc
        prophesee = [d for d in devices if not d.name.name.startswith("INIVATION")]
        matches = [d for d in prophesee if not self.cfg.serial or d.serial == self.cfg.serial]
        if not matches:
            seen = (
                ", ".join(f"{d.name.value} '{d.serial}'" + (f" ({d.error})" if d.error else "") for d in devices)
                or "none"
            )
            hint = (
                " (an iniVation camera: use adapter: inivation)"
                if any(d.serial == self.cfg.serial for d in devices)
                else ""
            )
            raise DriverError(f"no such Prophesee-sensor camera found{hint}; connected: {seen}", device=self.label)
        if matches[0].error:
            raise DriverError(
                f"{matches[0].name.value} found but not usable: {matches[0].error} "
                "(permissions: install the udev rules, see docs/cameras.md)",
                device=self.label,
            )
        return matches[0]

    def _settings(
        self, nd: Any, device: Any, listed: Any, configuration: Any, bounds: Any, clamped: list[str]
    ) -> dict[str, Any]:
        properties = device.properties()
        roi = self.cfg.roi.on_sensor(properties.width, properties.height).as_dict() if self.cfg.roi else None
        settings: dict[str, Any] = {
            "driver": "neuromorphic-drivers",
            "driver_version": sdk_version("neuromorphic-drivers", nd),
            "model": listed.name.value,
            "serial": plain(call_or_none(device, "serial")),
            "connection": plain(call_or_none(device, "connection") or call_or_none(device, "speed")),
            "device_encoding": self._stream.encoding if self._stream else "",
            "biases": plain(configuration.biases),
            "biases_clamped": clamped,
            "roi": roi,
            "rate_limiter": plain(getattr(configuration, "rate_limiter", None)),
            "trigger_in": plain(getattr(configuration, "enable_external_trigger", None)),
            "max_backlog_packets": self.cfg.max_backlog_packets,
        }
        if bounds is not None:
            settings["biases_bounds"] = {k: [v["minimum"], v["maximum"]] for k, v in plain(bounds).items()}
        temperature = call_or_none(device, "temperature_celsius")
        if temperature is not None:
            settings["temperature_celsius"] = float(temperature)
        return settings

    def _note_drops(self, status: Any) -> None:
        """The USB packets the library dropped since the last status (its count rising; an
        ``overflow_indices`` hole where the count did not move: a drop of unknown size)."""
        ring = getattr(status, "ring", None)
        if ring is None:
            return
        dropped = getattr(ring, "dropped_packets", None)
        new = 0
        if isinstance(dropped, int):
            new = dropped - self.dropped_packets if dropped >= self.dropped_packets else dropped
            self.dropped_packets = dropped
        if new > 0:
            log.warning("%s: %d USB packets dropped by the host (%d so far; ring full)", self.label, new, dropped)
            self._drops.append(DeviceDrop(RING_FULL, new, "usb_packets"))
        elif getattr(ring, "overflow_indices", None):
            log.warning("%s: the host's ring overflowed (USB packets dropped)", self.label)
            self._drops.append(DeviceDrop(RING_FULL, 0, "usb_packets"))

    def _clear_backlog(self, status: Any) -> None:
        """Drop every USB packet waiting in the host's ring when more than ``max_backlog_packets`` wait."""
        ring, limit = getattr(status, "ring", None), self.cfg.max_backlog_packets
        backlog = getattr(ring, "backlog", 0) if ring is not None else 0
        if limit is None or backlog <= limit:
            return
        try:
            self._device.clear_backlog(until=0)
        except Exception as exc:
            raise DriverError(f"camera failed or was unplugged: {exc}", device=self.label) from exc
        log.warning("%s: %d USB packets waited in the host's ring: cleared them to catch up", self.label, backlog)
        self._drops.append(DeviceDrop(BACKLOG_CLEARED, int(backlog), "usb_packets"))


def build_configuration(module: Any, cfg: PropheseeConfig, bounds: Any, model: str) -> tuple[Any, list[str]]:
    """The neuromorphic-drivers Configuration of a model for ``cfg``; also the names of clamped biases.

    Args:
        module: the model's module (``nd.prophesee_evk4``, ...).
        cfg: the adapter settings.
        bounds: the device's ``biases_bounds()`` (None: no clamping).
        model: model name for messages.

    Raises:
        ConfigError: a bias name or a setting the model does not have, naming its key.
    """
    fields = {f.name for f in dataclasses.fields(module.Configuration)}
    biases, clamped = _biases(module.Biases, cfg.biases, bounds, model)
    kwargs: dict[str, Any] = {"biases": biases}
    if cfg.roi is not None:
        if not {"x_mask", "y_mask"} <= fields:
            raise ConfigError(f"{model} has no ROI masks", key=f"{KEY}.roi")
        properties = module.Properties()
        roi = cfg.roi.on_sensor(int(properties.width), int(properties.height))
        defaults = module.Configuration()
        kwargs["x_mask"] = _mask_words(roi.x, roi.width, int(properties.width), len(defaults.x_mask))
        kwargs["y_mask"] = _mask_words(roi.y, roi.height, int(properties.height), len(defaults.y_mask))
        if "mask_intersection_only" in fields:
            kwargs["mask_intersection_only"] = False
    if cfg.rate_limiter is not None:
        if "rate_limiter" not in fields or not hasattr(module, "RateLimiter"):
            raise ConfigError(f"{model} has no rate limiter", key=f"{KEY}.rate_limiter")
        kwargs["rate_limiter"] = module.RateLimiter(
            reference_period_us=cfg.rate_limiter.reference_period_us,
            maximum_events_per_period=cfg.rate_limiter.maximum_events_per_period,
        )
    if cfg.trigger_in is not None:
        if "enable_external_trigger" not in fields:
            raise ConfigError(f"{model} has no external trigger input", key=f"{KEY}.trigger_in")
        kwargs["enable_external_trigger"] = cfg.trigger_in
    return module.Configuration(**kwargs), clamped


def _biases(biases_cls: Any, wanted: dict[str, int], bounds: Any, model: str) -> tuple[Any, list[str]]:
    """The model's Biases with ``wanted`` set, each clamped to the device's bounds."""
    names = [f.name for f in dataclasses.fields(biases_cls)]
    values = {}
    clamped = []
    for name, value in wanted.items():
        if name not in names:
            raise ConfigError(f"{model} has no bias {name!r} (known: {', '.join(names)})", key=f"{KEY}.biases.{name}")
        limits = getattr(bounds, name, None) if bounds is not None else None
        if limits is not None and limits.minimum <= limits.maximum:
            fitted = min(max(value, int(limits.minimum)), int(limits.maximum))
            if fitted != value:
                log.warning(
                    "bias %s = %d is outside the device's bounds [%d, %d]: set to %d",
                    name,
                    value,
                    limits.minimum,
                    limits.maximum,
                    fitted,
                )
                clamped.append(name)
            value = fitted
        values[name] = value
    return biases_cls(**values), clamped


def _mask_words(start: int, size: int, total: int, n_words: int) -> tuple[int, ...]:
    """Row or column mask as 64-bit words, bit i set = line i masked (outside [start, start + size))."""
    masked = np.ones(n_words * 64, dtype=bool)
    masked[total:] = False
    masked[start : start + size] = False
    return tuple(int(w) for w in np.packbits(masked, bitorder="little").view("<u8"))


def _close(device: Any) -> None:
    try:
        if hasattr(device, "close"):
            device.close()
        else:
            device.__exit__(None, None, None)
    except Exception as exc:  # noqa: BLE001 - closing a failed device must not hide the first error
        log.debug("closing the camera failed: %s", exc)
