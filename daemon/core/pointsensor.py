"""A point sensor against the reconstruction: the flag's lateral displacement at one fixed position.

The paper (Raynaud & Mulleners 2024, section 4, figure 5c-g) checks every reconstruction against a
laser distance sensor aimed across the flag at ``x/L = 0.73``: the reconstruction's lateral
displacement there is the intersection of the smoothed centreline with the beam (the line
``x = x_fixed`` of the flag's rest frame), and the error ``e(t)`` is the difference of the two
signals. Pure numpy: no clock, no I/O.

Rest frame: origin at the root, ``xi`` along the rest direction, ``eta`` perpendicular to it
(positive to its left), the same frame as :func:`~flagtrack.daemon.core.metrics.lateral_displacement`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BeamParams:
    """Where the point sensor looks and how its readings become a lateral displacement.

    ``lateral = direction * (reading - zero_reading) * units_per_reading`` in the tracker's length
    units (px, or m with a calibration).

    Attributes:
        x_over_l: beam position along the rest direction from the root, fraction of L (paper: 0.73).
        units_per_reading: tracker length units per sensor unit (e.g. 0.001 m/mm, or px/mm).
        zero_reading: the reading of the flag at rest; ``None`` matches the two signals' means (a
            constant bias is then reported apart, not counted in the error).
        direction: +1 when the reading grows with the lateral displacement, -1 when it shrinks (a
            distance sensor on the positive side looking back at the flag).
    """

    x_over_l: float = 0.73
    units_per_reading: float = 1.0
    zero_reading: float | None = 0.0
    direction: int = 1

    def __post_init__(self) -> None:
        if not 0.0 < self.x_over_l <= 1.0:
            raise ValueError(f"x_over_l must be in (0, 1], got {self.x_over_l}")
        if not self.units_per_reading > 0:
            raise ValueError("units_per_reading must be positive")
        if self.direction not in (-1, 1):
            raise ValueError(f"direction must be +1 or -1, got {self.direction}")

    @property
    def side(self) -> int:
        """Side of the flag the sensor is on (+1: positive lateral side); its beam meets that side first."""
        return -self.direction


def reading_to_lateral(values: np.ndarray, beam: BeamParams) -> np.ndarray:
    """Sensor readings (sensor units) to lateral displacement (tracker units); NaN stays NaN."""
    zero = 0.0 if beam.zero_reading is None else beam.zero_reading
    return beam.direction * (np.asarray(values, dtype=np.float64) - zero) * beam.units_per_reading


def lateral_to_reading(lateral: np.ndarray, beam: BeamParams) -> np.ndarray:
    """Inverse of :func:`reading_to_lateral` (what a sensor reads for a lateral displacement)."""
    zero = 0.0 if beam.zero_reading is None else beam.zero_reading
    return zero + beam.direction * np.asarray(lateral, dtype=np.float64) / beam.units_per_reading


def beam_lateral(
    x: np.ndarray, y: np.ndarray, root: tuple[float, float], direction_deg: float, x_beam: float, side: int = 1
) -> np.ndarray:
    """Lateral displacement where each centreline crosses the beam ``xi = x_beam`` of the rest frame.

    Args:
        x, y: (n_t, n_s) centrelines (root first).
        root, direction_deg: the rest frame.
        x_beam: beam position along the rest direction from the root (same units).
        side: +1 if the sensor is on the positive lateral side (of several crossings it sees the
            largest lateral displacement), -1 for the negative side.

    Returns:
        (n_t,) lateral displacement at the crossing, NaN where the centreline does not reach the beam.
    """
    x, y = np.atleast_2d(np.asarray(x, dtype=np.float64)), np.atleast_2d(np.asarray(y, dtype=np.float64))
    d = math.radians(direction_deg)
    xi = (x - root[0]) * math.cos(d) + (y - root[1]) * math.sin(d)
    eta = -(x - root[0]) * math.sin(d) + (y - root[1]) * math.cos(d)
    if xi.shape[1] < 2:
        return np.full(len(xi), np.nan)
    a, b = xi[:, :-1] - x_beam, xi[:, 1:] - x_beam
    with np.errstate(invalid="ignore", divide="ignore"):
        crosses = (a * b <= 0) & (a != b)
        w = np.where(crosses, a / (a - b), np.nan)
    eta_cross = eta[:, :-1] + w * (eta[:, 1:] - eta[:, :-1])
    scored = np.where(np.isfinite(eta_cross), side * eta_cross, -np.inf)
    best = np.argmax(scored, axis=1)
    rows = np.arange(len(xi))
    out = eta_cross[rows, best]
    out[~np.isfinite(scored[rows, best])] = np.nan
    return out


@dataclass(frozen=True)
class SensorComparison:
    """The point sensor against the reconstruction at the sensor's sample times (camera clock).

    Attributes:
        t_s: (n,) camera-clock times of the compared sensor samples, s.
        y_sensor, y_recon: (n,) lateral displacement by the sensor and by the reconstruction (tracker units).
        error: (n,) ``e = y_recon - y_sensor`` (the bias removed when the means are matched).
        length: flag length L.
        bias: mean difference removed (0 when the sensor's zero is known).
        n_samples: sensor samples in the record; n_valid: of them not missing; n_compared: of them
            inside the reconstruction (no gap, a crossing).
    """

    t_s: np.ndarray
    y_sensor: np.ndarray
    y_recon: np.ndarray
    error: np.ndarray
    length: float
    bias: float
    n_samples: int
    n_valid: int
    n_compared: int

    @property
    def error_rms_over_l(self) -> float:
        """RMS of e / L (NaN when nothing was compared)."""
        return float(np.sqrt(np.mean(self.error**2)) / self.length) if self.n_compared else math.nan

    @property
    def error_max_over_l(self) -> float:
        """max |e| / L."""
        return float(np.max(np.abs(self.error)) / self.length) if self.n_compared else math.nan

    @property
    def abs_error_mean_over_l(self) -> float:
        """Time mean of |e| / L (the paper's figure 5g marker)."""
        return float(np.mean(np.abs(self.error)) / self.length) if self.n_compared else math.nan

    @property
    def abs_error_std_over_l(self) -> float:
        """Standard deviation of |e| / L (the paper's figure 5g error bar)."""
        return float(np.std(np.abs(self.error)) / self.length) if self.n_compared else math.nan


def recon_at(t_recon_s: np.ndarray, y_recon: np.ndarray, t_s: np.ndarray, max_gap_s: float | None = None) -> np.ndarray:
    """Linear interpolation of the reconstruction at times ``t_s``; NaN across gaps and outside.

    Args:
        t_recon_s, y_recon: (n_t,) update times (increasing) and values (NaN allowed).
        t_s: (n,) query times.
        max_gap_s: updates further apart than this are not interpolated between (default 2.5 times
            the median update interval).
    """
    t_recon_s, y_recon = np.asarray(t_recon_s, dtype=np.float64), np.asarray(y_recon, dtype=np.float64)
    t_s = np.asarray(t_s, dtype=np.float64)
    out = np.full(len(t_s), np.nan)
    if len(t_recon_s) < 2:
        return out
    if max_gap_s is None:
        max_gap_s = 2.5 * float(np.median(np.diff(t_recon_s)))
    i = np.searchsorted(t_recon_s, t_s, side="right")
    inside = (i > 0) & (i < len(t_recon_s))
    i0 = np.clip(i - 1, 0, len(t_recon_s) - 2)
    t0, t1 = t_recon_s[i0], t_recon_s[i0 + 1]
    y0, y1 = y_recon[i0], y_recon[i0 + 1]
    ok = inside & (t1 - t0 <= max_gap_s) & np.isfinite(y0) & np.isfinite(y1)
    w = np.where(ok, (t_s - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0)
    out[ok] = (y0 + w * (y1 - y0))[ok]
    return out


def compare_signals(
    t_recon_s: np.ndarray,
    y_recon: np.ndarray,
    t_sensor_s: np.ndarray,
    y_sensor: np.ndarray,
    length: float,
    *,
    match_means: bool = False,
    max_gap_s: float | None = None,
) -> SensorComparison:
    """e(t) at each valid sensor sample inside the reconstruction (the reconstruction interpolated there).

    Args:
        t_recon_s, y_recon: reconstruction times (camera clock, s) and lateral displacement at the beam.
        t_sensor_s, y_sensor: sensor sample times already on the camera clock, and their lateral displacement.
        length: L, for the ratios.
        match_means: remove the mean difference (the sensor's zero is not known).
        max_gap_s: see :func:`recon_at`.
    """
    t_sensor_s, y_sensor = np.asarray(t_sensor_s, dtype=np.float64), np.asarray(y_sensor, dtype=np.float64)
    valid = np.isfinite(y_sensor) & np.isfinite(t_sensor_s)
    at = recon_at(t_recon_s, y_recon, t_sensor_s[valid], max_gap_s)
    both = np.isfinite(at)
    t, ys, yr = t_sensor_s[valid][both], y_sensor[valid][both], at[both]
    error = yr - ys
    bias = float(np.mean(error)) if match_means and len(error) else 0.0
    return SensorComparison(t, ys, yr, error - bias, float(length), bias, len(y_sensor), int(valid.sum()), len(t))
