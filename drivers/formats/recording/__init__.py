"""A live recording's files, written packet by packet: no bus, no threads (the recorder service drives them).

A recording ``BASE`` is ``BASE.raw`` (a valid RAW stream in the camera's native encoding: header,
a time-base preamble, the packets' bytes as they came), its JSON sidecar ``BASE.json`` (rewritten
atomically at each fsync: counts, sequence gaps, the configuration) and, optionally,
``BASE_centrelines.h5``. The packets of two camera streams do not make one valid stream, so each
new stream goes in a new part ``BASE_stream2`` (then ``_stream3`` ...), the sidecars linking them
(``continues``, ``continued_in``). A write that fails (a full disk) cuts the ``.raw`` file back to its
last flush, so it reads back whole; :class:`FreeSpaceGuard` stops a recording before the disk is full.
"""

from flagtrack.drivers.formats.recording.chain import PartChain, TrackerUpdates
from flagtrack.drivers.formats.recording.free_space import FreeSpaceGuard
from flagtrack.drivers.formats.recording.part import (
    CameraPacket,
    CentrelineUpdates,
    RecordingPart,
    SyncIntervals,
    gap_span,
    gap_times_s,
)
from flagtrack.drivers.formats.recording.paths import (
    RECORDING_SUFFIXES,
    confined_base,
    part_base,
    recording_base,
    recording_file,
)
from flagtrack.drivers.formats.recording.raw_part import RawPartFile

__all__ = [
    "RECORDING_SUFFIXES",
    "CameraPacket",
    "CentrelineUpdates",
    "FreeSpaceGuard",
    "PartChain",
    "RawPartFile",
    "RecordingPart",
    "SyncIntervals",
    "TrackerUpdates",
    "confined_base",
    "gap_span",
    "gap_times_s",
    "part_base",
    "recording_base",
    "recording_file",
]
