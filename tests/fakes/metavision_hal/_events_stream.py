"""The fake HAL's events stream and decoders, with the bindings' types by OpenEB version.

``get_latest_raw_data`` gives a ``RawBuffer`` with only ``size()`` (5.x: Python cannot read its bytes),
a ``RawDataBuffer`` vector that iterates as ints (4.5-4.6), or a numpy byte array (4.0-4.4). The
events-stream decoder (``I_Decoder``) takes such a buffer (5.x: only a ``RawBuffer``, as the bindings'
cast does) and calls back its CD decoder with at most 320 events at a time, as copies, and its trigger
decoder with one trigger at a time, in memory it lends (scribbled over once the callback returns), as
OpenEB 5.1's ``DecodedEventForwarder`` and bindings do. Events come out in the HAL's dtypes.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

EVENT_CD_DTYPE = np.dtype(
    {"names": ["x", "y", "p", "t"], "formats": ["<u2", "<u2", "<i2", "<i8"], "offsets": [0, 2, 4, 8], "itemsize": 16}
)
"""``metavision_sdk_base.EventCD``."""
EVENT_EXT_TRIGGER_DTYPE = np.dtype(
    {"names": ["p", "t", "id"], "formats": ["<i2", "<i8", "<i2"], "offsets": [0, 8, 16], "itemsize": 24}
)
"""``metavision_sdk_base.EventExtTrigger``."""
CD_BUFFER_EVENTS = 320  # OpenEB's DecodedEventForwarder<EventCD> buffer; triggers go one by one
_ids = itertools.count(1)


class RawBuffer:
    """OpenEB 5's ``RawBuffer`` (``DataTransfer::BufferPtr``): only ``size()``, the bytes stay in C++."""

    __slots__ = ("__data",)

    def __init__(self) -> None:
        raise TypeError("metavision_hal.RawBuffer: No constructor defined!")

    def size(self) -> int:
        return len(self.__data)


def raw_buffer(data: bytes) -> RawBuffer:
    """A RawBuffer holding ``data`` (as the HAL makes them)."""
    buffer = object.__new__(RawBuffer)
    object.__setattr__(buffer, "_RawBuffer__data", data)
    return buffer


class RawDataBuffer(list):
    """OpenEB 4.5-4.6's ``RawDataBuffer``: an opaque ``std::vector<uint8_t>`` (no buffer protocol, iterates as ints)."""


def buffer_bytes(raw: Any, api: str) -> bytes:
    """The bytes of a buffer handed to ``I_Decoder.decode``, or the error the bindings raise."""
    if api.startswith("5"):
        if not isinstance(raw, RawBuffer):
            raise RuntimeError(
                f"Unable to cast Python instance of type {type(raw)} to C++ type 'Metavision::DataTransfer::BufferPtr'"
            )
        return object.__getattribute__(raw, "_RawBuffer__data")
    return bytes(np.asarray(raw, dtype=np.uint8))


class _Callbacks:
    """Callbacks by id (``_callbacks``), each given copies or lent memory."""

    def __init__(self) -> None:
        self._callbacks: dict[int, tuple[Callable[[np.ndarray], object], bool]] = {}

    def _add(self, callback: Callable[[np.ndarray], object], lend: bool) -> int:
        callback_id = next(_ids)
        self._callbacks[callback_id] = (callback, lend)
        return callback_id

    def remove_callback(self, callback_id: int) -> bool:
        return self._callbacks.pop(callback_id, None) is not None

    def _dispatch(self, events: np.ndarray) -> None:
        for callback, lend in list(self._callbacks.values()):
            array = events.copy()
            callback(array)
            if lend:  # the HAL reuses this memory for the next events
                array.view(np.uint8)[:] = 0xA5


class I_EventDecoder_EventCD(_Callbacks):  # noqa: N801 - the bindings' name
    def add_event_buffer_callback(self, arg0: Callable[[np.ndarray], object]) -> int:
        return self._add(arg0, lend=False)

    def add_event_buffer_nocopy_callback(self, arg0: Callable[[np.ndarray], object]) -> int:
        return self._add(arg0, lend=True)


class I_EventDecoder_EventExtTrigger(_Callbacks):  # noqa: N801
    def add_event_buffer_callback(self, arg0: Callable[[np.ndarray], object]) -> int:
        return self._add(arg0, lend=True)


class I_Decoder:  # noqa: N801 - the bindings' name of I_EventsStreamDecoder
    """Decodes the stream's bytes (with flagtrack's decoders, set by the device at ``start``)."""

    def __init__(self, api: Callable[[], str]) -> None:
        self._api = api
        self.cd = I_EventDecoder_EventCD()
        self.trigger = I_EventDecoder_EventExtTrigger()
        self.words: Any = None
        self._last_t = -1
        self._time = _Callbacks()

    def decode(self, arg0: Any) -> None:
        events, triggers = self.words.decode(buffer_bytes(arg0, self._api()))
        for start in range(0, len(events), CD_BUFFER_EVENTS):
            chunk = events[start : start + CD_BUFFER_EVENTS]
            cd = np.empty(len(chunk), EVENT_CD_DTYPE)
            cd["x"], cd["y"], cd["p"], cd["t"] = chunk["x"], chunk["y"], chunk["p"], chunk["t"]
            self.cd._dispatch(cd)
        for trigger in triggers:
            one = np.empty(1, EVENT_EXT_TRIGGER_DTYPE)
            one["p"], one["t"], one["id"] = trigger["edge"], trigger["t"], trigger["channel"]
            self.trigger._dispatch(one)
        last = max([self._last_t] + [int(a["t"].max()) for a in (events, triggers) if len(a)])
        if last != self._last_t:
            self._last_t = last
            for callback, _ in list(self._time._callbacks.values()):
                callback(last)

    def get_last_timestamp(self) -> int:
        return self._last_t

    def add_time_callback(self, cb: Callable[[int], object]) -> int:
        return self._time._add(cb, lend=False)

    def remove_callback(self, callback_id: int) -> bool:
        return self._time.remove_callback(callback_id)


class I_EventsStream:  # noqa: N801
    """The device's stream: buffers from the device's feed (``device._make_feed()`` at ``start``)."""

    def __init__(self, device: Any) -> None:
        self._device = device
        self._feed: Any = None
        self._pending: bytes | None = None
        self._log: Any = None

    def start(self) -> None:
        self._device.camera.started += 1
        self._feed = self._device._make_feed()

    def stop(self) -> None:
        self._device.camera.stopped += 1
        self._feed = None
        self.stop_log_raw_data()

    def poll_buffer(self) -> int:
        camera, feed = self._device.camera, self._feed
        if feed is None:
            return -1
        if camera.unplug_after_bytes is not None and feed.delivered >= camera.unplug_after_bytes:
            return -1
        if self._pending is None:
            self._pending = feed.next()
        return 0 if self._pending is None else 1

    def wait_next_buffer(self) -> int:
        """1 when a buffer is there; -1 at the end (where a real stalled camera would block for ever)."""
        return 1 if self.poll_buffer() > 0 else -1

    def get_latest_raw_data(self) -> Any:
        data, self._pending = self._pending or b"", None
        if self._log is not None:
            self._log.write(data)
        api = self._device._api()
        if api.startswith("5"):
            return raw_buffer(data)
        if api == "4.6":
            return RawDataBuffer(data)
        return np.frombuffer(data, dtype=np.uint8).copy()

    def log_raw_data(self, f: str) -> bool:
        """Write the HAL's header, then every buffer taken from now on, to ``f``."""
        try:
            log = Path(f).open("wb")  # noqa: SIM115 - closed by stop_log_raw_data
        except OSError:
            return False
        self.stop_log_raw_data()
        log.write(self._device._header().encode())
        self._log = log
        return True

    def stop_log_raw_data(self) -> None:
        log, self._log = self._log, None
        if log is not None:
            log.close()
