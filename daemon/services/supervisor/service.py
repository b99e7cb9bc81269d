"""The supervisor service: owns the wind tunnel, watches the flag, runs sweeps or a feedback loop.

Whatever happens (a signal, an exception, a service going silent, a readback mismatch, a serial
error) the ``finally`` ramps the tunnel to zero, stops the recording and writes the run's stop
record with the reason. A supervisor killed outright is covered by the tunnel's own watchdog
(deploy/tunnel-*.yaml).
"""

from __future__ import annotations

import logging
import math
import os
import shutil
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, replace
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon.errors import ConfigError, DriverError, FlagtrackError
from flagtrack.daemon.schema import RecorderCommand, SupervisorState, TunnelState
from flagtrack.daemon.services.sd_notify import beat
from flagtrack.daemon.services.supervisor.analysis import point_metrics
from flagtrack.daemon.services.supervisor.feedback import ControllerState, control_step, measured_amplitude
from flagtrack.daemon.services.supervisor.monitor import BusMonitor, point_state
from flagtrack.daemon.services.supervisor.section import SupervisorConfig
from flagtrack.daemon.services.supervisor.validity import (
    BadPoint,
    TunnelWatch,
    expected_point_bytes,
    free_space_problem,
    recording_problem,
)
from flagtrack.daemon.sweep.actions import ActionOutcome, PauseAction, parse_action, run_command
from flagtrack.daemon.sweep.plan import Action, EndPoint, Point, Record, SetSpeed, Step, Wait, plan_points, sweep_plan
from flagtrack.daemon.sweep.progress import SweepProgress, is_suspect
from flagtrack.daemon.sweep.restart import start_decision
from flagtrack.daemon.sweep.runfiles import command_line
from flagtrack.daemon.sweep.runlock import RunLock
from flagtrack.daemon.sweep.runlog import POINTS_DIR, PointResult, RunLog, completed_points, point_paths, stored_sweep
from flagtrack.daemon.sweep.summary import write_summary
from flagtrack.daemon.transport import Bus

log = logging.getLogger(__name__)


class RunStopped(FlagtrackError):
    """The run was stopped (signal) or cannot go on (a required service is gone)."""


@dataclass(frozen=True)
class FlagGeometry:
    """The flag's rest frame and length in the tracker's units (for A/L and the lateral displacement)."""

    length: float
    root: tuple[float, float]
    direction_deg: float


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
    ) -> None:
        self.bus, self.cfg, self.flag = bus, cfg, flag
        self._open_tunnel, self.camera_id = open_tunnel, camera_id
        self.tunnel: Any = None  # opened by start()
        self.monitor: BusMonitor
        self.rig_snapshot = rig_snapshot
        self.resume_dir = resume_dir
        self.sensor = sensor
        self.run_dir: Path | None = None
        self.stop_reason = ""
        self.points_done: list[PointResult] = []
        self._mode, self._point, self._branch = cfg.mode, "", ""
        self._last_publish = 0.0
        self._stop = threading.Event()
        self.progress: SweepProgress | None = None
        self._observers: list[Callable[[SupervisorState], None]] = []
        self._observer_failed = False
        self._current_point: Point | None = None
        self._run_lock: RunLock | None = None
        self._earlier_points: list[PointResult] = []  # a resumed run's points before this session
        self._watch: TunnelWatch | None = None  # set during a point's settle and record
        self._tunnel_problem: str | None = None
        self._readbacks: list[float] | None = None  # the tunnel's readbacks while a point records

    def start(self) -> None:
        """Open the tunnel (not started: ``run`` starts it) and the bus watch (rates, centrelines,
        recorder, sensor samples, liveliness); a watch that fails closes the tunnel again."""
        self.tunnel = self._open_tunnel()
        try:
            sensor_id = None if self.sensor is None else self.sensor.id
            self.monitor = BusMonitor(self.bus, self.camera_id, self.cfg.onset, self.cfg.required, sensor_id)
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

    # -- service ---------------------------------------------------------------------------

    def run(self, stop: threading.Event) -> None:
        self._stop = stop
        keys = self.bus.keys
        self._state_pub = self.bus.publisher(keys.supervisor_state())
        self._tunnel_pub = self.bus.publisher(keys.tunnel_state())
        self._recorder_pub = self.bus.publisher(keys.recorder_command(), tag_source=True)  # the recorder logs who
        self.bus.declare_alive(self.name)
        watcher = threading.Thread(target=self._abort_on_stop, name="supervisor-abort", daemon=True)
        watcher.start()
        runlog: RunLog | None = None
        reason, error = "finished", None
        try:
            self.tunnel.start()
            if self.cfg.mode == "sweep" and self.resume_dir is None and self.cfg.resume_interrupted:
                self._take_up_runs()
            self._wait_for_services()
            if self.cfg.mode == "sweep":
                runlog = self._open_run()
                self._run_sweep(runlog)
            elif self.cfg.mode == "feedback":
                self._run_feedback()
            else:
                while not stop.is_set():
                    self._idle(0.05)
        except RunStopped as exc:
            reason = str(exc)
            log.warning("supervisor: %s", reason)
        except DriverError as exc:
            if stop.is_set():  # a ramp interrupted by the stop request: the request is the reason
                reason = self._stop_reason()
            else:
                reason, error = "error", f"{type(exc).__name__}: {exc}"
                log.error("supervisor: %s", error)
        except BaseException as exc:
            reason, error = "error", f"{type(exc).__name__}: {exc}"
            log.error("supervisor: %s", error)
            raise
        finally:
            self.stop_reason = reason
            self._safe_state(runlog, reason, error)

    def _stop_reason(self) -> str:
        """Why the stop was requested (a signal, another service failing), as the stop record says it."""
        return getattr(self._stop, "reason", "") or "stopped"

    def _abort_on_stop(self) -> None:
        """A stop request interrupts a ramp in progress (the finally then ramps to zero)."""
        self._stop.wait()
        self.tunnel.abort()

    def _safe_state(self, runlog: RunLog | None, reason: str, error: str | None) -> None:
        self._mode, self._watch, self._point = "safe", None, ""
        try:
            self._recorder(RecorderCommand("stop", request_id=uuid.uuid4().hex), wait=False)
        except FlagtrackError as exc:
            log.error("supervisor: could not stop the recorder: %s", exc)
        try:
            self.tunnel.safe_stop()
        except DriverError as exc:
            log.error("supervisor: %s", exc)
            error = error or str(exc)
        finally:
            self._publish(force=True)
            self.tunnel.close()
            if runlog is not None:
                self._close_run(runlog, reason, error)
            if self._run_lock is not None:
                self._run_lock.release()
            log.info("supervisor: tunnel at zero (%s)", reason)

    def _close_run(self, runlog: RunLog, reason: str, error: str | None) -> None:
        """Write the stop record and the summary; a disk that refuses them is said in one line."""
        try:
            runlog.stop(reason, error=error)
        except OSError as exc:
            log.error("supervisor: could not write the stop record to %s: %s", runlog.path, exc.strerror or exc)
        finally:
            runlog.close()
        try:
            write_summary(runlog.run_dir)
        except Exception as exc:  # noqa: BLE001 - the run is recorded; the summary is a convenience
            log.error("supervisor: summary failed: %s", exc)

    # -- helpers ---------------------------------------------------------------------------

    def _idle(self, duration_s: float) -> None:
        """Wait ``duration_s`` watching the bus; raise RunStopped on a stop request or a silent service."""
        deadline = time.monotonic() + duration_s
        while True:
            self._heartbeat()
            beat(self.name, f"{self._mode}, flag {self.monitor.state.value}")
            self.monitor.pump()
            self._publish()
            if self._stop.is_set():
                raise RunStopped(self._stop_reason())
            if self._point or self._mode == "feedback":
                problem = self.monitor.problem(self.cfg.silence_timeout_s)
                if problem:
                    raise RunStopped(problem)
            self._check_point()
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return
            self._stop.wait(min(0.02, remaining))

    def _heartbeat(self) -> None:
        """Tell the tunnel this loop is alive: its keep-alive stops when the loop hangs."""
        beat = getattr(self.tunnel, "heartbeat", None)
        if beat is not None:
            beat()

    def _check_point(self) -> None:
        """Raise BadPoint if the point under way is spoilt: the recorder failed (the sweep stops), the
        tunnel went silent, faulted or left its tolerance (seen in the last published status)."""
        point = self._current_point
        if not self._point or point is None:
            return
        if self.monitor.recorder_error and self._readbacks is not None:
            reason = f"recorder: {self.monitor.recorder_error}"
            raise BadPoint(PointResult.planned(point, status="failed", reason=reason), stop=True)
        if self._tunnel_problem:
            reason, self._tunnel_problem = self._tunnel_problem, None
            raise BadPoint(PointResult.planned(point, status="failed", reason=reason))

    def _wait_for_services(self) -> None:
        """Wait for the required services and for the still-flag baseline of the onset detector."""
        deadline = time.monotonic() + self.cfg.startup_timeout_s
        while (
            self.monitor.missing() or self.monitor.reading is None or not np.isfinite(self.monitor.thresholds_hz()[0])
        ):
            if time.monotonic() > deadline:
                missing = self.monitor.missing()
                what = f"services {', '.join(missing)} did not appear" if missing else "no event-rate baseline"
                raise RunStopped(f"{what} within {self.cfg.startup_timeout_s:g} s")
            self._idle(0.05)
        self.monitor.last_rate_s = time.monotonic()

    def _publish(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._last_publish < self.cfg.publish_interval_s:
            return
        self._last_publish = now
        m = self.monitor
        state = SupervisorState(
            m.state.value,
            float(m.rate_hz) if np.isfinite(m.rate_hz) else 0.0,
            self._mode,
            self._point,
            self._branch,
            float(self.tunnel.setpoint_mps) if np.isfinite(self.tunnel.setpoint_mps) else 0.0,
            self.stop_reason,
            **self._progress_fields(now),
        )
        self._state_pub.put(state)
        status = self.tunnel.status()
        self._watch_tunnel(status)
        self._tunnel_pub.put(
            TunnelState(
                float(status.speed_mps) if np.isfinite(status.speed_mps) else -1.0,
                float(status.setpoint_mps) if np.isfinite(status.setpoint_mps) else 0.0,
                "fault" if status.fault else self._mode,
                status.fault or "",
                time.time(),
            )
        )
        for observer in self._observers:
            try:
                observer(state)
            except Exception as exc:  # noqa: BLE001 - a display never stops a sweep (or its safe state)
                if not self._observer_failed:
                    log.error("supervisor: a progress observer failed (%s: %s)", type(exc).__name__, exc)
                self._observer_failed = True

    def _watch_tunnel(self, status: Any) -> None:
        """Note the readback (while recording) and any problem of the point under way."""
        if self._readbacks is not None:
            self._readbacks.append(status.speed_mps)
        if self._watch is not None and self._tunnel_problem is None:
            self._tunnel_problem = self._watch.check(status.speed_mps, status.fault, status.link_ok, time.monotonic())

    def _progress_fields(self, now_s: float) -> dict[str, Any]:
        """The sweep-progress fields of :class:`SupervisorState` (none outside a sweep)."""
        progress = self.progress
        if progress is None:
            return {}
        fields: dict[str, Any] = {
            "point_index": progress.current_position,
            "points_total": progress.total,
            "points_done": progress.done,
            "elapsed_s": progress.elapsed_s(now_s),
            "eta_s": _known(progress.eta_s(now_s)),
        }
        last = progress.last
        if last is not None:
            fields.update(
                last_point=last.point_id,
                last_index=last.position,
                last_speed_mps=_known(last.speed_mps),
                last_branch=last.branch,
                last_state=last.state,
                last_status=last.status,
                amplitude_over_l=_known(last.amplitude_over_l),
                frequency_hz=_known(last.frequency_hz),
                lost_fraction=_known(last.lost_fraction),
                sensor_error_rms_over_l=_known(last.sensor_error_rms_over_l),
            )
        return fields

    def _recorder(self, command: RecorderCommand, wait: bool = True) -> Any:
        """Send a command to the recorder; with ``wait``, return its acknowledgement."""
        self._recorder_pub.put(command)
        if not wait:
            return None
        deadline = time.monotonic() + self.cfg.recorder_timeout_s
        while command.request_id not in self.monitor.recorder_replies:
            if time.monotonic() > deadline:
                raise RunStopped(
                    f"the recorder did not acknowledge '{command.action}' within {self.cfg.recorder_timeout_s:g} s"
                )
            self._idle(0.02)
        return self.monitor.recorder_replies.pop(command.request_id)

    def _set_speed(self, speed_mps: float) -> None:
        self.monitor.pump()
        self._publish(force=True)
        self.tunnel.set_speed_mps(speed_mps)
        self.monitor.pump()
        if self._stop.is_set():
            raise RunStopped(self._stop_reason())

    # -- sweep -----------------------------------------------------------------------------

    def _take_up_runs(self) -> None:
        """Restart means resume: take up an interrupted run, or hold (RunStopped, tunnel to zero)."""
        decision = start_decision(Path(self.cfg.runs_dir).expanduser(), self.cfg.run_name)
        if decision.action == "hold":
            raise RunStopped(decision.why)
        if decision.action == "resume":
            log.warning("supervisor: %s", decision.why)
            self.resume_dir = decision.run_dir

    def _lock_run(self, run_dir: Path) -> None:
        """Own the run folder (one supervisor per run), or stop naming its holder."""
        try:
            self._run_lock = RunLock.acquire(run_dir, command_line())
        except ConfigError as exc:
            raise RunStopped(str(exc)) from None

    def _open_run(self) -> RunLog:
        if self.resume_dir is not None:
            self._lock_run(self.resume_dir)
            runlog, record = RunLog.resume(self.resume_dir, command=command_line())
            self.run_dir = runlog.run_dir
            self._sweep = stored_sweep(record)
            self._done = completed_points(self.run_dir)
            self._earlier_points = list(record.points)
            log.info("supervisor: resuming %s (%d points done)", self.run_dir, len(self._done))
            return runlog
        name = self.cfg.run_name or datetime.now().strftime("run-%Y%m%d-%H%M%S")
        self.run_dir = Path(self.cfg.runs_dir).expanduser() / name
        assert self.cfg.sweep is not None
        self._sweep, self._done = self.cfg.sweep, set()
        config = {**self.rig_snapshot, "sweep": _mapping(self.cfg.sweep)}
        self._lock_run(self.run_dir)
        return RunLog.create(
            self.run_dir, run_id=name, config=config, plan=plan_points(self.cfg.sweep), command=command_line()
        )

    def _run_sweep(self, runlog: RunLog) -> None:
        planned_point_s = self._sweep.settle_s + self._sweep.record_s
        self.progress = SweepProgress(plan_points(self._sweep), self._done, planned_point_s, time.monotonic())
        steps: list[Step] = []  # the steps of the point under way, from its Point to its EndPoint
        for step in sweep_plan(self._sweep, self._done):
            if isinstance(step, Point) or steps:
                steps.append(step)
                if isinstance(step, EndPoint):
                    self._measure(steps, runlog)
                    steps = []
            elif isinstance(step, SetSpeed):
                self._set_speed(step.speed_mps)
            elif isinstance(step, Wait):
                self._idle(step.duration_s)
        self._mode = "done"

    def _measure(self, steps: list[Step], runlog: RunLog) -> None:
        """Measure one point (its steps from Point to EndPoint); a bad point is recorded, then measured
        again or the sweep stops safe, as the plan's ``on_bad_point`` and ``retries`` say."""
        point = steps[0]
        assert isinstance(point, Point)
        retries = self._sweep.retries if self._sweep.on_bad_point == "retry" else 0
        for attempt in range(retries + 1):
            self._point, self._branch, self._current_point = point.point_id, point.branch.value, point
            self._tunnel_problem = None
            assert self.progress is not None
            self.progress.start_point(point, time.monotonic())
            log.info("supervisor: point %s%s", point.point_id, f" (attempt {attempt + 1})" if attempt else "")
            self._check_free_space(point)
            try:
                result = self._point_steps(point, steps[1:], runlog)
            except BadPoint as bad:
                self._finish_point(runlog, self._set_aside(bad.result))
                if bad.stop or attempt == retries:
                    raise RunStopped(str(bad)) from None
                log.warning("supervisor: %s; measuring it again", bad)
                continue
            finally:
                self._watch = None
            self._finish_point(runlog, result)
            return

    def _point_steps(self, point: Point, steps: list[Step], runlog: RunLog) -> PointResult:
        """Run a point's steps; return its record (raise BadPoint when it was not measured as planned)."""
        result: PointResult | None = None
        outcomes: list[ActionOutcome] = []
        for step in steps:
            if isinstance(step, SetSpeed):
                self._watch = None
                self._set_speed(step.speed_mps)
                self._watch = self._tunnel_watch(step.speed_mps)
            elif isinstance(step, Wait):
                self._idle(step.duration_s)
            elif isinstance(step, Record):
                result = self._record_point(point, step)
                self._watch = None  # the analysis and the actions after the recording are not spoilt by the tunnel
            elif isinstance(step, Action):
                outcome = self._run_action(step, point, len(outcomes))
                outcomes.append(outcome)
                if outcome.required and not outcome.ok:  # the point is failed (a resumed run measures it again)
                    failed = replace(
                        result or PointResult.planned(point),
                        status="failed",
                        error=f"required action: {outcome.summary()}",
                        actions=_summary(outcomes),
                    )
                    self._finish_point(runlog, failed)
                    raise RunStopped(f"point {point.point_id}: required action {outcome.summary()}")
        assert result is not None
        if outcomes:
            result = replace(result, actions=_summary(outcomes))
        if result.status != "done":
            raise BadPoint(result)
        return result

    def _finish_point(self, runlog: RunLog, result: PointResult) -> None:
        runlog.point(result)
        self.points_done.append(result)
        self._point = ""
        self._point_finished(result)

    def _tunnel_watch(self, speed_mps: float) -> TunnelWatch:
        params = getattr(self.tunnel, "params", None)
        tolerance = params.tolerance_mps if params is not None else 0.2
        return TunnelWatch(speed_mps, tolerance, self.cfg.readback_grace_s)

    def _check_free_space(self, point: Point) -> None:
        """Stop safe rather than start a point the disk cannot hold (expected size from the config and
        from the rate this run's points, before a resume too, filled the disk at)."""
        assert self.run_dir is not None
        measured = [self._bytes_per_s(p) for p in (*self._earlier_points, *self.points_done)]
        cfg = self.cfg
        need = expected_point_bytes(
            self._sweep.record_s, cfg.expected_rate_mev_s, cfg.bytes_per_event, max(measured, default=0.0)
        )
        free = shutil.disk_usage(self.run_dir).free
        problem = free_space_problem(free, need, cfg.free_space_margin_mb * 1e6, str(self.run_dir))
        if problem is not None:
            raise RunStopped(f"point {point.point_id} not started: {problem}")

    def _bytes_per_s(self, p: PointResult) -> float:
        """Bytes per second a recorded point wrote (its .raw and centreline files), 0 when unknown."""
        duration_s = p.t_stop_unix - p.t_start_unix
        if not duration_s > 0 or self.run_dir is None:
            return 0.0
        files = [self.run_dir / f for f in (p.raw_file, p.centreline_file) if f]
        return sum(f.stat().st_size for f in files if f.exists()) / duration_s

    def _set_aside(self, result: PointResult) -> PointResult:
        """Rename a bad attempt's files (``<id>.bad<N>.raw`` ...) so that measuring the point again
        loses nothing; return its record pointing at them."""
        assert self.run_dir is not None
        points = self.run_dir / POINTS_DIR
        n = 1
        while any(points.glob(f"{result.point_id}.bad{n}.*")) or any(points.glob(f"{result.point_id}.bad{n}_*")):
            n += 1
        moved: dict[str, str | None] = {}
        for old in sorted(points.glob(f"{result.point_id}[._]*")):
            if ".bad" in old.name or ".action" in old.name:
                continue
            new = old.with_name(f"{result.point_id}.bad{n}{old.name[len(result.point_id) :]}")
            try:
                os.replace(old, new)
            except OSError as exc:
                log.error("supervisor: could not set %s aside: %s", old, exc)
                continue
            moved[str(old.relative_to(self.run_dir))] = str(new.relative_to(self.run_dir))
        return replace(
            result,
            raw_file=moved.get(result.raw_file or "", result.raw_file),
            centreline_file=moved.get(result.centreline_file or "", result.centreline_file),
        )

    def _point_finished(self, result: PointResult) -> None:
        """Count the point and publish its facts at once (each finished point is in a state message)."""
        assert self.progress is not None
        self.progress.finish_point(result, time.monotonic())
        self._publish(force=True)

    def _run_action(self, step: Action, point: Point, number: int) -> ActionOutcome:
        """Run one per-point action (see :mod:`~flagtrack.daemon.sweep.actions`); stop requests still work."""
        action = parse_action(step.name, step.params)
        if isinstance(action, PauseAction):
            self._idle(action.seconds)
            return ActionOutcome(step.name, True, "", action.seconds)
        point_dir = self.run_dir / POINTS_DIR  # type: ignore[operator]
        raw, lines = point_paths(point.point_id)
        context = {
            "point_id": point.point_id,
            "index": point.index,
            "branch": point.branch.value,
            "speed_mps": f"{point.speed_mps:g}",
            "run_dir": str(self.run_dir.resolve()),  # type: ignore[union-attr]
            "point_dir": str(point_dir.resolve()),
            "raw": str((self.run_dir / raw).resolve()),  # type: ignore[operator]
            "centrelines": str((self.run_dir / lines).resolve()),
        }  # type: ignore[operator]
        log_path = point_dir / f"{point.point_id}.action{number}.log"
        log.info("supervisor: action %s for %s", step.name, point.point_id)
        outcome = run_command(action, step.name, context, self.run_dir, log_path, idle=self._idle)  # type: ignore[arg-type]
        if not outcome.ok:
            log.warning("supervisor: point %s: %s", point.point_id, outcome.summary())
        return outcome

    def _record_point(self, point: Point, step: Record) -> PointResult:
        base = self.run_dir / "points" / point.point_id  # type: ignore[operator]
        raw, lines = (self.run_dir / path for path in point_paths(point.point_id))  # type: ignore[operator]
        t_start = time.time()
        started = self._recorder(
            RecorderCommand("start", path=str(base.resolve()), centrelines=True, request_id=uuid.uuid4().hex)
        )
        self.monitor.start_collecting()
        self._readbacks = []
        try:
            self._idle(step.duration_s)
        except BadPoint as bad:  # the recording so far is kept (and named in the point's record)
            self.monitor.stop_collecting()
            if not bad.stop:
                self._recorder(RecorderCommand("stop", request_id=uuid.uuid4().hex))
            raise BadPoint(
                replace(
                    bad.result,
                    raw_file=str(raw.relative_to(self.run_dir)) if raw.exists() else None,  # type: ignore[arg-type]
                    raw_bytes=raw.stat().st_size if raw.exists() else 0,
                    centreline_file=str(lines.relative_to(self.run_dir)) if lines.exists() else None,  # type: ignore[arg-type]
                    t_start_unix=t_start,
                    t_stop_unix=time.time(),
                ),
                bad.stop,
            ) from None
        finally:
            readbacks, self._readbacks = self._readbacks, None
        collection = self.monitor.stop_collecting()
        stopped = self._recorder(RecorderCommand("stop", request_id=uuid.uuid4().hex))
        on_hz, off_hz = self.monitor.thresholds_hz()
        previous = self.points_done[-1].state if self.points_done else "still"
        state = point_state(collection.rates_hz, on_hz, off_hz, previous)
        metrics = point_metrics(collection.batches, self.flag.length, self.flag.root, self.flag.direction_deg)
        if state != "flapping":  # a still flag has no amplitude or frequency worth a number
            metrics = type(metrics)(
                amplitude_over_l=metrics.amplitude_over_l,
                delta_rms_over_l=metrics.delta_rms_over_l,
                updates=metrics.updates,
                delta_rms_std_over_l=metrics.delta_rms_std_over_l,
                lost_fraction=metrics.lost_fraction,
            )
        readback = [v for v in readbacks if np.isfinite(v)]
        sensor_fields = self._check_sensor(point, base, collection, raw, state)
        lost = recording_problem(started, stopped)
        return PointResult.planned(
            point,
            status="lossy" if lost else "done",
            reason=lost,
            state=state,
            speed_readback_mps=float(np.mean(readback)) if readback else math.nan,
            amplitude_over_l=metrics.amplitude_over_l,
            amplitude_std_over_l=metrics.amplitude_std_over_l,
            frequency_hz=metrics.frequency_hz,
            twi=metrics.twi,
            delta_rms_over_l=metrics.delta_rms_over_l,
            event_rate_mev_s=float(np.mean(collection.rates_hz)) / 1e6 if collection.rates_hz else math.nan,
            raw_bytes=raw.stat().st_size if raw.exists() else int(stopped.bytes),
            raw_file=str(raw.relative_to(self.run_dir)),
            centreline_file=str(lines.relative_to(self.run_dir)) if lines.exists() else None,
            t_start_unix=t_start,
            t_stop_unix=time.time(),
            delta_rms_std_over_l=metrics.delta_rms_std_over_l,
            lost_fraction=metrics.lost_fraction,
            suspect=is_suspect(metrics.lost_fraction, self.cfg.suspect_lost_fraction),
            **sensor_fields,
        )

    def _check_sensor(self, point: Point, base: Path, collection: Any, raw: Path, state: str) -> dict[str, Any]:
        """The point-sensor fields of the point (empty without a sensor); never raises."""
        if self.sensor is None:
            return {}
        from flagtrack.daemon.services.supervisor.sensor_check import check_point
        from flagtrack.daemon.validation.point import FlagFrame

        frame = FlagFrame(self.flag.length, self.flag.root, self.flag.direction_deg)
        title = f"{point.point_id}: {point.speed_mps:.2f} m/s, {state}"
        return check_point(base, self.run_dir, collection, raw, frame, self.sensor, state, title)  # type: ignore[arg-type]

    # -- feedback --------------------------------------------------------------------------

    def _run_feedback(self) -> None:
        fb = self.cfg.feedback
        self._mode = "feedback"
        self._set_speed(fb.start_speed_mps)
        self._idle(fb.settle_s)
        state = ControllerState(0.0, fb.start_speed_mps)
        started = time.monotonic()
        self.feedback_trace: list[tuple[float, float, float]] = []
        self.monitor.start_collecting()
        while fb.duration_s == 0 or time.monotonic() - started < fb.duration_s:
            self._idle(fb.period_s)
            collection = self.monitor.stop_collecting()
            recent = _last_seconds(collection.batches, fb.window_s)
            self.monitor.start_collecting()
            self.monitor.collection.batches.extend(recent)  # type: ignore[union-attr]
            window = point_metrics(recent, self.flag.length, self.flag.root, self.flag.direction_deg)
            amplitude = measured_amplitude(window.amplitude_over_l, window.lost_fraction, fb)
            state = control_step(state, amplitude, fb.period_s, fb)
            self.feedback_trace.append((time.monotonic() - started, amplitude, state.speed_mps))
            log.info("feedback: A/L %.3f -> %.2f m/s", amplitude, state.speed_mps)
            if abs(state.speed_mps - self.tunnel.setpoint_mps) > 1e-9:
                self._set_speed(state.speed_mps)
        self.monitor.stop_collecting()
        self._mode = "done"


def _last_seconds(batches: list, window_s: float) -> list:
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


def _known(value: float) -> float:
    """``value``, or -1.0 when it is not a finite number (the state messages' "not known")."""
    return float(value) if math.isfinite(value) else -1.0


def _mapping(obj: Any) -> Any:
    from flagtrack.daemon.typed_yaml import to_mapping

    return to_mapping(obj)


def _summary(outcomes: list[ActionOutcome]) -> str:
    """How a point's actions went, for its record: ``pause ok; command failed: exit code 3 (...)``."""
    return "; ".join(o.summary() for o in outcomes)
