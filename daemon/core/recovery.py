"""Scores of a reconstruction through a disruption (issue 19's targets), against the known shape.

Pure numpy: per-update shape error ``eps`` (epsilon_RMS / L), the tracker's ``/lost`` and whether the
window had events in the flag's region; the disruption's end; the flapping period.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

ON_FLAG = 0.01
"""An update is on the flag when epsilon_RMS <= this L (the target's "back on the flag")."""
OFF_FLAG = 0.05
"""An update is off the flag when epsilon_RMS > this L (where ``/lost`` should be set)."""


@dataclass(frozen=True)
class RecoveryScores:
    """How a reconstruction went through a disruption.

    Attributes:
        recovery_periods: time from the disruption's end until every later update is on the flag,
            in flapping periods (0: never off after the end; inf: not back by the recording's end).
        max_eps_after: largest epsilon_RMS / L from the end plus ``grace_periods`` on.
        false_lost: fraction of the updates on the flag that say ``lost`` (NaN if none).
        hit: fraction of the updates off the flag, with events in the flag's region, that say
            ``lost`` (NaN if none).
        n_off: updates off the flag with events.
    """

    recovery_periods: float
    max_eps_after: float
    false_lost: float
    hit: float
    n_off: int


def recovery_scores(
    t_s: np.ndarray,
    eps: np.ndarray,
    lost: np.ndarray,
    has_events: np.ndarray,
    end_s: float,
    period_s: float,
    grace_periods: float = 0.5,
) -> RecoveryScores:
    """Score one reconstruction; arrays are (n_t,) per update (``eps`` relative to L)."""
    after = t_s >= end_s
    off_after = np.nonzero(after & (eps > ON_FLAG))[0]
    if len(off_after) == 0:
        recovery = 0.0
    elif off_after[-1] == len(t_s) - 1:
        recovery = math.inf
    else:
        recovery = max(float(t_s[off_after[-1] + 1] - end_s), 0.0) / period_s
    late = t_s >= end_s + grace_periods * period_s
    on = eps <= ON_FLAG
    off = (eps > OFF_FLAG) & has_events
    lost_b = np.asarray(lost, dtype=bool)
    return RecoveryScores(
        recovery_periods=recovery,
        max_eps_after=float(eps[late].max()) if late.any() else math.nan,
        false_lost=float(lost_b[on].mean()) if on.any() else math.nan,
        hit=float(lost_b[off].mean()) if off.any() else math.nan,
        n_off=int(off.sum()),
    )
