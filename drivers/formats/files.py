"""Open any event file by its extension: readers, writers and whole-file helpers."""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import numpy as np

from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats.aedat_file import MAGIC as AEDAT_MAGIC
from flagtrack.drivers.formats.aedat_file import AedatReader
from flagtrack.drivers.formats.csv_file import CsvReader, CsvWriter
from flagtrack.drivers.formats.dat_file import DatReader, DatWriter
from flagtrack.drivers.formats.npy_file import MAGIC as NPY_MAGIC
from flagtrack.drivers.formats.npy_file import NpyReader, NpyWriter
from flagtrack.drivers.formats.raw_file import RawReader, RawWriter
from flagtrack.drivers.formats.reader import DEFAULT_CHUNK_BYTES, EventReader, Recording

READERS: dict[str, type[EventReader]] = {
    "raw": RawReader,
    "dat": DatReader,
    "aedat4": AedatReader,
    "npy": NpyReader,
    "csv": CsvReader,
}
WRITERS = {"raw": RawWriter, "dat": DatWriter, "npy": NpyWriter, "csv": CsvWriter}


class EventWriter(Protocol):
    """What :func:`open_writer` returns (a context manager)."""

    def write(self, events: np.ndarray, triggers: np.ndarray | None = None) -> None: ...

    def close(self) -> None: ...

    def __enter__(self) -> EventWriter: ...

    def __exit__(self, *exc: object) -> None: ...


def file_format(path: str | Path, *, sniff: bool = True) -> str:
    """The format of ``path`` from its extension (``.raw``, ``.dat``, ``.aedat4``, ``.npy``, ``.csv``).

    With an unknown extension and ``sniff``, the first bytes decide (AEDAT4 and .npy magic, RAW
    ``%`` header); otherwise FormatError.
    """
    path = Path(path)
    suffix = path.suffix.lower().lstrip(".")
    if suffix == "aedat":
        suffix = "aedat4"
    if suffix in READERS:
        return suffix
    if sniff and path.is_file():
        with path.open("rb") as f:
            head = f.read(16)
        if head.startswith(AEDAT_MAGIC):
            return "aedat4"
        if head.startswith(NPY_MAGIC):
            return "npy"
        if head.startswith(b"% "):
            return "raw"
    known = ", ".join(f".{k}" for k in READERS)
    raise FormatError(f"unknown event file type {path.suffix or '(no extension)'!r} (known: {known})", path=str(path))


def open_events(path: str | Path, *, strict: bool = False, chunk_bytes: int = DEFAULT_CHUNK_BYTES) -> EventReader:
    """Open an event file for streaming: ``with open_events(p) as r: for chunk in r: ...``.

    Args:
        path: a .raw (EVT 2.0/2.1/3.0), .dat, .aedat4, .npy or .csv file.
        strict: raise on a fault instead of keeping the events before it and warning.
        chunk_bytes: bytes read per block; bounds the memory used.

    Returns:
        an :class:`EventReader` whose ``info`` is a :class:`RecordingInfo`.
    """
    if Path(path).is_dir():  # (it was "unknown event file type '(no extension)'")
        raise FormatError("is a directory, not an event file", path=str(path))
    return READERS[file_format(path)](path, strict=strict, chunk_bytes=chunk_bytes)


def read_events(path: str | Path, *, strict: bool = False) -> Recording:
    """Read a whole event file: ``Recording(events, triggers, info)``."""
    with open_events(path, strict=strict) as reader:
        return reader.read()


def open_writer(path: str | Path, *, width: int | None, height: int | None, encoding: str | None = None) -> EventWriter:
    """Open a writer by extension: .raw (``encoding`` "evt2" or "evt3", default "evt3"), .npy, .csv, .dat."""
    kind = file_format(path, sniff=False)
    if kind not in WRITERS:
        raise FormatError(f"cannot write {kind} files (writable: .raw, .npy, .csv, .dat)", path=str(path))
    if kind != "raw" and encoding is not None:
        raise FormatError(f"--encoding applies to .raw files only, not .{kind}", path=str(path))
    return WRITERS[kind](path, width=width, height=height, encoding=encoding)


def write_events(
    path: str | Path,
    events: np.ndarray,
    *,
    width: int | None,
    height: int | None,
    encoding: str | None = None,
    triggers: np.ndarray | None = None,
) -> None:
    """Write a whole recording to ``path`` (format by extension, see :func:`open_writer`)."""
    with open_writer(path, width=width, height=height, encoding=encoding) as writer:
        writer.write(events, triggers)
