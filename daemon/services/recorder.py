"""The recorder service: every packet of a camera to a ``.raw`` file, loss-free, plus a JSON sidecar.

The file is a valid RAW stream in the camera's native encoding (header, a time-base preamble, the
packets' bytes as they came). Packets are appended by this service's own loop, never in Zenoh's
callback, so the camera is never held up; the file is flushed every ``flush_interval_s`` and
fsynced every ``fsync_interval_s`` and on close, so a recording cut by a crash is readable up to its
last flush. Sequence gaps are listed in the sidecar. Commands (start / stop / rotate) come on the
recorder command key; centrelines can be recorded beside the events (DESIGN.md HDF5 layout).
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

from flagtrack.daemon import __version__
from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.errors import SchemaError
from flagtrack.daemon.schema import CentrelineMessage, EventPacket, RecorderCommand, RecorderStatus, decode
from flagtrack.daemon.transport import Bus
from flagtrack.drivers.camera.packets import stream_preamble
from flagtrack.drivers.formats import raw_header
from flagtrack.drivers.formats.centreline import CentrelineWriter

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RecorderConfig:
    """Recorder settings.

    Attributes:
        camera_id: the camera recorded.
        directory: where relative recording paths go.
        path: start recording at launch to this path (no extension), or wait for a start command.
        centrelines: also record tracker centrelines to ``<path>_centrelines.h5``.
        flush_interval_s: hand written bytes to the OS at least this often.
        fsync_interval_s: force them to disk at least this often.
        max_queue_packets: packets held in memory while the disk catches up (beyond: counted as lost).
    """

    camera_id: str = "cam0"
    directory: Path = Path("recordings")
    path: str | None = None
    centrelines: bool = False
    flush_interval_s: float = 0.2
    fsync_interval_s: float = 2.0
    max_queue_packets: int = 1_000_000


@dataclass
class Recording:
    """One open recording: the .raw file, its sidecar and, optionally, the centreline file."""

    base: Path
    config: dict[str, Any]
    raw: BinaryIO | None = None
    centrelines: CentrelineWriter | None = None
    want_centrelines: bool = False
    bytes: int = 0
    packets: int = 0
    events: int = 0
    next_seq: int | None = None
    gaps: list[list[int]] = field(default_factory=list)
    malformed: int = 0
    started_wall: float = field(default_factory=time.time)
    first_t_us: int | None = None
    last_t_us: int | None = None
    geometry: dict[str, Any] = field(default_factory=dict)
    _last_flush: float = field(default_factory=time.monotonic)
    _last_fsync: float = field(default_factory=time.monotonic)
    _pending_lines: list[CentrelineBatch] = field(default_factory=list)

    @property
    def raw_path(self) -> Path:
        return self.base.with_name(self.base.name + ".raw")

    @property
    def sidecar_path(self) -> Path:
        return self.base.with_name(self.base.name + ".json")

    @property
    def centrelines_path(self) -> Path:
        return self.base.with_name(self.base.name + "_centrelines.h5")

    def write_packet(self, packet: EventPacket) -> None:
        """Append one packet (opening the file at the first one: its geometry and encoding)."""
        if self.raw is None:
            self.raw_path.parent.mkdir(parents=True, exist_ok=True)
            self.raw = open(self.raw_path, "wb")  # noqa: SIM115 - closed in close()
            self.geometry = {"width": packet.width, "height": packet.height, "encoding": packet.encoding}
            header = raw_header(packet.encoding, packet.width, packet.height,
                                {"camera_id": packet.camera_id, "recorder": f"flagtrack-{__version__}"})
            self.raw.write(header + stream_preamble(packet.encoding, packet.t_offset_us))
            self.write_sidecar()
        if self.next_seq is not None and packet.seq != self.next_seq:
            self.gaps.append([self.next_seq, packet.seq])
        self.next_seq = packet.seq + 1
        self.raw.write(packet.data)
        self.bytes += len(packet.data)
        self.packets += 1
        self.events += packet.n_events
        self.first_t_us = packet.t_first_us if self.first_t_us is None else self.first_t_us
        self.last_t_us = packet.t_last_us

    def write_centrelines(self, msg: CentrelineMessage) -> None:
        """Queue a batch of centrelines (written to HDF5 at the next sync, in one append)."""
        if not self.want_centrelines or len(msg.t_s) == 0:
            return
        if self.centrelines is None:
            self.centrelines = CentrelineWriter(self.centrelines_path, msg.s, msg.joints_x.shape[1] - 1,
                                                {"units": msg.units, "input_file": str(self.raw_path),
                                                 "source": msg.source})
        self._pending_lines.append(msg.batch())

    def _flush_centrelines(self) -> None:
        if self._pending_lines and self.centrelines is not None:
            self.centrelines.append(CentrelineBatch.concatenate(self._pending_lines))
        self._pending_lines = []

    def sync(self, cfg: RecorderConfig, force: bool = False) -> None:
        """Flush (and fsync) when due."""
        now = time.monotonic()
        if force or now - self._last_flush >= cfg.flush_interval_s:
            self._flush_centrelines()
        if self.raw is not None and (force or now - self._last_flush >= cfg.flush_interval_s):
            self.raw.flush()
            self._last_flush = now
            if force or now - self._last_fsync >= cfg.fsync_interval_s:
                os.fsync(self.raw.fileno())
                self._last_fsync = now
                self.write_sidecar()

    def write_sidecar(self, stopped: bool = False) -> None:
        """Rewrite the JSON sidecar atomically (temporary file then rename)."""
        doc = {
            "raw_file": self.raw_path.name, "started_unix_s": self.started_wall, "stopped": stopped,
            "flagtrack_version": __version__, **self.geometry, "packets": self.packets, "events": self.events,
            "bytes": self.bytes, "t_first_us": self.first_t_us, "t_last_us": self.last_t_us,
            "sequence_gaps": self.gaps, "missing_packets": sum(b - a for a, b in self.gaps),
            "malformed_packets": self.malformed, "config": self.config,
            "centrelines_file": self.centrelines_path.name if self.centrelines is not None else None,
        }
        self.sidecar_path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.sidecar_path.with_name(self.sidecar_path.name + ".tmp")
        tmp.write_text(json.dumps(doc, indent=2))
        os.replace(tmp, self.sidecar_path)

    def close(self) -> None:
        """Flush, fsync and close everything; final sidecar."""
        if self.raw is not None:
            self.raw.flush()
            os.fsync(self.raw.fileno())
            self.raw.close()
        if self.centrelines is not None:
            self._flush_centrelines()
            self.centrelines.close()
        self.write_sidecar(stopped=True)


class RecorderService:
    """Records one camera's packets on command (or from launch)."""

    name = "recorder"

    def __init__(self, bus: Bus, cfg: RecorderConfig, config_snapshot: dict[str, Any] | None = None,
                 exit_at_end_of_stream: bool = False) -> None:
        self.bus = bus
        self.exit_at_end_of_stream = exit_at_end_of_stream
        self._stream_ended = False
        self.cfg = cfg
        self.config_snapshot = config_snapshot or {}
        self.current: Recording | None = None
        self.finished: list[Path] = []
        self.lost_packets = 0

        keys = bus.keys
        self._packets = bus.subscribe(keys.camera_events(cfg.camera_id), EventPacket, capacity=cfg.max_queue_packets)
        self._lines = bus.subscribe(keys.centrelines(), CentrelineMessage, capacity=100_000)
        self._commands = bus.subscribe(keys.recorder_command(), RecorderCommand, capacity=1000)

    def run(self, stop: threading.Event) -> None:
        keys = self.bus.keys
        packets, lines, commands = self._packets, self._lines, self._commands
        self.status_pub = self.bus.publisher(keys.recorder_status())
        self.bus.declare_alive(self.name)
        if self.cfg.path:
            self.start(self.cfg.path, self.cfg.centrelines)
        try:
            while not stop.is_set():
                command = commands.recv(timeout_s=0)
                if command is not None:
                    self.handle(command)
                    continue
                item = packets.recv_raw(timeout_s=0.02)
                if item is not None:
                    self._write_raw_packet(*item)
                    for item in packets.channel.drain():
                        self._write_raw_packet(*item)
                if self._stream_ended and self.exit_at_end_of_stream:
                    break
                if self.current is None or not self.current.want_centrelines:
                    lines.channel.drain()  # not recording them: no need to decode
                else:
                    while (msg := lines.recv(timeout_s=0)) is not None:
                        self.current.write_centrelines(msg)
                self.lost_packets = packets.channel.dropped
                if self.current is not None:
                    self.current.sync(self.cfg)
            for item in packets.channel.drain():  # what arrived before the stop
                self._write_raw_packet(*item)
        finally:
            self.stop_recording()

    def handle(self, command: RecorderCommand) -> None:
        """Carry out a start / stop / rotate command and publish the resulting status."""
        if command.action in ("start", "rotate"):
            if not command.path:
                self._status("error", message=f"{command.action} needs a path", request_id=command.request_id)
                return
            self.stop_recording(request_id=command.request_id if self.current is not None else "")
            self.start(command.path, command.centrelines, request_id=command.request_id)
        elif command.action == "stop":
            self.stop_recording(request_id=command.request_id)
        else:
            self._status("error", message=f"unknown action {command.action!r}", request_id=command.request_id)

    def start(self, path: str, centrelines: bool, request_id: str = "") -> None:
        """Begin a recording at ``path`` (no extension; relative to the configured directory)."""
        base = Path(path).expanduser()
        if not base.is_absolute():
            base = Path(self.cfg.directory).expanduser() / base
        self.current = Recording(base=base, config=self.config_snapshot,
                                 want_centrelines=centrelines or self.cfg.centrelines)
        self.current.write_sidecar()
        log.info("recorder: recording to %s", self.current.raw_path)
        self._status("recording", request_id=request_id)

    def stop_recording(self, request_id: str = "") -> None:
        """Close the current recording (if any)."""
        if self.current is None:
            if request_id:
                self._status("idle", request_id=request_id)
            return
        recording, self.current = self.current, None
        recording.close()
        self.finished.append(recording.raw_path)
        log.info("recorder: closed %s (%d packets, %d bytes, %d gaps)", recording.raw_path, recording.packets,
                 recording.bytes, len(recording.gaps))
        self._status("idle", recording=recording, request_id=request_id)

    def _write_raw_packet(self, key: str, payload: bytes) -> None:
        try:
            packet = decode(payload, EventPacket, key=key)
        except SchemaError as exc:
            if self.current is not None:
                self.current.malformed += 1
            log.debug("recorder: %s", exc)
            return
        self._stream_ended |= packet.end_of_stream
        if self.current is not None:
            self.current.write_packet(packet)

    def _status(self, state: str, *, recording: Recording | None = None, message: str = "", request_id: str = "") -> None:
        rec = recording or self.current
        if not hasattr(self, "status_pub"):
            return
        self.status_pub.put(RecorderStatus(
            state=state, path=str(rec.raw_path) if rec else "", bytes=rec.bytes if rec else 0,
            packets=rec.packets if rec else 0, missing_packets=sum(b - a for a, b in rec.gaps) if rec else 0,
            request_id=request_id, message=message,
        ))
