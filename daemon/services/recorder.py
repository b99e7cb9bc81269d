"""The recorder service: every packet of a camera to a ``.raw`` file, loss-free, plus a JSON sidecar.

The files are :mod:`flagtrack.drivers.formats.recording`'s (a part per camera stream, sidecars,
roll-over, free-space checks); this service wires the bus to them and follows the camera's stream.
Packets are appended by its own loop, never in Zenoh's callback, so the camera is never held up; the
queue between holds up to ``max_queue_bytes`` (a disk that falls that far behind loses the oldest
packets, counted in the sidecar's ``dropped_packets``). Commands (start / stop / rotate) come on the
recorder command key; centrelines can be recorded beside the events
(:class:`~flagtrack.drivers.formats.centreline.CentrelineSink`).

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

import logging
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flagtrack.daemon.errors import FormatError, SchemaError
from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import CentrelineMessage, EventPacket, RecorderCommand, RecorderStatus, decode
from flagtrack.daemon.services.sd_notify import beat
from flagtrack.daemon.services.sequence import Arrival, PacketSequence, packet_problem
from flagtrack.daemon.transport import Bus
from flagtrack.drivers.formats.recording import (
    RECORDING_SUFFIXES,
    FreeSpaceGuard,
    PartChain,
    RecordingPart,
    confined_base,
    drop_summary,
    recording_base,
)

__all__ = [
    "RECORDING_SUFFIXES",
    "RecorderConfig",
    "RecorderService",
    "RecordingPart",
    "confined_base",
    "recording_base",
]

log = logging.getLogger(__name__)


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

    def __post_init__(self) -> None:
        if self.min_free_mb < 0:
            raise ValueError(f"min_free_mb must be >= 0, got {self.min_free_mb}")
        timeouts = (self.flush_interval_s, self.fsync_interval_s, self.drain_timeout_s)
        if min(timeouts) <= 0:
            raise ValueError(f"flush_interval_s, fsync_interval_s, drain_timeout_s must be positive, got {timeouts}")


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
        self._parts = PartChain(on_failure=self._write_failed)  # the current part, the previous one draining
        self.lost_packets = 0
        self.malformed_packets = 0  # whole run, recording or not
        self.late_packets = 0  # duplicates and late packets, dropped
        self.restarts = 0  # new camera streams while recording (each started a new file)
        self.problems = ProblemLog(log, "recorder")
        self._last_line_s = 0.0  # monotonic time of the last centreline message (or of the end of stream)
        self._final_seen = False
        self._dropped_before = 0  # the queue's drop count when the current part began
        self.refused_commands = 0
        self.failure = ""  # why the last recording stopped on its own (a full disk), "" if none did
        self._free_space = FreeSpaceGuard(cfg.min_free_mb, setting="recorder.min_free_mb")
        self._sequence = PacketSequence()  # the camera stream the current part follows

    def start(self) -> None:
        """Subscribe to the camera's packets, the centrelines and the recorder commands."""
        keys, cfg = self.bus.keys, self.cfg
        self._packets = self.bus.subscribe(
            keys.camera_events(cfg.camera_id),
            EventPacket,
            capacity=cfg.max_queue_packets,
            max_bytes=cfg.max_queue_bytes,
            ring=True,
        )
        self._lines = self.bus.subscribe(keys.centrelines(), CentrelineMessage, capacity=100_000, max_bytes=256 << 20)
        self._commands = self.bus.subscribe(
            keys.recorder_command(), RecorderCommand, capacity=1000, max_bytes=1 << 20, origins=True
        )

    @property
    def current(self) -> RecordingPart | None:
        """The part being recorded, if any."""
        return self._parts.current

    @property
    def finished(self) -> list[Path]:
        """The .raw files closed so far."""
        return self._parts.finished

    def run(self, stop: threading.Event) -> None:
        packets = self._packets
        self.status_pub = self.bus.publisher(self.bus.keys.recorder_status())
        self.bus.declare_alive(self.name)
        if self.cfg.path:
            self.start_recording(self.cfg.path, self.cfg.centrelines)
        try:
            while not stop.is_set():
                beat(self.name, self._beat_status())
                command = self._commands.recv(timeout_s=0)
                if command is not None:
                    self.handle(command)
                    continue
                item = packets.recv_raw(timeout_s=0.02)
                if item is not None:
                    self._write_raw_packet(*item)
                    self._write_queued_packets()
                now = time.monotonic()
                self._take_lines(now)
                if self._stream_ended and self.exit_at_end_of_stream and self._lines_done(now):
                    break
                self._keep_up(now)
            self._write_queued_packets()  # what arrived before the stop
            self._take_lines(time.monotonic())
        finally:
            self.stop_recording()
            self.problems.flush(force=True)

    def _keep_up(self, now: float) -> None:
        """The loop's chores: count the queue's drops, flush and fsync the files when due, check the
        free space, close a previous part whose centrelines stopped coming."""
        dropped = self._packets.channel.dropped
        if dropped > self.lost_packets:
            self.problems.add(
                "packets dropped by the full queue",
                f"the queue dropped {dropped} packet(s) in all (the disk falls behind)",
                dropped - self.lost_packets,
            )
            self.lost_packets = dropped
        if (part := self.current) is not None:
            part.dropped = self.lost_packets - self._dropped_before
            try:
                part.sync(self.cfg)
                self._free_space.check(part.raw_path.parent, now)
            except (OSError, RuntimeError) as exc:  # a full disk
                self._parts.fail(exc)
        if self._parts.draining is not None and now - self._last_line_s >= self.cfg.drain_timeout_s:
            self._parts.close_draining()
        self.problems.flush()

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

    def start_recording(self, path: str, centrelines: bool, request_id: str = "") -> None:
        """Begin a recording at ``path`` (no extension; relative to the configured directory), as the
        config's ``path`` says (a command's path is checked first, see :meth:`handle`)."""
        self._start_at(recording_base(self.cfg.directory, path), centrelines, request_id)

    def _start_at(self, base: Path, centrelines: bool, request_id: str = "") -> None:
        part = RecordingPart(
            base=base,
            config=self.config_snapshot,
            want_centrelines=centrelines or self.cfg.centrelines,
            centreline_attrs=self.centreline_attrs,
        )
        self._parts.begin(part)
        self._began(part, request_id)

    def _began(self, part: RecordingPart, request_id: str = "", message: str = "") -> None:
        self._sequence = PacketSequence()
        self._dropped_before = self._packets.channel.dropped
        log.info("recorder: recording to %s", part.raw_path)
        self._status("recording", request_id=request_id, message=message)

    def stop_recording(self, request_id: str = "") -> None:
        """Close the current recording (if any)."""
        part = self._parts.stop()
        if part is not None:
            self._status("idle", recording=part, request_id=request_id)
        elif request_id:
            self._status("idle", request_id=request_id)

    def _write_failed(self, part: RecordingPart, message: str) -> None:
        """Writing ``part`` failed (a full disk; it is cut back and closed): one error line, an ``error`` status."""
        log.error("recorder: %s", message)
        self.failure = message
        self._status("error", recording=part, message=message)

    def _write_queued_packets(self) -> None:
        for item in self._packets.channel.drain():
            self._write_raw_packet(*item)

    def _write_raw_packet(self, key: str, payload: bytes) -> None:
        try:
            packet = decode(payload, EventPacket, key=key)
        except SchemaError as exc:
            self._malformed(exc)
            return
        arrival, _ = self._sequence.classify(packet.seq, packet.stream_id)
        reason = self._new_stream(packet, arrival)
        # the horizon of the stream the packet continues, if it does (its times may not jump far past it)
        horizon = self._sequence.horizon_us if self.current is not None and reason is None else None
        problem = packet_problem(packet, horizon)
        if problem is not None:
            self._malformed(SchemaError(problem, key=key))
            return
        if self.current is not None and not self._record(packet, arrival, reason):
            return
        if packet.end_of_stream:
            self._stream_ended = True
            self._last_line_s = time.monotonic()  # the tracker's last centrelines come after this

    def _new_stream(self, packet: EventPacket, arrival: Arrival) -> str | None:
        """Why ``packet`` (``arrival`` in the current part's stream) begins a new camera stream (it
        cannot go in the current part's file), or None. O(1)."""
        part = self.current
        if part is None or not part.opened:
            return None
        if part.ended:
            return f"packet {packet.seq} after the end of stream"
        if arrival is Arrival.NEW_STREAM:
            last = (self._sequence.next_seq or 0) - 1
            return f"packet {packet.seq} of another stream after packet {last} (camera restarted)"
        return part.format_change(packet)

    def _record(self, packet: EventPacket, arrival: Arrival, new_stream: str | None) -> bool:
        """Write ``packet`` to the current part (to the next part first if ``new_stream`` says why);
        whether it was written."""
        if new_stream is not None:
            self._next_part(new_stream, packet)
            arrival, _ = self._sequence.classify(packet.seq, packet.stream_id)
        part = self.current
        assert part is not None
        if arrival is Arrival.LATE:
            self.late_packets += 1  # a duplicate, or a packet already passed: the file has it, or its gap
            part.late += 1
            self.problems.add("late or duplicate packets", f"packet {packet.seq}: dropped", 1)
            return False
        try:
            part.write_packet(packet, gap_from=self._sequence.next_seq if arrival is Arrival.GAP else None)
        except FormatError as exc:  # the first packet cannot start the file: nothing was written
            self._malformed(exc)
            return False
        except OSError as exc:  # a full disk
            self._parts.fail(exc)
            return False
        self._sequence.arrive(packet.seq, packet.stream_id)
        self._sequence.follow_horizon(packet.t_last_us)
        return True

    def _malformed(self, exc: Exception) -> None:
        self.malformed_packets += 1
        if self.current is not None:
            self.current.malformed += 1
        self.problems.add("malformed packets", exc)

    def _next_part(self, reason: str, packet: EventPacket) -> None:
        """A new camera stream (from ``packet`` on) while recording: go on in the next part; the old
        part keeps the old stream's centrelines until the tracker moves on (or times out)."""
        old, new = self._parts.roll_over(first_sent_ns=packet.sent_ns)
        if not old.ended:
            self.restarts += 1
        self.problems.add("new camera streams", f"{reason}: {old.raw_path.name} continues in {new.raw_path.name}")
        if self._parts.draining is old:
            self._last_line_s = time.monotonic()
        self._began(new, message=f"new camera stream ({reason}), continued from {old.raw_path.name}")

    def _take_lines(self, now: float) -> None:
        """Route the centreline messages that came to the parts (dropped undecoded if none takes them)."""
        if not self._parts.takes_centrelines:
            self._lines.channel.drain()  # not recording them: no need to decode
            return
        while (msg := self._lines.recv(timeout_s=0)) is not None:
            if self.current is not None and len(msg.source_ns) and msg.source_ns[-1] > self.current.last_sent_ns:
                self._write_queued_packets()  # the packets it comes from first: they may begin a new part
            self._last_line_s = now
            self._final_seen |= msg.final
            try:
                self._parts.take_centrelines(msg)
            except SchemaError as exc:
                self.problems.add("centreline messages not recorded", exc)

    def _lines_done(self, now: float) -> bool:
        """At the end of a stream: whether the tracker's last centrelines are in (or will not come)."""
        if not self._parts.takes_centrelines or self._final_seen:
            return True
        if timed_out := now - self._last_line_s >= self.cfg.drain_timeout_s:
            log.warning(
                "recorder: no final centreline message within %.1f s after the end of stream; closing",
                self.cfg.drain_timeout_s,
            )
        return timed_out

    def _status(
        self, state: str, *, recording: RecordingPart | None = None, message: str = "", request_id: str = ""
    ) -> None:
        if hasattr(self, "status_pub"):  # not before run()
            part, dropped = recording or self.current, self._packets.channel.dropped
            self.status_pub.put(recorder_status(state, part, dropped, message=message, request_id=request_id))


def recorder_status(
    state: str, part: RecordingPart | None, dropped_packets: int, *, message: str = "", request_id: str = ""
) -> RecorderStatus:
    """The status message of the recorder in ``state``, about ``part`` (None: no recording)."""
    return RecorderStatus(
        state=state,
        path=str(part.raw_path) if part else "",
        bytes=part.bytes if part else 0,
        packets=part.packets if part else 0,
        missing_packets=part.missing_packets if part else 0,
        request_id=request_id,
        message=message,
        malformed_packets=part.malformed if part else 0,
        dropped_packets=dropped_packets,
        device_drops=part.device_drop_reports if part else 0,
        device_drop_reason=drop_summary(part.device_drops) if part else "",
    )
