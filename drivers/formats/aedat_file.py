"""iniVation AEDAT 4.0 files, read with the ``aedat`` library (exact against dv-processing).

The library parses the IOHeader, decompresses (LZ4/Zstd) and decodes each packet; this module
walks the packet headers beside it (int32 stream id, int32 size, then the packet) to know each
packet's byte offset, for chunk offsets and error messages. The first ``events`` stream gives the
CD events and the sensor size. In the first ``triggers`` stream only external-signal and
generator edges are external triggers (dv TriggerType 1-5: signal rising, falling, pulse =
channel 0; generator rising, falling = channel 1); timestamp resets and APS frame/exposure markers
(types 0, 6-9) are not, and are left out.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from flagtrack.daemon.core.events import EVENT_DTYPE, TRIGGER_DTYPE, empty_events, empty_triggers
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats.reader import DEFAULT_CHUNK_BYTES, EventChunk, EventReader, RecordingInfo

MAGIC = b"#!AER-DAT4.0\r\n"
_TRIGGER_MAP = {1: (0, 1), 2: (0, 0), 3: (0, 1), 4: (1, 1), 5: (1, 0)}
"""dv TriggerType -> (channel, edge) for the external triggers."""


def io_header_problem(header: bytes) -> str | None:
    """What is wrong with an IOHeader (a flatbuffer: compression, data table position, the info node as
    an XML string), or None: its tables and the string lie inside it and the string is UTF-8."""
    try:
        (table,) = struct.unpack_from("<I", header, 0)
        (back,) = struct.unpack_from("<i", header, table)
        vtable = table - back
        if vtable < 0:  # (struct reads a negative offset from the end)
            raise struct.error("negative offset")
        vtable_size, _ = struct.unpack_from("<HH", header, vtable)
        info = 0
        if vtable_size >= 10:  # (the info node is the table's third field)
            (info,) = struct.unpack_from("<H", header, vtable + 8)
        if info == 0:
            return None
        string = table + info + struct.unpack_from("<I", header, table + info)[0]
        (length,) = struct.unpack_from("<I", header, string)
    except struct.error:
        return "its tables point outside it"
    if string + 4 + length > len(header):
        return "its info node runs past its end"
    try:
        header[string + 4 : string + 4 + length].decode("utf-8")
    except UnicodeDecodeError as exc:
        return f"its info node is not UTF-8 text: {exc.reason} at byte {exc.start}"
    return None


class AedatReader(EventReader):
    """Streams an AEDAT 4.0 file packet by packet (events batched to about ``chunk_bytes``)."""

    def __init__(self, path: str | Path, *, strict: bool = False, chunk_bytes: int = DEFAULT_CHUNK_BYTES) -> None:
        super().__init__(path, strict=strict, chunk_bytes=chunk_bytes)
        with self.path.open("rb") as f:
            head = f.read(len(MAGIC) + 4)
        if not head.startswith(MAGIC) or len(head) < len(MAGIC) + 4:
            raise FormatError("not an AEDAT 4.0 file (no '#!AER-DAT4.0' magic line)", path=str(self.path), offset=0)
        (header_size,) = struct.unpack("<i", head[len(MAGIC) :])
        self.first_packet = len(MAGIC) + 4 + header_size
        if header_size <= 0 or self.first_packet > self.size_bytes:
            raise FormatError(
                f"garbage AEDAT 4.0 header (IOHeader size {header_size})", path=str(self.path), offset=len(MAGIC)
            )
        with self.path.open("rb") as f:
            f.seek(len(MAGIC) + 4)
            problem = io_header_problem(f.read(header_size))
        if problem is not None:  # (the library aborts the process on some of these)
            raise FormatError(f"garbage AEDAT 4.0 header ({problem})", path=str(self.path), offset=len(MAGIC) + 4)
        streams = self._open_library().id_to_stream()
        events = sorted(i for i, s in streams.items() if s.get("type") == "events")
        triggers = sorted(i for i, s in streams.items() if s.get("type") == "triggers")
        self.events_stream = events[0] if events else None
        self.triggers_stream = triggers[0] if triggers else None
        size = streams.get(self.events_stream, {}) if events else {}
        header = {"streams": {str(i): dict(s) for i, s in streams.items()}}
        self.info = RecordingInfo(self.path, "aedat4", None, size.get("width"), size.get("height"), header)

    def _open_library(self):  # noqa: ANN202
        try:
            import aedat
        except ImportError:
            raise FormatError(
                "reading .aedat4 files needs the 'aedat' package (pip install aedat)", path=str(self.path)
            ) from None

        try:
            return aedat.Decoder(str(self.path))
        except BaseException as exc:  # noqa: BLE001 - RuntimeError/OSError without offsets, or a Rust panic
            _reraise_interrupts(exc)
            raise FormatError(
                f"cannot read the AEDAT 4.0 header: {exc}", path=str(self.path), offset=len(MAGIC)
            ) from None

    def _packet_offsets(self) -> Iterator[int]:
        """Byte offset of each packet, in file order (checks that each fits in the file)."""
        offset = self.first_packet
        with self.path.open("rb") as f:
            while True:
                f.seek(offset)
                head = f.read(8)
                if len(head) < 8:
                    raise FormatError(
                        "file ends inside a packet header (truncated file?)", path=str(self.path), offset=offset
                    )
                _, size = struct.unpack("<ii", head)
                if size < 0 or offset + 8 + size > self.size_bytes:
                    raise FormatError(
                        f"file ends inside a packet of {size} bytes (truncated file?)",
                        path=str(self.path),
                        offset=offset,
                    )
                yield offset
                offset += 8 + size

    def _chunks(self) -> Iterator[EventChunk]:
        decoder = self._open_library()
        offsets = self._packet_offsets()
        batch: list[np.ndarray] = []
        triggers: list[np.ndarray] = []
        batch_offset, batch_events = None, 0
        while True:
            try:
                packet = next(decoder)
            except StopIteration:
                break
            except BaseException as exc:  # noqa: BLE001 - the library's own errors carry no offset
                _reraise_interrupts(exc)
                if batch or triggers:  # keep what was decoded before the fault
                    yield _chunk(batch, triggers, batch_offset or self.first_packet)
                offset = next(offsets)  # raises with the offset if the file is cut inside this packet
                raise FormatError(f"cannot decode packet: {exc}", path=str(self.path), offset=offset) from None
            offset = next(offsets)
            if batch_offset is None:
                batch_offset = offset
            if packet["stream_id"] == self.events_stream and "events" in packet:
                batch.append(_events(packet["events"]))
                batch_events += len(batch[-1])
            elif packet["stream_id"] == self.triggers_stream and "triggers" in packet:
                triggers.append(_triggers(packet["triggers"]))
            if batch_events * EVENT_DTYPE.itemsize >= self.chunk_bytes:
                yield _chunk(batch, triggers, batch_offset)
                batch, triggers, batch_offset, batch_events = [], [], None, 0
        if batch or triggers:
            yield _chunk(batch, triggers, batch_offset or self.first_packet)


def _reraise_interrupts(exc: BaseException) -> None:
    """Let Ctrl-C and exits through; anything else the library raises becomes the caller's FormatError.

    The library is Rust: a damaged file can make it panic, which pyo3 raises as ``PanicException``, a
    ``BaseException`` (found by tests/unit/test_fuzz_readers.py: a header whose flatbuffer offsets
    point beyond the file).
    """
    if isinstance(exc, KeyboardInterrupt | SystemExit | GeneratorExit):
        raise exc


def _events(raw: np.ndarray) -> np.ndarray:
    events = np.empty(len(raw), dtype=EVENT_DTYPE)
    events["t"], events["x"], events["y"], events["p"] = raw["t"], raw["x"], raw["y"], raw["on"]
    return events


def _triggers(raw: np.ndarray) -> np.ndarray:
    keep = np.isin(raw["source"], list(_TRIGGER_MAP))
    raw = raw[keep]
    triggers = np.empty(len(raw), dtype=TRIGGER_DTYPE)
    triggers["t"] = raw["t"]
    triggers["channel"] = [_TRIGGER_MAP[int(s)][0] for s in raw["source"]]
    triggers["edge"] = [_TRIGGER_MAP[int(s)][1] for s in raw["source"]]
    return triggers


def _chunk(batch: list[np.ndarray], triggers: list[np.ndarray], offset: int) -> EventChunk:
    events = np.concatenate(batch) if batch else empty_events()
    trig = np.concatenate(triggers) if triggers else empty_triggers()
    return EventChunk(events, trig, offset)
