"""Bus messages -> Rerun entities, batched (no bus code here).

Messages only queue rows (one :class:`~.batching.RowQueue` per entity, times on the ``camera``
timeline); :meth:`RerunLogger.frame` draws the geometry of the moment (recent events, tip trail, A/L)
``geometry_rate_hz`` times a second and sends each queue that its :class:`~.batching.FlushPolicy`
says is due in one ``send_columns`` call.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from flagtrack.daemon.core.metrics import window_amplitude_over_l
from flagtrack.daemon.errors import ConfigError, FormatError
from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import CentrelineMessage, EventPacket, EventRate, SupervisorState, TunnelState
from flagtrack.daemon.sweep.quantities import QUANTITIES
from flagtrack.drivers.formats.packets import decode_packet

from . import layout
from .batching import FlushPolicy, RowQueue, UpdateSlots, changes
from .config import ViewerConfig, effective_sink
from .serve import RerunServer

log = logging.getLogger(__name__)

#: The fields every SupervisorState has; the others (per-point figures, progress) are shown as a table.
SUPERVISOR_FIELDS = ("flag_state", "rate_hz", "mode", "point", "branch", "speed_mps", "message")


#: Rows per chunk of entities whose rows Rerun reads back in a time that grows with their chunk: one
#: row of a LineStrips2D chunk costs Rerun O(chunk) to deserialize (`rerun rrd verify` of one chunk
#: of 20 000 strips of 51 points: 324 s; the same strips in chunks of 1 000 rows: 12.8 s).
MAX_ROWS = {layout.CENTRELINE: 2048}


def open_recording(cfg: ViewerConfig) -> tuple[rr.RecordingStream, str]:
    """Create the Rerun recording stream, connect its sink and send the layout; return it and a description."""
    rec = rr.RecordingStream("flagtrack")
    sink = effective_sink(cfg)
    if sink == "spawn":
        rec.spawn()
        description = "Rerun viewer window"
    elif sink == "serve":  # Rerun's serve_grpc binds every interface: its server, bound as configured
        server = _SERVERS[id(rec)] = RerunServer(cfg.serve_host, cfg.grpc_port, cfg.web_port)
        rec.connect_grpc(server.url)
        description = f"web viewer on {server.web_url} (data {server.url}, listening on {cfg.serve_host})"
    elif sink == "rrd":
        path = Path(cfg.rrd_path).expanduser()
        path.parent.mkdir(parents=True, exist_ok=True)
        kept = keep_previous_view(path)
        rec.save(path)
        description = f"recording to {path.resolve()}" + (f" (the previous view kept as {kept.name})" if kept else "")
    elif sink == "none":
        description = "nowhere (sink none)"
    else:
        raise ConfigError(f"unknown sink {sink!r}", key="viewer.sink")
    rec.send_blueprint(layout.blueprint(), make_active=True, make_default=True)
    return rec, description


def keep_previous_view(path: Path) -> Path | None:
    """Rename a non-empty ``path`` left by an earlier run to ``<stem>-<its mtime>.rrd`` beside it (a
    new run's view would overwrite it); return the new name, or None when there was nothing to keep."""
    try:
        stat = path.stat()
    except FileNotFoundError:
        return None
    if stat.st_size == 0 or not path.is_file():
        return None
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(stat.st_mtime))
    kept = path.with_name(f"{path.stem}-{stamp}{path.suffix}")
    n = 1
    while kept.exists():
        n += 1
        kept = path.with_name(f"{path.stem}-{stamp}-{n}{path.suffix}")
    try:
        path.rename(kept)
    except OSError as exc:
        raise ConfigError(
            f"{path}: cannot keep the previous view as {kept.name}: {exc.strerror}", key="viewer.rrd_path"
        ) from exc
    return kept


def close_recording(rec: rr.RecordingStream) -> None:
    """Disconnect ``rec`` and stop the server its ``serve`` sink started, if any."""
    rec.disconnect()
    server = _SERVERS.pop(id(rec), None)
    if server is not None:
        server.close()


_SERVERS: dict[int, RerunServer] = {}


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


def supervisor_text(msg: SupervisorState) -> str:
    """The supervisor's state as Markdown: flag state, mode, point, branch, speed, event rate, message,
    then a table of every other field the message sets (per-point figures, progress)."""
    head = f"**{msg.flag_state}** · {msg.mode}"
    if msg.point:
        head += f" · point `{msg.point}`" + (f" ({msg.branch})" if msg.branch else "")
    head += f" · {msg.speed_mps:.2f} m/s · event rate {msg.rate_hz:.3g} ev/s"
    lines = [head]
    if msg.message:
        lines += ["", msg.message]
    # the other fields, where they say something: a field at its default means "none" or "not known"
    extra = [f for f in dataclasses.fields(msg) if f.name not in SUPERVISOR_FIELDS]
    rows = [(f.name, getattr(msg, f.name, None)) for f in extra]
    rows = [(f.name, v) for f, (_, v) in zip(extra, rows, strict=True) if v is not None and v != "" and v != f.default]
    if rows:
        lines += ["", "| | |", "|---|---|"]
        lines += [f"| {name} | {_cell(name, value)} |" for name, value in rows]
    return "\n".join(lines)


def _cell(name: str, value: Any) -> str:
    """A field of the supervisor's table; an error or distance (a fraction of L) also as a person reads it,
    in %, as the terminal lines and README.txt show it (``daemon/sweep/quantities.py``)."""
    if not isinstance(value, float):
        return str(value)
    shown = QUANTITIES.get(name)
    percent = shown is not None and shown.unit == "%" and value >= 0
    return f"{value:.4g}" + (f" ({shown.text(value)})" if percent else "")  # type: ignore[union-attr]


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
            layout.SUPERVISOR_STATE: self._send_document,
            layout.SUPERVISOR_LOG: self._send_text_log,
        }
        self.slots = UpdateSlots(cfg.update_rate_hz)  # the tracker updates shown
        self._last_lost = 0.0
        self._packets: deque[EventPacket] = deque()
        self._track: deque[np.ndarray] = deque()  # (n, 5) arrays: t, root x, root y, tip x, tip y
        self._track_new = False
        self._length = math.nan
        self._units = "px"
        self._styled: set[str] = set()
        self._now: float | None = None
        self._last_frame = -math.inf
        self._camera_minus_wall_s: float | None = None
        self._supervisor_waiting: tuple[SupervisorState, float] | None = None
        self._supervisor_last: tuple[Any, ...] | None = None

    # -- messages: queue rows -------------------------------------------------------------------

    def centrelines(self, msg: CentrelineMessage) -> None:
        """Queue the updates of a batch the view shows (:attr:`slots`): centreline, joints, tip y, Δ_RMS,
        events used, the lost flags (at every change too) and the share shed (every update that shed);
        note every tip and root for the trail and A/L."""
        n = len(msg.t_s)
        if not n:
            return
        t = np.asarray(msg.t_s, dtype=np.float64)
        x, y = np.asarray(msg.x, dtype=np.float64), np.asarray(msg.y, dtype=np.float64)
        jx, jy = np.asarray(msg.joints_x, dtype=np.float64), np.asarray(msg.joints_y, dtype=np.float64)
        if x.shape != y.shape or x.shape[0] != n or jx.shape != jy.shape or jx.ndim != 2 or jx.shape[0] != n:
            raise ValueError(f"centreline message of {n} updates with x {x.shape}, joints {jx.shape}")
        lost = np.asarray(msg.lost, dtype=np.float64).reshape(-1)
        if len(lost) != n:
            raise ValueError(f"centreline message of {n} updates with {len(lost)} lost flags")
        keep = self.slots.keep(t)
        lost_rows = keep | changes(lost, self._last_lost)  # every change of the flag shows
        self._scalars(layout.LOST, t[lost_rows], lost[lost_rows])
        self._last_lost = float(lost[-1])
        shed = np.asarray(msg.shed, dtype=np.float64).reshape(-1)
        shed_rows = keep | (shed > 0) if len(shed) == n else keep
        self._scalars(layout.SHED, t[shed_rows], shed[shed_rows] if len(shed) == n else np.zeros(int(shed_rows.sum())))
        k, shown = t[keep], int(keep.sum())
        if shown:
            strips = np.stack([x[keep], y[keep]], axis=-1).astype(np.float32)  # (k, n_s, 2): a strip per update
            self._queue(layout.CENTRELINE, (k, strips), shown, strips.nbytes + 8 * shown)
            joints = np.stack([jx[keep], jy[keep]], axis=-1).astype(np.float32).reshape(-1, 2)
            self._queue(
                layout.JOINTS, (k, joints, np.full(shown, jx.shape[1]), None), shown, joints.nbytes + 12 * shown
            )
            self._scalars(layout.TIP_Y, k, np.asarray(msg.tip_y)[keep])
            self._scalars(layout.DELTA_RMS, k, np.asarray(msg.delta_rms)[keep])
            self._scalars(layout.EVENTS_PER_UPDATE, k, np.asarray(msg.n_events)[keep])
        self._units = msg.units or self._units
        self._length = float(msg.s[-1] - msg.s[0]) if len(msg.s) > 1 else math.nan
        self._track.append(np.stack([t, x[:, 0], y[:, 0], x[:, -1], y[:, -1]], axis=1))
        self._track_new = True
        keep_s = max(self.cfg.trail_s, self.cfg.amplitude_window_s)
        while len(self._track) > 1 and not self._track[0][-1, 0] >= t[-1] - keep_s:  # (NaN too)
            self._track.popleft()

    def events(self, packet: EventPacket) -> None:
        """Queue an event packet for the next frame; note the camera/wall clock offset."""
        if packet.n_events:
            self._packets.append(packet)
        self._camera_minus_wall_s = packet.t_last_us * 1e-6 - packet.sent_ns * 1e-9
        if self._supervisor_waiting is not None:
            self.supervisor(*self._supervisor_waiting)

    def rate(self, msg: EventRate) -> None:
        """Queue the camera's event rate."""
        self._scalars(layout.EVENT_RATE, np.array([_place(msg.t_us * 1e-6, "event rate")]), [msg.rate_hz])

    def tunnel(self, msg: TunnelState) -> None:
        """Queue the wind speed, placed on the camera clock once the offset is known."""
        if self._camera_minus_wall_s is None or msg.speed_mps < 0:
            return
        t = _place(msg.t_wall_s + self._camera_minus_wall_s, "wind speed")
        self._scalars(layout.WIND_SPEED, np.array([t]), [msg.speed_mps])

    def supervisor(self, msg: SupervisorState, wall_s: float) -> None:
        """Queue the supervisor's state (received at ``wall_s``, Unix seconds) as a text document, and a
        line in the sweep log when the flag state, mode, point, branch or message changes. Before the
        camera clock is known, the latest state waits for it."""
        if self._camera_minus_wall_s is None:
            self._supervisor_waiting = (msg, wall_s)
            return
        self._supervisor_waiting = None
        t = np.array([_place(wall_s + self._camera_minus_wall_s, "supervisor state")])
        text = supervisor_text(msg)
        self._queue(layout.SUPERVISOR_STATE, (t, text), 1, len(text) + 8)
        key = (msg.flag_state, msg.mode, msg.point, msg.branch, msg.message)
        if key != self._supervisor_last:
            self._supervisor_last = key
            where = msg.mode
            if msg.point:
                where += f", point {msg.point}" + (f" ({msg.branch})" if msg.branch else "")
            line = f"{where}: flag {msg.flag_state}" + (f"; {msg.message}" if msg.message else "")
            self._queue(layout.SUPERVISOR_LOG, (t, line, "INFO"), 1, len(line) + 8)

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
        """Queue the tip trail (the tip over the last ``trail_s``) and A/L over ``amplitude_window_s``."""
        if not self._track_new:
            return False
        self._track_new = False
        track = np.concatenate(list(self._track))
        t_last = track[-1, 0]
        recent = track[track[:, 0] >= t_last - self.cfg.trail_s]
        trail = recent[UpdateSlots(self.cfg.update_rate_hz).keep(recent[:, 0])][:, 3:5].astype(np.float32)
        t = np.array([_place(float(t_last), "tip trail")])
        if len(trail) > 1:
            self._queue(layout.TIP_TRAIL, (t, trail), 1, trail.nbytes + 16)
        window = track[track[:, 0] >= t_last - self.cfg.amplitude_window_s]
        if len(window) >= 8 and self._length > 0:
            amplitude = window_amplitude_over_l(window[:, 1], window[:, 2], window[:, 3], window[:, 4], self._length)
            if math.isfinite(amplitude):
                self._scalars(layout.AMPLITUDE, t, [amplitude])
        return True

    # -- queues and senders ----------------------------------------------------------------------

    def _queue(self, path: str, piece: Any, n_rows: int, n_bytes: int) -> None:
        queue = self.queues.get(path)
        if queue is None:
            queue = self.queues[path] = RowQueue(max_rows=MAX_ROWS.get(path))
        queue.add(piece, n_rows, n_bytes)
        if queue.since_s is None and self._now is not None:
            queue.since_s = self._now

    def _scalars(self, path: str, t: np.ndarray, values: Any) -> None:
        values = np.asarray(values, dtype=np.float64).reshape(-1)
        if len(values) != len(t):
            raise ValueError(f"{path}: {len(values)} values for {len(t)} times")
        self._queue(path, (t, values), len(t), 16 * len(t))

    def _send(self, path: str, pieces: list[Any]) -> None:
        if path in layout.SERIES_NAMES and path not in self._styled:
            self._styled.add(path)
            name = layout.SERIES_NAMES[path].format(units=self._units)
            self.rec.log(path, rr.SeriesLines(names=name), static=True)
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

    def _send_document(self, path: str, pieces: list[tuple[np.ndarray, str]]) -> None:
        t = np.concatenate([p[0] for p in pieces])
        texts = [p[1] for p in pieces]
        columns = rr.TextDocument.columns(text=texts, media_type=["text/markdown"] * len(texts))
        self.rec.send_columns(path, _times(t), columns)

    def _send_text_log(self, path: str, pieces: list[tuple[np.ndarray, str, str]]) -> None:
        t = np.concatenate([p[0] for p in pieces])
        columns = rr.TextLog.columns(text=[p[1] for p in pieces], level=[p[2] for p in pieces])
        self.rec.send_columns(path, _times(t), columns)
