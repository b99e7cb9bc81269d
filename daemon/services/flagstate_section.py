"""The ``flag_state:`` section of a rig (light: the rig's config reads it without loading SciPy)."""

from __future__ import annotations

from dataclasses import dataclass

from flagtrack.daemon.core.flagstate_params import StateParams


@dataclass(frozen=True)
class FlagStateConfig:
    """The ``flag_state:`` section (the flag's length and rest frame are the tracker's).

    Attributes:
        interval_s: a state at least this often (camera time) when no cycle completes, s.
        max_cycle_s: a cycle longer than this is not flapping, s.
        hysteresis_over_l: how far below its centre the tip must swing before its next upward
            crossing counts (a cycle), over L.
        history_s: centrelines kept, s.
        centre_tau_s: time constant of the tip's moving average (the centre it crosses), s.
        twi: compute each cycle's travelling-wave index.
    """

    interval_s: float = 0.1
    max_cycle_s: float = 1.0
    hysteresis_over_l: float = 0.01
    history_s: float = 2.0
    centre_tau_s: float = 0.5
    twi: bool = True

    def params(self, length: float, root: tuple[float, float], direction_deg: float) -> StateParams:
        """The core's parameters for a flag of ``length`` at ``root`` along ``direction_deg``."""
        return StateParams(
            length=length,
            root=root,
            direction_deg=direction_deg,
            interval_s=self.interval_s,
            max_cycle_s=self.max_cycle_s,
            hysteresis_over_l=self.hysteresis_over_l,
            history_s=self.history_s,
            centre_tau_s=self.centre_tau_s,
            twi=self.twi,
        )

    def __post_init__(self) -> None:
        self.params(1.0, (0.0, 0.0), 0.0)  # (the core's checks, as a ValueError naming them)
