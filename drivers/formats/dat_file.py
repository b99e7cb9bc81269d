"""Prophesee DAT files (legacy): CD events of 8 bytes, or external triggers.

Layout (as OpenEB's ``dat_tools`` reads it): ``% `` header lines, ended by the first line that
does not start with ``% ``; then one byte of event type and one of event size; then the events.
Types 0 (Event2D) and 12 (EventCD), 8 bytes: uint32 t µs, uint32 with x bits 0-13, y bits 14-27,
p bit 28. Type 14 (EventExtTrigger): int16 p, int64 t, int16 id (12 bytes). Sizes come from
``% Width`` / ``% Height`` lines when present. A file without header lines is type 0.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType

import numpy as np

from flagtrack.daemon.core.events import EVENT_DTYPE, TRIGGER_DTYPE, empty_events, empty_triggers
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats.reader import (
    DEFAULT_CHUNK_BYTES,
    EventChunk,
    EventReader,
    RecordingInfo,
    check_sensor_size,
)

CD_TYPES = (0, 12)
TRIGGER_TYPE = 14
_RAW_CD = np.dtype([("t", "<u4"), ("w", "<u4")])
_RAW_TRIGGER = np.dtype([("p", "<i2"), ("t", "<i8"), ("id", "<i2")])
_SIZES = {0: 8, 12: 8, 14: _RAW_TRIGGER.itemsize}


def _parse_dat_header(head: bytes, path: str) -> tuple[dict[str, str], int]:
    """Fields of the ``% `` lines and the offset of the type byte."""
    fields: dict[str, str] = {}
    pos = 0
    while head.startswith(b"% ", pos):
        end = head.find(b"\n", pos)
        if end < 0:
            raise FormatError("header line has no end (truncated or garbage header)", path=path, offset=pos)
        text = head[pos + 2 : end].decode("latin-1").strip()
        key, _, value = text.partition(" ")
        if key:
            fields[key] = value.strip()
        pos = end + 1
    return fields, pos


class DatReader(EventReader):
    """Streams a DAT file in blocks of whole events."""

    def __init__(self, path: str | Path, *, strict: bool = False, chunk_bytes: int = DEFAULT_CHUNK_BYTES) -> None:
        super().__init__(path, strict=strict, chunk_bytes=chunk_bytes)
        with self.path.open("rb") as f:
            head = f.read(1 << 20)
        fields, pos = _parse_dat_header(head, str(self.path))
        if pos:
            if len(head) < pos + 2:
                raise FormatError("file ends before the event type and size bytes", path=str(self.path), offset=pos)
            self.event_type, self.event_size = head[pos], head[pos + 1]
            pos += 2
        else:
            self.event_type, self.event_size = 0, 8
        if self.event_type not in _SIZES or _SIZES[self.event_type] != self.event_size:
            raise FormatError(
                f"unsupported DAT event type {self.event_type} of {self.event_size} bytes "
                f"(supported: CD types 0 and 12 of 8 bytes, trigger type 14)",
                path=str(self.path),
                offset=max(pos - 2, 0),
            )
        self.body_offset = pos
        width, height = fields.get("Width"), fields.get("Height")
        numbers = all(v and v.isascii() and v.isdigit() for v in (width, height))  # not "6²0": str.isdigit takes it
        size = (int(width), int(height)) if numbers and width and height else (None, None)
        if size[0] is not None and size[1] is not None:
            check_sensor_size(size[0], size[1], path=str(self.path))
        self.info = RecordingInfo(self.path, "dat", None, size[0], size[1], fields)

    def _chunks(self) -> Iterator[EventChunk]:
        per_chunk = max(self.chunk_bytes // self.event_size, 1)
        offset = self.body_offset
        with self.path.open("rb") as f:
            f.seek(offset)
            while True:
                data = f.read(per_chunk * self.event_size)
                if not data:
                    break
                whole = len(data) // self.event_size * self.event_size
                if whole:
                    yield self._decode(data[:whole], offset)
                if whole < len(data):
                    raise FormatError(
                        f"file ends inside a {self.event_size}-byte event "
                        f"({len(data) - whole} trailing bytes; truncated file?)",
                        path=str(self.path),
                        offset=offset + whole,
                    )
                offset += whole

    def _decode(self, data: bytes, offset: int) -> EventChunk:
        if self.event_type == TRIGGER_TYPE:
            raw = np.frombuffer(data, dtype=_RAW_TRIGGER)
            triggers = np.empty(len(raw), dtype=TRIGGER_DTYPE)
            triggers["t"], triggers["channel"], triggers["edge"] = raw["t"], raw["id"], raw["p"]
            return EventChunk(empty_events(), triggers, offset)
        raw = np.frombuffer(data, dtype=_RAW_CD)
        events = np.empty(len(raw), dtype=EVENT_DTYPE)
        events["t"] = raw["t"]
        events["x"] = raw["w"] & 0x3FFF
        events["y"] = (raw["w"] >> 14) & 0x3FFF
        events["p"] = (raw["w"] >> 28) & 1
        return EventChunk(events, empty_triggers(), offset)


class DatWriter:
    """Writes CD events as a DAT file (type 12 EventCD, 8 bytes, as Metavision's DatWriter)."""

    def __init__(self, path: str | Path, *, width: int | None, height: int | None, encoding: str | None = None) -> None:
        self.path = Path(path)
        if encoding is not None:
            raise FormatError("DAT files have no encoding option", path=str(self.path))
        self._file = self.path.open("wb")
        now = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M:%S")
        lines = ["% Data file containing EventCD events.", "% Version 2", f"% Date {now}"]
        if width is not None and height is not None:
            lines += [f"% Height {int(height)}", f"% Width {int(width)}"]
        self._file.write(("\n".join(lines) + "\n").encode("ascii") + bytes([12, 8]))
        self._count = 0

    def __enter__(self) -> DatWriter:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

    def write(self, events: np.ndarray, triggers: np.ndarray | None = None) -> None:
        """Append events; DAT CD files cannot hold triggers (refused if any)."""
        if triggers is not None and len(triggers):
            raise FormatError("a DAT CD file cannot hold trigger events", path=str(self.path))
        t = np.asarray(events["t"], dtype=np.int64)
        x, y, p = (np.asarray(events[k], dtype=np.uint32) for k in ("x", "y", "p"))
        bad = (t < 0) | (t > 0xFFFFFFFF) | (x > 0x3FFF) | (y > 0x3FFF) | (p > 1)
        if bad.any():
            i = int(np.argmax(bad))
            raise FormatError(
                f"cannot write event {self._count + i} {events[i]} to DAT (t must fit 32 bits, "
                "x and y 14 bits, p 0 or 1)",
                path=str(self.path),
            )
        raw = np.empty(len(t), dtype=_RAW_CD)
        raw["t"] = t
        raw["w"] = x | (y << 14) | (p << 28)
        self._file.write(raw.tobytes())
        self._count += len(t)

    def close(self) -> None:
        """Close the file."""
        self._file.close()
