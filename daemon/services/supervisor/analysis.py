"""Per-point numbers from the centrelines of a recording: A/L, f, travelling-wave index, Delta_RMS/L."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.metrics import (
    flapping_frequency_hz,
    lateral_displacement,
    tip_amplitude_over_l,
    travelling_wave_index_in_time,
)

MAX_CYCLES = 100_000
"""Cycles the amplitude spread is measured over at most (a point records seconds to minutes)."""
MAX_GAP_S = 60.0
"""Updates of one point are at most this far apart in camera time; one further on is not the point's
(the frequency's resampling grid would span the gap: a day of 0.25 ms steps is 3 GB)."""


@dataclass(frozen=True)
class PointMetrics:
    """What a point's centrelines say (NaN when they cannot say it); ``lost_fraction``: of the
    updates, those whose ``lost`` is 1; ``stale_fraction``: those whose ``stale`` is 1 (a shape
    remembered, not measured); ``shed_fraction``: :func:`shed_fraction`."""

    amplitude_over_l: float = math.nan
    amplitude_std_over_l: float = math.nan
    frequency_hz: float = math.nan
    twi: float = math.nan
    delta_rms_over_l: float = math.nan
    updates: int = 0
    delta_rms_std_over_l: float = math.nan
    lost_fraction: float = math.nan
    shed_fraction: float = math.nan
    stale_fraction: float = math.nan


def point_metrics(
    batches: list[CentrelineBatch],
    length: float,
    root: tuple[float, float],
    direction_deg: float,
    cycles_window: int = 1,
) -> PointMetrics:
    """A/L (half peak-to-peak of the tip's lateral displacement, and its spread over cycles), f, TWI, Delta_RMS/L
    (time mean and standard deviation).

    Args:
        batches: the point's centrelines, time order (updates that are not, and batches whose samples
            or joints differ from the first's, are left out: :func:`usable_batches`).
        length: flag length L (same units as the centrelines).
        root, direction_deg: the flag's rest frame (lateral = perpendicular to the rest direction).
        cycles_window: cycles per amplitude estimate when computing the spread.
    """
    batches = usable_batches(batches)
    if not batches:
        return PointMetrics()
    batch = CentrelineBatch.concatenate(batches)
    n = len(batch)
    if n < 8:
        return PointMetrics(
            updates=n,
            lost_fraction=float(batch.lost.mean()) if n else math.nan,
            shed_fraction=shed_fraction(batch),
            stale_fraction=float(batch.stale.mean()) if n else math.nan,
        )
    lateral = lateral_displacement(batch.x, batch.y, root, direction_deg)
    tip = lateral[:, -1]
    amplitude = tip_amplitude_over_l(tip, length)
    frequency = flapping_frequency_hz(batch.t_s, tip)  # gaps (dropped packets) are allowed for
    spread = _amplitude_spread(batch.t_s, tip, length, frequency, cycles_window)
    twi = travelling_wave_index_in_time(batch.t_s, lateral)
    delta = batch.delta_rms[np.isfinite(batch.delta_rms)] / length
    return PointMetrics(
        amplitude,
        spread,
        frequency,
        twi,
        float(delta.mean()) if len(delta) else math.nan,
        n,
        float(delta.std()) if len(delta) else math.nan,
        float(batch.lost.mean()),
        shed_fraction(batch),
        float(batch.stale.mean()),
    )


def shed_fraction(batch: CentrelineBatch) -> float:
    """The share of the camera time from the first update to the last that the live tracker shed:
    each update's ``shed`` is the share of the time since the update before it (NaN for fewer than
    two updates)."""
    if len(batch) < 2 or not batch.t_s[-1] > batch.t_s[0]:
        return math.nan
    return float(np.sum(batch.shed[1:] * np.diff(batch.t_s)) / (batch.t_s[-1] - batch.t_s[0]))


def usable_batches(batches: list[CentrelineBatch]) -> list[CentrelineBatch]:
    """The batches that can be measured together: those shaped as the first (samples, joints), with
    only their updates at finite times after every earlier update, and at most :data:`MAX_GAP_S`
    after it, kept (a forged or restarted stream's updates that go back in time, or jump ahead, are
    dropped, not sorted in). O(updates)."""
    kept: list[CentrelineBatch] = []
    last_t = -math.inf
    for batch in batches:
        if kept and (batch.x.shape[1] != kept[0].x.shape[1] or batch.joints_x.shape[1] != kept[0].joints_x.shape[1]):
            continue
        t_s = np.asarray(batch.t_s, dtype=float)
        finite = np.isfinite(t_s)
        before = np.maximum.accumulate(np.concatenate([[last_t], np.where(finite, t_s, -math.inf)]))[:-1]
        keep = finite & (t_s > before)  # after every update kept so far
        if np.isfinite(last_t):  # and not far after them (time may only step on from the first)
            keep &= t_s - np.maximum(before, last_t) <= MAX_GAP_S
        else:
            keep &= t_s - np.where(np.isfinite(before), before, t_s) <= MAX_GAP_S
        if not keep.any():
            continue
        chosen = batch if keep.all() else batch.select(keep)
        kept.append(chosen)
        last_t = float(chosen.t_s[-1])
    return kept


def _amplitude_spread(t_s: np.ndarray, tip: np.ndarray, length: float, frequency_hz: float, cycles: int) -> float:
    """Standard deviation of A/L measured cycle by cycle (error bars of the paper's figure 5h)."""
    if not np.isfinite(frequency_hz) or frequency_hz <= 0:
        return math.nan
    period_s = cycles / frequency_hz
    if (t_s[-1] - t_s[0]) / period_s > MAX_CYCLES:  # (a point records seconds: times this far apart are not one)
        return math.nan
    edges = np.arange(t_s[0], t_s[-1], period_s)
    values = [tip_amplitude_over_l(tip[(t_s >= a) & (t_s < a + period_s)], length) for a in edges[:-1]]
    values = [v for v in values if np.isfinite(v)]
    return float(np.std(values)) if len(values) >= 2 else math.nan
