"""How the metavision adapter turns the buffers of OpenEB's HAL events stream into camera data.

The HAL's Python bindings give the events stream's buffers (``I_EventsStream.get_latest_raw_data``)
in three shapes, by version: a numpy array of bytes (OpenEB 4.0-4.4), an opaque ``RawDataBuffer``
vector that iterates as ints (4.5-4.6), or a ``RawBuffer`` with only ``size()`` (5.x), whose bytes
Python cannot reach. :class:`DeviceBytes` hands the first two on as the device's own bytes (decoded
by flagtrack only for EVT 2.1); :class:`HalDecoded` has the HAL's own decoder
(``get_i_events_stream_decoder().decode(buffer)``) turn a 5.x buffer into events, delivered to the
callbacks of its CD and external-trigger decoders.
"""

from __future__ import annotations

import re
import time
from pathlib import Path
from types import ModuleType
from typing import Any, Protocol

import numpy as np

from flagtrack.daemon.core.events import EVENT_DTYPE, TRIGGER_DTYPE, empty_events, empty_triggers
from flagtrack.daemon.errors import DriverError
from flagtrack.drivers.camera.base import CameraData
from flagtrack.drivers.camera.hardware import RawStream, call_or_none


class HalStream(Protocol):
    """Camera data from the events stream's buffers (one of the classes below)."""

    @property
    def published(self) -> str:
        """Encoding of the packets the camera service makes (``evt3`` or ``evt2``)."""
        ...

    @property
    def bytes(self) -> int:
        """Bytes of the device's stream taken so far."""
        ...

    def take(self, buffer: Any) -> CameraData | None:
        """The data of one buffer of ``get_latest_raw_data``, or None if it is empty."""
        ...

    def close(self) -> None:
        """Let go of the device's decoders."""
        ...


def buffers_are_opaque(hal: ModuleType) -> bool:
    """Whether these bindings give buffers whose bytes Python cannot read (OpenEB 5's ``RawBuffer``)."""
    return getattr(hal, "RawBuffer", None) is not None


class DeviceBytes:
    """The device's own bytes (OpenEB 4.x bindings), through :class:`RawStream`."""

    def __init__(self, stream: RawStream) -> None:
        self._stream = stream
        self.published = stream.published

    @property
    def bytes(self) -> int:
        return self._stream.bytes

    def take(self, buffer: Any) -> CameraData | None:
        data = _as_bytes(buffer)
        return self._stream.take(data) if data else None

    def close(self) -> None:
        pass


class HalDecoded:
    """Events decoded by the HAL itself (OpenEB 5.x bindings), published as EVT 2.0.

    Args:
        device: the opened ``metavision_hal.Device``.
        label: device label for messages.
    """

    published = "evt2"

    def __init__(self, device: Any, label: str) -> None:
        self._decoder = call_or_none(device, "get_i_events_stream_decoder")
        cd = call_or_none(device, "get_i_event_cd_decoder")
        if self._decoder is None or cd is None:
            raise DriverError("the HAL has no event decoder for this camera's data format", device=label)
        self._events: list[np.ndarray] = []
        self._triggers: list[np.ndarray] = []
        # the CD callback's arrays are copies, kept as they come and converted once per buffer;
        # the trigger callback's lend the HAL's memory, copied at once
        self._callbacks = [(cd, cd.add_event_buffer_callback(self._events.append))]
        trigger = call_or_none(device, "get_i_event_ext_trigger_decoder")
        if trigger is not None:
            self._callbacks.append((trigger, trigger.add_event_buffer_callback(self._on_triggers)))
        self.bytes = 0

    def _on_triggers(self, triggers: np.ndarray) -> None:
        self._triggers.append(triggers_from_hal(triggers))

    def take(self, buffer: Any) -> CameraData | None:
        size = int(buffer.size())
        if not size:
            return None
        arrival_ns = time.time_ns()
        self.bytes += size
        self._decoder.decode(buffer)  # calls back with at most 320 events, or one trigger, at a time
        events = events_from_hal(_joined(self._events)) if self._events else empty_events()
        triggers = _joined(self._triggers) if self._triggers else empty_triggers()
        t_last_us = int(self._decoder.get_last_timestamp())  # every event before it has been decoded
        return CameraData(events, triggers, arrival_ns, t_until_us=t_last_us if t_last_us >= 0 else None)

    def close(self) -> None:
        callbacks, self._callbacks = self._callbacks, []
        for facility, callback_id in callbacks:
            call_or_none(facility, "remove_callback", callback_id)


def start_raw_log(events_stream: Any, folder: Path, serial: str) -> str:
    """Have the HAL write the stream's bytes (header and all) to a new file in ``folder``; its path.

    The HAL writes each buffer as it is taken (``get_latest_raw_data``), until the stream stops.

    Raises:
        OSError: the folder or the file cannot be made.
    """
    folder.mkdir(parents=True, exist_ok=True)
    stem = f"{re.sub(r'[^A-Za-z0-9_.-]', '_', serial) or 'camera'}_{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}"
    path = folder / f"{stem}.raw"
    for n in range(1, 1000):
        if not path.exists():
            break
        path = folder / f"{stem}_{n}.raw"
    if not events_stream.log_raw_data(str(path)):
        raise OSError(f"OpenEB's HAL cannot write {path}")
    return str(path)


def events_from_hal(cd: np.ndarray) -> np.ndarray:
    """EVENT_DTYPE copy of a HAL ``EventCD`` array."""
    out = np.empty(len(cd), EVENT_DTYPE)
    out["t"], out["x"], out["y"], out["p"] = cd["t"], cd["x"], cd["y"], cd["p"]
    return out


def triggers_from_hal(triggers: np.ndarray) -> np.ndarray:
    """TRIGGER_DTYPE copy of a HAL ``EventExtTrigger`` array (``id``: channel, ``p``: edge)."""
    out = np.empty(len(triggers), TRIGGER_DTYPE)
    out["t"], out["channel"], out["edge"] = triggers["t"], triggers["id"], triggers["p"]
    return out


def _joined(parts: list[np.ndarray]) -> np.ndarray:
    """The parts (at least one, contiguous, one dtype) in one array; the list is emptied.

    Joined as bytes: numpy concatenates a structured dtype with gaps (``EventCD``) field by field,
    several times slower.
    """
    joined = parts[0] if len(parts) == 1 else np.concatenate([p.view(np.uint8) for p in parts]).view(parts[0].dtype)
    parts.clear()
    return joined


def _as_bytes(raw: Any) -> bytes:
    """Bytes of a raw buffer: a numpy array, a buffer-protocol vector, or a plain sequence of ints."""
    try:
        return bytes(memoryview(raw).cast("B"))
    except TypeError:
        return bytes(np.asarray(raw, dtype=np.uint8))
