"""One part of a recording: its ``.raw`` file, its JSON sidecar and, optionally, its centreline file."""

from __future__ import annotations

import errno
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon import __version__
from flagtrack.daemon.errors import SchemaError
from flagtrack.drivers.atomic import atomic_write
from flagtrack.drivers.formats.centreline import CentrelineShapeError, CentrelineSink
from flagtrack.drivers.formats.recording.inputs import CameraPacket, CentrelineUpdates, SyncIntervals
from flagtrack.drivers.formats.recording.paths import part_base, recording_file
from flagtrack.drivers.formats.recording.raw_part import RawPartFile
from flagtrack.drivers.reserve import RESERVE_BYTES, RESERVE_BYTES_RAW_ONLY, DiskReserve, remove_stale_reserves

log = logging.getLogger(__name__)


@dataclass
class RecordingPart:
    """One open recording part: the .raw file, its sidecar and, optionally, the centreline file.

    ``part`` numbers the files of one recording (one per camera stream); ``first_base`` is the base
    path of part 1. ``centreline_attrs`` (processing parameters and calibration) go in the centreline
    file's attributes with the units, the source and the .raw file. ``dropped`` (packets a queue
    before the part dropped) is set by the caller. ``device_drops`` lists what the camera reported
    lost while the part recorded (:func:`device_drop`), ``device_drop_reports`` how many reports.
    """

    base: Path
    config: dict[str, Any]
    centrelines: CentrelineSink | None = None
    want_centrelines: bool = False
    centreline_attrs: dict[str, Any] = field(default_factory=dict)
    bytes: int = 0
    packets: int = 0
    events: int = 0
    gaps: list[list[int]] = field(default_factory=list)
    gap_spans: list[dict[str, int]] = field(default_factory=list)  # each gap's times (sidecar "gaps")
    last_sent_ns: int = 0
    malformed: int = 0
    late: int = 0  # duplicates and late packets of the stream, dropped
    dropped: int = 0
    device_drops: list[dict[str, Any]] = field(default_factory=list)  # sidecar "device_drops"
    device_drop_reports: int = 0
    device_drops_seen: int | None = None  # the stream's drop count at the last packet written
    started_wall: float = field(default_factory=time.time)
    first_t_us: int | None = None
    last_t_us: int | None = None
    geometry: dict[str, Any] = field(default_factory=dict)
    ended: bool = False
    first_sent_ns: int | None = None
    part: int = 1
    first_base: Path | None = None
    continues: str | None = None
    continued_in: str | None = None
    raw: RawPartFile = field(init=False, repr=False)
    reserve: DiskReserve = field(init=False, repr=False)
    _last_flush: float = field(default_factory=time.monotonic)
    _last_fsync: float = field(default_factory=time.monotonic)

    def __post_init__(self) -> None:
        self.raw = RawPartFile(self.raw_path)
        room = RESERVE_BYTES if self.want_centrelines else RESERVE_BYTES_RAW_ONLY
        self.reserve = DiskReserve(self.base.with_name(f".{self.base.name}.reserve"), room)
        if self.want_centrelines:  # the file is created at the first update
            self.centrelines = CentrelineSink(
                self.centrelines_path, {**self.centreline_attrs, "input_file": str(self.raw_path)}
            )

    @property
    def raw_path(self) -> Path:
        return recording_file(self.base, ".raw")

    @property
    def sidecar_path(self) -> Path:
        return recording_file(self.base, ".json")

    @property
    def centrelines_path(self) -> Path:
        return recording_file(self.base, "_centrelines.h5")

    @property
    def opened(self) -> bool:
        """Whether the .raw file was created (at the first packet)."""
        return self.raw.opened

    @property
    def flushed_at(self) -> int:
        """Size of the .raw file at its last flush (what a failed write cuts it back to)."""
        return self.raw.flushed_at

    @property
    def missing_packets(self) -> int:
        return sum(b - a for a, b in self.gaps)

    def format_change(self, packet: CameraPacket) -> str | None:
        """Why ``packet``'s encoding or geometry cannot go in this (opened) file, or None."""
        if not self.geometry or (packet.encoding, packet.width, packet.height) == self._stream_key:
            return None
        return (
            f"packet {packet.seq} is {packet.encoding} {packet.width}x{packet.height}, the file "
            f"{self.geometry['encoding']} {self.geometry['width']}x{self.geometry['height']}"
        )

    @property
    def _stream_key(self) -> tuple[str, int, int]:
        return self.geometry["encoding"], self.geometry["width"], self.geometry["height"]

    def write_packet(self, packet: CameraPacket, gap_from: int | None = None) -> None:
        """Append one packet (opening the file at the first one: its geometry and encoding).

        ``gap_from``: the first of the packets missing before this one (a sequence gap), or None.

        Raises:
            FormatError: the first packet cannot start a file (encoding, time offset, camera id in
                the header); nothing is written then.
            OSError: the write failed (a full disk): :meth:`abandon` the part.
        """
        if not self.raw.opened:
            self._take_reserve()
            camera = self.config.get("camera")
            simulated = isinstance(camera, dict) and camera.get("adapter") == "simulated"
            try:
                self.raw.open(
                    packet.encoding, packet.width, packet.height, packet.camera_id, packet.t_offset_us, simulated
                )
            except BaseException:
                self.reserve.release()
                raise
            self.geometry = {"width": packet.width, "height": packet.height, "encoding": packet.encoding}
            if self.centrelines is not None:  # the centreline file says the sensor's size
                self.centrelines.set_attrs({"sensor_width_px": packet.width, "sensor_height_px": packet.height})
            self.write_sidecar()
        if gap_from is not None:
            self.gaps.append([gap_from, packet.seq])
            self.gap_spans.append(gap_span(gap_from, packet, self.last_t_us, self.last_sent_ns))
            if self.centrelines is not None:  # the centreline file says where its updates have a hole
                self.centrelines.set_attrs({"gaps_t_s": gap_times_s(self.gap_spans)})
        self._note_device_drops(packet)
        self.last_sent_ns = packet.sent_ns
        data: bytes | memoryview = packet.data
        if packet.preamble_bytes and self.packets and gap_from is None:
            # the camera's own words as it sent them: the state words that made this packet decodable
            # alone are left out (kept at the file's start and after a gap, where they are needed)
            data = memoryview(data)[packet.preamble_bytes :]
        self.raw.write(data)
        self.bytes += len(data)
        self.packets += 1
        self.events += packet.n_events
        self.first_t_us = packet.t_first_us if self.first_t_us is None else self.first_t_us
        self.first_sent_ns = packet.sent_ns if self.first_sent_ns is None else self.first_sent_ns
        self.last_t_us = packet.t_last_us
        self.ended = packet.end_of_stream

    def _take_reserve(self) -> None:
        """Keep the room the files need to close on a full disk (:mod:`flagtrack.drivers.reserve`); a
        full disk stops the part before it starts, a file system that cannot allocate is said once."""
        stale = remove_stale_reserves(self.reserve.path.parent)
        if stale:
            log.info("removed the room kept by a recording that was killed: %s", ", ".join(p.name for p in stale))
        try:
            self.reserve.take()
        except OSError as exc:
            if exc.errno not in (errno.ENOSPC, errno.EDQUOT):
                log.warning("%s: recording with no room kept for closing its files: %s", self.raw_path, exc)
                return
            kept = f"keeping {self.reserve.size // 1024} KiB to close the files"
            raise OSError(exc.errno, f"{exc.strerror} ({kept})", str(self.raw_path)) from exc

    def _note_device_drops(self, packet: CameraPacket) -> None:
        """Record the drops the camera reported since the last packet written (its stream's count
        rose); the part's first packet sets where the count starts (drops before it are not its)."""
        seen, self.device_drops_seen = self.device_drops_seen, packet.device_drops
        if seen is None or packet.device_drops <= seen:
            return
        reports = packet.device_drops - seen
        self.device_drop_reports += reports
        self.device_drops.append(device_drop(packet, reports, self.last_t_us, self.last_sent_ns))

    def write_centrelines(self, msg: CentrelineUpdates) -> None:
        """Queue a batch of centrelines (written to HDF5 at the next sync, in one append).

        Raises:
            SchemaError: the message's samples or joints differ from the file's (another tracker setup).
        """
        if self.centrelines is None or len(msg.t_s) == 0:
            return
        try:
            self.centrelines.add(msg.batch(), units=msg.units, source=msg.source)
        except CentrelineShapeError as exc:
            raise SchemaError(
                f"centreline message {msg.seq} has {exc.got[0]} samples and {exc.got[1]} joints, the "
                f"file {exc.want[0]} and {exc.want[1]}: not recorded"
            ) from exc

    def sync(self, intervals: SyncIntervals, force: bool = False) -> None:
        """Flush (and fsync, then rewrite the sidecar) when due."""
        now = time.monotonic()
        flush_due = force or now - self._last_flush >= intervals.flush_interval_s
        if self.centrelines is not None and flush_due:
            self.centrelines.flush()
        if self.raw.opened and flush_due:
            self.raw.flush()
            self._last_flush = now
            if force or now - self._last_fsync >= intervals.fsync_interval_s:
                self.raw.fsync()
                self._last_fsync = now
                self.write_sidecar()

    def sidecar(self, stopped: bool = False) -> dict[str, Any]:
        """The sidecar's document: the part's counts, gaps and links, and the recorder's configuration."""
        return {
            "raw_file": self.raw_path.name,
            "started_unix_s": self.started_wall,
            "stopped": stopped,
            "flagtrack_version": __version__,
            **self.geometry,
            "packets": self.packets,
            "events": self.events,
            "bytes": self.bytes,
            "t_first_us": self.first_t_us,
            "t_last_us": self.last_t_us,
            "sequence_gaps": self.gaps,
            "gaps": self.gap_spans,
            "missing_packets": self.missing_packets,
            "malformed_packets": self.malformed,
            "late_packets": self.late,
            "dropped_packets": self.dropped,
            "device_drops": self.device_drops,
            "device_drop_reports": self.device_drop_reports,
            "part": self.part,
            "continues": self.continues,
            "continued_in": self.continued_in,
            "config": self.config,
            "centrelines_file": self.centrelines_path.name if self.centrelines and self.centrelines.opened else None,
        }

    def write_sidecar(self, stopped: bool = False) -> None:
        """Rewrite the JSON sidecar atomically."""
        self.sidecar_path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(self.sidecar_path, json.dumps(self.sidecar(stopped), indent=2))

    def close_raw(self) -> None:
        """Flush, fsync and close the .raw file (the centreline file stays open)."""
        self.raw.close()

    def close(self) -> None:
        """Flush, fsync and close everything; final sidecar."""
        self.reserve.release()  # (the room for the last flushes)
        self.close_raw()
        if self.centrelines is not None:
            self.centrelines.close()
        self.write_sidecar(stopped=True)

    def abandon(self) -> None:
        """After a failed write (a full disk): close everything as far as it goes and cut the .raw
        file back to its last flush, so it reads back whole up to there. Never raises."""
        steps = (self.raw.abandon, self.reserve.release, self._close_centrelines, lambda: self.write_sidecar(True))
        for step in steps:
            try:
                step()
            except (OSError, RuntimeError, ValueError) as exc:
                log.debug("abandoning %s: %s", self.raw_path, exc)

    def _close_centrelines(self) -> None:
        if self.centrelines is not None:
            self.centrelines.close()

    def next_part(self) -> RecordingPart:
        """The recording of the next camera stream: ``<first base>_stream<part + 1>``, linked to this one."""
        first = self.first_base or self.base
        part = RecordingPart(
            base=part_base(first, self.part + 1),
            config=self.config,
            want_centrelines=self.want_centrelines,
            centreline_attrs=self.centreline_attrs,
            part=self.part + 1,
            first_base=first,
            continues=self.raw_path.name,
        )
        self.continued_in = part.raw_path.name
        return part


def gap_span(expected: int, packet: CameraPacket, last_t_us: int | None, last_sent_ns: int) -> dict[str, int]:
    """A sequence gap before ``packet`` (``expected`` the first missing number): the packets and the
    camera time (``t_from_us`` the horizon of the last packet written, ``t_to_us`` the first time of
    this one) and wall time (``sent_*_ns``, when the camera received them) it spans."""
    return {
        "from_seq": expected,
        "to_seq": packet.seq,
        "missing_packets": packet.seq - expected,
        "t_from_us": last_t_us if last_t_us is not None else packet.t_first_us,
        "t_to_us": packet.t_first_us,
        "sent_from_ns": last_sent_ns,
        "sent_to_ns": packet.sent_ns,
    }


def device_drop(packet: CameraPacket, reports: int, last_t_us: int | None, last_sent_ns: int) -> dict[str, Any]:
    """The sidecar's entry for drops the camera reported before ``packet`` (``reports`` of them): what
    was lost (``count`` of ``unit``, 0: unknown), why, and the camera time (from the horizon of the
    last packet written to this one's first time) and wall time (``sent_*_ns``) it spans."""
    reason = packet.drop_reason or "reported on packets missing from the recording (see its gaps)"
    return {
        "seq": packet.seq,
        "reports": reports,
        "count": packet.drop_count,
        "unit": packet.drop_unit,
        "reason": reason,
        "t_from_us": last_t_us if last_t_us is not None else packet.t_first_us,
        "t_to_us": packet.t_first_us,
        "sent_from_ns": last_sent_ns,
        "sent_to_ns": packet.sent_ns,
    }


def drop_summary(drops: list[dict[str, Any]]) -> str:
    """The device drops of a sidecar in one line: each reason once, with how often and how much."""
    by_reason: dict[str, list[dict[str, Any]]] = {}
    for drop in drops:
        by_reason.setdefault(drop["reason"], []).append(drop)
    parts = []
    for reason, same in by_reason.items():
        reports = sum(d["reports"] for d in same)
        units = {d["unit"] for d in same}
        total = sum(d["count"] for d in same)
        amount = ""
        if len(units) == 1 and total:
            unit = units.pop()
            amount = f"{total * 1e-6:g} s" if unit == "us" else f"{total} {unit.replace('_', ' ')}"
        counted = ", ".join(x for x in (amount, f"{reports} times" if reports > 1 else "") if x)
        parts.append(f"{reason} ({counted})" if counted else reason)
    return "; ".join(parts)


def gap_times_s(spans: list[dict[str, int]]) -> np.ndarray:
    """(n, 2) start and end of each gap on the recording's clock (s), as a centreline file's ``t``."""
    return np.array([[g["t_from_us"] * 1e-6, g["t_to_us"] * 1e-6] for g in spans], dtype=np.float64).reshape(-1, 2)
