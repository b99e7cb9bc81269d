"""The simulated camera of the digital twin: a flag whose flutter follows the wind speed, as events.

The flag's motion comes from :class:`~flagtrack.drivers.sim.flutter.FlutterModel` (still below
onset, flapping above, with hysteresis) driven by a speed source (the simulated tunnel's readback
when the rig has one, else a fixed speed). Events are drawn where the laser line sweeps across
pixels (:mod:`flagtrack.drivers.sim.quickline`: ON on the leading edge, OFF on the trailing one)
plus uniform background activity, in real time (or at ``time_scale`` times real time).

Sync generator: with ``trigger_period_ms`` > 0 the camera's trigger input sees a pulse every period
(rising edge at ``k * period``, falling ``trigger_pulse_us`` later, camera time), as if a sync
generator (or a point sensor) drove it. The twin's true flag over the last seconds is kept in
:attr:`SimulatedCamera.truth` (:class:`TwinTruth`) for a simulated point sensor.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from flagtrack.daemon.core.events import MAX_SENSOR_PX, TRIGGER_DTYPE, empty_triggers
from flagtrack.daemon.errors import DriverError
from flagtrack.drivers.camera.base import CameraData, CameraInfo, DeviceDrop
from flagtrack.drivers.sim.flutter import FlutterModel, FlutterParams, FlutterState
from flagtrack.drivers.sim.kinematics import FlagKinematics, with_peak_to_peak
from flagtrack.drivers.sim.quickline import QuickLineParams, line_events

log = logging.getLogger(__name__)

_REFERENCE_AMP_OVER_L = 0.3  # the base kinematics is solved for this A/L; others scale its angle wave
SKIP_REASON = "simulated camera: cannot keep up with real time; skipped ahead (events dropped)"
"""What a skip ahead is reported as (a :class:`DeviceDrop` of the skipped camera time, µs)."""


@dataclass(frozen=True)
class SimulatedCameraConfig:
    """The simulated rig seen by the camera (pixels).

    Attributes:
        width, height: sensor size.
        length_px, root_px, direction_deg: the flag on the sensor.
        wavelength_over_l, w_travel: shape of the flapping wave.
        flutter: flutter curve (onset/decay speeds, amplitude, frequency).
        speed_mps: wind speed when no speed source is connected, and in a rig with a tunnel until
            the tunnel's speed is known (no supervisor has published it yet).
        still_amp_over_l: residual motion of a still flag (a few events from it).
        events_per_px2: events per pixel area swept by the line (sets the event rate).
        line_width_px: spread of events across the line.
        noise_rate_hz: background events per second over the whole sensor.
        slice_us: camera time generated per read (events are released at its end). Each read costs
            a few dozen hand-overs of the GIL; in a process shared with the rest of the rig, slices
            of 4 ms fell behind real time where 16 ms keep up.
        time_scale: camera seconds per wall second (1 = real time).
        max_lag_s: when the machine cannot generate events in real time and falls this far behind,
            the twin skips ahead (the flag moves on, no events for the skipped time), as a real
            camera's event-rate controller drops events, so the flag stays in step with the tunnel.
            Each skip is reported with the next data (``CameraData.drops``), so a recording made
            meanwhile is marked lossy.
        trigger_period_ms: sync generator period on the camera's trigger input (0: no pulses).
        trigger_pulse_us: width of each pulse.
        trigger_channel: trigger input channel of the pulses.
        truth_keep_s: camera time of true flag positions kept for a simulated point sensor.
        seed: random seed of the twin.
    """

    width: int = 640
    height: int = 480
    length_px: float = 300.0
    root_px: tuple[float, float] = (150.0, 240.0)
    direction_deg: float = 0.0
    wavelength_over_l: float = 2.0
    w_travel: float = 0.7
    flutter: FlutterParams = field(default_factory=FlutterParams)
    speed_mps: float = 0.0
    still_amp_over_l: float = 0.002
    events_per_px2: float = 2.0
    line_width_px: float = 0.8
    noise_rate_hz: float = 20_000.0
    slice_us: int = 16_000
    time_scale: float = 1.0
    max_lag_s: float = 0.25
    trigger_period_ms: float = 0.0
    trigger_pulse_us: int = 100
    trigger_channel: int = 0
    truth_keep_s: float = 5.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not (16 <= self.width <= MAX_SENSOR_PX and 16 <= self.height <= MAX_SENSOR_PX):
            raise ValueError(f"width and height must be 16 to {MAX_SENSOR_PX} pixels, got {self.width} x {self.height}")
        if self.speed_mps < 0:
            raise ValueError(f"speed_mps must be 0 or more, got {self.speed_mps}")
        if self.slice_us < 50 or self.time_scale <= 0:
            raise ValueError("slice_us must be >= 50 and time_scale > 0")
        if self.trigger_period_ms < 0 or (
            self.trigger_period_ms > 0 and not 0 < self.trigger_pulse_us < self.trigger_period_ms * 1000
        ):
            raise ValueError("trigger_period_ms must be >= 0 and trigger_pulse_us within (0, period)")


@dataclass(frozen=True)
class _TwinSlice:
    """The flag between two flutter states: phase and amplitude linear in time (LineKinematics)."""

    kinematics: FlagKinematics
    t0_s: float
    t1_s: float
    start: FlutterState
    end: FlutterState
    still_amp_over_l: float

    @property
    def length(self) -> float:
        return self.kinematics.length

    def positions(self, t_s: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        frac = np.clip((np.asarray(t_s, dtype=np.float64) - self.t0_s) / max(self.t1_s - self.t0_s, 1e-12), 0, 1)
        phase = self.start.phase_rad + frac * (self.end.phase_rad - self.start.phase_rad)
        amp = max(0.5 * (self.start.amp_over_l + self.end.amp_over_l), self.still_amp_over_l)  # slow: one per slice
        return self.kinematics.positions_at_phase(phase, s, amp_scale=amp / _REFERENCE_AMP_OVER_L, n_fine=64)


class TwinTruth:
    """The twin's true flag over the last ``keep_s`` of camera time (thread-safe: the camera adds,
    a simulated sensor reads from another thread)."""

    def __init__(self, keep_s: float = 5.0) -> None:
        self.keep_us = int(keep_s * 1e6)
        self._slices: collections.deque[_TwinSlice] = collections.deque()
        self._lock = threading.Lock()
        self._horizon_us = 0

    @property
    def horizon_us(self) -> int:
        """Camera time up to which the flag's motion is known (the camera has generated it), µs."""
        with self._lock:
            return self._horizon_us

    def add(self, twin: _TwinSlice) -> None:
        """Append the next slice of the flag's motion (camera time order)."""
        with self._lock:
            self._slices.append(twin)
            self._horizon_us = round(twin.t1_s * 1e6)
            while self._slices and (self._horizon_us - self._slices[0].t1_s * 1e6) > self.keep_us:
                self._slices.popleft()

    def positions(self, t_us: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """True x, y (len(t_us), len(s)) in pixels at camera times ``t_us``; NaN where not kept."""
        t_s = np.asarray(t_us, dtype=np.float64) * 1e-6
        x = np.full((len(t_s), len(s)), np.nan)
        y = np.full((len(t_s), len(s)), np.nan)
        with self._lock:
            slices = list(self._slices)
        if not slices:
            return x, y
        starts = np.array([sl.t0_s for sl in slices])
        k = np.searchsorted(starts, t_s, side="right") - 1
        inside = (k >= 0) & (t_s <= slices[-1].t1_s)
        for index in np.unique(k[inside]):
            rows = np.flatnonzero(inside & (k == index))
            x[rows], y[rows] = slices[index].positions(t_s[rows], s)
        return x, y


def trigger_edges(cfg: SimulatedCameraConfig, t0_us: int, t1_us: int) -> np.ndarray:
    """Sync-generator edges in camera time ``[t0_us, t1_us)`` (TRIGGER_DTYPE, time order)."""
    if cfg.trigger_period_ms <= 0 or t1_us <= t0_us:
        return empty_triggers()
    period_us = round(cfg.trigger_period_ms * 1000)
    first = -(-(t0_us - cfg.trigger_pulse_us) // period_us)
    starts = np.arange(first, (t1_us - 1) // period_us + 1, dtype=np.int64) * period_us
    times = np.concatenate([starts, starts + cfg.trigger_pulse_us])
    edges = np.concatenate([np.ones(len(starts), np.uint8), np.zeros(len(starts), np.uint8)])
    keep = (times >= t0_us) & (times < t1_us)
    order = np.argsort(times[keep], kind="stable")
    out = np.empty(int(keep.sum()), dtype=TRIGGER_DTYPE)
    out["t"], out["edge"], out["channel"] = times[keep][order], edges[keep][order], cfg.trigger_channel
    return out


class SimulatedCamera:
    """A :class:`~flagtrack.drivers.camera.base.Camera` of the digital twin.

    Args:
        cfg: the simulated rig.
        speed_source: returns the current wind speed (m/s); default: ``cfg.speed_mps``.
    """

    def __init__(self, cfg: SimulatedCameraConfig, speed_source: Callable[[], float] | None = None) -> None:
        self.cfg = cfg
        self.speed_source = speed_source or (lambda: cfg.speed_mps)
        base = FlagKinematics(
            length=cfg.length_px,
            root=cfg.root_px,
            direction_deg=cfg.direction_deg,
            wavelength_over_l=cfg.wavelength_over_l,
            w_travel=cfg.w_travel,
            w_standing=1.0 - cfg.w_travel,
        )
        solved = with_peak_to_peak(base, 2 * _REFERENCE_AMP_OVER_L)
        if solved is None:
            raise DriverError(f"simulated flag cannot reach A/L {_REFERENCE_AMP_OVER_L}", device="simulated camera")
        self.kinematics = solved
        self.flutter = FlutterModel(cfg.flutter, seed=cfg.seed)
        self.line = QuickLineParams(
            events_per_px2=cfg.events_per_px2,
            line_width_px=cfg.line_width_px,
            noise_rate_hz=cfg.noise_rate_hz,
            n_s=100,
            slice_us=100,
        )
        self._t_us = 0
        self._open = False
        self._wall0: float | None = None  # the wall clock at camera time 0, from the first read on
        self._slice = 0
        self.skipped_us = 0
        self._drops: list[DeviceDrop] = []  # skips not yet handed over with data
        self.truth = TwinTruth(cfg.truth_keep_s)
        self._pending_triggers = empty_triggers()

    @property
    def state(self) -> FlutterState:
        """The flag's current flutter state (flapping, A/L, frequency)."""
        return self.flutter.state

    def open(self) -> CameraInfo:
        self._warm_up()
        self._open = True
        flutter = self.flutter.params
        return CameraInfo(
            "simulated",
            self.cfg.width,
            self.cfg.height,
            "evt3",
            serial="digital-twin",
            settings={
                "onset_speed_mps": flutter.onset_speed_mps,
                "decay_speed_mps": flutter.decay_speed_mps,
                "noise_rate_hz": self.cfg.noise_rate_hz,
                "time_scale": self.cfg.time_scale,
            },
        )

    def _warm_up(self) -> None:
        """Render one slice of the flag as it is and throw it away, so that loading the renderer's
        compiled kernels (on a first run, compiling them: 1-2 s) happens before the camera's clock
        starts (at the first read, so that a service's own set-up is no lag either), not as a lag
        skipped at the stream's start. Nothing of the twin's state changes."""
        state, slice_s = self.flutter.state, self.cfg.slice_us * 1e-6
        twin = _TwinSlice(self.kinematics, 0.0, slice_s, state, state, self.cfg.still_amp_over_l)
        for _ in line_events(twin, 0, self.cfg.slice_us, self.cfg.width, self.cfg.height, self.line):
            pass

    def read(self, timeout_s: float) -> CameraData | None:
        if not self._open:
            raise DriverError("simulated camera is not open", device="simulated camera")
        if self._wall0 is None:
            self._wall0 = time.monotonic() - self._t_us * 1e-6 / self.cfg.time_scale
        t1_us = self._t_us + self.cfg.slice_us
        due = self._wall0 + t1_us * 1e-6 / self.cfg.time_scale
        wait = due - time.monotonic()
        if -wait > self.cfg.max_lag_s:
            self._skip(int(-wait * self.cfg.time_scale * 1e6) // self.cfg.slice_us * self.cfg.slice_us)
            t1_us = self._t_us + self.cfg.slice_us
        if wait > timeout_s:
            time.sleep(max(timeout_s, 0.0))
            return None
        if wait > 0:
            time.sleep(wait)
        return self._generate(t1_us)

    def _generate(self, t1_us: int) -> CameraData:
        t0_us = self._t_us
        start = self.flutter.state
        end = self.flutter.advance(float(self.speed_source()), (t1_us - t0_us) * 1e-6)
        twin = _TwinSlice(self.kinematics, t0_us * 1e-6, t1_us * 1e-6, start, end, self.cfg.still_amp_over_l)
        self.truth.add(twin)
        chunks = list(
            line_events(
                twin,
                t0_us,
                t1_us,
                self.cfg.width,
                self.cfg.height,
                self.line,
                seed=self.cfg.seed * 1_000_003 + self._slice,
                chunk_us=t1_us - t0_us,
            )
        )
        self._slice += 1
        self._t_us = t1_us
        events = chunks[0] if len(chunks) == 1 else np.concatenate(chunks)
        triggers = trigger_edges(self.cfg, t0_us, t1_us)
        if len(self._pending_triggers):  # pulses of skipped time: a camera keeps its trigger events
            triggers, self._pending_triggers = np.concatenate([self._pending_triggers, triggers]), empty_triggers()
        drops, self._drops = tuple(self._drops), []
        return CameraData(events, triggers, time.time_ns(), t_until_us=t1_us, drops=drops)

    def close(self) -> None:
        self._open = False
        self._wall0 = None

    def _skip(self, skip_us: int) -> None:
        """Move the flag (and the camera clock) on by ``skip_us`` without events."""
        if skip_us <= 0:
            return
        if self.skipped_us == 0:
            log.warning("simulated camera: cannot keep up with real time; skipping ahead (events dropped)")
        self._drops.append(DeviceDrop(SKIP_REASON, skip_us, "us", t_from_us=self._t_us, t_to_us=self._t_us + skip_us))
        start = self.flutter.state
        end = self.flutter.advance(float(self.speed_source()), skip_us * 1e-6)
        self.truth.add(
            _TwinSlice(
                self.kinematics, self._t_us * 1e-6, (self._t_us + skip_us) * 1e-6, start, end, self.cfg.still_amp_over_l
            )
        )
        self._pending_triggers = np.concatenate(
            [self._pending_triggers, trigger_edges(self.cfg, self._t_us, self._t_us + skip_us)]
        )
        self._t_us += skip_us
        self.skipped_us += skip_us


def fast_forward(camera: SimulatedCamera, duration_s: float) -> list[np.ndarray]:
    """Generate ``duration_s`` of camera time as fast as possible (tests and benchmarks)."""
    if not camera._open:
        camera.open()
    out = []
    stop_us = camera._t_us + int(duration_s * 1e6)
    while camera._t_us < stop_us:
        out.append(camera._generate(camera._t_us + camera.cfg.slice_us).events)
    return out


__all__ = ["SimulatedCamera", "SimulatedCameraConfig", "TwinTruth", "fast_forward", "replace", "trigger_edges"]
