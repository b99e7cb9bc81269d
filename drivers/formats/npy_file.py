"""NumPy ``.npy`` event files of our structured dtype (EVENT_DTYPE), streamed both ways.

Other structured dtypes with fields ``t``, ``x``, ``y`` and ``p`` (or ``on``) are read and cast.
The writer appends events and fixes the header's length on closing (the header is written with
room for any count), so memory stays bounded. Triggers go to a sidecar ``NAME.triggers.npy``.
``.npy`` holds no sensor size: it reads back as unknown (None).
"""

from __future__ import annotations

import struct
import tokenize
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType

import numpy as np

from flagtrack.daemon.core.events import EVENT_DTYPE, TRIGGER_DTYPE, empty_events
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats.csv_file import sidecar
from flagtrack.drivers.formats.reader import DEFAULT_CHUNK_BYTES, EventChunk, EventReader, RecordingInfo

MAGIC = b"\x93NUMPY"
_HEADER_BYTES = 128  # room for EVENT_DTYPE and a 20-digit count, a multiple of 64


def _read_npy_header(path: Path) -> tuple[np.dtype, int, int]:
    """(dtype, number of items, data offset) of a 1-D C-order .npy file."""
    with path.open("rb") as f:
        try:
            version = np.lib.format.read_magic(f)
            read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            shape, fortran, dtype = read(f)
        except (ValueError, SyntaxError, TypeError, struct.error, EOFError, tokenize.TokenError) as exc:
            raise FormatError(f"garbage .npy header: {exc}", path=str(path), offset=0) from None
        offset = f.tell()
    if len(shape) != 1 or fortran:
        raise FormatError(f".npy array of shape {shape} is not a 1-D event list", path=str(path), offset=0)
    return dtype, int(shape[0]), offset


def _field_names(dtype: np.dtype, path: Path) -> tuple[str, str, str, str]:
    names = dtype.names or ()
    polarity = "p" if "p" in names else "on" if "on" in names else None
    if not {"t", "x", "y"} <= set(names) or polarity is None:
        raise FormatError(f".npy dtype {dtype} has no fields t, x, y and p", path=str(path), offset=0)
    for name in ("t", "x", "y", polarity):  # one number each (not a sub-array, found by `bench fuzz`)
        field = dtype[name]
        if field.shape != () or field.kind not in "biuf":
            raise FormatError(f".npy field {name!r} is {field}, not one number per event", path=str(path), offset=0)
    return "t", "x", "y", polarity


class NpyReader(EventReader):
    """Streams a 1-D structured .npy file in blocks of whole events."""

    def __init__(self, path: str | Path, *, strict: bool = False, chunk_bytes: int = DEFAULT_CHUNK_BYTES) -> None:
        super().__init__(path, strict=strict, chunk_bytes=chunk_bytes)
        self.dtype, self.count, self.body_offset = _read_npy_header(self.path)
        self.fields = _field_names(self.dtype, self.path)
        header = {"descr": str(self.dtype), "shape": (self.count,)}
        self.info = RecordingInfo(self.path, "npy", None, None, None, header)

    def _chunks(self) -> Iterator[EventChunk]:
        size = self.dtype.itemsize
        per_chunk = max(self.chunk_bytes // size, 1)
        triggers = self._sidecar_triggers()
        done = 0
        with self.path.open("rb") as f:
            f.seek(self.body_offset)
            while done < self.count:
                want = min(per_chunk, self.count - done)
                data = f.read(want * size)
                got = len(data) // size
                offset = self.body_offset + done * size
                if got:
                    events = self._convert(np.frombuffer(data, dtype=self.dtype, count=got))
                    last = events["t"][-1]
                    take = (
                        np.searchsorted(triggers["t"], last, side="right") if done + got < self.count else len(triggers)
                    )
                    yield EventChunk(events, triggers[:take], offset)
                    triggers = triggers[take:]
                done += got
                if got < want:
                    raise FormatError(
                        f"file ends after {done} of {self.count} events (truncated file?)",
                        path=str(self.path),
                        offset=self.body_offset + done * size,
                    )
        if len(triggers):
            yield EventChunk(empty_events(), triggers, self.body_offset + done * size)

    def _convert(self, raw: np.ndarray) -> np.ndarray:
        if raw.dtype == EVENT_DTYPE:
            return raw.copy()
        events = np.empty(len(raw), dtype=EVENT_DTYPE)
        for ours, theirs in zip(("t", "x", "y", "p"), self.fields):
            events[ours] = raw[theirs]
        return events

    def _sidecar_triggers(self) -> np.ndarray:
        path = sidecar(self.path, ".npy")
        if not path.is_file():
            return np.empty(0, dtype=TRIGGER_DTYPE)
        try:
            return np.asarray(np.load(path), dtype=TRIGGER_DTYPE)
        except (ValueError, OSError) as exc:
            raise FormatError(f"bad trigger sidecar: {exc}", path=str(path), offset=0) from None


def _header(count: int) -> bytes:
    text = repr({"descr": np.lib.format.dtype_to_descr(EVENT_DTYPE), "fortran_order": False, "shape": (count,)})
    body = text.encode("latin-1")
    pad = _HEADER_BYTES - len(MAGIC) - 4 - len(body) - 1
    if pad < 0:
        raise FormatError(".npy header does not fit")  # pragma: no cover - EVENT_DTYPE is fixed
    return MAGIC + bytes([1, 0]) + struct.pack("<H", _HEADER_BYTES - 10) + body + b" " * pad + b"\n"


class NpyWriter:
    """Appends EVENT_DTYPE events to a .npy file (and triggers to a ``.triggers.npy`` sidecar)."""

    def __init__(self, path: str | Path, *, width: int | None, height: int | None, encoding: str | None = None) -> None:
        self.path = Path(path)
        if encoding is not None:
            raise FormatError(".npy files have no encoding option", path=str(self.path))
        self._file = self.path.open("wb")
        self._file.write(_header(0))
        self._count = 0
        self._triggers: list[np.ndarray] = []
        sidecar(self.path, ".npy").unlink(missing_ok=True)

    def __enter__(self) -> NpyWriter:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

    def write(self, events: np.ndarray, triggers: np.ndarray | None = None) -> None:
        """Append events (cast to EVENT_DTYPE); triggers are kept for the sidecar."""
        array = np.asarray(events)
        if array.dtype != EVENT_DTYPE:
            converted = np.empty(len(array), dtype=EVENT_DTYPE)
            for name in ("t", "x", "y", "p"):  # EVENT_DTYPE's fields
                converted[name] = array[name]
            array = converted
        self._file.write(np.ascontiguousarray(array).tobytes())
        self._count += len(array)
        if triggers is not None and len(triggers):
            self._triggers.append(np.asarray(triggers, dtype=TRIGGER_DTYPE))

    def close(self) -> None:
        """Write the final count into the header, close, and write the trigger sidecar."""
        if self._file.closed:
            return
        self._file.seek(0)
        self._file.write(_header(self._count))
        self._file.close()
        if self._triggers:
            np.save(sidecar(self.path, ".npy"), np.concatenate(self._triggers))
