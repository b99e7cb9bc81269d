"""Put a point sensor's clock on the camera's: external-trigger pulses, or cross-correlation.

Convention: the sensor clock reads ``t_sensor = t_cam + offset + drift * (t_cam - t_ref)``, all in
µs, ``drift`` dimensionless (reported in ppm). Three estimates, from the best to the roughest:

- **trigger**: the same pulses seen by both (the camera's trigger input, and the sensor that drove
  them or recorded them): each sensor pulse is paired with the nearest camera pulse after the prior
  offset is applied, pairs off the median by more than a tolerance are dropped, and a straight
  line through the pairs gives offset and drift; the uncertainty is the residual scatter over
  the square root of the pairs (never below the two 1 µs stamps' rounding). Pulses repeat, so the
  prior must be within half a trigger period.
- **xcorr**: the lag that maximises the correlation of the two displacement signals (sensor
  interpolated at the reconstruction's times), searched around the prior, refined by parabolas;
  the uncertainty is the scatter of the same estimate over contiguous blocks of the record. It
  also holds the reconstruction's own delay, so it differs from the trigger estimate by that.
- **coarse**: from wall-clock stamps of when each side's data became available (a prior, ms).

Pure numpy: no clock, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

_STAMP_RMS_US = 1.0 / math.sqrt(6.0)  # two timestamps rounded to 1 µs
_COARSE_POINTS = 2000


@dataclass(frozen=True)
class SyncParams:
    """How the sensor clock is put on the camera clock (config ``sensor.sync``).

    Attributes:
        mode: ``auto`` (trigger pulses when both sides have them, else cross-correlation), ``trigger``,
            ``xcorr`` or ``none`` (the two clocks are taken as one).
        trigger_channel: camera trigger input the pulses arrive on.
        trigger_edge: 1 rising, 0 falling: the edge both sides stamp.
        tolerance_us: pulse pairs further than this from the median offset are not paired.
        max_lag_ms: cross-correlation search half-width around the prior offset, ms (keep it under
            half a flapping period).
        min_correlation: smallest peak correlation accepted (a still flag has no signal to correlate).
        blocks: contiguous blocks for the cross-correlation's uncertainty.
    """

    mode: Literal["auto", "trigger", "xcorr", "none"] = "auto"
    trigger_channel: int = 0
    trigger_edge: int = 1
    tolerance_us: float = 200.0
    max_lag_ms: float = 20.0
    min_correlation: float = 0.8
    blocks: int = 8

    def __post_init__(self) -> None:
        if self.tolerance_us <= 0 or self.max_lag_ms <= 0 or self.blocks < 2:
            raise ValueError("tolerance_us and max_lag_ms must be positive and blocks >= 2")
        if not 0 < self.min_correlation < 1 or self.trigger_edge not in (0, 1):
            raise ValueError("min_correlation must be in (0, 1) and trigger_edge 0 or 1")


@dataclass(frozen=True)
class ClockSync:
    """A sensor-to-camera clock mapping and how well it is known.

    Attributes:
        method: ``trigger``, ``xcorr``, ``coarse`` or ``none`` (no estimate: offset 0 assumed).
        offset_us: sensor minus camera clock at ``t_ref_us``, µs (NaN when unknown).
        uncertainty_us: standard uncertainty of ``offset_us``, µs.
        drift_ppm: relative rate of the sensor clock, ppm (0 when not estimated).
        t_ref_us: camera time the offset refers to, µs.
        n: pulse pairs used (trigger) or blocks (xcorr).
        quality: residual RMS of the pairs, µs (trigger), or the peak correlation (xcorr).
        note: why there is no estimate, or what to watch.
    """

    method: str
    offset_us: float = math.nan
    uncertainty_us: float = math.nan
    drift_ppm: float = 0.0
    t_ref_us: float = 0.0
    n: int = 0
    quality: float = math.nan
    note: str = ""

    @property
    def ok(self) -> bool:
        """True when this is an estimate (finite offset)."""
        return math.isfinite(self.offset_us)

    def to_camera_us(self, t_sensor_us: np.ndarray) -> np.ndarray:
        """Sensor-clock times (µs) to camera-clock times (µs, float); offset 0 when unknown."""
        offset = self.offset_us if self.ok else 0.0
        rate = 1.0 + self.drift_ppm * 1e-6
        return self.t_ref_us + (np.asarray(t_sensor_us, dtype=np.float64) - self.t_ref_us - offset) / rate


def trigger_sync(
    camera_us: np.ndarray, sensor_us: np.ndarray, *, prior_offset_us: float = 0.0, tolerance_us: float = 200.0
) -> ClockSync:
    """Offset and drift from pulses stamped by both clocks (see the module docstring).

    Args:
        camera_us: (n_c,) pulse times on the camera clock, µs.
        sensor_us: (n_s,) the same pulses on the sensor clock, µs (some may be missing on either side).
        prior_offset_us: rough offset (within half a pulse period of the truth).
        tolerance_us: pairs further than this from the median offset are dropped.
    """
    cam = np.sort(np.asarray(camera_us, dtype=np.float64))
    sen = np.sort(np.asarray(sensor_us, dtype=np.float64))
    if len(cam) == 0 or len(sen) == 0:
        return ClockSync("none", note=f"no trigger pulses ({len(cam)} on the camera, {len(sen)} from the sensor)")
    idx = _nearest(cam, sen - prior_offset_us)
    diff = sen - cam[idx]
    keep = np.abs(diff - np.median(diff)) <= tolerance_us
    keep &= _first_of_each(idx, np.abs(diff - np.median(diff)))
    c, s = cam[idx][keep], sen[keep]
    if len(c) == 0:
        return ClockSync("none", note="no trigger pulse pairs within the tolerance")
    period = float(np.median(np.diff(cam))) if len(cam) > 1 else math.nan
    note = ""
    if math.isfinite(period) and abs(float(np.median(diff)) - prior_offset_us) > 0.25 * period:
        note = (
            f"offset {np.median(diff):.0f} us is far from the prior {prior_offset_us:.0f} us "
            f"(pulse period {period:.0f} us)"
        )
    t_ref = float(np.mean(c))
    if len(c) >= 3 and np.ptp(c) > 0:
        slope, intercept = np.polyfit(c - t_ref, s - c, 1)
        residual = (s - c) - (intercept + slope * (c - t_ref))
        scatter = max(float(np.sqrt(np.sum(residual**2) / (len(c) - 2))) if len(c) > 2 else 0.0, _STAMP_RMS_US)
        return ClockSync(
            "trigger",
            float(intercept),
            scatter / math.sqrt(len(c)),
            float(slope) * 1e6,
            t_ref,
            len(c),
            float(np.sqrt(np.mean(residual**2))),
            note,
        )
    spread = float(np.std(s - c)) if len(c) > 1 else 0.0
    return ClockSync(
        "trigger",
        float(np.mean(s - c)),
        max(spread, _STAMP_RMS_US) / math.sqrt(len(c)),
        0.0,
        t_ref,
        len(c),
        spread,
        note or f"only {len(c)} pulse pair(s): drift not estimated",
    )


def _nearest(sorted_values: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Index of the nearest element of ``sorted_values`` for each of ``at``."""
    i = np.clip(np.searchsorted(sorted_values, at), 1, max(len(sorted_values) - 1, 1))
    if len(sorted_values) == 1:
        return np.zeros(len(at), dtype=np.int64)
    left = sorted_values[i - 1]
    right = sorted_values[np.minimum(i, len(sorted_values) - 1)]
    return np.where(np.abs(at - left) <= np.abs(right - at), i - 1, i)


def _first_of_each(idx: np.ndarray, distance: np.ndarray) -> np.ndarray:
    """Mask keeping, for each repeated index, only the entry with the smallest distance."""
    order = np.lexsort((distance, idx))
    keep = np.zeros(len(idx), dtype=bool)
    first = np.ones(len(order), dtype=bool)
    first[1:] = idx[order][1:] != idx[order][:-1]
    keep[order[first]] = True
    return keep


def coarse_offset_us(
    sensor_t_us: np.ndarray, sensor_wall_ns: np.ndarray, camera_t_us: np.ndarray, camera_wall_ns: np.ndarray
) -> ClockSync:
    """A rough offset from wall-clock stamps of when each side's data became available.

    The camera clock is interpolated (piecewise linearly, so a camera that skips or runs slower
    than real time is followed) at the wall time each sensor batch arrived; the offset is the
    median of the differences, its uncertainty their scatter (at least 1 ms: both sides' delivery
    delays are unknown).

    Args:
        sensor_t_us, sensor_wall_ns: sensor-clock time of the newest sample and the wall time (ns) it arrived.
        camera_t_us, camera_wall_ns: camera-clock time and the wall time (ns) the camera data arrived.
    """
    s_t, s_w = np.asarray(sensor_t_us, dtype=np.float64), np.asarray(sensor_wall_ns, dtype=np.float64)
    c_t, c_w = np.asarray(camera_t_us, dtype=np.float64), np.asarray(camera_wall_ns, dtype=np.float64)
    if len(c_t) == 0 or len(s_t) == 0:
        return ClockSync("none", note="no wall-clock stamps")
    order = np.argsort(c_w, kind="stable")
    c_t, c_w = np.maximum.accumulate(c_t[order]), c_w[order]
    inside = (s_w >= c_w[0]) & (s_w <= c_w[-1])
    if not np.any(inside):  # no overlap in wall time: assume both clocks run at the wall's rate
        differences = np.array([np.median(s_t - s_w * 1e-3) - np.median(c_t - c_w * 1e-3)])
    else:
        differences = s_t[inside] - np.interp(s_w[inside], c_w, c_t)
    offset = float(np.median(differences))
    return ClockSync("coarse", offset, max(_mad(differences), 1000.0), 0.0, float(np.median(c_t)), len(differences))


def _mad(values: np.ndarray) -> float:
    """Median absolute deviation scaled to a standard deviation (0 for no values)."""
    return float(1.4826 * np.median(np.abs(values - np.median(values)))) if len(values) else 0.0


def xcorr_sync(
    t_recon_s: np.ndarray,
    y_recon: np.ndarray,
    t_sensor_us: np.ndarray,
    y_sensor: np.ndarray,
    *,
    prior_offset_us: float = 0.0,
    max_lag_us: float = 20_000.0,
    min_correlation: float = 0.8,
    blocks: int = 8,
    smooth_samples: float = 2.0,
) -> ClockSync:
    """The offset that best lines the sensor signal up with the reconstruction (see the module docstring).

    Args:
        t_recon_s, y_recon: reconstruction times (camera clock, s) and lateral displacement at the beam.
        t_sensor_us, y_sensor: sensor times (sensor clock, µs) and lateral displacement (NaN = missing).
        prior_offset_us: centre of the search.
        max_lag_us: half-width of the search.
        min_correlation: smallest peak correlation accepted.
        blocks: contiguous blocks for the uncertainty.
        smooth_samples: both signals are first smoothed by a Gaussian of this many samples (zero
            phase, so no lag): without it, interpolating noisy samples smooths them more between
            samples than on them, which pulls the peak off the true lag by up to a tenth of a
            sample period at 1 % noise.
    """
    tr = np.asarray(t_recon_s, dtype=np.float64) * 1e6
    yr = smooth_runs(tr, np.asarray(y_recon, dtype=np.float64), smooth_samples)
    ok = np.isfinite(yr)
    tr, yr = tr[ok], yr[ok]
    ts = np.asarray(t_sensor_us, dtype=np.float64)
    ys = smooth_runs(ts, np.asarray(y_sensor, dtype=np.float64), smooth_samples)
    good = np.isfinite(ys) & np.isfinite(ts)
    ts, ys = ts[good], ys[good]
    if len(tr) < 32 or len(ts) < 32:
        return ClockSync("none", note=f"too few samples to correlate ({len(tr)} updates, {len(ts)} sensor samples)")
    signal = _Signal(ts, ys)
    step = max(0.5 * min(signal.step_us, float(np.median(np.diff(tr)))), 1.0)
    lag, r = _search(signal, tr, yr, prior_offset_us - max_lag_us, prior_offset_us + max_lag_us, step)
    if not math.isfinite(r):
        return ClockSync("none", note="nothing to correlate (a constant signal: a still flag?)")
    if r < min_correlation:
        anti = _anti(signal, tr, yr, prior_offset_us, max_lag_us, step, min_correlation)
        hint = " (strongly negative: is beam.direction right?)" if anti else ""
        return ClockSync("none", quality=r, note=f"peak correlation {r:.2f} below {min_correlation:g}{hint}")
    if math.isfinite(lag) and abs(lag - prior_offset_us) > max_lag_us - step:
        return ClockSync(
            "none",
            quality=r,
            note=f"correlation peak at the edge of the search range ({lag:.0f} us, "
            f"prior {prior_offset_us:.0f} +- {max_lag_us:.0f} us)",
        )
    per_block = []
    for part in np.array_split(np.arange(len(tr)), blocks):
        if len(part) >= 16:
            lag_k, r_k = _search(signal, tr[part], yr[part], lag - 2 * step, lag + 2 * step, step / 4)
            if math.isfinite(r_k):
                per_block.append(lag_k)
    unc = float(np.std(per_block, ddof=1) / math.sqrt(len(per_block))) if len(per_block) >= 2 else math.nan
    return ClockSync("xcorr", lag, max(unc, _STAMP_RMS_US), 0.0, float(np.mean(tr)), len(per_block), r)


def smooth_runs(t: np.ndarray, y: np.ndarray, sigma_samples: float, gap_factor: float = 2.5) -> np.ndarray:
    """Gaussian smoothing over sample index (NaN-aware), within runs without time gaps."""
    if sigma_samples <= 0 or len(y) < 3:
        return y
    radius = int(math.ceil(3 * sigma_samples))
    kernel = np.exp(-0.5 * (np.arange(-radius, radius + 1) / sigma_samples) ** 2)
    steps = np.diff(t)
    finite_steps = steps[np.isfinite(steps)]
    median = float(np.median(finite_steps)) if len(finite_steps) else 0.0
    edges = np.concatenate([[0], np.flatnonzero(~(steps <= gap_factor * median)) + 1, [len(y)]])
    out = np.full(len(y), np.nan)
    for a, b in zip(edges[:-1], edges[1:]):
        part = y[a:b]
        weight = np.isfinite(part).astype(np.float64)
        num = np.convolve(np.where(weight > 0, part, 0.0), kernel)[radius : radius + b - a]
        den = np.convolve(weight, kernel)[radius : radius + b - a]
        with np.errstate(invalid="ignore", divide="ignore"):
            out[a:b] = np.where((den >= 0.5 * kernel.sum()) & (weight > 0), num / den, np.nan)
    return out


class _Signal:
    """The sensor signal, interpolated only between neighbouring samples (no bridging of gaps)."""

    def __init__(self, t_us: np.ndarray, y: np.ndarray) -> None:
        self.t, self.y = t_us, y
        self.step_us = float(np.median(np.diff(t_us)))
        self.max_gap_us = 3.0 * self.step_us

    def at(self, t_us: np.ndarray) -> np.ndarray:
        i = np.searchsorted(self.t, t_us, side="right")
        inside = (i > 0) & (i < len(self.t))
        i0 = np.clip(i - 1, 0, len(self.t) - 2)
        t0, t1 = self.t[i0], self.t[i0 + 1]
        ok = inside & (t1 - t0 <= self.max_gap_us)
        out = self.y[i0] + (t_us - t0) / (t1 - t0) * (self.y[i0 + 1] - self.y[i0])
        return np.where(ok, out, np.nan)


def _correlation(signal: _Signal, tr: np.ndarray, yr: np.ndarray, lag_us: float) -> float:
    ys = signal.at(tr + lag_us)
    ok = np.isfinite(ys)
    if ok.sum() < max(16, len(tr) // 2):
        return math.nan
    a, b = yr[ok] - yr[ok].mean(), ys[ok] - ys[ok].mean()
    denom = math.sqrt(float(a @ a) * float(b @ b))
    return float(a @ b) / denom if denom > 0 else math.nan


def _search(
    signal: _Signal, tr: np.ndarray, yr: np.ndarray, lo_us: float, hi_us: float, step_us: float
) -> tuple[float, float]:
    """Best lag on a grid, then twice a parabola-refined finer grid; returns (lag, correlation).

    The first (widest) grid looks at no more than ``_COARSE_POINTS`` updates, evenly spread.
    """
    stride = max(1, len(tr) // _COARSE_POINTS)
    for i in range(3):
        t_use, y_use = (tr[::stride], yr[::stride]) if i == 0 else (tr, yr)
        lags = np.arange(lo_us, hi_us + 0.5 * step_us, step_us)
        scores = np.array([_correlation(signal, t_use, y_use, float(lag)) for lag in lags])
        if not np.any(np.isfinite(scores)):
            return math.nan, math.nan
        k = int(np.nanargmax(scores))
        best, r = float(lags[k]), float(scores[k])
        if 0 < k < len(lags) - 1 and np.all(np.isfinite(scores[k - 1 : k + 2])):
            a, b, c = scores[k - 1 : k + 2]
            denom = a - 2 * b + c
            if denom < 0:
                best += 0.5 * step_us * (a - c) / denom
        lo_us, hi_us, step_us = best - 2 * step_us / 5, best + 2 * step_us / 5, step_us / 5
    return best, r


def _anti(
    signal: _Signal, tr: np.ndarray, yr: np.ndarray, prior: float, max_lag: float, step: float, min_correlation: float
) -> bool:
    """True when the signals are strongly anti-correlated (a sign error in the beam's direction)."""
    lags = np.arange(prior - max_lag, prior + max_lag + 0.5 * step, step)
    scores = np.array([_correlation(signal, tr, yr, float(lag)) for lag in lags])
    return bool(np.any(np.isfinite(scores))) and float(np.nanmin(scores)) < -min_correlation
