"""Mode ``control`` as a session's procedure: a control law, and speed requests from the bus, applied
to the tunnel inside the :class:`~flagtrack.daemon.sweep.session.Session` (the sweep's safety wrapper).

Each step, the law is called with the newest flag state (at most once per ``period_s``, as soon as a
state newer than the last one has come); what it asks is bounded by ``tunnel.safety`` and written as
the next set-point of the tunnel's ramp at once (no wait for the readback), and the step is recorded
with the latency from the camera packet behind the state to that write (the serial driver's flush
to the port when it says when, else the end of the exchange). The law runs in a thread of its own
(:class:`~flagtrack.daemon.services.supervisor.law_call.LawCall`): a law that raises, returns what is
not a speed, or does not return within ``law_timeout_s`` holds the speed (said once, in one line);
``max_faults`` in a row stop the run safe, and a law slower than ``period_s`` is said once.
Requests from the bus go through the same bounds and are answered. The session ends the run
with the tunnel ramped to zero, whatever ends it (the duration, a signal, a service gone, an error).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable
from typing import Any, Protocol

from flagtrack.daemon.schema import FlagState
from flagtrack.daemon.services.supervisor.control_record import ControlRecord
from flagtrack.daemon.services.supervisor.law_call import LawCall
from flagtrack.daemon.services.supervisor.laws import Law, bound_speed, checked_output
from flagtrack.daemon.services.supervisor.requests import Asked, SpeedDesk
from flagtrack.daemon.services.supervisor.section import ControlConfig
from flagtrack.daemon.sweep.session import RunStopped, Session
from flagtrack.daemon.transport import Subscription

log = logging.getLogger(__name__)

WATCH_S = 0.02
"""The loop looks at the rig (services, stop request, requests) at least this often, s."""


class Bounds(Protocol):
    """The tunnel's speed bounds (``tunnel.safety``)."""

    min_speed_mps: float
    max_speed_mps: float


class ControlLoop:
    """Runs a law and takes speed requests (see the module).

    Args:
        cfg: the ``control:`` section.
        law: the law, or None (requests only).
        states: the flag states' subscription.
        desk: the speed requests (None: not taken).
        record: the run folder.
        bounds: the tunnel's speed bounds.
        clock_ns: wall-clock nanoseconds (the camera stamps its packets with the same clock).
    """

    mode = "control"
    watch_services = False  # (watched from the loop on: services may take their time to come up)

    def __init__(
        self,
        cfg: ControlConfig,
        law: Law | None,
        states: Subscription,
        desk: SpeedDesk | None,
        record: ControlRecord,
        bounds: Bounds,
        clock_ns: Callable[[], int] = time.time_ns,
    ) -> None:
        self.cfg, self.law, self.states, self.desk, self.record, self.bounds = cfg, law, states, desk, record, bounds
        self.clock_ns = clock_ns
        self.target_mps = 0.0
        self.state: FlagState | None = None
        self.faults_in_a_row = 0
        self.fault_said = False
        self.slow_said = False
        self.bound_said = False
        self.safe_reason = ""  # why the run holds the safe speed with no law ("" while the law runs)
        self.calling: LawCall | None = None
        self._out_faults = 0  # the faults charged to the call still out
        self._used: FlagState | None = None
        self._t0_s = math.nan
        self._last_step_s = -math.inf
        self._last_write_s = -math.inf

    def prepare(self, session: Session) -> None:
        pass

    def run(self, session: Session) -> None:
        self.record.open(session.clock.time())
        if self.cfg.record:
            refused = session.start_recording(str(self.record.recording_base.resolve()))[1]
            if refused:  # (a read-only folder, a full disk): no experiment without its record
                raise RunStopped(refused)
        session.mode = "control"
        if self.cfg.start_speed_mps > 0:
            self.target_mps = bound_speed(
                self.cfg.start_speed_mps, self.bounds.min_speed_mps, self.bounds.max_speed_mps
            )[0]
            session.set_speed(self.target_mps)
            session.idle(self.cfg.settle_s)
        else:
            self.target_mps = max(0.0, session.tunnel.setpoint_mps)
        self._t0_s = session.clock.monotonic()
        if self.desk is not None:
            self.desk.taking = True
        if self.law is not None:
            self.calling = LawCall(self.law.function, self.cfg.law_timeout_s, check=checked_output)
        while self.cfg.duration_s == 0 or session.clock.monotonic() - self._t0_s < self.cfg.duration_s:
            session.idle(0)  # the rig watched: a stop request
            problem = session.outside.problem()
            if problem:  # a service gone, the camera silent
                raise RunStopped(problem)
            if self.cfg.record and (failed := session.outside.recorder_error()):  # the recording stopped
                raise RunStopped(f"recorder: {failed}")
            self._take_requests(session)
            self._law_turn(session)
            if session.clock.monotonic() - self._last_write_s >= self.cfg.period_s:
                self._ramp_on(session)
        if self.safe_reason:  # the run went to its end, but not under its law
            raise RunStopped(f"{self.safe_reason}; held the safe speed {self.cfg.safe_speed_mps:g} m/s to the end")
        session.mode = "done"

    def close(self, reason: str, error: str | None) -> None:
        if self.calling is not None:
            self.calling.close()
        if self.desk is not None:
            self.desk.taking = False
        if self.faults_in_a_row and self.fault_said:
            log.warning("supervisor: the law faulted %d times in a row at the end", self.faults_in_a_row)
        self.record.close(reason, error)

    # -- the law -------------------------------------------------------------------------------

    def _law_turn(self, session: Session) -> None:
        """The law's part of one turn of the loop: its call (or the one still out), or, with no law or
        after its faults, the newest state (recorded at the safe speed)."""
        if self.safe_reason:
            self._hold_safe(session)
        elif self.law is None:
            self._newest_state(WATCH_S)
        elif self.calling is not None and self.calling.busy:
            self._law_still_out(session)
        elif self._law_due(session):
            self._law_step(session)

    def _law_due(self, session: Session) -> bool:
        """Wait (at most ``WATCH_S``) for a state the law has not seen, once ``period_s`` has passed."""
        wait_s = self._last_step_s + self.cfg.period_s - session.clock.monotonic()
        if wait_s > 0:
            self._newest_state(min(wait_s, WATCH_S))
            return False
        self._newest_state(0.0 if self.state is not self._used else WATCH_S)
        return self.state is not None and self.state is not self._used

    def _newest_state(self, timeout_s: float) -> None:
        """Take the states that came (waiting up to ``timeout_s`` for one); keep the newest."""
        state = self.states.recv(timeout_s=timeout_s)
        while state is not None:
            self.state = state
            state = self.states.recv(timeout_s=0)

    def _law_step(self, session: Session) -> None:
        """Call the law with the newest state and apply what it asks."""
        assert self.law is not None and self.calling is not None and self.state is not None
        state, self._used = self.state, self.state
        self._last_step_s = session.clock.monotonic()
        answer = self.calling.call(state)
        self._out_faults = int(self.calling.busy)
        asked = answer.value if isinstance(answer.value, float) else None  # (checked_output's: a float or None)
        fault = answer.fault
        if not fault:
            self._say_if_slow(answer.took_s)
        record: dict[str, Any] = {"asked_mps": asked, "applied_mps": self.target_mps, "setpoint": self.law.setpoint()}
        if fault:
            self._fault(session, state, fault, record, answer.where)
            return
        self.faults_in_a_row = 0
        if asked is not None:
            applied, reason = bound_speed(asked, self.bounds.min_speed_mps, self.bounds.max_speed_mps)
            if reason and not self.bound_said:  # (once: 1e9 m/s each step is most likely a unit's mistake)
                log.warning("supervisor: the law %s %s: %g m/s applied (said once)", self.law.name, reason, applied)
                self.bound_said = True
            before_ns = self.clock_ns()
            written = self._command(session, applied)
            sent_ns = _sent_ns(session.tunnel, before_ns) or self.clock_ns()
            latency_ms = (sent_ns - state.source_ns) / 1e6 if state.source_ns > 0 else math.nan
            record.update(applied_mps=applied, setpoint_mps=written, latency_ms=latency_ms)
            if reason:
                record["reason"] = reason
        self._write(session, state, record)

    def _law_still_out(self, session: Session) -> None:
        """A call that did not return in time: each further ``law_timeout_s`` out is another fault;
        its late answer is dropped."""
        assert self.law is not None and self.calling is not None
        late = self.calling.late(WATCH_S)
        self._newest_state(0.0)
        if late is not None:
            log.warning(
                "supervisor: the law %s returned after %.3g s; that answer is dropped (its state is old)",
                self.law.name,
                late.took_s,
            )
            return
        out_s = self.calling.out_for_s()
        if out_s < (self._out_faults + 1) * self.cfg.law_timeout_s:
            return
        assert self._used is not None  # (the state of the call still out)
        self._out_faults += 1
        fault = f"has not returned for {out_s:.3g} s (supervisor.control.law_timeout_s {self.cfg.law_timeout_s:g})"
        record = {"asked_mps": None, "applied_mps": self.target_mps, "setpoint": self.law.setpoint()}
        self._fault(session, self._used, fault, record)

    def _hold_safe(self, session: Session) -> None:
        """After the law's faults: record the flag at the safe speed, at most once per ``period_s``."""
        self._newest_state(WATCH_S)
        if self.state is None or self.state is self._used:
            return
        if session.clock.monotonic() - self._last_step_s < self.cfg.period_s:
            return
        self._used, self._last_step_s = self.state, session.clock.monotonic()
        record = {"asked_mps": None, "applied_mps": self.target_mps, "reason": "safe speed after the law's faults"}
        self._write(session, self.state, record)

    def _say_if_slow(self, took_s: float) -> None:
        """Say once that the law takes longer than its period (it is then called as often as it returns)."""
        if took_s > self.cfg.period_s and not self.slow_said and self.law is not None:
            log.warning(
                "supervisor: the law %s took %.3g s, longer than supervisor.control.period_s %g s; "
                "it is called as often as it returns",
                self.law.name,
                took_s,
                self.cfg.period_s,
            )
            self.slow_said = True

    def _fault(self, session: Session, state: FlagState, fault: str, record: dict[str, Any], where: str = "") -> None:
        """Hold the speed; say the first fault in one line; stop safe after ``max_faults`` in a row."""
        assert self.law is not None
        self.faults_in_a_row += 1
        if where:
            record = {**record, "where": where}
        if not self.fault_said:
            log.error(
                "supervisor: the law %s %s%s; the speed is held at %g m/s (%d faults in a row stop the run)",
                self.law.name,
                fault,
                f" (at {where})" if where else "",
                self.target_mps,
                self.cfg.max_faults,
            )
            self.fault_said = True
        self._write(session, state, {**record, "reason": f"fault: {fault}; speed held"})
        if self.faults_in_a_row < self.cfg.max_faults:
            return
        why = f"the law {self.law.name} faulted {self.faults_in_a_row} times in a row (last: {fault})"
        if self.cfg.safe_speed_mps <= 0:
            raise RunStopped(f"{why}; stopped safe")
        log.error("supervisor: %s; holding the safe speed %g m/s until the run ends", why, self.cfg.safe_speed_mps)
        self.safe_reason = why
        self.target_mps = self.cfg.safe_speed_mps
        session.set_speed(self.target_mps)

    # -- requests ------------------------------------------------------------------------------

    def _take_requests(self, session: Session) -> None:
        """Apply and answer the speed requests that came (the newest of each identity)."""
        if self.desk is None:
            return
        for asked in self.desk.take(on_refused=lambda asked, why: self._refused(session, asked, why)):
            self._request(session, asked)

    def _request(self, session: Session, asked: Asked) -> None:
        speed, problem = checked_output(asked.request.speed_mps)
        if self.safe_reason:  # (the safe speed holds to the end, as after the law's faults)
            speed, problem = None, "the run holds its safe speed after the law's faults"
        if speed is None:
            problem = problem or "no speed"
            self.desk.answer(asked, False, -1.0, problem)  # type: ignore[union-attr]
            self._refused(session, asked, problem)
            return
        applied, reason = bound_speed(speed, self.bounds.min_speed_mps, self.bounds.max_speed_mps)
        written = self._command(session, applied)
        readback = self.state.speed_mps if self.state is not None else math.nan
        self.desk.answer(asked, True, applied, reason, written, readback)  # type: ignore[union-attr]
        record = {"requester": asked.who, "request_id": asked.request.request_id, "asked_mps": speed}
        self._write(session, self.state, {**record, "applied_mps": applied, "setpoint_mps": written, "reason": reason})

    def _refused(self, session: Session, asked: Asked, why: str) -> None:
        """Record a refused request (its speed when it was a number); the speed stays as it was."""
        fields = {
            "requester": asked.who,
            "request_id": asked.request.request_id,
            "asked_mps": checked_output(asked.request.speed_mps)[0],
            "applied_mps": self.target_mps,
            "reason": f"refused: {why}",
        }
        self._write(session, self.state, fields)

    # -- the record ----------------------------------------------------------------------------

    def _write(self, session: Session, state: FlagState | None, fields: dict[str, Any]) -> None:
        record = {
            "t_s": session.clock.monotonic() - self._t0_s,
            "requester": "law",
            "state": dataclasses.asdict(state) if state is not None else None,
            **fields,
        }
        if not record.get("reason"):
            record.pop("reason", None)
        self.record.write(record)

    # -- the tunnel ----------------------------------------------------------------------------

    def _command(self, session: Session, target_mps: float) -> float:
        """Make ``target_mps`` the target and write the ramp's next set-point toward it; return that."""
        self.target_mps = target_mps
        self._last_write_s = session.clock.monotonic()
        return float(session.tunnel.step_toward(target_mps))  # type: ignore[attr-defined]  # (a SafeTunnel's)

    def _ramp_on(self, session: Session) -> None:
        """Keep the ramp going to the target between steps (a law that holds, a request)."""
        if abs(session.tunnel.setpoint_mps - self.target_mps) > 1e-9:
            self._command(session, self.target_mps)


def _sent_ns(tunnel: Any, since_ns: int) -> int:
    """When the tunnel's serial driver last flushed a command to its port, if it says and that was
    after ``since_ns`` (0 otherwise: the caller takes the time the exchange ended, the reply read)."""
    sent_ns = getattr(getattr(getattr(tunnel, "link", None), "adapter", None), "last_sent_ns", 0)
    return sent_ns if isinstance(sent_ns, int) and sent_ns >= since_ns else 0
