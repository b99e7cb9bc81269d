"""The viewer service: subscribes to the camera, tracker, tunnel and supervisor topics and logs them to Rerun."""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path
from typing import Any

from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import CentrelineMessage, EventPacket, EventRate, SupervisorState, TunnelState
from flagtrack.daemon.services.sd_notify import beat
from flagtrack.daemon.transport import Bus

from .config import ViewerConfig, effective_sink
from .logger import RerunLogger, close_recording, open_recording

log = logging.getLogger(__name__)


class ViewerService:
    """Subscribes to camera, tracker, tunnel and supervisor topics and logs them to Rerun."""

    name = "viewer"

    def __init__(self, bus: Bus, cfg: ViewerConfig, exit_after_final: bool = False) -> None:
        self.bus = bus
        self.cfg = cfg
        self.exit_after_final = exit_after_final
        self.description = ""
        self.rrd_path: Path | None = None
        """The ``.rrd`` file this view is saved to, when its sink is a file (after :meth:`start`)."""
        self.frames = 0
        self.updates = 0
        self.unusable = 0  # messages (or frames) that could not be logged
        self.problems = ProblemLog(log, "viewer")
        self.subs: dict[str, Any] = {}
        self._rec: Any = None  # the Rerun recording, opened by start()

    def start(self) -> None:
        """Subscribe to the topics shown; open the recording (a viewer spawned, a server, an .rrd file)."""
        keys, cfg, bus = self.bus.keys, self.cfg, self.bus
        self.subs = {
            # a live view: when it falls behind, the oldest go (and at most this much memory waits)
            "centrelines": bus.subscribe(
                keys.centrelines(), CentrelineMessage, capacity=100_000, ring=True, max_bytes=256 << 20
            ),
            "events": bus.subscribe(
                keys.camera_events(cfg.camera_id), EventPacket, capacity=100_000, ring=True, max_bytes=64 << 20
            ),
            "rate": bus.subscribe(keys.event_rate(cfg.camera_id), EventRate, capacity=1000, ring=True),
            "tunnel": bus.subscribe(keys.tunnel_state(), TunnelState, capacity=1000, ring=True),
            "supervisor": bus.subscribe(keys.supervisor_state(), SupervisorState, capacity=1000, ring=True),
        }
        self._rec, self.description = open_recording(self.cfg)
        if effective_sink(self.cfg) == "rrd":
            self.rrd_path = Path(self.cfg.rrd_path).expanduser().resolve()
        log.info("viewer: %s", self.description)

    def end_line(self) -> str:
        """What a command says of this view once the rig has stopped ("" when nothing is left to open)."""
        return f"Rerun view saved in {self.rrd_path} (open it with: rerun {self.rrd_path})" if self.rrd_path else ""

    def close(self) -> None:
        """Close the recording, for a viewer that will not run (``run`` closes it itself)."""
        rec, self._rec = self._rec, None
        if rec is not None:
            rec.flush()
            close_recording(rec)

    def run(self, stop: threading.Event) -> None:
        subs, rec = self.subs, self._rec
        if rec is None:
            raise RuntimeError(f"{self.name}: start() first")
        self.bus.declare_alive(self.name)
        logger = RerunLogger(rec, self.cfg, self.problems)
        handlers = (
            ("centrelines", logger.centrelines),
            ("events", logger.events),
            ("rate", logger.rate),
            ("tunnel", logger.tunnel),
            ("supervisor", lambda msg: logger.supervisor(msg, time.time())),
        )
        try:
            while not stop.is_set():
                beat(self.name, f"{self.updates} updates, {self.frames} frames")
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
                stop.wait(min(0.25 / self.cfg.geometry_rate_hz, self.cfg.flush_s / 4))
            self._show(logger.frame, time.monotonic(), True)
        finally:
            self.problems.flush(force=True)
            self.close()

    def _show(self, step: Any, *args: Any) -> Any:
        """Run one logging step; a message Rerun (or the logger) cannot take is counted, not fatal."""
        try:
            return step(*args)
        except Exception as exc:
            self.unusable += 1
            log.debug("viewer: %s failed", getattr(step, "__name__", step), exc_info=exc)
            self.problems.add("messages that could not be shown", f"{type(exc).__name__}: {exc}")
            return None
