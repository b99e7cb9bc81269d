"""A live recording's files, written packet by packet: no bus, no threads (the recorder service drives them).

A recording ``BASE`` is ``BASE.raw`` (a valid RAW stream in the camera's native encoding: header,
a time-base preamble, the packets' bytes as they came), its JSON sidecar ``BASE.json`` (counts,
sequence gaps with their times, what the camera reported lost, the configuration; rewritten
atomically at each fsync) and, optionally, ``BASE_centrelines.h5``. The ``.raw`` file is flushed
every ``flush_interval_s`` and fsynced every ``fsync_interval_s`` and at its close, so a recording
cut by a crash reads back up to its last flush; a write that fails (a full disk) cuts it back to its last flush, so it reads back
whole. :class:`FreeSpaceGuard` stops a recording before the disk is full.

The packets of two camera streams do not make one valid stream (the second one's times start
again), so each new stream goes in a new part, ``BASE_stream2`` (then ``_stream3`` ...), the sidecars
linking them (``continues``, ``continued_in``). The tracker's centrelines lag the packets, so after
a roll-over :class:`PartChain` keeps the old part open for the centrelines of packets sent before the
new stream's first, until the tracker's first of the new stream or its final message (or the
caller's time-out).
"""

from flagtrack.drivers.formats.recording.chain import PartChain
from flagtrack.drivers.formats.recording.free_space import FreeSpaceGuard
from flagtrack.drivers.formats.recording.inputs import CameraPacket, CentrelineUpdates, SyncIntervals, TrackerUpdates
from flagtrack.drivers.formats.recording.part import RecordingPart, device_drop, drop_summary, gap_span, gap_times_s
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
    "device_drop",
    "drop_summary",
    "gap_span",
    "gap_times_s",
    "part_base",
    "recording_base",
    "recording_file",
]
