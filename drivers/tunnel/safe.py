"""The safety layer every wind tunnel goes through: bounds, ramps, readback checks, keep-alive.

:class:`SafeTunnel` wraps any :class:`~flagtrack.drivers.tunnel.base.TunnelLink` (the bytes) and
implements :class:`~flagtrack.drivers.tunnel.base.WindTunnel`:

- every target is checked against ``[min_speed_mps, max_speed_mps]`` (0 is always allowed);
- the set-point moves at most ``max_ramp_mps2`` (a new set-point every ``ramp_period_s``, which
  also keeps the link alive while ramping);
- after a set, the readback must reach the target within ``tolerance_mps`` and
  ``settle_timeout_s``, or the step fails;
- a keep-alive thread talks to the controller whenever the link has been idle for
  ``keepalive_s`` (which must be below half the controller's ``watchdog_s``); once the owner calls
  :meth:`SafeTunnel.heartbeat` from its loop, the keep-alive stops when that loop has been silent
  for ``loop_timeout_s``, so a hung owner lets the controller's own watchdog stop the fan;
- on start it reads the current speed and ramps from there, never from an assumed zero;
- any failure of a set (no reply, error reply, readback mismatch, abort) ramps the tunnel to zero
  where it still answers and raises one :class:`DriverError` naming the device.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from types import TracebackType
from typing import Any, TypeVar

from flagtrack.daemon.errors import DriverError
from flagtrack.drivers.tunnel.base import TunnelLink, TunnelStatus

log = logging.getLogger(__name__)
T = TypeVar("T")


@dataclass(frozen=True)
class SafetyParams:
    """Limits of one tunnel (config section ``tunnel.safety``).

    Attributes:
        min_speed_mps: smallest non-zero target accepted, m/s (the ramp passes below it).
        max_speed_mps: largest target accepted, m/s.
        max_ramp_mps2: fastest set-point change, m/s per second.
        ramp_period_s: interval between set-points while ramping, s.
        tolerance_mps: readback within this of the target counts as reached, m/s.
        settle_timeout_s: time after the ramp for the readback to reach the target, s.
        poll_period_s: interval between readbacks while waiting, s.
        keepalive_s: idle time after which a keep-alive exchange is sent, s.
        watchdog_s: the controller's communication watchdog, s (``keepalive_s`` must be below half).
        loop_timeout_s: an owner that calls :meth:`SafeTunnel.heartbeat` and then stays silent this
            long is taken as hung: no keep-alive is sent for it any more, s.
    """

    min_speed_mps: float = 0.0
    max_speed_mps: float = 15.0
    max_ramp_mps2: float = 0.5
    ramp_period_s: float = 0.2
    tolerance_mps: float = 0.2
    settle_timeout_s: float = 30.0
    poll_period_s: float = 0.2
    keepalive_s: float = 1.0
    watchdog_s: float = 5.0
    loop_timeout_s: float = 10.0

    def __post_init__(self) -> None:
        for name, value in dataclasses.asdict(self).items():  # a limit of inf or nan is no limit
            if not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value}")
        if not 0.0 <= self.min_speed_mps <= self.max_speed_mps or self.max_speed_mps <= 0:
            raise ValueError("need 0 <= min_speed_mps <= max_speed_mps and max_speed_mps > 0")
        names = (
            "max_ramp_mps2",
            "ramp_period_s",
            "tolerance_mps",
            "settle_timeout_s",
            "poll_period_s",
            "loop_timeout_s",
        )
        for name in names:
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive")
        if not 0 < self.keepalive_s <= self.watchdog_s / 2:
            raise ValueError(
                f"keepalive_s ({self.keepalive_s}) must be positive and at most half of the "
                f"controller's watchdog_s ({self.watchdog_s})"
            )

    def check_setpoint(self, speed_mps: float, device: str) -> None:
        """Raise DriverError (naming ``device``) if ``speed_mps`` is outside the bounds (0 is always allowed)."""
        if speed_mps == 0.0:
            return
        if not math.isfinite(speed_mps) or not self.min_speed_mps <= speed_mps <= self.max_speed_mps:
            raise DriverError(
                f"set-point {speed_mps:g} m/s outside the bounds [{self.min_speed_mps:g}, "
                f"{self.max_speed_mps:g}] m/s (tunnel.safety); nothing sent",
                device=device,
            )


class TunnelAborted(DriverError):
    """A set was interrupted by :meth:`SafeTunnel.abort` (SIGTERM); the tunnel was sent to zero."""


class SafeTunnel:
    """A :class:`WindTunnel` made of a protocol link and the safety rules of :class:`SafetyParams`.

    A context manager: entering starts it (reads the speed, starts the keep-alive), leaving ramps it
    to zero and closes the port, whatever happened inside. One driving thread (the keep-alive's is its own).

    Attributes:
        simulator: the in-process simulated tunnel when the config asked for one (so a simulated
            camera can read its speed), else ``None``.
    """

    def __init__(self, link: TunnelLink, params: SafetyParams = SafetyParams()) -> None:
        self.link = link
        self.params = params
        self.simulator: Any = None
        self._on_close: list[Callable[[], None]] = []
        self._lock = threading.Lock()
        self._abort = threading.Event()
        self._closing = threading.Event()
        self._thread: threading.Thread | None = None
        self._setpoint_mps: float | None = None
        self._last_exchange_s = time.monotonic()
        self._link_ok = True
        self._answered_s = time.monotonic()  # the last exchange that succeeded
        self._link_error = ""  # the last exchange's error while the link is down
        self._keepalive_failures = 0
        self._heartbeat_s: float | None = None  # the owner's loop, once it reports (None: not watched)
        self._withheld = False
        self._owner_was_silent = False  # once the keep-alive was withheld, the owner's set-points are refused
        self._last_step_s: float | None = None  # when step_toward last wrote a set-point

    @property
    def device(self) -> str:
        """Port or name of the controller."""
        return self.link.device

    @property
    def setpoint_mps(self) -> float:
        """Last set-point sent (``nan`` before start)."""
        return math.nan if self._setpoint_mps is None else self._setpoint_mps

    def add_closer(self, closer: Callable[[], None]) -> None:
        """Call ``closer`` when the tunnel is closed (after the port), e.g. to stop a simulator."""
        self._on_close.append(closer)

    def start(self) -> float:
        """Read the current speed (the ramp start), start the keep-alive; return the speed, m/s."""
        if self._setpoint_mps is not None:
            return self.read_speed_mps()
        speed = self._exchange(self.link.read_speed_mps)
        self._setpoint_mps = max(0.0, speed)
        fault = self._exchange(self.link.read_fault)
        if fault:
            log.warning("%s: controller reports a fault at start: %s", self.device, fault)
        self._thread = threading.Thread(target=self._keepalive_loop, name=f"keepalive {self.device}", daemon=True)
        self._thread.start()
        log.info("%s: started at %.2f m/s", self.device, speed)
        return speed

    def set_speed_mps(self, speed_mps: float) -> None:
        """Ramp to ``speed_mps`` and wait until the readback is within tolerance.

        Raises:
            DriverError: target out of bounds (nothing is sent), or the controller failed, or the
                readback did not reach the target in time, or :meth:`abort` was called; in the last
                three cases the tunnel has been ramped to zero (where it still answers).
        """
        self.check_setpoint(speed_mps)
        self._refuse_after_silence()
        if self._setpoint_mps is None:
            self.start()
        try:
            self._ramp_to(speed_mps, abortable=True)
            self._wait_for(speed_mps, abortable=True)
        except DriverError as exc:
            raise self._stop_after(exc) from exc

    def step_toward(self, target_mps: float) -> float:
        """Write one set-point on the ramp to ``target_mps`` and return it (m/s), without waiting for
        the readback: for a loop that commands every period. The set-point moves at most
        ``max_ramp_mps2`` times the time since the last step (at most ``ramp_period_s``).

        Raises:
            DriverError: target out of bounds (nothing sent), the controller failed, or :meth:`abort`
                was called (in the last two cases the tunnel has been ramped to zero where it answers).
        """
        self.check_setpoint(target_mps)
        self._refuse_after_silence()
        if self._setpoint_mps is None:
            self.start()
        now_s = time.monotonic()
        last_s = self._last_step_s
        dt_s = self.params.ramp_period_s if last_s is None else min(self.params.ramp_period_s, now_s - last_s)
        self._last_step_s = now_s
        largest = self.params.max_ramp_mps2 * dt_s
        value = self.setpoint_mps + max(-largest, min(largest, target_mps - self.setpoint_mps))
        try:
            if self._abort.is_set():
                raise TunnelAborted("set-point change aborted", device=self.device)
            self._exchange(lambda: self.link.write_setpoint_mps(value))
        except DriverError as exc:
            raise self._stop_after(exc) from exc
        self._setpoint_mps = value
        self._beat_if_watched()
        return value

    def _refuse_after_silence(self) -> None:
        """A set-point from an owner whose loop went silent long enough for the keep-alive to be
        withheld is refused (the tunnel ramped to zero): the controller's watchdog stopped the fan,
        and an owner that comes back must not quietly bring it up again (its run stops, said)."""
        if self._owner_was_silent:
            silent = DriverError(
                f"the owner's loop was silent for over {self.params.loop_timeout_s:g} s: the keep-alive was "
                "withheld and the controller's watchdog stopped the fan; no set-point is taken after that",
                device=self.device,
            )
            raise self._stop_after(silent)

    def read_speed_mps(self) -> float:
        """Speed read back from the controller, m/s."""
        return self._exchange(self.link.read_speed_mps)

    def safe_stop(self) -> None:
        """Ramp the set-point to zero, stop the fan, wait (up to ``settle_timeout_s``) for zero.

        Raises:
            DriverError: the stop command could not be delivered (the controller's own watchdog
                is then what stops the fan).
        """
        if self._setpoint_mps is None:
            try:
                self.start()
            except DriverError as exc:
                log.warning("%s: cannot read the speed before stopping: %s", self.device, _text(exc))
                self._setpoint_mps = 0.0
        try:
            self._ramp_to(0.0, abortable=False)
        except DriverError as exc:
            log.warning("%s: ramp to zero failed (%s); sending stop directly", self.device, _text(exc))
        try:
            self._exchange(self.link.stop)
        except DriverError as exc:
            raise DriverError(
                f"could not command the tunnel to zero ({_text(exc)}); its watchdog "
                f"({self.params.watchdog_s:g} s) must stop it",
                device=self.device,
            ) from exc
        self._setpoint_mps = 0.0
        try:
            self._wait_for(0.0, abortable=False)
        except DriverError as exc:
            log.warning("%s: stop sent but %s", self.device, _text(exc))

    def status(self) -> TunnelStatus:
        """Read speed and fault from the controller; link errors are reported, not raised."""
        try:
            speed = self.read_speed_mps()
            fault = self._exchange(self.link.read_fault)
        except DriverError as exc:
            speed, fault = math.nan, _text(exc)
        return TunnelStatus(self.device, self.setpoint_mps, speed, fault, self._link_ok, self._keepalive_failures)

    def heartbeat(self) -> None:
        """The owner's loop is alive (call it from that loop); from the first call on, the keep-alive
        is sent only while such calls keep coming (within ``loop_timeout_s``)."""
        self._heartbeat_s = time.monotonic()

    def unanswered(self) -> tuple[float, str]:
        """How long the controller has not answered (0 while the last exchange succeeded), s, and
        the last exchange's error ("" then)."""
        if self._link_ok:
            return 0.0, ""
        return time.monotonic() - self._answered_s, self._link_error

    @property
    def owner_silent(self) -> bool:
        """The owner reported a heartbeat once and then none for ``loop_timeout_s``."""
        beat = self._heartbeat_s
        return beat is not None and time.monotonic() - beat > self.params.loop_timeout_s

    def abort(self) -> None:
        """Make the running (and any later) :meth:`set_speed_mps` stop and raise TunnelAborted.

        Safe to call from a signal handler or another thread; :meth:`safe_stop` is not affected.
        """
        self._abort.set()

    def close(self) -> None:
        """Stop the keep-alive and close the port; does not command anything (idempotent)."""
        self._closing.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        try:
            with self._lock:
                self.link.close()
        finally:
            while self._on_close:
                self._on_close.pop()()

    def __enter__(self) -> SafeTunnel:
        self.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        try:
            self.safe_stop()
        except DriverError as stop_exc:
            log.error("%s", stop_exc)
            if exc is None:
                raise
        finally:
            self.close()

    def check_setpoint(self, speed_mps: float) -> None:
        """Raise DriverError if ``speed_mps`` is outside the bounds (:meth:`SafetyParams.check_setpoint`)."""
        self.params.check_setpoint(speed_mps, self.device)

    # -- internals -------------------------------------------------------------------------

    def _exchange(self, call: Callable[[], T]) -> T:
        """Run one link exchange under the lock; record success; wrap stray errors."""
        with self._lock:
            try:
                result = call()
            except DriverError as exc:
                self._link_ok, self._link_error = False, _text(exc)
                raise
            except (OSError, ValueError) as exc:
                self._link_ok, self._link_error = False, f"link error: {exc}"
                raise DriverError(f"link error: {exc}", device=self.device) from exc
            self._link_ok = True
            self._last_exchange_s = self._answered_s = time.monotonic()
            return result

    def _ramp_to(self, target_mps: float, *, abortable: bool) -> None:
        """Move the set-point from the current one to ``target_mps`` at ``max_ramp_mps2``."""
        start_mps = self.setpoint_mps
        rate = self.params.max_ramp_mps2
        duration_s = abs(target_mps - start_mps) / rate
        direction = math.copysign(1.0, target_mps - start_mps)
        t0 = time.monotonic()
        while True:
            if abortable and self._abort.is_set():
                raise TunnelAborted("set-point change aborted", device=self.device)
            elapsed = time.monotonic() - t0
            value = target_mps if elapsed >= duration_s else start_mps + direction * rate * elapsed
            self._exchange(partial(self.link.write_setpoint_mps, value))
            self._setpoint_mps = value
            self._beat_if_watched()
            if value == target_mps:
                return
            self._sleep(min(self.params.ramp_period_s, duration_s - elapsed), abortable)

    def _wait_for(self, target_mps: float, *, abortable: bool) -> None:
        """Poll the readback until it is within tolerance of ``target_mps`` or time runs out."""
        p = self.params
        deadline = time.monotonic() + p.settle_timeout_s
        while True:
            if abortable and self._abort.is_set():
                raise TunnelAborted("wait for the set-point aborted", device=self.device)
            speed = self.read_speed_mps()
            self._beat_if_watched()
            if abs(speed - target_mps) <= p.tolerance_mps:
                return
            if time.monotonic() >= deadline:
                fault = self._exchange(self.link.read_fault)
                raise DriverError(
                    f"readback {speed:.2f} m/s did not reach the set-point {target_mps:.2f} ± "
                    f"{p.tolerance_mps:g} m/s within {p.settle_timeout_s:g} s"
                    + (f" (controller fault: {fault})" if fault else ""),
                    device=self.device,
                )
            self._sleep(p.poll_period_s, abortable)

    def _beat_if_watched(self) -> None:
        """A ramp or a wait in progress is the owner's loop at work (when the owner is watched)."""
        if self._heartbeat_s is not None:
            self._heartbeat_s = time.monotonic()

    def _sleep(self, duration_s: float, abortable: bool) -> None:
        if abortable:
            self._abort.wait(max(0.0, duration_s))
        else:
            time.sleep(max(0.0, duration_s))

    def _stop_after(self, exc: DriverError) -> DriverError:
        """Ramp to zero after a failed set; return the error to raise (it says how the stop went)."""
        log.error("%s; ramping the tunnel to zero", exc)
        try:
            self.safe_stop()
        except DriverError as stop_exc:
            outcome = f"commanding zero failed too: {_text(stop_exc)}"
        else:
            outcome = "tunnel commanded to zero"
        kind = TunnelAborted if isinstance(exc, TunnelAborted) else DriverError
        return kind(f"{_text(exc)}; {outcome}", device=self.device)

    def _keepalive_loop(self) -> None:
        period_s = self.params.keepalive_s
        while not self._closing.wait(period_s / 4):
            if time.monotonic() - self._last_exchange_s < period_s:
                continue
            if self.owner_silent:
                if not self._withheld:
                    log.error(
                        "%s: the owner's loop has been silent for over %g s; keep-alive withheld, the "
                        "controller's watchdog (%g s) stops the fan",
                        self.device,
                        self.params.loop_timeout_s,
                        self.params.watchdog_s,
                    )
                self._withheld = self._owner_was_silent = True
                continue
            self._withheld = False
            try:
                self._exchange(self.link.keep_alive)
            except DriverError as exc:
                self._keepalive_failures += 1
                if self._keepalive_failures in (1, 10, 100) or self._keepalive_failures % 1000 == 0:
                    count = self._keepalive_failures
                    log.warning("%s: keep-alive failed (%d so far): %s", self.device, count, _text(exc))
                self._last_exchange_s = time.monotonic()


def _text(exc: DriverError) -> str:
    """The message of a DriverError without its ``device:`` prefix."""
    text = str(exc)
    prefix = f"{exc.device}: " if exc.device else ""
    return text[len(prefix) :] if prefix and text.startswith(prefix) else text
