"""The supervisor service: owns the wind tunnel, watches the flag, runs sweeps or a feedback loop.

The service only wires things together: the mode's procedure (a
:class:`~flagtrack.daemon.sweep.runner.SweepRunner`, a :class:`.feedback_loop.FeedbackLoop`, or
watching) runs in a :class:`~flagtrack.daemon.sweep.session.Session` with the tunnel, the bus
(:class:`.busside.BusSide`) and each point's measure (:class:`.measure.BusMeasure`). Whatever
happens, the session's ``finally`` ramps the tunnel to zero, stops the recording and writes the
run's stop record with the reason. A supervisor killed outright is covered by the tunnel's own
watchdog (deploy/tunnel-*.yaml).
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from flagtrack.daemon.schema import FlagState, SupervisorState
from flagtrack.daemon.services.supervisor.busside import BusSide
from flagtrack.daemon.services.supervisor.control_loop import ControlLoop
from flagtrack.daemon.services.supervisor.control_record import ControlRecord
from flagtrack.daemon.services.supervisor.feedback_loop import FeedbackLoop
from flagtrack.daemon.services.supervisor.laws import Law, load_law
from flagtrack.daemon.services.supervisor.measure import BusMeasure, FlagGeometry
from flagtrack.daemon.services.supervisor.monitor import BusMonitor
from flagtrack.daemon.services.supervisor.requests import SpeedDesk
from flagtrack.daemon.services.supervisor.section import SupervisorConfig
from flagtrack.daemon.sweep.runlog import PointResult
from flagtrack.daemon.sweep.runner import SweepRunner, SweepSettings
from flagtrack.daemon.sweep.session import Limits, Monitoring, Session
from flagtrack.daemon.transport import Bus

if TYPE_CHECKING:
    from flagtrack.daemon.tracking.setup import TrackingSetup

__all__ = ["FlagGeometry", "SupervisorService"]  # FlagGeometry: where the rig builds it from


class SupervisorService:
    """Runs the configured mode with the tunnel ``open_tunnel`` opens (not started) when it starts.

    Args:
        bus: the bus.
        cfg: the supervisor section.
        open_tunnel: opens the tunnel, called by :meth:`start`: a
            :class:`~flagtrack.drivers.tunnel.safe.SafeTunnel` (or any WindTunnel with start/abort/close).
        camera_id: the camera watched.
        flag: the flag's geometry for the metrics.
        rig_snapshot: the whole rig config, stored in the run's start record.
        resume_dir: resume this run instead of starting a new one.
        sensor: a point sensor (``SensorConfig``) compared with each point's reconstruction, or None.
        tracking: the rig's tracking set-up, for each flapping point's chain
            reach (:class:`.measure.BusMeasure`), or None.
    """

    name = "supervisor"

    def __init__(
        self,
        bus: Bus,
        cfg: SupervisorConfig,
        open_tunnel: Callable[[], Any],
        camera_id: str,
        flag: FlagGeometry,
        rig_snapshot: dict[str, Any],
        resume_dir: Path | None = None,
        sensor: Any = None,
        tracking: TrackingSetup | None = None,
    ) -> None:
        self.bus, self.cfg, self.flag = bus, cfg, flag
        self.tracking = tracking  # a point's chain reach is judged with it
        self._open_tunnel, self.camera_id = open_tunnel, camera_id
        self.tunnel: Any = None  # opened by start()
        self.monitor: BusMonitor
        self.rig_snapshot = rig_snapshot
        self.resume_dir = resume_dir
        self.sensor = sensor
        self.session: Session | None = None
        self.procedure: SweepRunner | FeedbackLoop | ControlLoop | Monitoring | None = None
        self.desk: SpeedDesk | None = None
        self._law: Law | None = None
        self._states: Any = None
        self._observers: list[Callable[[SupervisorState], None]] = []

    def start(self) -> None:
        """Open the tunnel (not started: ``run`` starts it) and the bus watch (rates, centrelines,
        recorder, sensor samples, liveliness); a watch that fails closes the tunnel again."""
        self.tunnel = self._open_tunnel()
        try:
            sensor_id = None if self.sensor is None else self.sensor.id
            self.monitor = BusMonitor(self.bus, self.camera_id, self.cfg.onset, self.cfg.required, sensor_id)
            self.desk = SpeedDesk(self.bus)
            self.desk.start()
            if self.cfg.mode == "control":
                control = self.cfg.control
                self._law = None if control.controller is None else load_law(control.controller, self.cfg.feedback)
                self._states = self.bus.subscribe(self.bus.keys.flag_state(), FlagState, capacity=256, ring=True)
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Close the tunnel, for a supervisor that will not run (``run`` ends at a safe state itself)."""
        if self.tunnel is not None:
            self.tunnel.close()

    def add_observer(self, observer: Callable[[SupervisorState], None]) -> None:
        """Call ``observer`` with every state the supervisor publishes, in its thread (a command draws
        the sweep's progress with it). The supervisor's own work goes on whatever the observer does:
        an exception it raises is logged once and the states keep coming."""
        self._observers.append(observer)

    def run(self, stop: threading.Event) -> None:
        self.procedure = self._procedure()
        refusing = None
        if self.desk is not None:
            why = f"the supervisor is in mode {self.cfg.mode}; speed requests go to mode control"
            if self.cfg.mode == "control":
                why = "the control loop has not started, or has ended"
                if not self.cfg.control.requests:
                    why = "this control run takes no speed requests (supervisor.control.requests)"
            refusing = (self.desk, why)
        outside = BusSide(self.bus, self.name, self.cfg, self.monitor, self._observers, refusing)
        self.bus.declare_alive(self.name)
        cfg = self.cfg
        limits = Limits(
            silence_timeout_s=cfg.silence_timeout_s,
            startup_timeout_s=cfg.startup_timeout_s,
            publish_interval_s=cfg.publish_interval_s,
            recorder_timeout_s=cfg.recorder_timeout_s,
        )
        self.session = Session(self.tunnel, outside, limits)
        self.session.run(self.procedure, stop)

    def _procedure(self) -> SweepRunner | FeedbackLoop | ControlLoop | Monitoring:
        """The mode's procedure."""
        cfg = self.cfg
        if cfg.mode == "control":
            return self._control_loop()
        if cfg.mode == "feedback":
            return FeedbackLoop(cfg.feedback, self.monitor, self.flag)
        if cfg.mode != "sweep":
            return Monitoring()
        params = getattr(self.tunnel, "params", None)
        settings = SweepSettings(
            runs_dir=cfg.runs_dir,
            run_name=cfg.run_name,
            sweep=cfg.sweep,
            resume_interrupted=cfg.resume_interrupted,
            tolerance_mps=params.tolerance_mps if params is not None else 0.2,
            readback_grace_s=cfg.readback_grace_s,
            suspect_lost_fraction=cfg.suspect_lost_fraction,
            expected_rate_mev_s=cfg.expected_rate_mev_s,
            bytes_per_event=cfg.bytes_per_event,
            free_space_margin_mb=cfg.free_space_margin_mb,
            ramp_mps2=params.max_ramp_mps2 if params is not None else None,
        )
        measure = BusMeasure(self.monitor, self.flag, self.sensor, self.tracking)
        return SweepRunner(settings, measure, self.rig_snapshot, self.resume_dir)

    def _control_loop(self) -> ControlLoop:
        """Mode ``control``'s procedure, its run folder in ``runs_dir``."""
        cfg, control = self.cfg, self.cfg.control
        name = cfg.run_name or datetime.now().strftime("control-%Y%m%d-%H%M%S")
        about = {
            "law": None if self._law is None else self._law.name,
            "period_s": control.period_s,
            "control": dataclasses.asdict(control),
            "rig": self.rig_snapshot,
        }
        record = ControlRecord(Path(cfg.runs_dir).expanduser() / name, about)
        desk = self.desk if control.requests else None
        return ControlLoop(control, self._law, self._states, desk, record, self.tunnel.params)

    @property
    def stop_reason(self) -> str:
        """Why the run ended (``finished``, a signal, an error), "" while it runs."""
        return "" if self.session is None else self.session.stop_reason

    @property
    def run_dir(self) -> Path | None:
        """The sweep's or the control run's folder, once known."""
        if isinstance(self.procedure, ControlLoop):
            return self.procedure.record.run_dir
        return self.procedure.run_dir if isinstance(self.procedure, SweepRunner) else None

    @property
    def points_done(self) -> list[PointResult]:
        """The point records written in this session, in order (bad attempts too)."""
        return self.procedure.points_done if isinstance(self.procedure, SweepRunner) else []

    @property
    def feedback_trace(self) -> list[tuple[float, float, float]]:
        """(s since the loop began, measured A/L, commanded m/s) per period of the feedback loop."""
        return self.procedure.trace if isinstance(self.procedure, FeedbackLoop) else []

    @property
    def recording_point(self) -> str:
        """The id of the point whose recording is under way ("" when none)."""
        watch = None if self.session is None else self.session.point
        return watch.point.point_id if watch is not None and watch.recording else ""
