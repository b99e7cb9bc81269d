"""Update times and windows of the tracker: ``t_k`` and ``[t_k - tau/2, t_k + tau/2)``.

The paper leaves the time increment ``dt`` and the update interval ``tau`` free, and lets them change
along a recording. A :class:`WindowSchedule` is a list of segments ``(t_from_s, dt_s, tau_s)``; update
times start at ``t_start`` and advance by the ``dt`` of the segment they fall in. When an update time
reaches the next segment's ``t_from_s``, that update and the following ones use the new ``dt`` and
``tau`` (the grid continues from that update). Every time is computed from a segment anchor plus an
integer multiple of ``dt`` (no accumulated rounding), so the schedule is the same however the events
are chunked. Times are float microseconds on the recording's clock; a window holds the events with
integer ``t_us`` in ``[ceil(t - tau/2), ceil(t + tau/2))``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

STEP_RANGE_S = (1e-6, 3600.0)
"""dt and tau: from 1 µs (the events' resolution) to an hour."""
MAX_ABS_TIME_S = 1e11
"""Largest update time in seconds (a recording's clock may be Unix time, 1.6e9 s in 2020; its
microseconds fit in 64 bits with room)."""
_MAX_BATCH = 1 << 16  # update times generated per step (bounds memory after a long gap)
_SCALAR_MAX = 32  # up to this many candidate windows, take() tests them one by one (no array passes)
_NONE = (np.empty(0), np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64))  # what take() returns for no update
for _array in _NONE:
    _array.flags.writeable = False


@dataclass(frozen=True)
class WindowSegment:
    """From ``t_from_s`` on, update every ``dt_s`` with windows of ``tau_s`` (seconds)."""

    t_from_s: float
    dt_s: float
    tau_s: float

    def __post_init__(self) -> None:
        lo, hi = STEP_RANGE_S
        if not (lo <= self.dt_s <= hi):
            raise ValueError(f"dt_s must be in [{lo:g}, {hi:g}] s, got {self.dt_s}")
        if not (lo <= self.tau_s <= hi):
            raise ValueError(f"tau_s must be in [{lo:g}, {hi:g}] s, got {self.tau_s}")
        if not abs(self.t_from_s) <= MAX_ABS_TIME_S:
            raise ValueError(f"t_from_s must be a finite time within +-{MAX_ABS_TIME_S:g} s, got {self.t_from_s}")


@dataclass(frozen=True)
class WindowSchedule:
    """Update times and window lengths along a recording.

    Attributes:
        segments: at least one segment, sorted by ``t_from_s``; the first applies before its
            ``t_from_s`` too.
        t_start_s: first update time, seconds; ``None``: the first event's time + tau/2.
        t_stop_s: no update after this time, seconds; ``None``: until the events end.
    """

    segments: tuple[WindowSegment, ...]
    t_start_s: float | None = None
    t_stop_s: float | None = None

    def __post_init__(self) -> None:
        if not self.segments:
            raise ValueError("a window schedule needs at least one segment")
        for name in ("t_start_s", "t_stop_s"):
            value = getattr(self, name)
            if value is not None and not abs(value) <= MAX_ABS_TIME_S:
                raise ValueError(f"{name} must be a finite time within +-{MAX_ABS_TIME_S:g} s, got {value}")
        if self.t_start_s is not None and self.t_stop_s is not None and not self.t_start_s < self.t_stop_s:
            raise ValueError(f"t_start_s must be before t_stop_s, got {self.t_start_s} >= {self.t_stop_s}")
        starts = [seg.t_from_s for seg in self.segments]
        if any(b <= a for a, b in zip(starts, starts[1:])):
            raise ValueError(f"schedule segments must have increasing t_from_s, got {starts}")

    @staticmethod
    def uniform(
        tau_s: float, dt_s: float | None = None, t_start_s: float | None = None, t_stop_s: float | None = None
    ) -> WindowSchedule:
        """One segment: windows of ``tau_s`` every ``dt_s`` (default ``tau_s``)."""
        return WindowSchedule((WindowSegment(0.0, dt_s or tau_s, tau_s),), t_start_s, t_stop_s)

    def window_ends_us(self, t_s: np.ndarray) -> np.ndarray:
        """(n,) int64: the end ``ceil(t + tau/2)`` (exclusive, µs) of the windows centred at ``t_s``
        (update times as a batch gives them, in seconds: the 1e-6 µs taken off undoes their rounding
        through seconds, so a window ending on a whole µs ends there)."""
        t_s = np.asarray(t_s, dtype=np.float64)
        starts = np.array([seg.t_from_s for seg in self.segments])
        taus_us = np.array([seg.tau_s for seg in self.segments]) * 1e6
        index = np.maximum(np.searchsorted(starts, t_s, side="right") - 1, 0)
        return np.ceil(t_s * 1e6 + taus_us[index] / 2 - 1e-6).astype(np.int64)

    def segment_at(self, t_s: float) -> int:
        """Index of the segment that applies at ``t_s``."""
        index = 0
        for i, seg in enumerate(self.segments):
            if seg.t_from_s <= t_s:
                index = i
        return index


class UpdateClock:
    """Generates the update times of a :class:`WindowSchedule` incrementally (state: a few numbers).

    Args:
        schedule: the schedule.
        first_event_t_us: time of the first event, µs (used when ``schedule.t_start_s`` is None).
    """

    def __init__(self, schedule: WindowSchedule, first_event_t_us: int) -> None:
        self.schedule = schedule
        if schedule.t_start_s is None:
            seg = schedule.segments[schedule.segment_at(first_event_t_us * 1e-6)]
            start_us = first_event_t_us + seg.tau_s * 1e6 / 2
        else:
            start_us = schedule.t_start_s * 1e6
        self._segment = schedule.segment_at(start_us * 1e-6)
        self._anchor_us = start_us
        self._count = 0
        self._stop_us = math.inf if schedule.t_stop_s is None else schedule.t_stop_s * 1e6
        self._skip_windows_ending_by(first_event_t_us)

    def _skip_windows_ending_by(self, t_us: int) -> None:
        """Step over the updates whose windows end at or before ``t_us`` (a start before the stream's
        first event: those windows hold nothing; with a recording's Unix-time clock, billions of them)."""
        segments = self.schedule.segments
        while True:
            t_first, tau_us = self._peek()
            dt_us = segments[self._segment].dt_s * 1e6
            steps = math.floor((t_us - tau_us / 2 - t_first) / dt_us) + 1  # those windows end by t_us
            if steps > 0 and math.ceil(self._anchor_us + (self._count + steps - 1) * dt_us + tau_us / 2) > t_us:
                steps -= 1  # rounding: the last of them, computed as take() does, ends after t_us
            nxt = self._segment + 1
            if nxt < len(segments):  # into the next segment only step by step (its grid starts there)
                steps = min(steps, math.ceil((segments[nxt].t_from_s * 1e6 - t_first) / dt_us))
            if steps <= 0:
                return
            self._count += steps

    def _peek(self) -> tuple[float, float]:
        """(t_us, tau_us) of the next update, advancing to a new segment when reached."""
        seg = self.schedule.segments[self._segment]
        t_us = self._anchor_us + float(self._count) * (seg.dt_s * 1e6)
        nxt = self._segment + 1
        while nxt < len(self.schedule.segments) and t_us >= self.schedule.segments[nxt].t_from_s * 1e6:
            self._segment, self._anchor_us, self._count = nxt, t_us, 0
            seg = self.schedule.segments[nxt]
            nxt += 1
        return t_us, seg.tau_s * 1e6

    def next_window_start_us(self) -> float:
        """Earliest event time any future window can use, µs (the buffer may drop older events)."""
        t_us, _ = self._peek()
        later = self.schedule.segments[self._segment :]
        return t_us - max(seg.tau_s for seg in later) * 1e6 / 2

    def take(
        self, complete_before_us: int, started_before_us: int | None = None, limit: int = _MAX_BATCH
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pop the next updates whose windows end at or before ``complete_before_us``.

        Args:
            complete_before_us: windows ``[lo, hi)`` with ``hi <= complete_before_us`` are taken.
            started_before_us: if given (end of stream), also take windows with ``lo <= started_before_us``.
            limit: take at most about this many updates (call again for the rest).

        Returns:
            t_us (n,) float64 window centres, lo_us (n,) int64, hi_us (n,) int64 integer bounds.
        """
        if not self._next_ready(complete_before_us, started_before_us):
            return _NONE
        parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        reach = complete_before_us if started_before_us is None else max(complete_before_us, started_before_us)
        taken = 0
        while taken < limit:
            t_first, tau_us = self._peek()
            seg = self.schedule.segments[self._segment]
            dt_us = seg.dt_s * 1e6
            nxt = self._segment + 1
            seg_end_us = self.schedule.segments[nxt].t_from_s * 1e6 if nxt < len(self.schedule.segments) else math.inf
            # every candidate window starts before ``reach`` (+1 for rounding); bounded count
            n_max = min(limit - taken, max(0, int((reach + tau_us - t_first) // dt_us) + 2))
            if n_max <= _SCALAR_MAX:  # a live packet completes a few windows: plain floats are quicker
                t_us, lo, hi = self._ready_few(n_max, dt_us, tau_us, complete_before_us, started_before_us, seg_end_us)
                n = len(t_us)
            else:
                t_us = self._anchor_us + (self._count + np.arange(n_max, dtype=np.float64)) * dt_us
                lo = np.ceil(t_us - tau_us / 2).astype(np.int64)
                hi = np.ceil(t_us + tau_us / 2).astype(np.int64)
                ready = hi <= complete_before_us
                if started_before_us is not None:
                    ready |= lo <= started_before_us
                ok = ready & (t_us <= self._stop_us) & (t_us < seg_end_us)
                n = int(np.argmin(ok)) if not ok.all() else n_max
            if n:
                parts.append((t_us[:n], lo[:n], hi[:n]))
                self._count += n
                taken += n
            if n == n_max and n > 0:
                continue  # the bound was reached; look again
            self._peek()
            if self._segment == nxt and n > 0:
                continue  # moved into the next segment: keep going there
            break
        if not parts:
            return _NONE
        if len(parts) == 1:
            return parts[0]
        t_cols, lo_cols, hi_cols = zip(*parts)
        return np.concatenate(t_cols), np.concatenate(lo_cols), np.concatenate(hi_cols)

    def _ready_few(
        self,
        n_max: int,
        dt_us: float,
        tau_us: float,
        complete_before_us: int,
        started_before_us: int | None,
        seg_end_us: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The ready windows among the next ``n_max`` of the segment, one by one (the same float
        operations, in the same order, as the array path of :meth:`take`)."""
        t_list: list[float] = []
        lo_list: list[int] = []
        hi_list: list[int] = []
        for i in range(n_max):
            t_us = self._anchor_us + float(self._count + i) * dt_us
            lo, hi, ready = _bounds(t_us, tau_us, complete_before_us, started_before_us)
            if not (ready and t_us <= self._stop_us and t_us < seg_end_us):
                break
            t_list.append(t_us)
            lo_list.append(lo)
            hi_list.append(hi)
        return (
            np.array(t_list, dtype=np.float64),
            np.array(lo_list, dtype=np.int64),
            np.array(hi_list, dtype=np.int64),
        )

    def _next_ready(self, complete_before_us: int, started_before_us: int | None) -> bool:
        """Whether the next update can be taken (the cheap test that spares :meth:`take` its arrays
        when a chunk completed no window); the same rounding as :meth:`take`."""
        t_us, tau_us = self._peek()
        return t_us <= self._stop_us and _bounds(t_us, tau_us, complete_before_us, started_before_us)[2]


def _bounds(
    t_us: float, tau_us: float, complete_before_us: int, started_before_us: int | None
) -> tuple[int, int, bool]:
    """Integer bounds [lo, hi) of the window centred at ``t_us``, and whether :meth:`UpdateClock.take`
    takes it (complete, or started before the end of the stream); the rounding of its array path."""
    lo, hi = math.ceil(t_us - tau_us / 2), math.ceil(t_us + tau_us / 2)
    return lo, hi, hi <= complete_before_us or (started_before_us is not None and lo <= started_before_us)
