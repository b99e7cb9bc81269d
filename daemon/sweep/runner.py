"""The sweep's state machine: a plan (:func:`~.plan.sweep_plan`, a generator of steps) carried out in
a :class:`~.session.Session`, point by point, into the run's log.

Each point's steps (``Point`` to ``EndPoint``) are one attempt: its speed set and watched, its
settle, its recording, its actions. An attempt that was not measured as planned (BadPoint: the
tunnel silent, faulted or out of tolerance, packets lost) is recorded with its files set aside,
then measured again or the sweep stops safe, as the plan's ``on_bad_point`` and ``retries`` say.
A resumed run (from its folder, or taken up on start: restart means resume) skips its finished
points. The run's log is closed (stop record, summary) after the session has the tunnel at zero.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from datetime import datetime
from pathlib import Path
from typing import Any

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.sweep.actions import ActionOutcome
from flagtrack.daemon.sweep.attempts import set_aside, space_problem
from flagtrack.daemon.sweep.plan import (
    Action,
    EndPoint,
    Point,
    Record,
    SetSpeed,
    Step,
    SweepConfig,
    Wait,
    plan_duration_s,
    plan_points,
    sweep_plan,
)
from flagtrack.daemon.sweep.ports import PointMeasure
from flagtrack.daemon.sweep.progress import SweepProgress
from flagtrack.daemon.sweep.record import record_point, run_action
from flagtrack.daemon.sweep.restart import start_decision
from flagtrack.daemon.sweep.runfiles import command_line
from flagtrack.daemon.sweep.runlock import RunLock
from flagtrack.daemon.sweep.runlog import PointResult, RunLog, completed_points, stored_sweep
from flagtrack.daemon.sweep.session import RunStopped, Session
from flagtrack.daemon.sweep.summary import write_summary
from flagtrack.daemon.sweep.validity import BadPoint, TunnelWatch
from flagtrack.daemon.typed_yaml import to_mapping

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SweepSettings:
    """What a sweep run takes from the ``supervisor:`` section (same names) and the tunnel.

    Attributes:
        runs_dir, run_name: where the run folder is made, and its name (default: date and time).
        sweep: the plan of a new run (a resumed run keeps its own).
        resume_interrupted: on start, take up an interrupted run or hold (:mod:`~.restart`).
        tolerance_mps: the readback must stay within this of a point's speed, m/s.
        readback_grace_s: how long it may stay out (or the link silent) before the point fails, s.
        suspect_lost_fraction: a point whose updates are lost more often is ``suspect``.
        expected_rate_mev_s, bytes_per_event, free_space_margin_mb: the free-space check.
        ramp_mps2: the tunnel's ramp rate, m/s^2 (the ETA before the first point ends; None: ramps
            not counted).
    """

    runs_dir: Path = Path("runs")
    run_name: str | None = None
    sweep: SweepConfig | None = None
    resume_interrupted: bool = True
    tolerance_mps: float = 0.2
    readback_grace_s: float = 1.0
    suspect_lost_fraction: float = 0.05
    expected_rate_mev_s: float = 5.0
    bytes_per_event: float = 2.0
    free_space_margin_mb: float = 50.0
    ramp_mps2: float | None = None


class SweepRunner:
    """A sweep as a session's procedure (see the module).

    Args:
        settings: the run's settings.
        measure: what each point's recording found.
        rig_snapshot: the whole rig config, stored in the run's start record.
        resume_dir: resume this run instead of starting a new one.
        summarise: writes the run's summary files from its folder once it ends.

    Attributes:
        run_dir: the run folder, once known.
        points_done: the point records written in this session, in order (bad attempts too).
    """

    mode = "sweep"
    watch_services = False

    def __init__(
        self,
        settings: SweepSettings,
        measure: PointMeasure,
        rig_snapshot: Mapping[str, Any] | None = None,
        resume_dir: Path | None = None,
        summarise: Callable[[Path], object] = write_summary,
    ) -> None:
        self.settings, self.measure = settings, measure
        self.rig_snapshot = dict(rig_snapshot or {})
        self.resume_dir = resume_dir
        self.run_dir: Path | None = None
        self.points_done: list[PointResult] = []
        self._summarise = summarise
        self._runlog: RunLog | None = None
        self._lock: RunLock | None = None
        self._sweep = settings.sweep
        self._done: set[str] = set()
        self._earlier: list[PointResult] = []  # a resumed run's points before this session

    # -- the session's procedure ---------------------------------------------------------------

    def prepare(self, session: Session) -> None:
        """Restart means resume: take up an interrupted run, or hold (RunStopped, tunnel at zero)."""
        if self.resume_dir is not None or not self.settings.resume_interrupted:
            return
        decision = start_decision(Path(self.settings.runs_dir).expanduser(), self.settings.run_name)
        if decision.action == "hold":
            raise RunStopped(decision.why)
        if decision.action == "resume":
            log.warning("supervisor: %s", decision.why)
            self.resume_dir = decision.run_dir

    def run(self, session: Session) -> None:
        self._runlog = self._resume() if self.resume_dir is not None else self._create(session.clock.time())
        assert self._sweep is not None
        points = plan_points(self._sweep)
        planned_point_s = plan_duration_s(self._sweep, self.settings.ramp_mps2) / max(len(points), 1)
        session.progress = SweepProgress(points, self._done, planned_point_s, session.clock.monotonic())
        steps: list[Step] = []  # the steps of the point under way, from its Point to its EndPoint
        for step in sweep_plan(self._sweep, self._done):
            if isinstance(step, Point) or steps:
                steps.append(step)
                if isinstance(step, EndPoint):
                    self._measure(session, steps)
                    steps = []
            elif isinstance(step, SetSpeed):
                session.set_speed(step.speed_mps)
            elif isinstance(step, Wait):
                session.idle(step.duration_s)
        session.mode = "done"

    def close(self, reason: str, error: str | None) -> None:
        """Write the stop record and the summary (a disk that refuses them is said in one line);
        give the run folder up."""
        if self._runlog is not None:
            _close_run(self._runlog, reason, error, self._summarise)
        if self._lock is not None:
            self._lock.release()

    # -- the run's folder ----------------------------------------------------------------------

    def _lock_run(self, run_dir: Path) -> None:
        """Own the run folder (one supervisor per run), or stop naming its holder."""
        try:
            self._lock = RunLock.acquire(run_dir, command_line())
        except ConfigError as exc:
            raise RunStopped(str(exc)) from None

    def _resume(self) -> RunLog:
        assert self.resume_dir is not None
        self._lock_run(self.resume_dir)
        runlog, record = RunLog.resume(self.resume_dir, command=command_line())
        self.run_dir = runlog.run_dir
        try:
            self._sweep = stored_sweep(record)
        except BaseException:
            runlog.close()
            raise
        self._done = completed_points(self.run_dir)
        self._earlier = list(record.points)
        log.info("supervisor: resuming %s (%d points done)", self.run_dir, len(self._done))
        return runlog

    def _create(self, now_unix: float) -> RunLog:
        sweep, settings = self._sweep, self.settings
        assert sweep is not None
        name = settings.run_name or datetime.fromtimestamp(now_unix).strftime("run-%Y%m%d-%H%M%S")
        self.run_dir = Path(settings.runs_dir).expanduser() / name
        config = {**self.rig_snapshot, "sweep": to_mapping(sweep)}
        self._lock_run(self.run_dir)
        return RunLog.create(self.run_dir, run_id=name, config=config, plan=plan_points(sweep), command=command_line())

    # -- one point -----------------------------------------------------------------------------

    def _measure(self, session: Session, steps: list[Step]) -> None:
        """Measure one point (its steps from Point to EndPoint); a bad attempt is recorded, then
        measured again or the sweep stops safe."""
        point = steps[0]
        assert isinstance(point, Point) and self._sweep is not None and session.progress is not None
        retries = self._sweep.retries if self._sweep.on_bad_point == "retry" else 0
        for attempt in range(retries + 1):
            session.begin_point(point)
            session.progress.start_point(point, session.clock.monotonic())
            log.info("supervisor: point %s%s", point.point_id, f" (attempt {attempt + 1})" if attempt else "")
            self._check_free_space(point)
            try:
                result = self._attempt(session, steps[1:])
            except BadPoint as bad:
                self._finish(session, set_aside(self._folder(), bad.result))
                if bad.stop or attempt == retries:
                    raise RunStopped(str(bad)) from None
                log.warning("supervisor: %s; measuring it again", bad)
                continue
            self._finish(session, result)
            return

    def _attempt(self, session: Session, steps: list[Step]) -> PointResult:
        """Run a point's steps; return its record (BadPoint when it was not measured as planned)."""
        watch = session.point
        assert watch is not None
        settings, run_dir = self.settings, self._folder()
        result: PointResult | None = None
        outcomes: list[ActionOutcome] = []
        for step in steps:
            if isinstance(step, SetSpeed):
                watch.tunnel = None
                session.set_speed(step.speed_mps)
                watch.tunnel = TunnelWatch(step.speed_mps, settings.tolerance_mps, settings.readback_grace_s)
            elif isinstance(step, Wait):
                session.idle(step.duration_s)
            elif isinstance(step, Record):
                previous = self.points_done[-1].state if self.points_done else "still"
                result = record_point(session, self.measure, step, run_dir, previous, settings.suspect_lost_fraction)
                watch.tunnel = None  # the analysis and the actions after the recording are not spoilt by the tunnel
            elif isinstance(step, Action):
                outcomes.append(run_action(session, step, len(outcomes), run_dir))
                if outcomes[-1].required and not outcomes[-1].ok:  # failed (a resumed run measures it again)
                    failed = replace(
                        result or PointResult.planned(watch.point),
                        status="failed",
                        error=f"required action: {outcomes[-1].summary()}",
                        actions=_summary(outcomes),
                    )
                    self._finish(session, failed)
                    raise RunStopped(f"point {watch.point.point_id}: required action {outcomes[-1].summary()}")
        assert result is not None
        if outcomes:
            result = replace(result, actions=_summary(outcomes))
        if result.status != "done":
            raise BadPoint(result)
        return result

    def _finish(self, session: Session, result: PointResult) -> None:
        """Write the point's record, count it and publish its facts at once."""
        assert self._runlog is not None and session.progress is not None
        self._runlog.point(result)
        self.points_done.append(result)
        session.end_point()
        session.progress.finish_point(result, session.clock.monotonic())
        session.publish(force=True)

    def _check_free_space(self, point: Point) -> None:
        """Stop safe rather than start a point the disk cannot hold."""
        assert self._sweep is not None
        s = self.settings
        problem = space_problem(
            self._folder(),
            self._sweep.record_s,
            [*self._earlier, *self.points_done],
            s.expected_rate_mev_s,
            s.bytes_per_event,
            s.free_space_margin_mb,
        )
        if problem is not None:
            raise RunStopped(f"point {point.point_id} not started: {problem}")

    def _folder(self) -> Path:
        assert self.run_dir is not None
        return self.run_dir


def _close_run(runlog: RunLog, reason: str, error: str | None, summarise: Callable[[Path], object]) -> None:
    try:
        runlog.stop(reason, error=error)
    except OSError as exc:
        log.error("supervisor: could not write the stop record to %s: %s", runlog.path, exc.strerror or exc)
    finally:
        runlog.close()
    try:
        summarise(runlog.run_dir)
    except Exception as exc:  # noqa: BLE001 - the run is recorded; the summary is a convenience
        log.error("supervisor: summary failed: %s", exc)


def _summary(outcomes: list[ActionOutcome]) -> str:
    """How a point's actions went, for its record: ``pause ok; command failed: exit code 3 (...)``."""
    return "; ".join(o.summary() for o in outcomes)
