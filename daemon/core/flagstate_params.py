"""The parameters of the flag's cycle-by-cycle state (:mod:`.flagstate`), apart from it so that a rig's
config reads them without loading SciPy."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class StateParams:
    """How the state is made (the ``flag_state:`` section; the flag's frame from the tracker's).

    Attributes:
        length: the flag's length L, in the centrelines' units.
        root, direction_deg: the flag's rest frame (lateral = perpendicular to the rest direction).
        interval_s: a state at least this often, camera seconds, when no cycle completes.
        max_cycle_s: a cycle longer than this is not flapping (nor is a flag whose last cycle ended
            longer ago), s.
        hysteresis_over_l: how far below the centre the tip must swing before an upward crossing
            counts, over L.
        history_s: updates kept, s; at least ``max_cycle_s``.
        centre_tau_s: time constant of the tip's moving average (the centre it crosses), s.
        twi: compute the travelling-wave index of each cycle (an SVD of the cycle's lateral displacement).
    """

    length: float
    root: tuple[float, float] = (0.0, 0.0)
    direction_deg: float = 0.0
    interval_s: float = 0.1
    max_cycle_s: float = 1.0
    hysteresis_over_l: float = 0.01
    history_s: float = 2.0
    centre_tau_s: float = 0.5
    twi: bool = True

    def __post_init__(self) -> None:
        if not min(self.length, self.interval_s, self.max_cycle_s, self.centre_tau_s) > 0:
            raise ValueError("length, interval_s, max_cycle_s and centre_tau_s must be positive")
        if not self.hysteresis_over_l >= 0 or not self.history_s >= self.max_cycle_s:
            raise ValueError("need hysteresis_over_l >= 0 and history_s >= max_cycle_s")
