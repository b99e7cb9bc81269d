"""Shared parts of the hardware camera adapters (Prophesee, Metavision HAL, iniVation).

The adapters import their SDK only when a camera is opened (:func:`import_sdk`, with the install
hint in the error), decode the raw EVT bytes a device gives with our streaming decoders
(:class:`RawStream`, buffers may cut words anywhere), and report a device that stops delivering
data (:class:`StallWatch`). Settings read back from a device are made JSON-friendly with
:func:`plain` before they go into :class:`~flagtrack.drivers.camera.base.CameraInfo`.
"""

from __future__ import annotations

import dataclasses
import enum
import importlib
import logging
import time
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from flagtrack.daemon.core.events import MAX_SENSOR_PX, empty_events, empty_triggers
from flagtrack.daemon.errors import ConfigError, DriverError
from flagtrack.drivers.camera.base import CameraData, DeviceDrop
from flagtrack.drivers.formats import make_decoder

log = logging.getLogger(__name__)

KEY = "camera.hardware"
"""Dotted prefix of the hardware settings in a rig config (errors name ``camera.hardware.<key>``)."""

PUBLISHED_ENCODING = {"evt3": "evt3", "evt2": "evt2", "evt21": "evt2"}
"""Encoding of our packets for a device encoding: the packetizer writes EVT 2.0 or EVT 3.0 only."""
_NO_EVENTS, _NO_TRIGGERS = empty_events(), empty_triggers()
CORRUPT_WORDS = "corrupt words in the camera's EVT 2.1 stream skipped (their events lost)"


@dataclass(frozen=True)
class Roi:
    """A rectangular region of interest, pixels: events outside it are not produced by the sensor.

    Attributes:
        x, y: top-left pixel (column, row) of the region.
        width, height: size of the region, pixels.
        clip: cut the region at the sensor's edges instead of refusing it (``roi: auto``, worked out
            before the sensor's size is known).
    """

    x: int
    y: int
    width: int
    height: int
    clip: bool = False

    def __post_init__(self) -> None:
        if self.x < 0 or self.y < 0:
            raise ConfigError("x and y must be >= 0", key=f"{KEY}.roi")
        if self.width < 1 or self.height < 1:
            raise ConfigError("width and height must be >= 1", key=f"{KEY}.roi")
        if self.x + self.width > MAX_SENSOR_PX or self.y + self.height > MAX_SENSOR_PX:  # (1e9 passed config check)
            raise ConfigError(
                f"{self.as_dict()} reaches past any event sensor ({MAX_SENSOR_PX} pixels)", key=f"{KEY}.roi"
            )

    def check_inside(self, width: int, height: int) -> None:
        """Raise ConfigError unless the region fits a ``width`` x ``height`` sensor."""
        if self.x + self.width > width or self.y + self.height > height:
            raise ConfigError(f"region {self.as_dict()} does not fit the {width}x{height} sensor", key=f"{KEY}.roi")

    def on_sensor(self, width: int, height: int) -> Roi:
        """The region on a ``width`` x ``height`` sensor: cut at its edges (``clip``), else checked.

        Raises:
            ConfigError: the region does not fit the sensor (nothing of it is on it, with ``clip``).
        """
        if not self.clip:
            self.check_inside(width, height)
            return self
        if self.x >= width or self.y >= height:
            raise ConfigError(f"region {self.as_dict()} lies off the {width}x{height} sensor", key=f"{KEY}.roi")
        return Roi(self.x, self.y, min(self.width, width - self.x), min(self.height, height - self.y))

    def as_dict(self) -> dict[str, int]:
        return {"x": self.x, "y": self.y, "width": self.width, "height": self.height}


def check_serial(serial: object) -> None:
    """A serial YAML read as a number (``serial: 00050423`` unquoted) is an error that says to quote it."""
    if isinstance(serial, int) and not isinstance(serial, bool):
        raise ConfigError(
            f'write the serial in quotes (serial: "..."): YAML read it as the number {serial}', key=f"{KEY}.serial"
        )


def device_label(serial: str | int | None) -> str:
    """How errors name the device: ``camera 'SERIAL'`` or ``first camera``."""
    return f"camera '{serial}'" if serial else "first camera"


def import_sdk(module: str, adapter: str, hint: str) -> ModuleType:
    """Import a camera SDK module, or raise DriverError telling the user how to install it.

    Args:
        module: import name (``neuromorphic_drivers``, ``metavision_hal``, ``dv_processing``).
        adapter: adapter name, for the message.
        hint: what to install (the exact ``pip install`` line or build instructions).
    """
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise DriverError(
            f"the '{adapter}' camera adapter needs the {module} module, which cannot be imported ({exc}): {hint}",
            device=f"camera adapter '{adapter}'",
        ) from exc


def sdk_version(distribution: str, module: ModuleType) -> str:
    """Version of an installed SDK (its distribution metadata, else ``__version__``, else empty)."""
    version = getattr(module, "__version__", None)
    if version:
        return str(version)
    try:
        from importlib.metadata import PackageNotFoundError
        from importlib.metadata import version as dist_version

        return dist_version(distribution)
    except (ImportError, PackageNotFoundError, ValueError):
        return ""


class RawStream:
    """A device's raw EVT byte stream, cut anywhere, as :class:`CameraData`: the bytes themselves
    (EVT 3.0/2.0) or, for EVT 2.1, decoded (corrupt words skipped, counted in ``faults`` and
    reported as drops).

    Args:
        encoding: the device's encoding (``evt3``, ``evt2`` or ``evt21``).
        width, height: sensor size, pixels.
        endianness: EVT 2.1 layout (``little`` or ``legacy``).
        device: device label for messages.
    """

    def __init__(self, encoding: str, width: int, height: int, endianness: str = "little", device: str = "") -> None:
        if encoding not in PUBLISHED_ENCODING:
            raise DriverError(f"unsupported device encoding {encoding!r} (known: evt3, evt2, evt21)", device=device)
        self.encoding = encoding
        self.published = PUBLISHED_ENCODING[encoding]
        self.decoder = make_decoder(
            encoding, width=width, height=height, strict=False, endianness=endianness, source=device
        )
        self.bytes = 0

    @property
    def faults(self) -> int:
        """Corrupt words skipped so far."""
        return self.decoder.faults

    def take(self, data: bytes | bytearray | memoryview) -> CameraData:
        """The next bytes (any length): handed over as they are in EVT 3.0/2.0 (the camera service cuts
        them into packets), decoded into events and triggers in EVT 2.1 (published as EVT 2.0)."""
        arrival_ns = time.time_ns()
        self.bytes += len(data)
        if self.published == self.encoding:
            return CameraData(_NO_EVENTS, _NO_TRIGGERS, arrival_ns, raw=bytes(data))
        faults = self.decoder.faults
        events, triggers = self.decoder.decode(data)
        skipped = self.decoder.faults - faults
        drops = (DeviceDrop(CORRUPT_WORDS, skipped, "words"),) if skipped else ()
        return CameraData(events, triggers, arrival_ns, drops=drops)


class StallWatch:
    """Raises DriverError when a device has delivered no data at all for ``timeout_s``.

    Args:
        timeout_s: allowed silence, seconds (None or 0: never raise).
        device: device label for the message.
    """

    def __init__(self, timeout_s: float | None, device: str) -> None:
        self.timeout_s = timeout_s
        self.device = device
        self._last = time.monotonic()

    def fed(self) -> None:
        """Data arrived."""
        self._last = time.monotonic()

    def check(self) -> None:
        """Raise DriverError if the silence has lasted longer than the timeout."""
        silent_s = time.monotonic() - self._last
        if self.timeout_s and silent_s > self.timeout_s:
            raise DriverError(
                f"camera stopped delivering data (nothing for {silent_s:.1f} s, stall_timeout_s = {self.timeout_s:g})",
                device=self.device,
            )


def parse_encoding(name: str) -> tuple[str, str]:
    """Our encoding and EVT 2.1 layout for an SDK format string (``EVT3``, ``EVT 3.0``, ``EVT21;endianness=legacy``).

    Raises:
        DriverError: the format is not one of EVT 2.0, 2.1, 3.0.
    """
    head, *options = str(name).split(";")
    token = "".join(ch for ch in head.upper() if ch.isalnum())
    encoding = {"EVT3": "evt3", "EVT30": "evt3", "EVT2": "evt2", "EVT20": "evt2", "EVT21": "evt21"}.get(token)
    if encoding is None:
        raise DriverError(f"the camera streams {name!r}, which flagtrack cannot decode (EVT 2.0, 2.1, 3.0 only)")
    fields = dict(option.split("=", 1) for option in options if "=" in option)
    endianness = fields.get("endianness", "little").strip().lower()
    return encoding, endianness if endianness in ("little", "legacy") else "little"


def plain(value: Any) -> Any:
    """A JSON-friendly copy of a settings value (dataclasses, enums, numpy scalars, tuples)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, enum.Enum):  # text values (neuromorphic-drivers' names) read better than member names
        return value.value if isinstance(value.value, str) else value.name
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, str | int | float | bool):
        return value
    name = getattr(value, "name", None)  # pybind11 enums
    return name if isinstance(name, str) else str(value)


def call_or_none(obj: Any, method: str, *args: Any) -> Any:
    """``obj.method(*args)``, or None when the SDK version lacks it or the device refuses."""
    fn = getattr(obj, method, None)
    if fn is None:
        return None
    try:
        return fn(*args)
    except Exception as exc:  # noqa: BLE001 - optional read-back: SDKs raise anything
        log.debug("%s(%s) failed: %s", method, args, exc)
        return None
