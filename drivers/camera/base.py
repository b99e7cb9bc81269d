"""The camera interface every adapter implements, and what it yields."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from flagtrack.drivers.formats.packets import Packet


@dataclass(frozen=True)
class CameraInfo:
    """What an opened camera reports.

    Attributes:
        adapter: adapter name (``replay``, ``simulated``, ``prophesee``, ...).
        width, height: sensor size, pixels.
        encoding: native stream encoding (``evt3`` or ``evt2``).
        serial: device serial number or source file.
        settings: settings as read back from the device (biases, ROI, rate limiter, trigger, ...).
        t_offset_us: time the native bytes' times start from (a replayed flagtrack file's
            ``% t_offset_us``, whole time loops; 0 for a device).
    """

    adapter: str
    width: int
    height: int
    encoding: str
    serial: str = ""
    settings: dict[str, Any] = field(default_factory=dict)
    t_offset_us: int = 0


@dataclass(frozen=True)
class DeviceDrop:
    """Data the camera or its driver says it lost before the data it comes with.

    Attributes:
        reason: one line naming who dropped what and why (``neuromorphic-drivers dropped USB
            packets: the host's ring was full``).
        count: how many ``unit`` were lost (0: the device cannot say).
        unit: what ``count`` counts: ``usb_packets``, ``us`` (camera time skipped), ``words``, ``events``.
        t_from_us, t_to_us: the camera time lost, when the adapter knows it (None: the recorder
            takes the span between the packets around the drop).
    """

    reason: str
    count: int = 0
    unit: str = ""
    t_from_us: int | None = None
    t_to_us: int | None = None


@dataclass(frozen=True)
class CameraData:
    """A piece of the camera's stream: the device's own bytes (``raw``) or decoded events.

    Attributes:
        events: EVENT_DTYPE array, camera time order (empty when ``raw`` is given).
        triggers: TRIGGER_DTYPE array.
        arrival_ns: wall-clock time (ns) the data reached the adapter.
        t_until_us: the stream is complete before this camera time (every event with an earlier time
            has been delivered), or None if the camera cannot say.
        raw: the device's bytes in its native encoding (``CameraInfo.encoding``, evt3 or evt2), as
            received: the service cuts them into packets without decoding them.
        packets: the device's bytes already cut into self-contained packets (instead of ``raw``),
            when the adapter had to scan them anyway (a paced replay, which cuts them per
            ``slice_us`` of camera time to pace itself): the service publishes them as they are if
            they are no longer than its own packets, rather than scanning the bytes a second time,
            and otherwise cuts their bytes again.
        drops: what the device or its driver lost before this data (the camera service puts them
            on the next packet it publishes; the recorder writes them in the sidecar).
    """

    events: np.ndarray
    triggers: np.ndarray
    arrival_ns: int
    t_until_us: int | None = None
    raw: bytes | None = None
    packets: list[Packet] | None = None
    drops: tuple[DeviceDrop, ...] = ()


class EndOfStream(Exception):
    """The camera has no more data (end of a replayed file)."""


class Camera(Protocol):
    """An event camera: open, read decoded data as it comes, close."""

    def open(self) -> CameraInfo:
        """Start streaming; return the sensor description and settings read back."""
        ...

    def read(self, timeout_s: float) -> CameraData | None:
        """Return the next data, None if nothing came within ``timeout_s``; raise EndOfStream at the end."""
        ...

    def close(self) -> None:
        """Stop streaming and release the device (idempotent)."""
        ...
