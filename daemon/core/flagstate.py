"""The flag's state cycle by cycle, from its centrelines: what a controller acts on.

:class:`FlagStateTracker` takes the tracker's updates as they come and returns a state for every
flapping cycle it completes and, between those, one every ``interval_s`` of camera time (a still
flag, a slow cycle). A cycle runs from one upward crossing of the tip's lateral displacement through
its centre (its moving average over ``centre_tau_s``, counted from when that average has run that
long) to the next; an upward crossing counts once the tip has swung ``hysteresis_over_l`` below the
centre since the last one (noise on a still flag makes no cycles; nor does a stretch with a gap in its updates, or one more than 30 % shorter or longer
than the last cycle). A cycle's figures are those the sweep's per-point figures are made with, over the
cycle's updates: A/L by :func:`~.metrics.tip_amplitude_over_l` of the lateral displacement
(:func:`~.metrics.lateral_displacement`), the travelling-wave index by
:func:`~.metrics.travelling_wave_index_in_time`; its frequency is one over its duration. Updates
the tracker marked lost or stale are counted, not measured.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.flagstate_params import StateParams
from flagtrack.daemon.core.metrics import lateral_displacement, tip_amplitude_over_l, travelling_wave_index_in_time

GAP_STEPS = 5.0
"""A cycle whose updates are further apart somewhere than this many times their median step is no
cycle (its duration and amplitude span a gap)."""
CYCLE_RATIO = 1.3
"""A cycle more than this many times shorter or longer than the last one counted (if it ended within
``max_cycle_s``) is no cycle: a flag's period changes by a few per cent a cycle at the most (the
twin's, ramped at 2 m/s^2, by 6 %); remembered or jumping shapes (a tracker or a camera behind) make
such crossings."""
TWI_UPDATES, TWI_SAMPLES = 64, 16
"""A cycle's travelling-wave index is taken from at most this many of its updates (evenly spread in
time) and this many samples along the flag (root and tip included): an SVD of 64 x 16 takes well
under a millisecond where one of a whole cycle (hundreds of updates) takes ten or more."""


def _spread(indices: np.ndarray, at_most: int) -> np.ndarray:
    """At most ``at_most`` of ``indices``, evenly spread, first and last included."""
    if len(indices) <= at_most:
        return indices
    return indices[np.unique(np.linspace(0, len(indices) - 1, at_most).round().astype(int))]


@dataclass(frozen=True)
class CycleState:
    """The flag's state at one update (NaN: not known).

    Attributes:
        index: the update's position in the batch given to :meth:`FlagStateTracker.push`.
        t_s: the update's time, camera seconds.
        tip_x, tip_y: the tip's position then (the centrelines' units).
        tip_lateral_over_l: the tip's lateral displacement from the rest direction, over L.
        flapping: a cycle of at most ``max_cycle_s`` ended within ``max_cycle_s``.
        amplitude_over_l: A/L over the last cycle (a still flag: over the last ``interval_s``).
        frequency_hz: one over the last cycle's duration (NaN when still).
        phase_rad: the cycle's phase at ``t_s`` (0 at the upward crossing, 2 pi a period later; NaN when still).
        twi: the last cycle's travelling-wave index (NaN where not defined).
        lost_fraction, stale_fraction: of the updates the figures are over, those lost or stale.
        cycle_start_s, cycle_end_s: what the figures are over.
        updates: how many updates that is.
        completes_cycle: this update completed the cycle (otherwise a state of the interval).
    """

    index: int
    t_s: float
    tip_x: float
    tip_y: float
    tip_lateral_over_l: float
    flapping: bool
    amplitude_over_l: float
    frequency_hz: float
    phase_rad: float
    twi: float
    lost_fraction: float
    stale_fraction: float
    cycle_start_s: float
    cycle_end_s: float
    updates: int
    completes_cycle: bool


@dataclass(frozen=True)
class _Figures:
    """A cycle's (or a still interval's) figures."""

    amplitude_over_l: float
    frequency_hz: float
    twi: float
    lost_fraction: float
    stale_fraction: float
    start_s: float
    end_s: float
    updates: int


@dataclass(frozen=True)
class _Chunk:
    """One pushed batch, as the tracker keeps it."""

    t_s: np.ndarray
    tip: np.ndarray  # the tip's lateral displacement, NaN where not measured
    lateral: np.ndarray  # (n, <= TWI_SAMPLES) lateral displacement along the flag
    tip_xy: np.ndarray  # (n, 2)
    lost: np.ndarray
    stale: np.ndarray


class FlagStateTracker:
    """Cycle-by-cycle state of one flag (see the module); feed it every update in time order.

    Work per batch is O(its updates), plus O(a cycle's updates) for each cycle it completes.
    """

    def __init__(self, params: StateParams) -> None:
        self.params = params
        self._reset()

    def _reset(self) -> None:
        self._chunks: list[_Chunk] = []
        self._centre, self._centre_t_s, self._centre_from_s = math.nan, math.nan, math.nan
        self._last_d = math.nan
        self._crossings: list[float] = []  # times of the last two counted upward crossings
        self._armed = False
        self._cycle: _Figures | None = None
        self._last_emit_s = -math.inf

    def push(self, batch: CentrelineBatch) -> list[CycleState]:
        """Take ``batch``'s updates; return the states they make, in time order (usually none or one)."""
        if len(batch) == 0:
            return []
        t_s = np.asarray(batch.t_s, dtype=np.float64)
        if self._chunks:
            last_s = float(self._chunks[-1].t_s[-1])
            if t_s[0] <= last_s or t_s[0] - last_s > self.params.max_cycle_s:
                self._reset()  # a new stream, or a gap longer than a cycle: start again
        chunk = self._append(batch, t_s)
        d = chunk.tip - self._centres(chunk)
        crossings = self._upward_crossings(d)
        self._last_d = float(d[-1])
        states = []
        position, k = 0, 0
        while True:
            due = int(np.searchsorted(t_s, self._last_emit_s + self.params.interval_s, side="left"))
            due = max(due, position)
            if k < len(crossings) and crossings[k][0] <= due:
                i, t_cross = crossings[k]
                k += 1
                self._crossings = [*self._crossings[-1:], t_cross]
                if len(self._crossings) == 2 and self._crossings[1] - self._crossings[0] <= self.params.max_cycle_s:
                    figures = self._figures(self._crossings[0], self._crossings[1], cycle=True)
                    if figures is not None:
                        self._cycle = figures
                        states.append(self._state(chunk, i, completes=True))
                        position = i + 1
            elif due < len(t_s):
                states.append(self._state(chunk, due, completes=False))
                position = due + 1
            else:
                break
        self._trim()
        return states

    def _append(self, batch: CentrelineBatch, t_s: np.ndarray) -> _Chunk:
        """Keep the batch's updates."""
        p = self.params
        lateral = lateral_displacement(batch.x, batch.y, p.root, p.direction_deg)
        stale = getattr(batch, "stale", None)  # (a tracker without the stale verdict: none stale)
        lost = np.asarray(batch.lost) != 0
        stale_flags = np.zeros(len(t_s), dtype=bool) if stale is None else np.asarray(stale) != 0
        tip = np.where(~lost & ~stale_flags, lateral[:, -1], np.nan)
        columns = _spread(np.arange(lateral.shape[1]), TWI_SAMPLES)
        chunk = _Chunk(
            t_s, tip, lateral[:, columns], np.column_stack([batch.x[:, -1], batch.y[:, -1]]), lost, stale_flags
        )
        self._chunks.append(chunk)
        return chunk

    def _centres(self, chunk: _Chunk) -> np.ndarray:
        """The centre at each update of ``chunk`` (the tip's moving average before it; NaN while that
        average has run less than ``centre_tau_s``), carried on from the batch before."""
        tau_s = self.params.centre_tau_s
        centre, last_s, centres = self._centre, self._centre_t_s, []
        for t, tip in zip(chunk.t_s.tolist(), chunk.tip.tolist()):
            ready = t - self._centre_from_s >= tau_s
            centres.append(centre if ready else math.nan)
            if tip != tip:  # (NaN: not measured)
                continue
            if centre != centre:
                centre, self._centre_from_s = tip, t
            else:
                centre += (tip - centre) * (1.0 - math.exp(-(t - last_s) / tau_s))
            last_s = t
        self._centre, self._centre_t_s = centre, last_s
        return np.asarray(centres)

    def _trim(self) -> None:
        """Forget the batches wholly older than ``history_s``."""
        newest_s = float(self._chunks[-1].t_s[-1])
        while len(self._chunks) > 1 and self._chunks[0].t_s[-1] < newest_s - self.params.history_s:
            self._chunks.pop(0)

    def _upward_crossings(self, d: np.ndarray) -> list[tuple[int, float]]:
        """(update index, time) of the counted upward crossings of the centre in this batch, whose
        tip displacement from the centre is ``d``: each once the tip swung ``hysteresis`` below."""
        t_s = self._chunks[-1].t_s
        prev_t = self._chunks[-2].t_s[-1] if len(self._chunks) > 1 else math.nan
        before = np.concatenate([[self._last_d], d[:-1]])
        t_before = np.concatenate([[prev_t], t_s[:-1]])
        candidates = np.flatnonzero((before < 0.0) & (d >= 0.0))  # (NaN compares False: unmeasured skipped)
        below = np.flatnonzero(d < -self.params.hysteresis_over_l * self.params.length)
        found, start = [], 0
        for j in candidates:
            k = int(np.searchsorted(below, start))
            if self._armed or (k < len(below) and below[k] < j):
                d0, d1, t0, t1 = before[j], d[j], t_before[j], t_s[j]
                found.append((int(j), float(t0 + (t1 - t0) * (-d0) / (d1 - d0)) if d1 != d0 else float(t1)))
                self._armed, start = False, int(j)
        self._armed = self._armed or bool(len(below) and below[-1] >= start)
        return found

    def _rows(self, start_s: float, end_s: float) -> _Chunk:
        """The kept updates with times in [start_s, end_s], as one chunk."""
        parts = [c for c in self._chunks if c.t_s[-1] >= start_s and c.t_s[0] <= end_s]
        t_s = np.concatenate([c.t_s for c in parts])
        rows = (t_s >= start_s) & (t_s <= end_s)
        return _Chunk(
            t_s[rows],
            np.concatenate([c.tip for c in parts])[rows],
            np.concatenate([c.lateral for c in parts])[rows],
            np.zeros((0, 2)),
            np.concatenate([c.lost for c in parts])[rows],
            np.concatenate([c.stale for c in parts])[rows],
        )

    def _figures(self, start_s: float, end_s: float, cycle: bool) -> _Figures | None:
        """The figures over the updates in [start_s, end_s] (a cycle's: its frequency and TWI too);
        None for a cycle with a gap in its updates (dropped packets, a camera that skipped ahead), or
        more than :data:`CYCLE_RATIO` times shorter or longer than the last cycle counted."""
        p = self.params
        last = self._cycle
        if cycle and last is not None and start_s - last.end_s <= p.max_cycle_s:
            ratio = (end_s - start_s) / (last.end_s - last.start_s)
            if not 1.0 / CYCLE_RATIO <= ratio <= CYCLE_RATIO:
                return None
        rows = self._rows(start_s, end_s)
        measured = np.isfinite(rows.tip)
        n = len(rows.t_s)
        steps = np.diff(rows.t_s)
        if cycle and (n < 4 or steps.max() > GAP_STEPS * np.median(steps)):
            return None
        twi = math.nan
        if cycle and p.twi and measured.sum() >= 16:
            used = _spread(np.flatnonzero(measured), TWI_UPDATES)
            twi = travelling_wave_index_in_time(rows.t_s[used], rows.lateral[used])
        return _Figures(
            amplitude_over_l=tip_amplitude_over_l(rows.tip[measured], p.length),
            frequency_hz=1.0 / (end_s - start_s) if cycle and end_s > start_s else math.nan,
            twi=twi,
            lost_fraction=float(rows.lost.mean()) if n else math.nan,
            stale_fraction=float(rows.stale.mean()) if n else math.nan,
            start_s=start_s,
            end_s=end_s,
            updates=n,
        )

    def _state(self, chunk: _Chunk, i: int, completes: bool) -> CycleState:
        """The state at update ``i`` of the newest batch ``chunk``."""
        p, t_s = self.params, float(chunk.t_s[i])
        self._last_emit_s = t_s
        cycle = self._cycle
        if cycle is not None and t_s - cycle.end_s <= p.max_cycle_s:
            figures, flapping = cycle, True
            phase = 2.0 * math.pi * ((t_s - self._crossings[-1]) * cycle.frequency_hz % 1.0)
        else:
            still = self._figures(t_s - p.interval_s, t_s, cycle=False)
            assert still is not None
            figures, flapping, phase = still, False, math.nan
        return CycleState(
            index=i,
            t_s=t_s,
            tip_x=float(chunk.tip_xy[i, 0]),
            tip_y=float(chunk.tip_xy[i, 1]),
            tip_lateral_over_l=float(chunk.lateral[i, -1] / p.length),
            flapping=flapping,
            amplitude_over_l=figures.amplitude_over_l,
            frequency_hz=figures.frequency_hz,
            phase_rad=phase,
            twi=figures.twi,
            lost_fraction=figures.lost_fraction,
            stale_fraction=figures.stale_fraction,
            cycle_start_s=figures.start_s,
            cycle_end_s=figures.end_s,
            updates=figures.updates,
            completes_cycle=completes,
        )
