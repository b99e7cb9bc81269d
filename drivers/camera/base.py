"""The camera interface every adapter implements, and what it yields."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np


@dataclass(frozen=True)
class CameraInfo:
    """What an opened camera reports.

    Attributes:
        adapter: adapter name (``replay``, ``simulated``, ``prophesee``, ...).
        width, height: sensor size, pixels.
        encoding: native stream encoding (``evt3`` or ``evt2``).
        serial: device serial number or source file.
        settings: settings as read back from the device (biases, ROI, rate limiter, trigger, ...).
    """

    adapter: str
    width: int
    height: int
    encoding: str
    serial: str = ""
    settings: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class CameraData:
    """A piece of the camera's stream, decoded (adapters decode to packetise and count).

    Attributes:
        events: EVENT_DTYPE array, camera time order.
        triggers: TRIGGER_DTYPE array.
        arrival_ns: wall-clock time (ns) the data reached the adapter.
        t_until_us: the stream is complete before this camera time (every event with an earlier time
            has been delivered), or None if the camera cannot say.
    """

    events: np.ndarray
    triggers: np.ndarray
    arrival_ns: int
    t_until_us: int | None = None


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
