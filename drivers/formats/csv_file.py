"""CSV event files: one ``t,x,y,p`` row per event (t µs, p 1 = ON, 0 = OFF; -1 is read as OFF).

Leading ``#`` lines are comments; flagtrack writes ``# width=W height=H`` there and reads it back.
An optional header row names the columns (``t,x,y,p`` in any order). Triggers, which have no
place in ``t,x,y,p`` rows, go to a sidecar ``NAME.triggers.csv`` of ``t,channel,edge`` rows.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType

import numpy as np

from flagtrack.daemon.core.events import EVENT_DTYPE, TRIGGER_DTYPE, empty_events
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats._csv_kernels import BAD, FULL, format_rows, parse_rows
from flagtrack.drivers.formats.reader import DEFAULT_CHUNK_BYTES, EventChunk, EventReader, RecordingInfo

COLUMNS = ("t", "x", "y", "p")
_SIZE = re.compile(r"width\s*=\s*(\d+)\D+height\s*=\s*(\d+)")


def sidecar(path: Path, suffix: str) -> Path:
    """``rec.csv`` -> ``rec.triggers.csv`` (the trigger file beside an event file)."""
    return path.with_name(f"{path.stem}.triggers{suffix}")


def _preamble(path: Path) -> tuple[list[str], tuple[str, ...] | None, int]:
    """Comment lines, the header row's columns (None if there is none) and the data offset."""
    comments: list[str] = []
    offset = 0
    with path.open("rb") as f:
        for raw in iter(f.readline, b""):
            text = raw.decode("utf-8", errors="replace").strip()
            if text.startswith("#"):
                comments.append(text[1:].strip())
            elif not text:
                pass
            elif re.search(r"[A-Za-z]", text):
                names = tuple(name.strip().lower() for name in text.split(","))
                if sorted(names) != sorted(COLUMNS):
                    raise FormatError(f"CSV header {text!r} is not t,x,y,p", path=str(path), offset=offset)
                return comments, names, offset + len(raw)
            else:
                return comments, None, offset
            offset += len(raw)
    return comments, None, offset


class CsvReader(EventReader):
    """Streams a ``t,x,y,p`` CSV file in blocks of whole lines."""

    def __init__(self, path: str | Path, *, strict: bool = False, chunk_bytes: int = DEFAULT_CHUNK_BYTES) -> None:
        super().__init__(path, strict=strict, chunk_bytes=chunk_bytes)
        comments, names, self.body_offset = _preamble(self.path)
        self.order = [(names or COLUMNS).index(c) for c in COLUMNS]
        size = next((m.groups() for m in map(_SIZE.search, comments) if m), None)
        header = {"comments": comments, "columns": ",".join(names or COLUMNS)}
        width, height = (int(size[0]), int(size[1])) if size else (None, None)
        self.info = RecordingInfo(self.path, "csv", None, width, height, header)

    def _chunks(self) -> Iterator[EventChunk]:
        rows = np.empty((max(self.chunk_bytes // 16, 1024), 4), dtype=np.int64)
        offset = self.body_offset
        pending = b""
        with self.path.open("rb") as f:
            f.seek(offset)
            while True:
                block = f.read(self.chunk_bytes)
                data = pending + block
                if not data:
                    break
                cut = len(data) if not block else data.rfind(b"\n") + 1
                yield from self._parse(np.frombuffer(data[:cut], dtype=np.uint8), rows, offset)
                pending, offset = data[cut:], offset + cut
                if not block:
                    break
        yield from _sidecar_chunk(sidecar(self.path, ".csv"), offset)

    def _parse(self, buf: np.ndarray, rows: np.ndarray, offset: int) -> Iterator[EventChunk]:
        pos = 0
        while pos < len(buf):
            start = pos
            pos, n, status, fault = parse_rows(buf, pos, rows, 4)
            if n:
                yield EventChunk(self._events(rows[:n], offset + start), np.empty(0, TRIGGER_DTYPE), offset + start)
            if status == BAD:
                line_end = bytes(buf[pos : pos + 80]).split(b"\n")[0].decode("utf-8", errors="replace")
                raise FormatError(
                    f"bad CSV row {line_end!r}: expected 4 integers t,x,y,p", path=str(self.path), offset=offset + fault
                )
            if status != FULL:
                break

    def _events(self, rows: np.ndarray, offset: int) -> np.ndarray:
        t, x, y, p = (rows[:, i] for i in self.order)
        p = np.where(p == -1, 0, p)
        bad = (x < 0) | (x > 0xFFFF) | (y < 0) | (y > 0xFFFF) | (p < 0) | (p > 1)
        if bad.any():
            raise FormatError(
                f"CSV row {rows[int(np.argmax(bad))].tolist()} out of range (x, y 0-65535, p 0 or 1)",
                path=str(self.path),
                offset=offset,
            )
        events = np.empty(len(rows), dtype=EVENT_DTYPE)
        events["t"], events["x"], events["y"], events["p"] = t, x, y, p
        return events


def _sidecar_chunk(path: Path, offset: int) -> Iterator[EventChunk]:
    """The triggers of a ``.triggers.csv`` sidecar, if there is one, as a last chunk."""
    if not path.is_file():
        return
    buf = np.frombuffer(path.read_bytes(), dtype=np.uint8)
    if buf[:1].tobytes().isalpha() or buf[:1].tobytes() == b"#":
        start = bytes(buf).find(b"\n") + 1
    else:
        start = 0
    rows = np.empty((max(len(buf) // 6, 1), 3), dtype=np.int64)
    _, n, status, fault = parse_rows(buf, start, rows, 3)
    if status == BAD:
        raise FormatError("bad trigger row: expected t,channel,edge", path=str(path), offset=fault)
    triggers = np.empty(n, dtype=TRIGGER_DTYPE)
    triggers["t"], triggers["channel"], triggers["edge"] = rows[:n, 0], rows[:n, 1], rows[:n, 2]
    yield EventChunk(empty_events(), triggers, offset)


class CsvWriter:
    """Writes ``t,x,y,p`` rows (and a ``.triggers.csv`` sidecar when there are triggers)."""

    def __init__(self, path: str | Path, *, width: int | None, height: int | None, encoding: str | None = None) -> None:
        self.path = Path(path)
        if encoding is not None:
            raise FormatError("CSV files have no encoding option", path=str(self.path))
        self._file = self.path.open("wb")
        if width is not None and height is not None:
            self._file.write(f"# width={int(width)} height={int(height)}\n".encode())
        self._file.write(b"t,x,y,p\n")
        self._triggers: list[np.ndarray] = []
        sidecar(self.path, ".csv").unlink(missing_ok=True)

    def __enter__(self) -> CsvWriter:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

    def write(self, events: np.ndarray, triggers: np.ndarray | None = None) -> None:
        """Append events as rows; triggers are kept for the sidecar."""
        step = 1 << 18
        out = np.empty(64 * min(len(events), step) + 64, dtype=np.uint8)
        for start in range(0, len(events), step):
            part = events[start : start + step]
            k = format_rows(part["t"], part["x"], part["y"], part["p"], out)
            self._file.write(out[:k].tobytes())
        if triggers is not None and len(triggers):
            self._triggers.append(np.asarray(triggers, dtype=TRIGGER_DTYPE))

    def close(self) -> None:
        """Close the file and write the trigger sidecar, if any."""
        if self._file.closed:
            return
        self._file.close()
        if self._triggers:
            triggers = np.concatenate(self._triggers)
            rows = "".join(f"{t},{c},{e}\n" for t, c, e in zip(triggers["t"], triggers["channel"], triggers["edge"]))
            sidecar(self.path, ".csv").write_text("t,channel,edge\n" + rows)
