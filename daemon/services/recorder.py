"""The recorder service: every packet of a camera to a ``.raw`` file, loss-free, plus a JSON sidecar.

The file is a valid RAW stream in the camera's native encoding (header, a time-base preamble, the
packets' bytes as they came). Packets are appended by this service's own loop, never in Zenoh's
callback, so the camera is never held up; the file is flushed every ``flush_interval_s`` and
fsynced every ``fsync_interval_s`` and on close, so a recording cut by a crash is readable up to its
last flush. The queue between Zenoh and that loop holds up to ``max_queue_bytes`` (512 MB: a disk
that falls that far behind loses the oldest packets, counted in the sidecar's ``dropped_packets``).
Sequence gaps are listed in the sidecar. Commands (start / stop / rotate) come on the
recorder command key; centrelines can be recorded beside the events (the centreline file layout).

**One file per camera stream.** The packets of two streams do not make one valid stream (the
second one's times start again), so when a new stream begins while recording to ``BASE`` (the
sequence number goes back: the camera restarted; a packet after the end of stream; or another
encoding or geometry) the recorder closes ``BASE.raw`` and goes on in ``BASE_stream2.raw`` (then
``_stream3`` ...), with its own sidecar and centreline file. The sidecars link the parts
(``continued_in``, ``continues``). The tracker's centrelines lag the packets, so the old part keeps
taking those whose newest packet (``source_ns``) came before the new stream's first, until the
tracker's first of the new stream, its final message, or ``drain_timeout_s`` without any.

**Nothing one message holds stops the service.** A message that does not decode, a packet whose
encoding or time offset cannot start a file, a centreline message that does not fit the file, a
command that cannot be carried out: each is counted (sidecar ``malformed_packets``, status) and
logged as a rate-limited summary.

**Commands stay in the recorder's folders.** A start or rotate command names a recording inside
``directory`` (or ``allowed_dirs``: the rig builder adds the supervisor's ``runs_dir``, where sweep
points go); a path that resolves elsewhere (an absolute path elsewhere, ``..``, a symbolic link out,
``~user``) is refused with an error status, before anything is written or the current recording
stopped. Every command carried out is logged with where it came from (:attr:`Subscription.origin`).

**End of stream.** With ``exit_at_end_of_stream``, the recorder stops after the camera's end of
stream only once it has the tracker's last centreline message (``final``), or after
``drain_timeout_s`` without any centreline message, so the last updates are in the file.
"""

from __future__ import annotations

import errno
import json
import logging
import os
import shutil
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from flagtrack.daemon import __version__
from flagtrack.daemon.errors import FormatError, SchemaError
from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import CentrelineMessage, EventPacket, RecorderCommand, RecorderStatus, decode
from flagtrack.daemon.services.sd_notify import beat
from flagtrack.daemon.services.sequence import Arrival, PacketSequence, packet_problem
from flagtrack.daemon.transport import Bus
from flagtrack.drivers.formats import raw_header
from flagtrack.drivers.formats.centreline import CentrelineShapeError, CentrelineSink
from flagtrack.drivers.formats.packets import stream_preamble

log = logging.getLogger(__name__)


def recording_base(directory: str | Path, path: str) -> Path:
    """The base path (no extension) of a recording named ``path``: as given if absolute, else in ``directory``."""
    base = Path(path).expanduser()
    return base if base.is_absolute() else Path(directory).expanduser() / base


RECORDING_SUFFIXES = (".raw", ".json", ".json.tmp", "_centrelines.h5")
"""The files of a recording ``BASE``: ``BASE.raw``, its sidecar (written through ``.json.tmp``), its centrelines."""


def confined_base(path: str, roots: Sequence[str | Path]) -> Path:
    """The base path of the recording a command names, if it stays inside one of ``roots``.

    ``path`` is relative to the first root, or absolute inside one. It is refused when it is empty,
    starts with ``~`` (not expanded: ``~user`` would name another home), has a ``..`` part, or
    resolves (symbolic links followed) outside every root, or when one of the recording's files is a
    symbolic link. Nothing is created. Returns the resolved path.

    Raises:
        ValueError: naming the path and why.
    """
    if not path or "\x00" in path:
        raise ValueError("an empty path or one with a NUL character")
    folders = [Path(root).expanduser().resolve() for root in roots]
    where = " or ".join(map(str, folders))
    if path.startswith("~"):
        raise ValueError(f"{path!r}: '~' is not expanded in a command; name a path in {where}")
    given = Path(path)
    if ".." in given.parts:
        raise ValueError(f"{path!r}: '..' is not allowed; name a path in {where}")
    resolved = (given if given.is_absolute() else folders[0] / given).resolve()
    if not any(resolved != folder and resolved.is_relative_to(folder) for folder in folders):
        raise ValueError(f"{path!r} resolves to {resolved}, outside {where}")
    for suffix in RECORDING_SUFFIXES:
        file = resolved.with_name(resolved.name + suffix)
        if file.is_symlink():
            raise ValueError(f"{path!r}: {file} is a symbolic link")
    return resolved


@dataclass(frozen=True)
class RecorderConfig:
    """Recorder settings.

    Attributes:
        camera_id: the camera recorded.
        directory: where relative recording paths go, and where commands may name recordings.
        allowed_dirs: other folders commands may name recordings in (the rig builder adds the
            supervisor's ``runs_dir``).
        path: start recording at launch to this path (no extension), or wait for a start command.
        centrelines: also record tracker centrelines to ``<path>_centrelines.h5``.
        flush_interval_s: hand written bytes to the OS at least this often.
        fsync_interval_s: force them to disk at least this often.
        max_queue_packets: packets held in memory while the disk catches up (beyond: dropped, counted).
        max_queue_bytes: bytes of packets held in memory while the disk catches up (beyond: the
            oldest are dropped, counted in the sidecar's ``dropped_packets`` and listed as a sequence
            gap; the newest, and so the end of stream, are kept); the camera is never held up.
        drain_timeout_s: after the end of a stream (or a restart), how long to wait for more of its
            centrelines once none come.
        min_free_mb: a recording stops (one error line, an ``error`` status) when its disk has less
            than this free, MB, before the disk is full: the HDF5 library does not survive a full disk.
    """

    camera_id: str = "cam0"
    directory: Path = Path("recordings")
    allowed_dirs: tuple[Path, ...] = ()
    path: str | None = None
    centrelines: bool = False
    flush_interval_s: float = 0.2
    fsync_interval_s: float = 2.0
    max_queue_packets: int = 1_000_000
    max_queue_bytes: int = 512 << 20
    drain_timeout_s: float = 5.0
    min_free_mb: float = 64.0


@dataclass
class RecordingPart:
    """One open recording: the .raw file, its sidecar and, optionally, the centreline file.

    ``part`` numbers the files of one recording (one per camera stream, see the module docstring);
    ``first_base`` is the base path of part 1. ``centreline_attrs`` (processing parameters and
    calibration) go in the centreline file's attributes with the units, the source and the .raw file.
    """

    base: Path
    config: dict[str, Any]
    raw: BinaryIO | None = None
    centrelines: CentrelineSink | None = None
    want_centrelines: bool = False
    centreline_attrs: dict[str, Any] = field(default_factory=dict)
    bytes: int = 0
    packets: int = 0
    events: int = 0
    sequence: PacketSequence = field(default_factory=PacketSequence)
    gaps: list[list[int]] = field(default_factory=list)
    gap_spans: list[dict[str, int]] = field(default_factory=list)  # each gap's times (sidecar "gaps")
    last_sent_ns: int = 0
    malformed: int = 0
    late: int = 0  # duplicates and late packets of the stream, dropped
    dropped: int = 0
    flushed_at: int = 0  # size of the .raw file at its last flush (what a failed write cuts it back to)
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
    _stream_key: tuple[str, int, int] | None = None
    _last_flush: float = field(default_factory=time.monotonic)
    _last_fsync: float = field(default_factory=time.monotonic)

    def __post_init__(self) -> None:
        if self.want_centrelines:  # the file is created at the first update
            self.centrelines = CentrelineSink(
                self.centrelines_path, {**self.centreline_attrs, "input_file": str(self.raw_path)}
            )

    @property
    def raw_path(self) -> Path:
        return self.base.with_name(self.base.name + ".raw")

    @property
    def sidecar_path(self) -> Path:
        return self.base.with_name(self.base.name + ".json")

    @property
    def centrelines_path(self) -> Path:
        return self.base.with_name(self.base.name + "_centrelines.h5")

    def new_stream(self, packet: EventPacket, arrival: Arrival) -> str | None:
        """Why ``packet`` (``arrival`` in this file's sequence) begins a new camera stream (it cannot go
        in this file), or None. O(1)."""
        if self._stream_key is None:
            return None
        if self.ended:
            return f"packet {packet.seq} after the end of stream"
        if arrival is Arrival.NEW_STREAM:
            return (
                f"packet {packet.seq} of another stream after packet {(self.sequence.next_seq or 0) - 1} "
                "(camera restarted)"
            )
        if (packet.encoding, packet.width, packet.height) != self._stream_key:
            return (
                f"packet {packet.seq} is {packet.encoding} {packet.width}x{packet.height}, the file "
                f"{self._stream_key[0]} {self._stream_key[1]}x{self._stream_key[2]}"
            )
        return None

    def write_packet(self, packet: EventPacket) -> None:
        """Append one packet (opening the file at the first one: its geometry and encoding).

        Raises:
            FormatError: the first packet cannot start a file (encoding, time offset, camera id in
                the header); nothing is written then.
        """
        if self.raw is None:
            start = raw_header(
                packet.encoding,
                packet.width,
                packet.height,
                {"camera_id": packet.camera_id, "recorder": f"flagtrack-{__version__}"},
                simulated=(self.config.get("camera") or {}).get("adapter") == "simulated",
            ) + stream_preamble(packet.encoding, packet.t_offset_us)
            self.raw_path.parent.mkdir(parents=True, exist_ok=True)
            self.raw = open(self.raw_path, "wb")  # noqa: SIM115 - closed in close()
            self.geometry = {"width": packet.width, "height": packet.height, "encoding": packet.encoding}
            self._stream_key = (packet.encoding, packet.width, packet.height)
            if self.centrelines is not None:  # the centreline file says the sensor's size
                self.centrelines.set_attrs({"sensor_width_px": packet.width, "sensor_height_px": packet.height})
            self.raw.write(start)
            self.raw.flush()
            self.flushed_at = self.raw.tell()
            self.write_sidecar()
        expected = self.sequence.next_seq
        arrival, _ = self.sequence.arrive(packet.seq, packet.stream_id)
        self.sequence.follow_horizon(packet.t_last_us)
        if arrival is Arrival.GAP:
            self.gaps.append([expected, packet.seq])
            self.gap_spans.append(gap_span(expected, packet, self.last_t_us, self.last_sent_ns))
            if self.centrelines is not None:  # the centreline file says where its updates have a hole
                self.centrelines.set_attrs({"gaps_t_s": gap_times_s(self.gap_spans)})
        self.last_sent_ns = packet.sent_ns
        data = packet.data
        if packet.preamble_bytes and self.packets and arrival is not Arrival.GAP:
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

    def write_centrelines(self, msg: CentrelineMessage) -> None:
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

    def sync(self, cfg: RecorderConfig, force: bool = False) -> None:
        """Flush (and fsync) when due."""
        now = time.monotonic()
        if self.centrelines is not None and (force or now - self._last_flush >= cfg.flush_interval_s):
            self.centrelines.flush()
        if self.raw is not None and (force or now - self._last_flush >= cfg.flush_interval_s):
            self.raw.flush()
            self.flushed_at = self.raw.tell()
            self._last_flush = now
            if force or now - self._last_fsync >= cfg.fsync_interval_s:
                os.fsync(self.raw.fileno())
                self._last_fsync = now
                self.write_sidecar()

    def write_sidecar(self, stopped: bool = False) -> None:
        """Rewrite the JSON sidecar atomically (temporary file then rename)."""
        doc = {
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
            "missing_packets": sum(b - a for a, b in self.gaps),
            "malformed_packets": self.malformed,
            "late_packets": self.late,
            "dropped_packets": self.dropped,
            "part": self.part,
            "continues": self.continues,
            "continued_in": self.continued_in,
            "config": self.config,
            "centrelines_file": self.centrelines_path.name if self.centrelines and self.centrelines.opened else None,
        }
        self.sidecar_path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.sidecar_path.with_name(self.sidecar_path.name + ".tmp")
        tmp.write_text(json.dumps(doc, indent=2))
        os.replace(tmp, self.sidecar_path)

    def close_raw(self) -> None:
        """Flush, fsync and close the .raw file (the centreline file stays open)."""
        if self.raw is not None and not self.raw.closed:
            self.raw.flush()
            os.fsync(self.raw.fileno())
            self.raw.close()

    def close(self) -> None:
        """Flush, fsync and close everything; final sidecar."""
        self.close_raw()
        if self.centrelines is not None:
            self.centrelines.close()
        self.write_sidecar(stopped=True)

    def abandon(self) -> None:
        """After a failed write (a full disk): close everything as far as it goes and cut the .raw
        file back to its last flush, so it reads back whole up to there. Never raises."""
        for step in (self._close_raw_file, self._cut_back, self._close_centrelines, lambda: self.write_sidecar(True)):
            try:
                step()
            except (OSError, RuntimeError, ValueError) as exc:
                log.debug("recorder: abandoning %s: %s", self.raw_path, exc)

    def _close_raw_file(self) -> None:
        if self.raw is not None and not self.raw.closed:
            self.raw.close()

    def _cut_back(self) -> None:
        if self.raw is not None:
            os.truncate(self.raw_path, self.flushed_at)

    def _close_centrelines(self) -> None:
        if self.centrelines is not None:
            self.centrelines.close()

    def next_part(self) -> RecordingPart:
        """The recording of the next camera stream: ``<first base>_stream<part + 1>``, linked to this one."""
        first = self.first_base or self.base
        part = RecordingPart(
            base=first.with_name(f"{first.name}_stream{self.part + 1}"),
            config=self.config,
            want_centrelines=self.want_centrelines,
            centreline_attrs=self.centreline_attrs,
            part=self.part + 1,
            first_base=first,
            continues=self.raw_path.name,
        )
        self.continued_in = part.raw_path.name
        return part


def gap_span(expected: int, packet: EventPacket, last_t_us: int | None, last_sent_ns: int) -> dict[str, int]:
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


def gap_times_s(spans: list[dict[str, int]]) -> np.ndarray:
    """(n, 2) start and end of each gap on the recording's clock (s), as a centreline file's ``t``."""
    return np.array([[g["t_from_us"] * 1e-6, g["t_to_us"] * 1e-6] for g in spans], dtype=np.float64).reshape(-1, 2)


class RecorderService:
    """Records one camera's packets on command (or from launch)."""

    name = "recorder"

    def __init__(
        self,
        bus: Bus,
        cfg: RecorderConfig,
        config_snapshot: dict[str, Any] | None = None,
        exit_at_end_of_stream: bool = False,
        centreline_attrs: dict[str, Any] | None = None,
    ) -> None:
        self.bus = bus
        self.exit_at_end_of_stream = exit_at_end_of_stream
        self._stream_ended = False
        self.cfg = cfg
        self.config_snapshot = config_snapshot or {}
        self.centreline_attrs = centreline_attrs or {}  # processing parameters and calibration, for every file
        self.current: RecordingPart | None = None
        self.finished: list[Path] = []
        self.lost_packets = 0
        self.malformed_packets = 0  # whole run, recording or not
        self.late_packets = 0  # duplicates and late packets, dropped
        self.restarts = 0  # new camera streams while recording (each started a new file)
        self.problems = ProblemLog(log, "recorder")
        self._draining: RecordingPart | None = None  # the previous stream's part, still taking its centrelines
        self._last_line_s = 0.0  # monotonic time of the last centreline message (or of the end of stream)
        self._final_seen = False
        self._dropped_before = 0  # the queue's drop count when the current part began

        keys = bus.keys
        self._packets = bus.subscribe(
            keys.camera_events(cfg.camera_id),
            EventPacket,
            capacity=cfg.max_queue_packets,
            max_bytes=cfg.max_queue_bytes,
            ring=True,
        )
        self._lines = bus.subscribe(keys.centrelines(), CentrelineMessage, capacity=100_000, max_bytes=256 << 20)
        self._commands = bus.subscribe(
            keys.recorder_command(), RecorderCommand, capacity=1000, max_bytes=1 << 20, origins=True
        )
        self.refused_commands = 0
        self._free_checked_s = 0.0

    def run(self, stop: threading.Event) -> None:
        keys = self.bus.keys
        packets, commands = self._packets, self._commands
        self.status_pub = self.bus.publisher(keys.recorder_status())
        self.bus.declare_alive(self.name)
        if self.cfg.path:
            self.start(self.cfg.path, self.cfg.centrelines)
        try:
            while not stop.is_set():
                beat(self.name, self._beat_status())
                command = commands.recv(timeout_s=0)
                if command is not None:
                    self.handle(command)
                    continue
                item = packets.recv_raw(timeout_s=0.02)
                if item is not None:
                    self._write_raw_packet(*item)
                    for item in packets.channel.drain():
                        self._write_raw_packet(*item)
                now = time.monotonic()
                self._take_lines(now)
                if self._stream_ended and self.exit_at_end_of_stream and self._lines_done(now):
                    break
                if packets.channel.dropped > self.lost_packets:
                    self.problems.add(
                        "packets dropped by the full queue",
                        f"the queue dropped {packets.channel.dropped} packet(s) in all (the disk falls behind)",
                        packets.channel.dropped - self.lost_packets,
                    )
                    self.lost_packets = packets.channel.dropped
                if self.current is not None:
                    self.current.dropped = self.lost_packets - self._dropped_before
                    try:
                        self.current.sync(self.cfg)
                        self._check_free_space(now)
                    except (OSError, RuntimeError) as exc:  # a full disk
                        self._write_failed(exc)
                if self._draining is not None and now - self._last_line_s >= self.cfg.drain_timeout_s:
                    self._close_draining()
                self.problems.flush()
            for item in packets.channel.drain():  # what arrived before the stop
                self._write_raw_packet(*item)
            self._take_lines(time.monotonic())
        finally:
            self.stop_recording()
            self.problems.flush(force=True)

    def _beat_status(self) -> str:
        where = self.current.raw_path.name if self.current is not None else "idle"
        return f"{where}, {self.lost_packets} packets lost"

    def handle(self, command: RecorderCommand, origin: str = "") -> None:
        """Carry out a start / stop / rotate command and publish the resulting status (an error
        status if it cannot be carried out: a path outside the recorder's folders, one that cannot
        be written). ``origin``: where it came from, for the log (default: the command subscription's)."""
        origin = origin or self._commands.origin or "this process"
        request = f" (request {command.request_id})" if command.request_id else ""
        if command.action not in ("start", "rotate", "stop"):
            self._refuse(command, f"unknown action {command.action!r}", origin)
            return
        base = None
        if command.action != "stop":
            try:
                base = confined_base(command.path, [self.cfg.directory, *self.cfg.allowed_dirs])
            except ValueError as exc:  # outside the recorder's folders: refused, nothing written or stopped
                self._refuse(command, f"{command.action} refused: {exc}", origin)
                return
        log.info("recorder: %s%s%s, on %s", command.action, f" {base}" if base else "", request, origin)
        try:
            if base is None:
                self.stop_recording(request_id=command.request_id)
            else:
                self.stop_recording(request_id=command.request_id if self.current is not None else "")
                self._start_at(base, command.centrelines, request_id=command.request_id)
        except (OSError, ValueError, RuntimeError) as exc:  # e.g. a path under a file
            self.problems.add("commands that failed", f"{command.action} {command.path!r} on {origin}: {exc}")
            self._status("error", message=f"{command.action} failed: {exc}", request_id=command.request_id)

    def _refuse(self, command: RecorderCommand, why: str, origin: str) -> None:
        self.refused_commands += 1
        self.problems.add("commands refused", f"{why} (on {origin})")
        self._status("error", message=why, request_id=command.request_id)

    def start(self, path: str, centrelines: bool, request_id: str = "") -> None:
        """Begin a recording at ``path`` (no extension; relative to the configured directory), as the
        config's ``path`` says (a command's path is checked first, see :meth:`handle`)."""
        self._start_at(recording_base(self.cfg.directory, path), centrelines, request_id)

    def _start_at(self, base: Path, centrelines: bool, request_id: str = "") -> None:
        self._begin(
            RecordingPart(
                base=base,
                config=self.config_snapshot,
                want_centrelines=centrelines or self.cfg.centrelines,
                centreline_attrs=self.centreline_attrs,
            ),
            request_id,
        )

    def _begin(self, recording: RecordingPart, request_id: str = "", message: str = "") -> None:
        recording.write_sidecar()
        self.current = recording
        self._dropped_before = self._packets.channel.dropped
        log.info("recorder: recording to %s", recording.raw_path)
        self._status("recording", request_id=request_id, message=message)

    def stop_recording(self, request_id: str = "") -> None:
        """Close the current recording (if any)."""
        self._close_draining()
        if self.current is None:
            if request_id:
                self._status("idle", request_id=request_id)
            return
        recording, self.current = self.current, None
        self._close(recording)
        self._status("idle", recording=recording, request_id=request_id)

    def _check_free_space(self, now_s: float) -> None:
        """Raise OSError(ENOSPC) when the current recording's disk has less than ``min_free_mb`` free
        (looked at every 0.25 s at most)."""
        if self.current is None or now_s - self._free_checked_s < 0.25:
            return
        self._free_checked_s = now_s
        free = shutil.disk_usage(self.current.raw_path.parent).free
        if free < self.cfg.min_free_mb * 1e6:
            raise OSError(
                errno.ENOSPC, f"No space left on device: {free / 1e6:.1f} MB free, below recorder.min_free_mb"
            )

    def _write_failed(self, exc: BaseException, recording: RecordingPart | None = None) -> None:
        """Writing a recording (by default the current one) failed (a full disk): stop it, its .raw
        file cut back to its last flush; say so in one line and in an ``error`` status. The recorder
        goes on, idle."""
        if recording is None or recording is self.current:
            recording, self.current = self.current, None
        if recording is None:
            return
        why = getattr(exc, "strerror", None) or str(exc)
        message = (
            f"recording stopped: writing {recording.raw_path} failed: {why}; the file is kept up to its "
            f"last flush ({recording.flushed_at} bytes)"
        )
        log.error("recorder: %s", message)
        recording.abandon()
        self.finished.append(recording.raw_path)
        self._status("error", recording=recording, message=message)

    def _close(self, recording: RecordingPart) -> None:
        try:
            recording.close()
        except (OSError, RuntimeError) as exc:  # a full disk at the last flush
            self._write_failed(exc, recording)
            return
        self.finished.append(recording.raw_path)
        log.info(
            "recorder: closed %s (%d packets, %d bytes, %d gaps)",
            recording.raw_path,
            recording.packets,
            recording.bytes,
            len(recording.gaps),
        )

    def _close_draining(self) -> None:
        if self._draining is not None:
            recording, self._draining = self._draining, None
            self._close(recording)

    def _write_raw_packet(self, key: str, payload: bytes) -> None:
        try:
            packet = decode(payload, EventPacket, key=key)
        except SchemaError as exc:
            self._malformed(exc)
            return
        horizon = None  # of the stream the packet continues, if it does (its times may not jump far past it)
        if self.current is not None:
            arrival, _ = self.current.sequence.classify(packet.seq, packet.stream_id)
            if self.current.new_stream(packet, arrival) is None:
                horizon = self.current.sequence.horizon_us
        problem = packet_problem(packet, horizon)
        if problem is not None:
            self._malformed(SchemaError(problem, key=key))
            return
        if self.current is not None:
            reason = self.current.new_stream(packet, arrival)
            if reason is not None:
                self._next_part(reason, packet)
            elif arrival is Arrival.LATE:
                self.late_packets += 1  # a duplicate, or a packet already passed: the file has it, or its gap
                self.current.late += 1
                self.problems.add("late or duplicate packets", f"packet {packet.seq}: dropped", 1)
                return
            try:
                self.current.write_packet(packet)
            except FormatError as exc:  # the first packet cannot start the file: nothing was written
                self._malformed(exc)
                return
            except OSError as exc:  # a full disk
                self._write_failed(exc)
                return
        if packet.end_of_stream:
            self._stream_ended = True
            self._last_line_s = time.monotonic()  # the tracker's last centrelines come after this

    def _malformed(self, exc: Exception) -> None:
        self.malformed_packets += 1
        if self.current is not None:
            self.current.malformed += 1
        self.problems.add("malformed packets", exc)

    def _next_part(self, reason: str, packet: EventPacket) -> None:
        """A new camera stream (from ``packet`` on) while recording: close this part's .raw file and
        go on in the next part; this part keeps the old stream's centrelines until the tracker moves
        on (or times out)."""
        old = self.current
        assert old is not None
        new = old.next_part()
        new.first_sent_ns = packet.sent_ns
        if not old.ended:
            self.restarts += 1
        self.problems.add("new camera streams", f"{reason}: {old.raw_path.name} continues in {new.raw_path.name}")
        self._close_draining()
        old.close_raw()
        if old.want_centrelines:
            self._draining = old
            self._last_line_s = time.monotonic()
        else:
            self._close(old)
        self._begin(new, message=f"new camera stream ({reason}), continued from {old.raw_path.name}")

    def _take_lines(self, now: float) -> None:
        """Route the centreline messages that came: to the previous part while they are of its stream,
        else to the current recording (read and dropped undecoded when nothing records them)."""
        lines = self._lines
        if not self._recording_lines:
            lines.channel.drain()  # not recording them: no need to decode
            return
        while (msg := lines.recv(timeout_s=0)) is not None:
            self._last_line_s = now
            self._final_seen |= msg.final
            target, draining = self.current, self._draining
            if draining is not None:
                if self._of_previous_stream(msg):
                    target = draining
                else:  # the tracker is on the new stream: the old one's centrelines are all in
                    self._close_draining()
            if target is not None:
                try:
                    target.write_centrelines(msg)
                except SchemaError as exc:
                    self.problems.add("centreline messages not recorded", exc)
            if msg.final and target is draining is not None:
                self._close_draining()

    @property
    def _recording_lines(self) -> bool:
        """Whether a part (the current one, or the previous one still draining) records centrelines."""
        return self._draining is not None or (self.current is not None and self.current.want_centrelines)

    def _of_previous_stream(self, msg: CentrelineMessage) -> bool:
        """Whether ``msg`` (while a previous part drains) comes from packets older than the current
        part's first (an empty one, such as a final message, goes with the previous part). O(1)."""
        first_ns = self.current.first_sent_ns if self.current is not None else None
        return len(msg.source_ns) == 0 or first_ns is not None and 0 < msg.source_ns[-1] < first_ns

    def _lines_done(self, now: float) -> bool:
        """At the end of a stream: whether the tracker's last centrelines are in (or will not come)."""
        if not self._recording_lines:
            return True
        if self._final_seen:
            return True
        if now - self._last_line_s >= self.cfg.drain_timeout_s:
            log.warning(
                "recorder: no final centreline message within %.1f s after the end of stream; closing",
                self.cfg.drain_timeout_s,
            )
            return True
        return False

    def _status(
        self, state: str, *, recording: RecordingPart | None = None, message: str = "", request_id: str = ""
    ) -> None:
        rec = recording or self.current
        if not hasattr(self, "status_pub"):
            return
        self.status_pub.put(
            RecorderStatus(
                state=state,
                path=str(rec.raw_path) if rec else "",
                bytes=rec.bytes if rec else 0,
                packets=rec.packets if rec else 0,
                missing_packets=sum(b - a for a, b in rec.gaps) if rec else 0,
                request_id=request_id,
                message=message,
                malformed_packets=rec.malformed if rec else 0,
                dropped_packets=self._packets.channel.dropped,
            )
        )
