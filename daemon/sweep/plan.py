"""Sweep plans: a YAML description of the speeds, turned into a generator of steps.

A plan only says what to do; a runner (the supervisor service) executes the steps with a wind
tunnel and a recorder, and its ``finally`` returns the tunnel to zero. Plans are tested by
listing what they yield. Example (section ``sweep`` of a run config)::

    sweep:
      range: {start: 3.0, stop: 9.0, step: 0.25}   # or: speeds: [3.0, 4.0, 4.5, ...]
      branches: [up, down]        # up: ascending speeds, down: descending (hysteresis)
      settle_s: 10                # wait after each speed change, s
      record_s: 20                # recording per point, s
      actions:                    # per point (see daemon/sweep/actions.py): command, pause
        - {name: command, when: after_record, params: {argv: [flagtrack, events, info, "{raw}"]}}
      on_bad_point: retry         # a failed or lossy point: measure it again (retry) or stop safe (stop)
      retries: 1                  # how many times a bad point is measured again before the sweep stops

Each point yields: ``Point`` (metadata), ``SetSpeed``, ``Wait`` (settle), the ``before_record``
actions, ``Record``, the ``after_record`` actions, ``EndPoint``; the plan ends with
``SetSpeed(0)``. Resuming (:func:`sweep_plan` with ``done``) skips finished points; a down-branch
point whose predecessor was skipped (the tunnel comes from zero after a crash) is preceded by a
re-entry from the top speed, so the flag is on the right side of the hysteresis loop.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Collection, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.sweep.actions import parse_action
from flagtrack.daemon.typed_yaml import from_mapping, load_yaml


class Branch(enum.Enum):
    """Direction of a sweep branch."""

    UP = "up"
    DOWN = "down"


_MAX_S = 86_400.0
"""A point's settle and record times at most: a day."""
MAX_SPEEDS = 10_000
"""Speeds a plan may have at most (a step of 1e-12 m/s would be billions of points)."""


@dataclass(frozen=True)
class SpeedRange:
    """Speeds ``start, start + step, ...`` up to ``stop`` included, m/s."""

    start: float
    stop: float
    step: float

    def __post_init__(self) -> None:
        if not all(math.isfinite(v) for v in (self.start, self.stop, self.step)):
            raise ValueError("range needs finite start, stop and step")
        if not (self.step > 0 and 0 <= self.start <= self.stop):
            raise ValueError("range needs step > 0 and 0 <= start <= stop")
        if (self.stop - self.start) / self.step >= MAX_SPEEDS:
            raise ValueError(f"range gives more than {MAX_SPEEDS} speeds: a larger step")

    def values(self) -> tuple[float, ...]:
        """The speeds, rounded to 1e-9 m/s (no 3.0000000000004)."""
        n = int(math.floor((self.stop - self.start) / self.step + 1e-9)) + 1
        return tuple(round(self.start + k * self.step, 9) for k in range(n))


@dataclass(frozen=True)
class ActionSpec:
    """A named action at every point (a built-in of :mod:`~flagtrack.daemon.sweep.actions`, checked here)."""

    name: str
    when: Literal["before_record", "after_record"] = "after_record"
    params: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        parse_action(self.name, self.params)


@dataclass(frozen=True)
class SweepConfig:
    """A sweep (config section ``sweep``): exactly one of ``speeds`` and ``range``.

    Attributes:
        speeds: the speeds, m/s (any order; each branch sorts them its way).
        range: the speeds as a range.
        branches: the branches in order.
        settle_s: wait after setting each speed, s.
        record_s: recording time per point, s.
        repeat_turning_point: measure the speed where the branch direction turns twice.
        actions: per-point actions.
        on_bad_point: what follows a point that was not measured as planned (tunnel silent, faulted
            or out of tolerance, packets lost): ``retry`` measures it again, up to ``retries``
            times, then stops safe; ``stop`` stops safe at once.
        retries: how many times a bad point is measured again (``on_bad_point: retry``).
    """

    speeds: tuple[float, ...] | None = None
    range: SpeedRange | None = None
    branches: tuple[Branch, ...] = (Branch.UP, Branch.DOWN)
    settle_s: float = 10.0
    record_s: float = 20.0
    repeat_turning_point: bool = False
    actions: tuple[ActionSpec, ...] = ()
    on_bad_point: Literal["retry", "stop"] = "retry"
    retries: int = 1

    def __post_init__(self) -> None:
        if (self.speeds is None) == (self.range is None):
            raise ValueError("give exactly one of 'speeds' and 'range'")
        if self.speeds is not None and (not self.speeds or any(not (math.isfinite(v) and v >= 0) for v in self.speeds)):
            raise ValueError("speeds must be a non-empty list of speeds >= 0")
        if self.speeds is not None and len(self.speeds) > MAX_SPEEDS:
            raise ValueError(f"speeds: more than {MAX_SPEEDS}")
        if not self.branches:
            raise ValueError("branches must not be empty")
        if not (0 <= self.settle_s <= _MAX_S and 0 < self.record_s <= _MAX_S):
            raise ValueError(f"need settle_s >= 0 and record_s > 0, both at most {_MAX_S:g} s")
        if not 0 <= self.retries <= 100:
            raise ValueError("retries must be within 0..100")

    def speed_values(self) -> tuple[float, ...]:
        """The distinct speeds, ascending, m/s."""
        values = self.speeds if self.speeds is not None else self.range.values()  # type: ignore[union-attr]
        return tuple(sorted(set(values)))


@dataclass(frozen=True)
class Point:
    """A measurement point begins (metadata for the run log)."""

    point_id: str
    index: int
    branch: Branch
    speed_mps: float


@dataclass(frozen=True)
class SetSpeed:
    """Ramp the tunnel to ``speed_mps`` (and verify)."""

    speed_mps: float
    reason: str = ""


@dataclass(frozen=True)
class Wait:
    """Wait ``duration_s`` (keeping the tunnel alive)."""

    duration_s: float
    reason: str = "settle"


@dataclass(frozen=True)
class Record:
    """Record ``duration_s`` of events for point ``point_id``."""

    duration_s: float
    point_id: str


@dataclass(frozen=True)
class Action:
    """Run the named per-point action."""

    name: str
    point_id: str
    params: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class EndPoint:
    """The point is finished: write its record to the run log."""

    point_id: str


Step = Point | SetSpeed | Wait | Record | Action | EndPoint


def point_id(index: int, branch: Branch, speed_mps: float) -> str:
    """Stable, file-name-safe id of a point: ``007-up-5.50``."""
    return f"{index:03d}-{branch.value}-{speed_mps:.2f}"


def plan_points(cfg: SweepConfig) -> list[Point]:
    """Every point of the sweep, in order."""
    ascending = cfg.speed_values()
    points: list[Point] = []
    for branch in cfg.branches:
        speeds = list(ascending if branch is Branch.UP else reversed(ascending))
        if points and not cfg.repeat_turning_point and speeds[0] == points[-1].speed_mps:
            speeds = speeds[1:]
        for speed in speeds:
            points.append(Point(point_id(len(points), branch, speed), len(points), branch, speed))
    return points


def sweep_plan(cfg: SweepConfig, done: Collection[str] = ()) -> Iterator[Step]:
    """Yield the steps of the sweep, skipping the points whose ids are in ``done``."""
    all_points = plan_points(cfg)
    top_mps = max(p.speed_mps for p in all_points)
    before = [a for a in cfg.actions if a.when == "before_record"]
    after = [a for a in cfg.actions if a.when == "after_record"]
    previous_ran = True
    for point in all_points:
        if point.point_id in done:
            previous_ran = False
            continue
        if point.branch is Branch.DOWN and not previous_ran and point.speed_mps < top_mps:
            yield SetSpeed(top_mps, reason="re-enter the down branch from its top")
            yield Wait(cfg.settle_s, reason="re-enter the down branch from its top")
        previous_ran = True
        yield point
        yield SetSpeed(point.speed_mps)
        yield Wait(cfg.settle_s)
        yield from (Action(a.name, point.point_id, dict(a.params)) for a in before)
        yield Record(cfg.record_s, point.point_id)
        yield from (Action(a.name, point.point_id, dict(a.params)) for a in after)
        yield EndPoint(point.point_id)
    yield SetSpeed(0.0, reason="end of sweep")


def plan_duration_s(cfg: SweepConfig, ramp_mps2: float | None) -> float:
    """The plan's expected duration, s: its waits, records and pauses, and its ramps at ``ramp_mps2``
    (None: not counted)."""
    duration_s, speed_mps = 0.0, 0.0
    for step in sweep_plan(cfg):
        if isinstance(step, SetSpeed):
            duration_s += abs(step.speed_mps - speed_mps) / ramp_mps2 if ramp_mps2 else 0.0
            speed_mps = step.speed_mps
        elif isinstance(step, Wait | Record):
            duration_s += step.duration_s
        elif isinstance(step, Action) and step.name == "pause":
            duration_s += float(step.params.get("seconds", 0.0))
    return duration_s


def load_sweep_config(path: str | Path, section: str = "sweep") -> SweepConfig:
    """Read the ``section`` of a YAML file as a :class:`SweepConfig` (errors name key and file)."""
    data = load_yaml(path)
    if section not in data:
        raise ConfigError("section is missing", key=section, path=str(path))
    body = data[section]
    if isinstance(body, dict) and isinstance(body.get("range"), dict):
        # Checked alone first: through the optional field the reason would be lost.
        from_mapping(SpeedRange, body["range"], path=str(path), key=f"{section}.range")
    return from_mapping(SweepConfig, body, path=str(path), key=section)
