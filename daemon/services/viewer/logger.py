"""Bus messages -> Rerun entities, batched (no bus code here).

Messages only queue rows (one :class:`~.batching.RowQueue` per entity, times on the ``camera``
timeline); :meth:`RerunLogger.frame` draws the geometry of the moment (recent events, tip trail)
``geometry_rate_hz`` times a second and sends each queue that its :class:`~.batching.FlushPolicy`
says is due in one ``send_columns`` call.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from flagtrack.daemon.errors import ConfigError, FormatError
from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import CentrelineMessage, EventPacket, EventRate, TunnelState
from flagtrack.drivers.formats.packets import decode_packet

from . import layout
from .batching import FlushPolicy, RowQueue
from .config import ViewerConfig, effective_sink

log = logging.getLogger(__name__)


def open_recording(cfg: ViewerConfig) -> tuple[rr.RecordingStream, str]:
    """Create the Rerun recording stream and connect its sink; return it and a description."""
    rec = rr.RecordingStream("flagtrack")
    sink = effective_sink(cfg)
    if sink == "spawn":
        rec.spawn()
        description = "Rerun viewer window"
    elif sink == "serve":
        url = rec.serve_grpc()
        rr.serve_web_viewer(web_port=cfg.web_port, open_browser=False, connect_to=url)
        description = f"web viewer on http://localhost:{cfg.web_port} (data {url})"
    elif sink == "rrd":
        path = Path(cfg.rrd_path).expanduser()
        path.parent.mkdir(parents=True, exist_ok=True)
        rec.save(path)
        description = f"recording to {path.resolve()}"
    elif sink == "none":
        description = "nowhere (sink none)"
    else:
        raise ConfigError(f"unknown sink {sink!r}", key="viewer.sink")
    return rec, description


def age_colours(age_s: np.ndarray, horizon_s: float) -> np.ndarray:
    """RGB uint8 (n, 3): young events yellow, old ones dark purple (viridis-like ramp)."""
    frac = np.clip(1.0 - age_s / max(horizon_s, 1e-9), 0.0, 1.0)[:, None]
    dark, bright = np.array([68, 1, 84], float), np.array([253, 231, 37], float)
    return (dark + frac * (bright - dark)).astype(np.uint8)


def _times(t_s: np.ndarray) -> list[rr.TimeColumn]:
    return [rr.TimeColumn(layout.TIMELINE, duration=np.asarray(t_s, dtype=np.float64))]


def _place(t_s: float, what: str) -> float:
    """``t_s`` if Rerun can place it on the timeline, else ValueError (the message is counted, not queued:
    one bad time would lose the whole chunk it went into)."""
    if not math.isfinite(t_s):
        raise ValueError(f"{what} at a time Rerun cannot place ({t_s} s)")
    return t_s


class RerunLogger:
    """Turns bus messages into Rerun entities (no bus code here); see the module docstring.

    Args:
        rec: the recording stream (its sink connected).
        cfg: the viewer section.
        problems: where what cannot be shown is counted.
        live: whether a person watches the stream as it comes (queues sent every ``cfg.flush_s``) or it
            goes to a file (every ``cfg.rrd_flush_s`` or ``cfg.chunk_bytes``); None: from ``cfg``'s sink.
    """

    def __init__(
        self, rec: rr.RecordingStream, cfg: ViewerConfig, problems: ProblemLog | None = None, live: bool | None = None
    ) -> None:
        self.rec = rec
        self.cfg = cfg
        self.problems = problems or ProblemLog(log, "viewer")
        live = effective_sink(cfg) != "rrd" if live is None else live
        self.policy = FlushPolicy(cfg.flush_s if live else cfg.rrd_flush_s, cfg.chunk_bytes)
        self.queues: dict[str, RowQueue] = {}
        self._senders: dict[str, Callable[[str, list[Any]], None]] = {
            layout.CENTRELINE: self._send_strips,
            layout.JOINTS: self._send_points,
            layout.EVENTS: self._send_points,
            layout.TIP_TRAIL: self._send_trail,
        }
        self._packets: deque[EventPacket] = deque()
        self._track: deque[np.ndarray] = deque()  # (n, 3) arrays: t, tip x, tip y
        self._track_new = False
        self._styled: set[str] = set()
        self._now: float | None = None
        self._last_frame = -math.inf
        self._camera_minus_wall_s: float | None = None

    # -- messages: queue rows -------------------------------------------------------------------

    def centrelines(self, msg: CentrelineMessage) -> None:
        """Queue a batch of tracker updates: centreline, joints, tip y, Δ_RMS, events used; note the tip
        for the trail."""
        n = len(msg.t_s)
        if not n:
            return
        t = np.asarray(msg.t_s, dtype=np.float64)
        x, y = np.asarray(msg.x, dtype=np.float64), np.asarray(msg.y, dtype=np.float64)
        jx, jy = np.asarray(msg.joints_x, dtype=np.float64), np.asarray(msg.joints_y, dtype=np.float64)
        if x.shape != y.shape or x.shape[0] != n or jx.shape != jy.shape or jx.ndim != 2 or jx.shape[0] != n:
            raise ValueError(f"centreline message of {n} updates with x {x.shape}, joints {jx.shape}")
        strips = np.stack([x, y], axis=-1).astype(np.float32)  # (n, n_s, 2): one strip per update
        self._queue(layout.CENTRELINE, (t, strips), n, strips.nbytes + 8 * n)
        joints = np.stack([jx, jy], axis=-1).astype(np.float32).reshape(-1, 2)
        self._queue(layout.JOINTS, (t, joints, np.full(n, jx.shape[1]), None), n, joints.nbytes + 12 * n)
        self._scalars(layout.TIP_Y, t, msg.tip_y)
        self._scalars(layout.DELTA_RMS, t, msg.delta_rms)
        self._scalars(layout.EVENTS_PER_UPDATE, t, msg.n_events)
        self._track.append(np.stack([t, x[:, -1], y[:, -1]], axis=1))
        self._track_new = True
        while len(self._track) > 1 and not self._track[0][-1, 0] >= t[-1] - self.cfg.trail_s:  # (NaN too)
            self._track.popleft()

    def events(self, packet: EventPacket) -> None:
        """Queue an event packet for the next frame; note the camera/wall clock offset."""
        if packet.n_events:
            self._packets.append(packet)
        self._camera_minus_wall_s = packet.t_last_us * 1e-6 - packet.sent_ns * 1e-9

    def rate(self, msg: EventRate) -> None:
        """Queue the camera's event rate."""
        self._scalars(layout.EVENT_RATE, np.array([_place(msg.t_us * 1e-6, "event rate")]), [msg.rate_hz])

    def tunnel(self, msg: TunnelState) -> None:
        """Queue the wind speed, placed on the camera clock once the offset is known."""
        if self._camera_minus_wall_s is None or msg.speed_mps < 0:
            return
        t = _place(msg.t_wall_s + self._camera_minus_wall_s, "wind speed")
        self._scalars(layout.WIND_SPEED, np.array([t]), [msg.speed_mps])

    # -- frames: draw the geometry of the moment, send what is due -------------------------------

    def frame(self, now_s: float, force: bool = False) -> bool:
        """Draw a frame if one is due (or ``force``) and send the queues that are due (all with ``force``).

        Args:
            now_s: a monotonic clock, seconds (the queues' ages are on it).
            force: draw and send everything now (the end of a run).

        Returns:
            Whether a frame was drawn or rows were sent.
        """
        self._now = now_s
        for queue in self.queues.values():
            if queue.n_rows and queue.since_s is None:
                queue.since_s = now_s
        drew = False
        if force or now_s - self._last_frame >= 1.0 / self.cfg.geometry_rate_hz:
            self._last_frame = now_s
            drew = self._draw_events()
            drew = self._draw_track() or drew
        sent = False
        for path, queue in self.queues.items():
            if queue.n_rows and (force or self.policy.due(queue, now_s)):
                self._send(path, queue.take())
                sent = True
        return drew or sent

    def close(self) -> None:
        """Draw and send everything queued (call before the recording is flushed and disconnected)."""
        self.frame(self._now if self._now is not None else 0.0, force=True)

    def _draw_events(self) -> bool:
        if not self._packets:
            return False
        horizon_us = self.cfg.recent_events_ms * 1e3
        t_newest = self._packets[-1].t_last_us
        while self._packets and self._packets[0].t_last_us < t_newest - horizon_us:
            self._packets.popleft()
        packets = list(self._packets)
        self._packets.clear()
        decoded = []
        for packet in packets:
            try:
                decoded.append(
                    decode_packet(packet.encoding, packet.data, packet.t_offset_us, source=f"packet {packet.seq}")[0]
                )
            except FormatError as exc:
                self.problems.add("undecodable packets", exc)
        if not decoded:
            return False
        recent = np.concatenate(decoded)
        recent = recent[recent["t"] >= t_newest - horizon_us]
        if len(recent) > self.cfg.max_points:
            recent = recent[:: int(np.ceil(len(recent) / self.cfg.max_points))]
        positions = np.stack([recent["x"], recent["y"]], axis=1).astype(np.float32)
        colours = age_colours((t_newest - recent["t"]) * 1e-6, horizon_us * 1e-6)
        t = np.array([_place(t_newest * 1e-6, "events")])
        self._queue(layout.EVENTS, (t, positions, np.array([len(recent)]), colours), 1, 11 * len(recent) + 12)
        return True

    def _draw_track(self) -> bool:
        """Queue the tip trail (the tip over the last ``trail_s``)."""
        if not self._track_new:
            return False
        self._track_new = False
        track = np.concatenate(list(self._track))
        t_last = track[-1, 0]
        trail = track[track[:, 0] >= t_last - self.cfg.trail_s][:, 1:3].astype(np.float32)
        t = np.array([_place(float(t_last), "tip trail")])
        if len(trail) > 1:
            self._queue(layout.TIP_TRAIL, (t, trail), 1, trail.nbytes + 16)
        return True

    # -- queues and senders ----------------------------------------------------------------------

    def _queue(self, path: str, piece: Any, n_rows: int, n_bytes: int) -> None:
        queue = self.queues.setdefault(path, RowQueue())
        queue.add(piece, n_rows, n_bytes)
        if queue.since_s is None and self._now is not None:
            queue.since_s = self._now

    def _scalars(self, path: str, t: np.ndarray, values: Any) -> None:
        values = np.asarray(values, dtype=np.float64).reshape(-1)
        if len(values) != len(t):
            raise ValueError(f"{path}: {len(values)} values for {len(t)} times")
        self._queue(path, (t, values), len(t), 16 * len(t))

    def _send(self, path: str, pieces: list[Any]) -> None:
        self._senders.get(path, self._send_scalars)(path, pieces)

    def _send_scalars(self, path: str, pieces: list[tuple[np.ndarray, np.ndarray]]) -> None:
        t = np.concatenate([p[0] for p in pieces])
        values = np.concatenate([p[1] for p in pieces])
        self.rec.send_columns(path, _times(t), rr.Scalars.columns(scalars=values))

    def _send_strips(self, path: str, pieces: list[tuple[np.ndarray, np.ndarray]]) -> None:
        """Strips of one width in one array (Rerun converts it at once, a list strip by strip); a change
        of width (another tracker setup) starts another call."""
        start = 0
        for k in range(1, len(pieces) + 1):
            if k == len(pieces) or pieces[k][1].shape[1:] != pieces[start][1].shape[1:]:
                run = pieces[start:k]
                t = np.concatenate([p[0] for p in run])
                strips = np.concatenate([p[1] for p in run])
                columns = rr.LineStrips2D.columns(strips=strips).partition(np.ones(len(t), dtype=np.int32))
                self.rec.send_columns(path, _times(t), columns)
                start = k

    def _send_points(self, path: str, pieces: list[tuple[np.ndarray, np.ndarray, np.ndarray, Any]]) -> None:
        t = np.concatenate([p[0] for p in pieces])
        positions = np.concatenate([p[1] for p in pieces])
        lengths = np.concatenate([p[2] for p in pieces]).astype(np.int32)
        if pieces[0][3] is None:
            columns = rr.Points2D.columns(positions=positions)
        else:
            colours = np.concatenate([p[3] for p in pieces])
            columns = rr.Points2D.columns(positions=positions, colors=colours)
        if path == layout.EVENTS and path not in self._styled:
            self._styled.add(path)
            self.rec.log(path, rr.Points2D.from_fields(radii=0.5), static=True)
        self.rec.send_columns(path, _times(t), columns.partition(lengths))

    def _send_trail(self, path: str, pieces: list[tuple[np.ndarray, np.ndarray]]) -> None:
        t = np.concatenate([p[0] for p in pieces])
        columns = rr.LineStrips2D.columns(strips=[p[1] for p in pieces])
        self.rec.send_columns(path, _times(t), columns.partition(np.ones(len(t), dtype=np.int32)))
