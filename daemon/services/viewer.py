"""The viewer service: bridges the bus to Rerun (the only module that imports rerun).

Entities (stable paths), all on the ``camera`` timeline (seconds of the camera clock):
``camera/events`` recent events coloured by age, ``tracker/joints``, ``tracker/centreline``,
``tracker/tip_trail``, and time series under ``plots/`` (event rate, Δ_RMS, events per update,
tip lateral position, wind speed). Centrelines and scalars are batched with ``send_columns``;
point clouds and the trail are logged at most ``geometry_rate_hz`` times per second.

No message stops the viewer: one that cannot be shown (EVT bytes that do not decode, times Rerun
cannot place, ...) is counted (``ViewerService.unusable``) and logged as a rate-limited summary,
and centreline messages of another tracker setup (other samples or joints) are sent apart.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import rerun as rr

from flagtrack.daemon.errors import ConfigError, FormatError
from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import CentrelineMessage, EventPacket, EventRate, TunnelState
from flagtrack.daemon.transport import Bus
from flagtrack.drivers.formats.packets import decode_packet

log = logging.getLogger(__name__)
TIMELINE = "camera"


@dataclass(frozen=True)
class ViewerConfig:
    """Where the Rerun data goes and how much of it.

    Attributes:
        sink: ``auto`` (a viewer window when a display exists, else an .rrd file), ``spawn``, ``serve``
            (gRPC + web viewer for a browser), ``rrd`` (headless file) or ``none``.
        rrd_path: the .rrd file for the ``rrd`` sink (and ``auto`` without display).
        web_port: port of the web viewer for ``serve``.
        camera_id: the camera whose events are shown.
        recent_events_ms: events younger than this are drawn.
        max_points: at most this many event points per frame (subsampled beyond).
        trail_s: length of the tip trail.
        geometry_rate_hz: frames per second for event clouds and the tip trail.
    """

    sink: Literal["auto", "spawn", "serve", "rrd", "none"] = "auto"
    rrd_path: Path = Path("flagtrack.rrd")
    web_port: int = 9090
    camera_id: str = "cam0"
    recent_events_ms: float = 10.0
    max_points: int = 20_000
    trail_s: float = 0.5
    geometry_rate_hz: float = 30.0


def effective_sink(cfg: ViewerConfig) -> str:
    """The sink the viewer uses: ``auto`` is a window where a display exists, else the .rrd file."""
    if cfg.sink != "auto":
        return cfg.sink
    return "spawn" if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY") else "rrd"


def open_recording(cfg: ViewerConfig) -> tuple[rr.RecordingStream, str]:
    """Create the Rerun recording stream and connect its sink; return it and a description."""
    rec = rr.RecordingStream("flagtrack")
    sink = effective_sink(cfg)
    if sink == "spawn":
        rec.spawn()
        return rec, "Rerun viewer window"
    if sink == "serve":
        url = rec.serve_grpc()
        rr.serve_web_viewer(web_port=cfg.web_port, open_browser=False, connect_to=url)
        return rec, f"web viewer on http://localhost:{cfg.web_port} (data {url})"
    if sink == "rrd":
        path = Path(cfg.rrd_path).expanduser()
        path.parent.mkdir(parents=True, exist_ok=True)
        rec.save(path)
        return rec, f"recording to {path.resolve()}"
    if sink == "none":
        return rec, "nowhere (sink none)"
    raise ConfigError(f"unknown sink {sink!r}", key="viewer.sink")


def age_colours(age_s: np.ndarray, horizon_s: float) -> np.ndarray:
    """RGB uint8 (n, 3): young events yellow, old ones dark purple (viridis-like ramp)."""
    frac = np.clip(1.0 - age_s / max(horizon_s, 1e-9), 0.0, 1.0)[:, None]
    dark, bright = np.array([68, 1, 84], float), np.array([253, 231, 37], float)
    return (dark + frac * (bright - dark)).astype(np.uint8)


class RerunLogger:
    """Turns bus messages into Rerun entities (no bus code here).

    Messages are only queued as they come; :meth:`frame` (``geometry_rate_hz`` times a second)
    sends every queued centreline in one ``send_columns`` per entity and decodes only the packets
    of the recent-events window, so the viewer keeps up with kHz update rates.
    """

    def __init__(self, rec: rr.RecordingStream, cfg: ViewerConfig, problems: ProblemLog | None = None) -> None:
        self.rec = rec
        self.cfg = cfg
        self.problems = problems or ProblemLog(log, "viewer")
        self._lines: list[CentrelineMessage] = []
        self._packets: deque[EventPacket] = deque()
        self._trail: deque[np.ndarray] = deque()  # (n, 3) arrays of t, tip x, tip y
        self._last_frame = 0.0
        self._camera_minus_wall_s: float | None = None

    def centrelines(self, msg: CentrelineMessage) -> None:
        """Queue a batch of tracker updates (the queued ones are sent first if their samples or joints
        differ: they are sent as one array)."""
        if len(msg.t_s):
            if self._lines and (msg.x.shape[1], msg.joints_x.shape[1]) != (
                self._lines[0].x.shape[1],
                self._lines[0].joints_x.shape[1],
            ):
                self._send_lines()
            self._lines.append(msg)

    def events(self, packet: EventPacket) -> None:
        """Queue an event packet; note the camera/wall clock offset."""
        if packet.n_events:
            self._packets.append(packet)
        self._camera_minus_wall_s = packet.t_last_us * 1e-6 - packet.sent_ns * 1e-9

    def rate(self, msg: EventRate) -> None:
        """Log the camera's event rate."""
        self.rec.set_time(TIMELINE, duration=msg.t_us * 1e-6)
        self.rec.log("plots/event_rate_hz", rr.Scalars(msg.rate_hz))

    def tunnel(self, msg: TunnelState) -> None:
        """Log the wind speed, placed on the camera clock when the offset is known."""
        if self._camera_minus_wall_s is None or msg.speed_mps < 0:
            return
        self.rec.set_time(TIMELINE, duration=msg.t_wall_s + self._camera_minus_wall_s)
        self.rec.log("plots/wind_speed_mps", rr.Scalars(msg.speed_mps))

    def frame(self, now_s: float, force: bool = False) -> bool:
        """Send what is queued if a frame is due (or ``force``); return whether one was sent."""
        if not force and now_s - self._last_frame < 1.0 / self.cfg.geometry_rate_hz:
            return False
        self._last_frame = now_s
        sent = self._send_lines()
        return self._send_events() or sent

    def _send_lines(self) -> bool:
        if not self._lines:
            return False
        msgs, self._lines = self._lines, []
        t_s = np.concatenate([m.t_s for m in msgs])
        times = [rr.TimeColumn(TIMELINE, duration=t_s)]
        x, y = np.concatenate([m.x for m in msgs]), np.concatenate([m.y for m in msgs])
        jx, jy = np.concatenate([m.joints_x for m in msgs]), np.concatenate([m.joints_y for m in msgs])
        strips = np.stack([x, y], axis=-1)  # one (n, n_s, 2) array: Rerun converts it at once, a list strip by strip
        self.rec.send_columns(
            "tracker/centreline",
            times,
            rr.LineStrips2D.columns(strips=strips).partition(np.ones(len(t_s), dtype=np.int32)),
        )
        self.rec.send_columns(
            "tracker/joints",
            times,
            rr.Points2D.columns(positions=np.stack([jx, jy], axis=-1).reshape(-1, 2)).partition(
                np.full(len(t_s), jx.shape[1], np.int32)
            ),
        )
        for name, field_name in (
            ("plots/delta_rms", "delta_rms"),
            ("plots/events_per_update", "n_events"),
            ("plots/tip_y", "tip_y"),
        ):
            values = np.concatenate([np.asarray(getattr(m, field_name), float) for m in msgs])
            self.rec.send_columns(name, times, rr.Scalars.columns(scalars=values))
        self._trail.append(np.stack([t_s, x[:, -1], y[:, -1]], axis=1))
        while len(self._trail) > 1 and not self._trail[0][-1, 0] >= t_s[-1] - self.cfg.trail_s:  # (NaN too)
            self._trail.popleft()
        trail = np.concatenate(list(self._trail))
        trail = trail[trail[:, 0] >= t_s[-1] - self.cfg.trail_s]
        if len(trail) > 1:
            self.rec.set_time(TIMELINE, duration=float(t_s[-1]))
            self.rec.log("tracker/tip_trail", rr.LineStrips2D([trail[:, 1:].astype(np.float32)]))
        return True

    def _send_events(self) -> bool:
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
        self.rec.set_time(TIMELINE, duration=t_newest * 1e-6)
        self.rec.log(
            "camera/events",
            rr.Points2D(
                np.stack([recent["x"], recent["y"]], axis=1).astype(np.float32),
                colors=age_colours((t_newest - recent["t"]) * 1e-6, horizon_us * 1e-6),
                radii=0.5,
            ),
        )
        return True


class ViewerService:
    """Subscribes to camera, tracker and tunnel topics and logs them to Rerun."""

    name = "viewer"

    def __init__(self, bus: Bus, cfg: ViewerConfig, exit_after_final: bool = False) -> None:
        self.bus = bus
        self.cfg = cfg
        self.exit_after_final = exit_after_final
        self.description = ""
        self.frames = 0
        self.updates = 0
        self.unusable = 0  # messages (or frames) that could not be logged
        self.problems = ProblemLog(log, "viewer")
        keys = bus.keys
        self.subs: dict[str, Any] = {
            # a live view: when it falls behind, the oldest go (and at most this much memory waits)
            "centrelines": bus.subscribe(
                keys.centrelines(), CentrelineMessage, capacity=100_000, ring=True, max_bytes=256 << 20
            ),
            "events": bus.subscribe(
                keys.camera_events(cfg.camera_id), EventPacket, capacity=100_000, ring=True, max_bytes=64 << 20
            ),
            "rate": bus.subscribe(keys.event_rate(cfg.camera_id), EventRate, capacity=1000, ring=True),
            "tunnel": bus.subscribe(keys.tunnel_state(), TunnelState, capacity=1000, ring=True),
        }

    def run(self, stop: threading.Event) -> None:
        subs = self.subs
        self.bus.declare_alive(self.name)
        rec, self.description = open_recording(self.cfg)
        log.info("viewer: %s", self.description)
        logger = RerunLogger(rec, self.cfg, self.problems)
        handlers = (
            ("centrelines", logger.centrelines),
            ("events", logger.events),
            ("rate", logger.rate),
            ("tunnel", logger.tunnel),
        )
        try:
            while not stop.is_set():
                final = False
                for name, handler in handlers:
                    while (msg := subs[name].recv(timeout_s=0)) is not None:
                        self._show(handler, msg)
                        if name == "centrelines":
                            self.updates += len(msg.t_s)
                            final |= msg.final
                self.frames += bool(self._show(logger.frame, time.monotonic(), final))
                self.problems.flush()
                if final and self.exit_after_final:
                    break
                stop.wait(0.25 / self.cfg.geometry_rate_hz)
            self._show(logger.frame, time.monotonic(), True)
        finally:
            self.problems.flush(force=True)
            rec.flush()
            rec.disconnect()

    def _show(self, step: Any, *args: Any) -> Any:
        """Run one logging step; a message Rerun (or the logger) cannot take is counted, not fatal."""
        try:
            return step(*args)
        except Exception as exc:
            self.unusable += 1
            log.debug("viewer: %s failed", getattr(step, "__name__", step), exc_info=exc)
            self.problems.add("messages that could not be shown", f"{type(exc).__name__}: {exc}")
            return None
