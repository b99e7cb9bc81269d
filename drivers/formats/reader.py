"""What every event-file reader gives: recording info, streamed chunks, whole recordings.

A reader is opened on one file, states what it knows from the header (:class:`RecordingInfo`),
and yields :class:`EventChunk` s in file order with bounded memory. Faults (truncated file,
corrupt word, garbage) raise :class:`FormatError` naming file and byte offset when ``strict``;
otherwise a RAW reader skips a corrupt stretch to the next valid time base and goes on (listing
what it skipped in :attr:`EventReader.skipped`), and the others keep every event decoded before the
fault; either warns with :class:`~flagtrack.drivers.formats.codec.FormatWarning`.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, Self

import numpy as np

from flagtrack.daemon.core.events import MAX_SENSOR_PX, empty_events, empty_triggers
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats.codec import FormatWarning, SkippedRange

DEFAULT_CHUNK_BYTES = 8 << 20


def check_sensor_size(width: int, height: int, *, path: str | None = None, offset: int | None = None) -> None:
    """Refuse a header's sensor size that no event sensor has (0, negative, over :data:`MAX_SENSOR_PX`)."""
    if not (0 < width <= MAX_SENSOR_PX and 0 < height <= MAX_SENSOR_PX):
        raise FormatError(
            f"sensor size {width} x {height} in the header: not an event sensor's (1 to {MAX_SENSOR_PX} pixels a side)",
            path=path,
            offset=offset,
        )


@dataclass(frozen=True)
class RecordingInfo:
    """What a file's header says.

    Attributes:
        path: the file.
        format: ``"raw"``, ``"dat"``, ``"aedat4"``, ``"npy"`` or ``"csv"``.
        encoding: ``"evt2"``, ``"evt21"``, ``"evt3"`` for RAW files, else None.
        width, height: sensor size in pixels, or None if the file does not say.
        header: the header's fields (text), as found in the file.
    """

    path: Path
    format: str
    encoding: str | None
    width: int | None
    height: int | None
    header: dict[str, Any] = field(default_factory=dict)


@dataclass
class EventChunk:
    """A piece of a recording, in file order.

    Attributes:
        events: EVENT_DTYPE array.
        triggers: TRIGGER_DTYPE array (external-trigger events of the same span).
        byte_offset: where the chunk's data starts in the file.
    """

    events: np.ndarray
    triggers: np.ndarray
    byte_offset: int


@dataclass
class Recording:
    """A whole recording in memory."""

    events: np.ndarray
    triggers: np.ndarray
    info: RecordingInfo


class EventReader:
    """Base of the per-format readers: a context manager that streams chunks.

    Subclasses set ``self.info`` in ``__init__`` and implement :meth:`_chunks`.
    """

    info: RecordingInfo

    def __init__(self, path: str | Path, *, strict: bool = False, chunk_bytes: int = DEFAULT_CHUNK_BYTES) -> None:
        self.path = Path(path)
        self.strict = strict
        self.chunk_bytes = max(int(chunk_bytes), 4096) // 8 * 8
        if not self.path.is_file():
            raise FormatError("no such file", path=str(self.path))
        self.size_bytes = self.path.stat().st_size
        if self.size_bytes == 0:  # (a 0-byte .dat read as 0 events, a .raw as "no encoding")
            raise FormatError("empty file (0 bytes)", path=str(self.path))
        self.skipped: list[SkippedRange] = []  # byte ranges skipped after faults (non-strict), in file order

    @property
    def events_lost_at_most(self) -> int:
        """Upper bound on the events in the :attr:`skipped` byte ranges."""
        return sum(r.events_at_most for r in self.skipped)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        """Release the file (readers open it only while iterating; nothing to do by default)."""

    def __iter__(self) -> Iterator[EventChunk]:
        return self.chunks()

    def chunks(self) -> Iterator[EventChunk]:
        """Yield the recording's chunks in file order; faults per ``strict`` (see module doc)."""
        try:
            yield from self._chunks()
        except FormatError as exc:
            if self.strict:
                raise
            warnings.warn(f"{exc}; kept the events before it", FormatWarning, stacklevel=2)

    def _chunks(self) -> Iterator[EventChunk]:
        raise NotImplementedError

    def read(self) -> Recording:
        """Decode the whole file into one :class:`Recording`."""
        events, triggers = [], []
        for chunk in self.chunks():
            events.append(chunk.events)
            triggers.append(chunk.triggers)
        return Recording(
            events=np.concatenate(events) if events else empty_events(),
            triggers=np.concatenate(triggers) if triggers else empty_triggers(),
            info=self.info,
        )
