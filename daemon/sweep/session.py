"""The safety wrapper every supervised run goes through: a procedure (a sweep, a feedback loop, or
just watching) decides what the tunnel does; the :class:`Session` applies it, watches the rig
while the procedure waits, and returns the tunnel to zero whatever happens.

Whatever ends the run (a stop request, an exception, a service going silent, a bad point, a serial
error), :meth:`Session.run`'s ``finally`` stops the recorder, ramps the tunnel to zero, publishes
the safe state, closes the tunnel and only then lets the procedure close its records (the stop
record names the reason). A supervisor killed outright is covered by the tunnel's own watchdog.
"""

from __future__ import annotations

import logging
import math
import threading
import uuid
from dataclasses import dataclass
from typing import Protocol

from flagtrack.daemon.errors import DriverError, FlagtrackError
from flagtrack.daemon.schema import RecorderCommand, RecorderStatus
from flagtrack.daemon.sweep.plan import Point
from flagtrack.daemon.sweep.ports import Clock, Outside, Report, SystemClock, Tunnel
from flagtrack.daemon.sweep.progress import SweepProgress
from flagtrack.daemon.sweep.validity import PointWatch

log = logging.getLogger(__name__)


class RunStopped(FlagtrackError):
    """The run was stopped (signal) or cannot go on (a required service is gone)."""


@dataclass(frozen=True)
class Limits:
    """How long a session waits, and how often it reports (the ``supervisor:`` section's keys)."""

    silence_timeout_s: float = 3.0
    startup_timeout_s: float = 20.0
    publish_interval_s: float = 0.2
    recorder_timeout_s: float = 10.0


class Procedure(Protocol):
    """What a session runs: a sweep, a feedback loop, watching.

    Attributes:
        mode: the mode published while the services are awaited.
        watch_services: stop the run when a required service goes (or the camera falls silent) at
            any time; otherwise only while a point is under way.
    """

    mode: str
    watch_services: bool

    def prepare(self, session: Session) -> None:
        """Before the services are awaited (raise RunStopped to hold the tunnel at zero)."""
        ...

    def run(self, session: Session) -> None:
        """The work (set speeds, wait, record) once the services are there."""
        ...

    def close(self, reason: str, error: str | None) -> None:
        """After the tunnel is at zero: write the records that say how the run ended."""
        ...


class Monitoring:
    """Watch and publish until stopped (mode ``monitor``)."""

    mode = "monitor"
    watch_services = False

    def prepare(self, session: Session) -> None:
        pass

    def run(self, session: Session) -> None:
        while True:
            session.idle(0.05)  # raises RunStopped on the stop request

    def close(self, reason: str, error: str | None) -> None:
        pass


class Session:
    """Applies speeds to the tunnel, waits watching the rig, and ends safe.

    Attributes:
        mode, branch, progress: what the state messages say (set by the procedure).
        point: the point under way, None between points.
        stop_reason: why the run ended ("" while it runs).
    """

    def __init__(self, tunnel: Tunnel, outside: Outside, limits: Limits, clock: Clock | None = None) -> None:
        self.tunnel, self.outside, self.limits = tunnel, outside, limits
        self.clock: Clock = clock or SystemClock()
        self.mode, self.branch = "monitor", ""
        self.progress: SweepProgress | None = None
        self.point: PointWatch | None = None
        self.stop_reason = ""
        self._stop = threading.Event()
        self._watch_services = False
        self._last_publish_s = -math.inf

    def run(self, procedure: Procedure, stop: threading.Event) -> None:
        """Run ``procedure`` until it ends or ``stop`` is set (a ``reason`` attribute says why); the
        tunnel ends at zero. Errors other than RunStopped and DriverError go on after the safe state."""
        self._stop, self.mode, self._watch_services = stop, procedure.mode, procedure.watch_services
        threading.Thread(target=self._abort_on_stop, name="supervisor-abort", daemon=True).start()
        reason, error = "finished", None
        try:
            self.tunnel.start()
            procedure.prepare(self)
            self._wait_for_services()
            procedure.run(self)
        except RunStopped as exc:
            reason = str(exc)
            log.warning("supervisor: %s", reason)
        except DriverError as exc:
            if stop.is_set():  # a ramp interrupted by the stop request: the request is the reason
                reason = self._requested_reason()
            else:
                reason, error = "error", f"{type(exc).__name__}: {exc}"
                log.error("supervisor: %s", error)
        except BaseException as exc:
            reason, error = "error", f"{type(exc).__name__}: {exc}"
            log.error("supervisor: %s", error)
            raise
        finally:
            self.stop_reason = reason
            self._safe_state(procedure, reason, error)

    def idle(self, duration_s: float) -> None:
        """Wait ``duration_s`` watching the rig; raise RunStopped on a stop request or a silent
        service, BadPoint when the point under way is spoilt."""
        deadline_s = self.clock.monotonic() + duration_s
        while True:
            self._heartbeat()
            self.outside.beat(self.mode)
            self.outside.pump()
            self.publish()
            self._check_stop()
            if self.point is not None or self._watch_services:
                problem = self.outside.problem()
                if problem:
                    raise RunStopped(problem)
            if self.point is not None:
                self.point.check(self.outside.recorder_error())
            remaining_s = deadline_s - self.clock.monotonic()
            if remaining_s <= 0:
                return
            self.clock.wait(self._stop, min(0.02, remaining_s))

    def begin_point(self, point: Point) -> PointWatch:
        """``point`` is under way (an attempt at it begins); return its watch."""
        self.point, self.branch = PointWatch(point), point.branch.value
        return self.point

    def end_point(self) -> None:
        """No point is under way (the attempt is recorded)."""
        self.point = None

    def set_speed(self, speed_mps: float) -> None:
        """Ramp the tunnel to ``speed_mps`` (verified); RunStopped when a stop came meanwhile."""
        self.outside.pump()
        self.publish(force=True)
        self.tunnel.set_speed_mps(speed_mps)
        self.outside.pump()
        self._check_stop()

    def ask_recorder(self, command: RecorderCommand) -> RecorderStatus:
        """Send ``command`` to the recorder and wait (watching) for its answer."""
        self.outside.send(command)
        deadline_s = self.clock.monotonic() + self.limits.recorder_timeout_s
        while (reply := self.outside.reply(command.request_id)) is None:
            if self.clock.monotonic() > deadline_s:
                raise RunStopped(
                    f"the recorder did not acknowledge '{command.action}' within {self.limits.recorder_timeout_s:g} s"
                )
            self.idle(0.02)
        return reply

    def start_recording(self, base: str) -> tuple[RecorderStatus, str]:
        """Ask the recorder to record the camera and the centrelines to ``base``; its answer, and why
        nothing is recorded ("" when it started)."""
        started = self.ask_recorder(RecorderCommand("start", path=base, centrelines=True, request_id=uuid.uuid4().hex))
        refused = f"recorder: {started.message or 'the recording did not start'}" if started.state == "error" else ""
        return started, refused

    def publish(self, force: bool = False) -> None:
        """Publish the run's and the tunnel's state (at most every ``publish_interval_s`` unless ``force``)."""
        now_s = self.clock.monotonic()
        if not force and now_s - self._last_publish_s < self.limits.publish_interval_s:
            return
        self._last_publish_s = now_s
        point_id = "" if self.point is None else self.point.point.point_id
        report = Report(
            self.mode, point_id, self.branch, self.tunnel.setpoint_mps, self.stop_reason, self.progress, now_s
        )
        status = self.tunnel.status()
        if self.point is not None:
            self.point.see(status, now_s)
        self.outside.publish(report, status)

    def _wait_for_services(self) -> None:
        """Wait for the required services and for the still-flag baseline of the onset detector."""
        deadline_s = self.clock.monotonic() + self.limits.startup_timeout_s
        while (waiting := self.outside.waiting_for()) is not None:
            if self.clock.monotonic() > deadline_s:
                raise RunStopped(f"{waiting} within {self.limits.startup_timeout_s:g} s")
            self.idle(0.05)
        self.outside.watch_from_now()

    def _safe_state(self, procedure: Procedure, reason: str, error: str | None) -> None:
        self.mode, self.point = "safe", None
        try:
            self.outside.send(RecorderCommand("stop", request_id=uuid.uuid4().hex))
        except FlagtrackError as exc:
            log.error("supervisor: could not stop the recorder: %s", exc)
        try:
            self.tunnel.safe_stop()
        except DriverError as exc:
            log.error("supervisor: %s", exc)
            error = error or str(exc)
        finally:
            self.publish(force=True)
            self.tunnel.close()
            procedure.close(reason, error)
            log.info("supervisor: tunnel at zero (%s)", reason)

    def _check_stop(self) -> None:
        if self._stop.is_set():
            raise RunStopped(self._requested_reason())

    def _requested_reason(self) -> str:
        """Why the stop was requested (a signal, another service failing), as the stop record says it."""
        return getattr(self._stop, "reason", "") or "stopped"

    def _abort_on_stop(self) -> None:
        """A stop request interrupts a ramp in progress (the finally then ramps to zero)."""
        self._stop.wait()
        self.tunnel.abort()

    def _heartbeat(self) -> None:
        """Tell the tunnel this loop is alive: its keep-alive stops when the loop hangs."""
        beat = getattr(self.tunnel, "heartbeat", None)
        if beat is not None:
            beat()
