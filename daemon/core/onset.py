"""Onset and decay of flapping from the event rate: a median filter, hysteresis and dwell times.

A flapping flag sweeps the laser line across many pixels and multiplies the event rate by 10-100
compared to a still one (the paper's observation that the raw file size tells the flapping state).
The detector turns a stream of ``(t_s, rate_hz)`` samples into a state:

1. the rate is smoothed by a running median over ``window_s`` (robust to bursts and dropouts);
2. thresholds are ``on_ratio`` and ``off_ratio`` times a baseline learned during the first
   ``learn_s`` (the flag is still when the tunnel is at zero), or absolute rates when given;
   while still, the baseline follows slow drifts (time constant ``baseline_tau_s``);
3. still -> flapping when the median stays above the on threshold for ``dwell_on_s``;
   flapping -> still when it stays below the off threshold for ``dwell_off_s`` (hysteresis);
4. the state is ``unknown`` before a baseline exists, after a gap of ``max_gap_s`` without
   samples, while the median is below ``min_rate_hz`` (camera not delivering), and, coming back
   from unknown, until the median is clearly on one side of the hysteresis band for a dwell time.

Pure: times come with the samples, no clock, no I/O. Defaults and how they were measured (false
alarms per hour, detection delays on synthetic traces): docs/tunnel.md.
"""

from __future__ import annotations

import enum
import math
import statistics
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass


class FlagState(enum.Enum):
    """What the flag does."""

    UNKNOWN = "unknown"
    STILL = "still"
    FLAPPING = "flapping"


@dataclass(frozen=True)
class OnsetParams:
    """Parameters of :class:`OnsetDetector` (config ``supervisor.onset``).

    Attributes:
        window_s: running-median window, s.
        on_ratio: flapping threshold, times the still baseline.
        off_ratio: still-again threshold, times the baseline (below ``on_ratio``: hysteresis).
        on_rate_hz, off_rate_hz: absolute thresholds, events/s; when both are set no baseline is
            learned and the ratios are unused.
        dwell_on_s: time the median must stay above the on threshold, s.
        dwell_off_s: time the median must stay below the off threshold, s.
        learn_s: baseline learning time from the first sample (flag still), s.
        baseline_tau_s: time constant of the baseline's drift-following while still, s.
        min_rate_hz: a median below this means the camera is not delivering: unknown, events/s.
        max_gap_s: no sample for longer than this: unknown (and the window restarts), s.
        min_samples: samples needed in the window before the median is trusted.
    """

    window_s: float = 1.0
    on_ratio: float = 4.0
    off_ratio: float = 2.0
    on_rate_hz: float | None = None
    off_rate_hz: float | None = None
    dwell_on_s: float = 2.0
    dwell_off_s: float = 1.0
    learn_s: float = 3.0
    baseline_tau_s: float = 60.0
    min_rate_hz: float = 10.0
    max_gap_s: float = 1.0
    min_samples: int = 3

    def __post_init__(self) -> None:
        for name in ("window_s", "learn_s", "baseline_tau_s", "max_gap_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive")
        if self.dwell_on_s < 0 or self.dwell_off_s < 0 or self.min_rate_hz < 0 or self.min_samples < 1:
            raise ValueError("dwell times and min_rate_hz must be >= 0, min_samples >= 1")
        if not 1.0 < self.off_ratio < self.on_ratio:
            raise ValueError("need 1 < off_ratio < on_ratio")
        if (self.on_rate_hz is None) != (self.off_rate_hz is None):
            raise ValueError("give both on_rate_hz and off_rate_hz, or neither")
        if self.on_rate_hz is not None and self.off_rate_hz is not None and not 0 < self.off_rate_hz < self.on_rate_hz:
            raise ValueError("need 0 < off_rate_hz < on_rate_hz")


@dataclass(frozen=True)
class OnsetReading:
    """The detector's output after one sample.

    Attributes:
        t_s: time of the sample, s.
        state: the flag state.
        rate_hz: running-median event rate, events/s (``nan`` when the window is empty).
        baseline_hz: still baseline, events/s (``nan`` while learning or with absolute thresholds).
        on_rate_hz, off_rate_hz: thresholds in force, events/s (``nan`` while learning).
        changed: the state differs from the previous reading's.
    """

    t_s: float
    state: FlagState
    rate_hz: float
    baseline_hz: float
    on_rate_hz: float
    off_rate_hz: float
    changed: bool


class OnsetDetector:
    """Stateful onset/decay detector; feed it samples in time order with :meth:`update`.

    Args:
        params: thresholds, windows and dwell times.
        baseline_hz: a known still baseline (skips learning), events/s.
    """

    def __init__(self, params: OnsetParams = OnsetParams(), baseline_hz: float | None = None) -> None:
        self.params = params
        self.reset(baseline_hz)

    def reset(self, baseline_hz: float | None = None) -> None:
        """Forget everything (use when the flag is known to be still, e.g. tunnel at zero)."""
        self._window: deque[tuple[float, float]] = deque()
        self._learned: list[float] = []
        self._learn_start_s: float | None = None
        self._baseline_hz = baseline_hz
        self._state = FlagState.UNKNOWN if baseline_hz is None and self.params.on_rate_hz is None else FlagState.STILL
        self._candidate: FlagState | None = None
        self._candidate_since_s = 0.0
        self._last_t_s: float | None = None

    @property
    def state(self) -> FlagState:
        """The current state."""
        return self._state

    def sample_problem(self, t_s: float, rate_hz: float) -> str | None:
        """Why :meth:`update` would refuse this sample, or None: a time that is not finite or goes
        backwards, a rate that is negative or infinite (``nan`` is a missing rate, taken). For a
        caller that skips samples it cannot use (a message from the bus) instead of failing. O(1)."""
        if not math.isfinite(t_s):
            return f"time {t_s} is not a finite number"
        if self._last_t_s is not None and t_s < self._last_t_s:
            return f"time went backwards: {t_s} s after {self._last_t_s} s"
        if rate_hz < 0 or math.isinf(rate_hz):
            return f"{'negative' if rate_hz < 0 else 'infinite'} event rate {rate_hz} at {t_s} s"
        return None

    def update(self, t_s: float, rate_hz: float) -> OnsetReading:
        """Take one sample (time s, rate events/s; ``nan`` = missing) and return the reading.

        Raises:
            ValueError: a sample :meth:`sample_problem` refuses (time not finite or going backwards,
                a negative or infinite rate); the detector is unchanged.
        """
        problem = self.sample_problem(t_s, rate_hz)
        if problem is not None:
            raise ValueError(problem)
        previous = self._state
        dt_s = 0.0 if self._last_t_s is None else t_s - self._last_t_s
        if self._window and t_s - self._window[-1][0] > self.params.max_gap_s:
            self._lose_track()
        self._last_t_s = t_s
        if not math.isnan(rate_hz):
            self._window.append((t_s, rate_hz))
        while self._window and self._window[0][0] <= t_s - self.params.window_s:
            self._window.popleft()
        median = statistics.median(r for _, r in self._window) if self._window else math.nan
        if len(self._window) >= self.params.min_samples:
            self._step(t_s, median, dt_s)
        on_hz, off_hz = self._thresholds()
        baseline = math.nan if self._baseline_hz is None else self._baseline_hz
        return OnsetReading(t_s, self._state, median, baseline, on_hz, off_hz, self._state is not previous)

    def _step(self, t_s: float, median: float, dt_s: float) -> None:
        p = self.params
        if median < p.min_rate_hz:
            self._lose_track(keep_window=True)
            return
        if p.on_rate_hz is None and self._baseline_hz is None:
            self._learn(t_s, median)
            return
        on_hz, off_hz = self._thresholds()
        target = FlagState.FLAPPING if median >= on_hz else FlagState.STILL if median <= off_hz else None
        if target is None or target is self._state:
            self._candidate = None
        elif self._candidate is not target:
            self._candidate, self._candidate_since_s = target, t_s
        if self._candidate is not None:
            dwell = p.dwell_on_s if self._candidate is FlagState.FLAPPING else p.dwell_off_s
            if t_s - self._candidate_since_s >= dwell:
                self._state, self._candidate = self._candidate, None
        if self._state is FlagState.STILL and target is FlagState.STILL and self._baseline_hz is not None:
            gain = min(1.0, dt_s / p.baseline_tau_s)
            self._baseline_hz *= (median / self._baseline_hz) ** gain

    def _learn(self, t_s: float, median: float) -> None:
        if self._learn_start_s is None:
            self._learn_start_s = t_s
        self._learned.append(median)
        if t_s - self._learn_start_s >= self.params.learn_s:
            self._baseline_hz = statistics.median(self._learned)
            self._state = FlagState.STILL
            self._learned = []

    def _lose_track(self, keep_window: bool = False) -> None:
        if not keep_window:
            self._window.clear()
        self._state, self._candidate = FlagState.UNKNOWN, None
        if self._baseline_hz is None:
            self._learned, self._learn_start_s = [], None

    def _thresholds(self) -> tuple[float, float]:
        p = self.params
        if p.on_rate_hz is not None and p.off_rate_hz is not None:
            return p.on_rate_hz, p.off_rate_hz
        if self._baseline_hz is None:
            return math.nan, math.nan
        return p.on_ratio * self._baseline_hz, p.off_ratio * self._baseline_hz


def detect_states(
    t_s: Iterable[float], rate_hz: Iterable[float], params: OnsetParams = OnsetParams()
) -> list[OnsetReading]:
    """Run a fresh detector over a whole trace; one reading per sample."""
    detector = OnsetDetector(params)
    return [detector.update(float(t), float(r)) for t, r in zip(t_s, rate_hz, strict=True)]


def transitions(readings: Iterable[OnsetReading]) -> list[tuple[float, FlagState]]:
    """``(t_s, new_state)`` of every change of state in ``readings``."""
    return [(r.t_s, r.state) for r in readings if r.changed]
