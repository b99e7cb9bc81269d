"""Sweep progress: how far a plan is, how long the rest should take, what each finished point found.

The supervisor keeps a :class:`SweepProgress` while a sweep runs and puts its facts in every
``SupervisorState`` it publishes (so a viewer in another process shows them); the commands draw
them as a line per finished point and a progress bar (``daemon/commands/_progress.py``). Nothing
here prints or reads a clock: the caller gives the time (monotonic seconds).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass

from flagtrack.daemon.core.chain_reach import TOLERANCE as REACH_TOLERANCE
from flagtrack.daemon.sweep.plan import Point
from flagtrack.daemon.sweep.runlog import PointResult


def lost_fraction(result: PointResult) -> float:
    """Fraction of the point's updates the tracker flagged lost, or NaN when the record has none
    (a run log written before ``/lost``, or a point without updates: shown as ``-``)."""
    value = getattr(result, "lost_fraction", None)
    return math.nan if value is None else float(value)


def stale_fraction(result: PointResult) -> float:
    """Fraction of the point's updates that were stale, or NaN when the record has none (a run log
    written before ``/stale``)."""
    value = getattr(result, "stale_fraction", None)
    return math.nan if value is None else float(value)


def is_suspect(
    lost_fraction: float, bound: float, stale_fraction: float = math.nan, state: str = "", chain_reach: float = math.nan
) -> bool:
    """Whether a point is suspect: its updates were lost more often than ``bound``, or, for a flapping
    point, stale more often (a still flag gives few events: a still point is not suspect for being
    stale), or the flag's events ended more than :data:`~.core.chain_reach.TOLERANCE` of L from the
    chain's tip (``chain_reach``). NaN: not known, not suspect."""
    if math.isfinite(lost_fraction) and lost_fraction > bound:
        return True
    if math.isfinite(chain_reach) and abs(chain_reach - 1.0) > REACH_TOLERANCE:
        return True
    return state == "flapping" and math.isfinite(stale_fraction) and stale_fraction > bound


@dataclass(frozen=True)
class PointFacts:
    """What a finished point found, as the line per point and the bus show it.

    Attributes:
        point_id, branch, speed_mps: as planned.
        position: 1-based position of the point in the plan.
        status: ``done``, ``failed`` or ``lossy``.
        state: flag state over the recording (``still``, ``flapping``, ``unknown``).
        amplitude_over_l, frequency_hz: tip amplitude A/L and flapping frequency (Hz), NaN if none.
        lost_fraction: see :func:`lost_fraction`; stale_fraction: :func:`stale_fraction`.
        sensor_error_rms_over_l: RMS of |e|/L against the point sensor, NaN without a comparison.
        error: why a failed point failed.
        chain_reach: where the flag's events ended along the chain, a fraction of L (NaN: not judged).
        suspect: the point's numbers may not be the flag's (:func:`is_suspect`; the run log says why).
    """

    point_id: str
    position: int
    branch: str
    speed_mps: float
    status: str
    state: str
    amplitude_over_l: float
    frequency_hz: float
    lost_fraction: float
    sensor_error_rms_over_l: float
    error: str = ""
    stale_fraction: float = math.nan
    chain_reach: float = math.nan
    suspect: bool = False

    @classmethod
    def of(cls, result: PointResult) -> PointFacts:
        """The facts of a point record."""
        return cls(
            point_id=result.point_id,
            position=result.index + 1,
            branch=result.branch,
            speed_mps=result.speed_mps,
            status=result.status,
            state=result.state,
            amplitude_over_l=result.amplitude_over_l,
            frequency_hz=result.frequency_hz,
            lost_fraction=lost_fraction(result),
            sensor_error_rms_over_l=result.sensor_error_rms_over_l,
            error=result.error or "",
            stale_fraction=stale_fraction(result),
            chain_reach=result.chain_reach,
            suspect=result.suspect,
        )


class SweepProgress:
    """Counts the finished points of a plan and estimates the time left.

    ``done`` counts distinct points (a point redone after a lossy or failed record counts once);
    ``records`` counts the point records of this session (a redone point has two).

    The estimate per point is the mean duration (start of the point to its record) of the points
    finished in this session, or ``planned_point_s`` before the first one (settle plus record time:
    the ramps and actions make the real figure larger). The time left is that times the points
    left, less what the point in progress has already taken.

    Args:
        plan: every point of the sweep.
        done: ids of the points finished before this session (a resumed run).
        planned_point_s: the plan's own estimate of one point, s.
        now_s: the time the sweep starts (monotonic s).
    """

    def __init__(self, plan: Sequence[Point], done: Collection[str], planned_point_s: float, now_s: float) -> None:
        self.total = len(plan)
        self._plan_ids = {p.point_id for p in plan}
        self._done_ids = {p.point_id for p in plan if p.point_id in done}
        self.records = 0
        self.planned_point_s = planned_point_s
        self.started_s = now_s
        self.current: Point | None = None
        self.last: PointFacts | None = None
        self._current_since_s = now_s
        self._durations: list[float] = []

    def start_point(self, point: Point, now_s: float) -> None:
        """The point ``point`` begins (its speed is about to be set)."""
        self.current, self._current_since_s = point, now_s

    def finish_point(self, result: PointResult, now_s: float) -> PointFacts:
        """The point of ``result`` is recorded (done or failed); return its facts."""
        if self.current is not None and self.current.point_id == result.point_id:
            self._durations.append(now_s - self._current_since_s)
        self.current = None
        if result.point_id in self._plan_ids:
            self._done_ids.add(result.point_id)
        self.records += 1
        self.last = PointFacts.of(result)
        return self.last

    @property
    def done(self) -> int:
        """Distinct points of the plan finished (this session's and earlier ones)."""
        return len(self._done_ids)

    @property
    def current_position(self) -> int:
        """1-based plan position of the point in progress (0: none)."""
        return 0 if self.current is None else self.current.index + 1

    def point_s(self) -> float:
        """The expected duration of one point, s."""
        return sum(self._durations) / len(self._durations) if self._durations else self.planned_point_s

    def elapsed_s(self, now_s: float) -> float:
        """Seconds since this session's sweep began."""
        return max(0.0, now_s - self.started_s)

    def eta_s(self, now_s: float) -> float:
        """Estimated seconds to the end of the plan (0 when every point is finished)."""
        left = self.total - self.done
        if left <= 0:
            return 0.0
        per_point = self.point_s()
        if self.current is None:
            return left * per_point
        return (left - 1) * per_point + max(0.0, per_point - (now_s - self._current_since_s))
