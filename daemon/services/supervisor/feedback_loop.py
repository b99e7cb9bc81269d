"""Mode ``feedback`` as a session's procedure: the PI law of :mod:`.feedback` decides the speed from
the amplitude measured over the last window; the :class:`~flagtrack.daemon.sweep.session.Session`
applies it (bounded, ramped, verified), keeps the rig watched and ends with the tunnel at zero."""

from __future__ import annotations

import logging

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.services.supervisor.analysis import point_metrics
from flagtrack.daemon.services.supervisor.feedback import ControllerState, control_step, measured_amplitude
from flagtrack.daemon.services.supervisor.measure import FlagGeometry
from flagtrack.daemon.services.supervisor.monitor import BusMonitor
from flagtrack.daemon.services.supervisor.section import FeedbackConfig
from flagtrack.daemon.sweep.session import Session

log = logging.getLogger(__name__)


class FeedbackLoop:
    """Holds a target tip amplitude (see the module).

    Attributes:
        trace: (seconds since the loop began, measured A/L, commanded speed m/s) per period.
    """

    mode = "feedback"
    watch_services = True  # a required service gone or a silent camera stops the loop at any time

    def __init__(self, cfg: FeedbackConfig, monitor: BusMonitor, flag: FlagGeometry) -> None:
        self.cfg, self.monitor, self.flag = cfg, monitor, flag
        self.trace: list[tuple[float, float, float]] = []

    def prepare(self, session: Session) -> None:
        pass

    def run(self, session: Session) -> None:
        fb, clock = self.cfg, session.clock
        session.mode = "feedback"
        session.set_speed(fb.start_speed_mps)
        session.idle(fb.settle_s)
        state = ControllerState(0.0, fb.start_speed_mps)
        started_s = clock.monotonic()
        self.monitor.start_collecting()
        while fb.duration_s == 0 or clock.monotonic() - started_s < fb.duration_s:
            session.idle(fb.period_s)
            amplitude = self._window_amplitude()
            state = control_step(state, amplitude, fb.period_s, fb)
            self.trace.append((clock.monotonic() - started_s, amplitude, state.speed_mps))
            log.info("feedback: A/L %.3f -> %.2f m/s", amplitude, state.speed_mps)
            if abs(state.speed_mps - session.tunnel.setpoint_mps) > 1e-9:
                session.set_speed(state.speed_mps)
        self.monitor.stop_collecting()
        session.mode = "done"

    def close(self, reason: str, error: str | None) -> None:
        pass

    def _window_amplitude(self) -> float:
        """A/L over the last ``window_s`` of centrelines (NaN: hold), gathering on."""
        collection = self.monitor.stop_collecting()
        recent = last_seconds(collection.batches, self.cfg.window_s)
        self.monitor.start_collecting()
        assert self.monitor.collection is not None
        self.monitor.collection.batches.extend(recent)
        window = point_metrics(recent, self.flag.length, self.flag.root, self.flag.direction_deg)
        return measured_amplitude(window.amplitude_over_l, window.lost_fraction, self.cfg)


def last_seconds(batches: list[CentrelineBatch], window_s: float) -> list[CentrelineBatch]:
    """The batches (trimmed) covering the last ``window_s`` of camera time."""
    if not batches:
        return []
    t_end = batches[-1].t_s[-1]
    kept = []
    for batch in reversed(batches):
        if batch.t_s[-1] < t_end - window_s:
            break
        kept.append(batch.select(batch.t_s >= t_end - window_s))
    return kept[::-1]
