"""Prophesee cameras through OpenEB's Metavision HAL Python bindings (``metavision_hal``), when installed.

OpenEB is not on PyPI: it is built from source or installed with Prophesee's Metavision SDK, and
brings the camera plugins (EVK4, EVK3, SilkyEvCam through CenturyArks' plugin, ...). The camera
is opened with ``DeviceDiscovery.open``. With OpenEB 4.x bindings the buffers of its events stream
(EVT 3.0, 2.0 or 2.1, as ``get_current_data_encoding_format`` says) are handed to the camera
service as they are (EVT 3.0/2.0: it cuts them into packets) or decoded by our decoders (EVT 2.1).
OpenEB 5.x bindings do not let Python read a buffer's bytes: the HAL's own decoder turns them into
events, published as EVT 2.0 (:mod:`.metavision_stream`); ``raw_log_dir`` has the HAL write the
device's own bytes to a file (``log_raw_data``). Biases, ROI, event rate controller (ERC)
and trigger input come from ``camera.hardware`` and are read back from the device where the
bindings can (``get_all_biases``, ``get_cd_event_rate``, ``is_enabled``); facilities or methods a
binding lacks are skipped in read-back. Drops: the HAL's Python bindings report none (no counter, no
callback; what the ERC drops by design is not counted); corrupt EVT 2.1 words flagtrack's decoder
skips (OpenEB 4) are reported as drops (``CameraData.drops``).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from flagtrack.daemon.errors import ConfigError, DriverError
from flagtrack.daemon.typed_yaml import from_mapping
from flagtrack.drivers.camera.base import CameraData, CameraInfo
from flagtrack.drivers.camera.hardware import (
    KEY,
    RawStream,
    Roi,
    StallWatch,
    call_or_none,
    check_serial,
    device_label,
    import_sdk,
    parse_encoding,
    plain,
    sdk_version,
)
from flagtrack.drivers.camera.metavision_stream import (
    DeviceBytes,
    HalDecoded,
    HalStream,
    buffers_are_opaque,
    start_raw_log,
)

log = logging.getLogger(__name__)

INSTALL_HINT = (
    "install OpenEB (or the Metavision SDK) with its Python bindings and make metavision_hal "
    "importable from this Python (see docs/cameras.md), or use adapter: prophesee "
    "(pip install -e '.[prophesee]' in flagtrack's folder)"
)
POLL_INTERVAL_S = 0.001


@dataclass(frozen=True)
class MetavisionConfig:
    """``camera.hardware`` of ``adapter: metavision``.

    Attributes:
        serial: serial number of the camera ("": the first camera found; quote it in YAML).
        format: data format asked of the camera at open (``EVT3``, ``EVT21``, ``EVT2``; None: its default).
        biases: HAL bias name (``bias_diff_on``, ``bias_diff_off``, ``bias_fo``, ``bias_hpf``, ``bias_refr``,
            ...) -> value; others keep the camera's defaults.
        roi: region of interest (one window).
        rate_limiter_events_per_s: event rate controller (ERC) limit, events per second (None: ERC untouched).
        trigger_in: enable (True) or disable (False) the main external trigger input (None: untouched).
        evt21_endianness: EVT 2.1 word layout; ``auto`` follows the format string, else OpenEB's rule.
        stall_timeout_s: raise "camera stopped delivering data" after this long without any byte (0: never).
        raw_log_dir: at each open, start a new RAW file in this folder with the camera's own bytes as the
            HAL records them (``log_raw_data``): the device's stream, byte for byte (None: no such file).
    """

    serial: str | int = ""
    format: str | None = None
    biases: dict[str, int] = field(default_factory=dict)
    roi: Roi | None = None
    rate_limiter_events_per_s: int | None = None
    trigger_in: bool | None = None
    evt21_endianness: Literal["auto", "little", "legacy"] = "auto"
    stall_timeout_s: float = 5.0
    raw_log_dir: str | None = None

    def __post_init__(self) -> None:
        check_serial(self.serial)
        if self.stall_timeout_s < 0:
            raise ConfigError("must be >= 0 (0: never)", key=f"{KEY}.stall_timeout_s")
        if self.rate_limiter_events_per_s is not None and self.rate_limiter_events_per_s < 0:
            raise ConfigError("must be >= 0", key=f"{KEY}.rate_limiter_events_per_s")


KNOWN_BIASES = ("bias_diff", "bias_diff_on", "bias_diff_off", "bias_fo", "bias_hpf", "bias_pr", "bias_refr")
"""HAL bias names of the sensors the adapter is written for (IMX636 / Gen4.1, Gen3.1; docs/cameras.md)."""


def check_config(hardware: dict[str, Any], path: str | None = None) -> MetavisionConfig:
    """``camera.hardware`` checked as far as it can be without the device (when a rig is loaded).

    Keys, types, the ROI's form and each bias name against the HAL names of the known sensors;
    whether the sensor in hand has that bias, takes its value and fits the ROI is checked when it opens.

    Raises:
        ConfigError: naming ``camera.hardware.<key>`` and the rig file ``path``.
    """
    cfg = from_mapping(MetavisionConfig, hardware, path=path, key=KEY)
    for name in cfg.biases:
        if name not in KNOWN_BIASES:
            raise ConfigError(
                f"not a HAL bias name (known: {', '.join(KNOWN_BIASES)})", key=f"{KEY}.biases.{name}", path=path
            )
    return cfg


def open_from_config(hardware: dict[str, Any]) -> MetavisionCamera:
    """The camera ``camera.hardware`` describes (checked here; ``metavision_hal`` is imported by ``open``).

    Raises:
        ConfigError: unknown key or wrong type, naming ``camera.hardware.<key>``.
    """
    return MetavisionCamera(from_mapping(MetavisionConfig, hardware, key=KEY))


class MetavisionCamera:
    """A :class:`~flagtrack.drivers.camera.base.Camera` reading a camera through OpenEB's HAL."""

    def __init__(self, cfg: MetavisionConfig) -> None:
        self.cfg = cfg
        self.label = device_label(cfg.serial)
        self._device: Any = None
        self._events_stream: Any = None
        self._stream: HalStream | None = None
        self._stall = StallWatch(cfg.stall_timeout_s, self.label)

    def open(self) -> CameraInfo:
        hal = import_sdk("metavision_hal", "metavision", INSTALL_HINT)
        device = self._open_device(hal)
        try:
            geometry = device.get_i_geometry()
            width, height = int(geometry.get_width()), int(geometry.get_height())
            hw = call_or_none(device, "get_i_hw_identification")
            serial = str(call_or_none(hw, "get_serial") or self.cfg.serial)
            self.label = device_label(serial)
            native = str(call_or_none(hw, "get_current_data_encoding_format") or self.cfg.format or "")
            settings: dict[str, Any] = {
                "driver": "openeb",
                "driver_version": sdk_version("metavision-hal", hal),
                "serial": serial,
                "device_encoding": native,
            }
            settings.update(self._identification(hw))
            settings["biases"] = self._apply_biases(device)
            settings["roi"] = self._apply_roi(hal, device, width, height)
            settings["rate_limiter"] = self._apply_erc(device)
            settings["trigger_in"] = self._apply_trigger(hal, device)
            self._stream = self._make_stream(hal, device, hw, native, width, height)
            settings["data_path"] = "hal_decoder" if isinstance(self._stream, HalDecoded) else "device_bytes"
            self._events_stream = device.get_i_events_stream()
            settings["raw_log"] = self._start_raw_log(serial)
            self._events_stream.start()
        except BaseException:
            if self._stream is not None:
                self._stream.close()
            self._device = self._events_stream = self._stream = None
            raise
        self._device = device
        self._stall = StallWatch(self.cfg.stall_timeout_s, self.label)
        settings = plain(settings)
        log.info("%s: %dx%d %s, settings %s", self.label, width, height, native, settings)
        return CameraInfo("metavision", width, height, self._stream.published, serial=serial, settings=settings)

    def read(self, timeout_s: float) -> CameraData | None:
        events_stream, stream = self._events_stream, self._stream
        if events_stream is None or stream is None:
            raise DriverError("camera is not open", device=self.label)
        deadline = time.monotonic() + max(timeout_s, 0.0)
        while True:
            try:
                status = events_stream.poll_buffer()
                data = stream.take(events_stream.get_latest_raw_data()) if status > 0 else None
            except Exception as exc:
                raise DriverError(f"camera failed or was unplugged: {exc}", device=self.label) from exc
            if status < 0:
                self._stream_stopped()
            if data is not None:
                self._stall.fed()
                return data
            if time.monotonic() >= deadline:
                self._stall.check()
                return None
            time.sleep(POLL_INTERVAL_S)

    def close(self) -> None:
        events_stream, stream = self._events_stream, self._stream
        self._events_stream = self._stream = self._device = None
        if events_stream is not None:
            try:
                events_stream.stop()
            except Exception as exc:  # noqa: BLE001
                log.debug("%s: stopping the events stream failed: %s", self.label, exc)
        if stream is not None:
            stream.close()

    def _start_raw_log(self, serial: str) -> str | None:
        if self.cfg.raw_log_dir is None:
            return None
        try:
            return start_raw_log(self._events_stream, Path(self.cfg.raw_log_dir).expanduser(), serial)
        except OSError as exc:
            raise ConfigError(f"cannot write the camera's bytes there: {exc}", key=f"{KEY}.raw_log_dir") from exc

    def _stream_stopped(self) -> None:
        """The events stream says it has stopped (``poll_buffer`` < 0): a camera only does when unplugged."""
        raise DriverError("the camera's events stream stopped (unplugged?)", device=self.label)

    def _make_stream(self, hal: Any, device: Any, hw: Any, native: str, width: int, height: int) -> HalStream:
        """The HAL's decoder where the bindings hide the bytes (OpenEB 5), else the device's bytes."""
        if buffers_are_opaque(hal):
            return HalDecoded(device, self.label)
        encoding, endianness = self._encoding(hw, native)
        return DeviceBytes(RawStream(encoding, width, height, endianness, device=self.label))

    def _open_device(self, hal: Any) -> Any:
        try:
            if self.cfg.format:
                config = hal.DeviceConfig()
                config.set_format(self.cfg.format)
                device = hal.DeviceDiscovery.open(self.cfg.serial, config)
            else:
                device = hal.DeviceDiscovery.open(self.cfg.serial)
        except Exception as exc:
            raise DriverError(f"cannot open the camera: {exc}", device=self.label) from exc
        if device is None:
            seen = call_or_none(hal.DeviceDiscovery, "list")
            raise DriverError(
                f"camera not found (connected: {', '.join(seen) if seen else 'none'}; "
                "check the USB cable, the udev rules and the OpenEB plugins)",
                device=self.label,
            )
        return device

    def _encoding(self, hw: Any, native: str) -> tuple[str, str]:
        """(our encoding, EVT 2.1 layout) of the camera's format string, for our decoders."""
        if not native:
            raise DriverError("cannot tell the camera's data format: set camera.hardware.format", device=self.label)
        try:
            encoding, endianness = parse_encoding(native)
        except DriverError as exc:
            raise DriverError(str(exc), device=self.label) from None
        if self.cfg.evt21_endianness != "auto":
            endianness = self.cfg.evt21_endianness
        elif encoding == "evt21" and "endianness" not in native:
            system_id = call_or_none(hw, "get_system_id")
            prophesee = call_or_none(hw, "get_integrator") == "Prophesee"
            endianness = "legacy" if prophesee and isinstance(system_id, int) and system_id < 0x37 else "little"
        return encoding, endianness

    def _identification(self, hw: Any) -> dict[str, Any]:
        sensor = call_or_none(hw, "get_sensor_info")
        return {
            "integrator": call_or_none(hw, "get_integrator"),
            "system_id": call_or_none(hw, "get_system_id"),
            "sensor": getattr(sensor, "name", None),
            "available_formats": call_or_none(hw, "get_available_data_encoding_formats"),
            "system_info": call_or_none(hw, "get_system_info"),
        }

    def _apply_biases(self, device: Any) -> dict[str, int] | None:
        facility = call_or_none(device, "get_i_ll_biases")
        if facility is None:
            if self.cfg.biases:
                raise ConfigError("this camera has no bias settings", key=f"{KEY}.biases")
            return None
        known = call_or_none(facility, "get_all_biases") or {}
        for name, value in self.cfg.biases.items():
            key = f"{KEY}.biases.{name}"
            if known and name not in known:
                raise ConfigError(f"unknown bias (known: {', '.join(sorted(known))})", key=key)
            try:
                ok = facility.set(name, int(value))
            except Exception as exc:
                raise ConfigError(f"the camera refused {value}: {exc}{_allowed(facility, name)}", key=key) from exc
            if ok is False:
                raise ConfigError(f"the camera refused {value}{_allowed(facility, name)}", key=key)
        return call_or_none(facility, "get_all_biases") or {n: facility.get(n) for n in self.cfg.biases}

    def _apply_roi(self, hal: Any, device: Any, width: int, height: int) -> dict[str, Any] | None:
        if self.cfg.roi is None:
            return None
        r = self.cfg.roi.on_sensor(width, height)
        facility = call_or_none(device, "get_i_roi")
        if facility is None:
            raise ConfigError("this camera has no ROI", key=f"{KEY}.roi")
        try:
            facility.set_window(hal.I_ROI.Window(r.x, r.y, r.width, r.height))
            facility.enable(True)
        except Exception as exc:
            raise ConfigError(f"the camera refused the ROI: {exc}", key=f"{KEY}.roi") from exc
        windows = call_or_none(facility, "get_windows")
        if windows:
            w = windows[0]
            return {"x": w.x, "y": w.y, "width": w.width, "height": w.height, "read_back": True}
        return {**r.as_dict(), "read_back": False}

    def _apply_erc(self, device: Any) -> dict[str, Any] | None:
        facility = call_or_none(device, "get_i_erc_module")
        if self.cfg.rate_limiter_events_per_s is not None:
            key = f"{KEY}.rate_limiter_events_per_s"
            if facility is None:
                raise ConfigError("this camera has no event rate controller (ERC)", key=key)
            try:
                facility.set_cd_event_rate(int(self.cfg.rate_limiter_events_per_s))
                facility.enable(True)
            except Exception as exc:
                low = call_or_none(facility, "get_min_supported_cd_event_rate")
                high = call_or_none(facility, "get_max_supported_cd_event_rate")
                raise ConfigError(f"the camera refused it: {exc} (supported: {low}..{high})", key=key) from exc
        if facility is None:
            return None
        return {
            "enabled": call_or_none(facility, "is_enabled"),
            "events_per_s": call_or_none(facility, "get_cd_event_rate"),
        }

    def _apply_trigger(self, hal: Any, device: Any) -> bool | None:
        facility = call_or_none(device, "get_i_trigger_in")
        if facility is None:
            if self.cfg.trigger_in is not None:
                raise ConfigError("this camera has no trigger input", key=f"{KEY}.trigger_in")
            return None
        channels = getattr(getattr(hal, "I_TriggerIn", None), "Channel", None)
        main = channels.MAIN if channels is not None else 0  # bindings before 4.0 take channel numbers
        if self.cfg.trigger_in is not None:
            ok = facility.enable(main) if self.cfg.trigger_in else facility.disable(main)
            if ok is False:
                raise ConfigError("the camera refused to change its trigger input", key=f"{KEY}.trigger_in")
        return call_or_none(facility, "is_enabled", main)


def _allowed(facility: Any, name: str) -> str:
    info = call_or_none(facility, "get_bias_info", name)
    allowed = call_or_none(info, "get_bias_allowed_range") if info is not None else None
    return f" (allowed: {allowed[0]}..{allowed[1]})" if allowed else ""
