"""Replay a recording file as a camera: real time, at a speed factor, or as fast as possible."""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flagtrack.daemon.core.events import empty_events, empty_triggers
from flagtrack.daemon.errors import DriverError
from flagtrack.drivers.camera.base import CameraData, CameraInfo, EndOfStream
from flagtrack.drivers.formats import open_events
from flagtrack.drivers.formats.codec import LOOP_US
from flagtrack.drivers.formats.native import NativeCutter
from flagtrack.drivers.formats.packets import Packet, PacketParams, slot_table
from flagtrack.drivers.formats.raw_file import RawReader

log = logging.getLogger(__name__)

_READ_CHUNK_BYTES = 256 << 10  # decoded events stay in cache for the packetizer; paced, no burst of slices


@dataclass(frozen=True)
class ReplayConfig:
    """Replay settings.

    Attributes:
        path: the recording (any format the file layer reads).
        speed: 1 = real time, 2 = twice as fast, 0 = as fast as possible.
        loop: start again at the end (time keeps increasing across loops).
        slice_us: camera time handed over per read (pacing granularity).
        encoding: stream encoding to publish (default: the file's own EVT encoding, else evt3).
        width, height: sensor size when the file does not say.
        native: hand a RAW file's bytes over as they are, as the device would (EVT 3.0/2.0 replayed
            once in its own encoding); False: decode them into events (the camera service re-encodes).
    """

    path: Path
    speed: float = 1.0
    loop: bool = False
    slice_us: int = 1000
    encoding: str | None = None
    width: int | None = None
    height: int | None = None
    native: bool = True

    def __post_init__(self) -> None:
        if self.speed < 0:
            raise ValueError("speed must be >= 0 (0 = as fast as possible)")
        if self.slice_us < 1:
            raise ValueError("slice_us must be positive")
        if self.encoding not in (None, "evt2", "evt3"):
            raise ValueError(
                f"encoding must be evt2 or evt3 (the encodings packets are made in), got {self.encoding!r}"
            )


_Slice = tuple[np.ndarray | bytes | Packet, np.ndarray, int]
"""(events, triggers, t_until_us): decoded events, or a native replay's bytes as read or cut packet."""


class ReplayCamera:
    """A :class:`~flagtrack.drivers.camera.base.Camera` reading a file.

    A RAW file in EVT 3.0 or 2.0, replayed once in its own encoding, is handed over as the device
    would: its bytes as they are (``CameraData.raw``; paced by a word scan of their times). Other
    files, loops and other encodings are decoded and handed over as events.
    """

    def __init__(self, cfg: ReplayConfig) -> None:
        self.cfg = cfg
        self._slices: Iterator[_Slice] | None = None
        self.native = False
        self.t_offset_us = 0  # a native file's % t_offset_us (its times start there)
        self._body_offset = 0
        self._pending: _Slice | None = None
        self._wall0 = 0.0
        self._t0_us: int | None = None
        self.loops = 0

    def open(self) -> CameraInfo:
        path = Path(self.cfg.path).expanduser()
        with open_events(path) as reader:
            info = reader.info
        width, height = info.width or self.cfg.width, info.height or self.cfg.height
        if not width or not height:
            raise DriverError(
                "the file does not give the sensor size: set camera.replay.width and height", device=str(path)
            )
        encoding = self.cfg.encoding or (info.encoding if info.encoding in ("evt2", "evt3") else "evt3")
        self.native = self.cfg.native and info.format == "raw" and info.encoding == encoding and not self.cfg.loop
        if self.native:
            with RawReader(path) as raw:
                self.t_offset_us, self._body_offset = raw.layout.t_offset_us, raw.body_offset
            self.native = self.t_offset_us % LOOP_US[encoding] == 0  # packets' offsets are whole loops
        self._slices = self._native_slices(path, encoding) if self.native else self._loop_slices(path)
        self._wall0 = time.monotonic()
        return CameraInfo(
            "replay",
            int(width),
            int(height),
            encoding,
            serial=str(path),
            t_offset_us=self.t_offset_us if self.native else 0,
            settings={
                "speed": self.cfg.speed,
                "loop": self.cfg.loop,
                "source_format": info.format,
                "native_bytes": self.native,
            },
        )

    def read(self, timeout_s: float) -> CameraData | None:
        if self._slices is None:
            raise DriverError("replay camera is not open", device=str(self.cfg.path))
        if self._pending is None:
            self._pending = next(self._slices, None)
            if self._pending is None:
                raise EndOfStream(str(self.cfg.path))
        events, triggers, t_until = self._pending
        if self.cfg.speed > 0 and t_until >= 0:
            if self._t0_us is None:
                self._t0_us = t_until - self.cfg.slice_us
                self._wall0 = time.monotonic()
            due = self._wall0 + (t_until - self._t0_us) * 1e-6 / self.cfg.speed
            wait = due - time.monotonic()
            if wait > timeout_s:
                time.sleep(max(timeout_s, 0.0))
                return None
            if wait > 0:
                time.sleep(wait)
        self._pending = None
        # a native replay hands over the file's bytes, or the packet a paced replay cut
        if isinstance(events, Packet):
            return CameraData(empty_events(), empty_triggers(), time.time_ns(), t_until, packets=[events])
        if isinstance(events, bytes):
            until = t_until if t_until >= 0 else None
            return CameraData(empty_events(), empty_triggers(), time.time_ns(), t_until_us=until, raw=events)
        return CameraData(events, triggers, time.time_ns(), t_until_us=t_until)

    def close(self) -> None:
        self._slices = None

    def _native_slices(self, path: Path, encoding: str) -> Iterator[_Slice]:
        """(bytes, no triggers, -1) of the file's body as read (as fast as possible), or (packet, no
        triggers, t_until_us) per ``slice_us`` of camera time (paced; cut by a word scan, nothing
        decoded: the packets go to the service as cut)."""
        body_offset = self._body_offset
        params = PacketParams(self.cfg.slice_us, 1 << 40)
        cutter = NativeCutter(encoding, params, self.t_offset_us) if self.cfg.speed > 0 else None
        no_triggers = empty_triggers()
        with path.open("rb") as f:
            f.seek(body_offset)
            while block := f.read(_READ_CHUNK_BYTES):
                if cutter is None:
                    yield block, no_triggers, -1
                    continue
                for piece in cutter.push(block):
                    yield piece, no_triggers, piece.t_last_us + 1
            if cutter is not None:
                for piece in cutter.flush():
                    yield piece, no_triggers, piece.t_last_us + 1

    def _loop_slices(self, path: Path) -> Iterator[_Slice]:
        shift = 0
        while True:
            t_first: int | None = None
            t_last = 0
            for events, triggers, t_until in self._file_slices(path):
                if shift:  # the slices are the decoder's own arrays: shifted in place
                    events["t"] += shift
                    triggers["t"] += shift
                t_first = t_until if t_first is None else t_first
                t_last = t_until
                yield events, triggers, t_until + shift
            if not self.cfg.loop or t_first is None:
                return
            self.loops += 1
            shift += t_last - t_first + 2 * self.cfg.slice_us
            log.info("replay: loop %d of %s", self.loops, path)

    @staticmethod
    def _file_chunks(path: Path) -> Iterator[tuple[np.ndarray, np.ndarray, int]]:
        """(events, triggers, t_until_us) per chunk of the file: complete before its last event's time."""
        with open_events(path, chunk_bytes=_READ_CHUNK_BYTES) as reader:
            t_until = None
            for chunk in reader:
                times = [int(a["t"].max()) for a in (chunk.events, chunk.triggers) if len(a)]
                if times:
                    t_until = max(times) if t_until is None else max(t_until, *times)
                    yield chunk.events, chunk.triggers, t_until
            if t_until is not None:
                yield empty_events(), empty_triggers(), t_until + 1

    def _file_slices(self, path: Path) -> Iterator[tuple[np.ndarray, np.ndarray, int]]:
        """(events, triggers, t_until_us) per ``slice_us`` of camera time, from the file's chunks.

        As fast as possible (speed 0) there is nothing to pace: the file's chunks are handed over
        as they are (the camera service cuts packets of its own size).
        """
        if self.cfg.speed == 0:
            yield from self._file_chunks(path)
            return
        slice_us = self.cfg.slice_us
        held, held_tr, held_slot = empty_events(), empty_triggers(), -1  # the slice still open
        running_max = np.iinfo(np.int64).min
        # small reads: decoding a big chunk would hold back (and then burst) many slices
        with open_events(path, chunk_bytes=_READ_CHUNK_BYTES) as reader:
            for chunk in reader:
                triggers = np.concatenate([held_tr, chunk.triggers]) if len(chunk.triggers) else held_tr
                events = chunk.events
                if len(events) == 0:
                    held_tr = triggers
                    continue
                starts, slots, maxima = slot_table(events["t"], running_max, slice_us)
                running_max = int(maxima[-1])
                for q in range(len(slots)):
                    piece = events[starts[q] : starts[q + 1]]
                    slot = int(slots[q])
                    if q == 0 and len(held) and slot == held_slot:  # the open slice goes on
                        piece = np.concatenate([held, piece])
                    elif q == 0 and len(held):
                        piece_tr, triggers = _triggers_before(triggers, (held_slot + 1) * slice_us)
                        yield held, piece_tr, (held_slot + 1) * slice_us
                    if q == len(slots) - 1:  # may go on in the next chunk
                        held, held_slot = piece, slot
                        continue
                    piece_tr, triggers = _triggers_before(triggers, (slot + 1) * slice_us)
                    yield piece, piece_tr, (slot + 1) * slice_us
                held_tr = triggers
            if len(held) or len(held_tr):
                t_end = int(held["t"].max()) + 1 if len(held) else int(held_tr["t"].max()) + 1
                yield held, held_tr, t_end


def _triggers_before(triggers: np.ndarray, t_until_us: int) -> tuple[np.ndarray, np.ndarray]:
    """(the triggers before ``t_until_us``, the rest)."""
    if len(triggers) == 0:
        return triggers, triggers
    take = triggers["t"] < t_until_us
    return triggers[take], triggers[~take]
