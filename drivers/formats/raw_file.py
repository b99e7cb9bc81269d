"""Prophesee RAW files (EVT 2.0 / 2.1 / 3.0): a streaming reader and a writer."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from types import TracebackType

import numpy as np

from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats.codec import Decoder, Encoder
from flagtrack.drivers.formats.raw_header import MAX_HEADER_BYTES, parse_header_lines, raw_header, raw_layout
from flagtrack.drivers.formats.reader import DEFAULT_CHUNK_BYTES, EventChunk, EventReader, RecordingInfo


def read_header_bytes(path: Path) -> bytes:
    """The first bytes of ``path``, enough to hold any header (up to 1 MiB)."""
    with path.open("rb") as f:
        return f.read(MAX_HEADER_BYTES)


class RawReader(EventReader):
    """Streams a RAW file: header on opening, EVT words decoded block by block."""

    def __init__(self, path: str | Path, *, strict: bool = False, chunk_bytes: int = DEFAULT_CHUNK_BYTES) -> None:
        super().__init__(path, strict=strict, chunk_bytes=chunk_bytes)
        head = read_header_bytes(self.path)
        if not head.startswith(b"%"):
            raise FormatError("not a RAW file: no '%' header (encoding unknown)", path=str(self.path), offset=0)
        fields, self.body_offset, offsets = parse_header_lines(head, str(self.path))
        self.layout = raw_layout(fields, offsets, str(self.path))
        self.info = RecordingInfo(self.path, "raw", self.layout.encoding, self.layout.width, self.layout.height, fields)

    def decoder(self) -> Decoder:
        """A fresh decoder positioned at the body (file offsets in its errors): strict, or (by default)
        resynchronising after a corrupt stretch (what it skipped: :attr:`skipped`)."""
        lay = self.layout
        return Decoder(
            lay.encoding,
            width=lay.width,
            height=lay.height,
            t_offset_us=lay.t_offset_us,
            strict=self.strict,
            resync=not self.strict,
            source=str(self.path),
            base_offset=self.body_offset,
            endianness=lay.endianness,
            max_events=max(self.chunk_bytes // 8, 1 << 16),
        )

    def _chunks(self) -> Iterator[EventChunk]:
        decoder = self.decoder()
        self.skipped = decoder.skipped  # filled as the decoder goes
        buffer = bytearray(self.chunk_bytes)
        with self.path.open("rb") as f:
            f.seek(self.body_offset)
            while True:
                n = f.readinto(buffer)
                if not n:
                    break
                for events, triggers, offset in decoder.pieces(memoryview(buffer)[:n]):
                    yield EventChunk(events, triggers, offset)
        decoder.finish()


class RawWriter:
    """Writes events as a RAW file of EVT 2.0 or 3.0 with a Metavision header.

    The header is written with the first events (or on closing) so that it can hold the stream's
    time offset (``% t_offset_us``, a whole number of time loops; see :mod:`.codec`). A
    ``simulated`` stream's header says that flagtrack simulated it (:func:`.raw_header.raw_header`).
    """

    def __init__(
        self,
        path: str | Path,
        *,
        width: int | None,
        height: int | None,
        encoding: str | None = None,
        simulated: bool = False,
    ) -> None:
        self.path = Path(path)
        self.simulated = simulated
        if width is None or height is None:
            raise FormatError("a RAW file needs the sensor width and height", path=str(self.path))
        self.width, self.height = int(width), int(height)
        self.encoding = encoding or "evt3"
        self._encoder = Encoder(self.encoding, width=self.width, height=self.height, target=str(self.path))
        self._file = self.path.open("wb")
        self._header_written = False

    def __enter__(self) -> RawWriter:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

    def _write_header(self) -> None:
        offset = self._encoder.t_offset_us or 0
        extra = {"t_offset_us": offset} if offset else None
        self._file.write(raw_header(self.encoding, self.width, self.height, extra, simulated=self.simulated))
        self._header_written = True

    def write(self, events: np.ndarray, triggers: np.ndarray | None = None) -> None:
        """Append events (EVENT_DTYPE) and triggers (TRIGGER_DTYPE), each in stream order."""
        data = self._encoder.encode(events, triggers)
        if not self._header_written and data:
            self._write_header()
        self._file.write(data)

    def write_bytes(self, data: bytes) -> None:
        """Append native stream bytes as they are (e.g. a camera's packets) after the header."""
        if not self._header_written:
            self._write_header()
        self._file.write(data)

    def close(self) -> None:
        """Write the header if nothing was written yet, and close the file."""
        if self._file.closed:
            return
        if not self._header_written:
            self._write_header()
        self._file.close()
