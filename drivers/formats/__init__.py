"""Event files and packet codecs (EVT 2.0/2.1/3.0 .raw, .dat, .aedat4, .npy, .csv) and centreline HDF5.

Reading: :func:`open_events` streams any event file in bounded memory, :func:`read_events` reads a
whole one. Writing: :func:`open_writer` / :func:`write_events` (.raw EVT 2.0/3.0, .npy, .csv, .dat).
Live packets: :func:`make_decoder` / :func:`make_encoder` are the same codecs, stateful across
packets; :func:`raw_header` / :func:`parse_raw_header` handle RAW headers. See docs/formats.md.
"""

from flagtrack.drivers.formats.codec import ENCODINGS, Decoder, Encoder, FormatWarning, make_decoder, make_encoder
from flagtrack.drivers.formats.files import (
    EventWriter,
    file_format,
    open_events,
    open_writer,
    read_events,
    write_events,
)
from flagtrack.drivers.formats.raw_header import parse_raw_header, raw_header
from flagtrack.drivers.formats.reader import EventChunk, EventReader, Recording, RecordingInfo

__all__ = [
    "ENCODINGS",
    "Decoder",
    "Encoder",
    "EventChunk",
    "EventReader",
    "EventWriter",
    "FormatWarning",
    "Recording",
    "RecordingInfo",
    "file_format",
    "make_decoder",
    "make_encoder",
    "open_events",
    "open_writer",
    "parse_raw_header",
    "raw_header",
    "read_events",
    "write_events",
]
