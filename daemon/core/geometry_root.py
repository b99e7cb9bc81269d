"""The root's position along the rest axis and the flag's length, from the motion field.

Both work in the flag's frame (u along the axis, v across it) on the events and the
:class:`~.geometry_field.FieldFit` of :mod:`.geometry`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import ndimage
from scipy.optimize import nnls

from flagtrack.daemon.core.geometry_field import FieldFit, References

_REACH = 0.3
"""The root is searched at most this fraction of the flag's extent behind its first moving point."""
_FIT_LOW = 1.5
"""The extrapolation fits the amplitudes from this many times the onset amplitude (the counts of the
first moving pixels undershoot the straight-line relation to the amplitude)..."""
_FIT_HIGH = 1.5
"""... up to this many pixels (measured on the simulator's grid; docs/first-day.md)."""


def _filled(values: np.ndarray, at: np.ndarray) -> np.ndarray:
    good = np.isfinite(values)
    if good.sum() < 2:
        return np.zeros_like(at)
    return np.interp(at, at[good], values[good])


def _band_counts(
    u: np.ndarray, v: np.ndarray, fit: FieldFit, edges: np.ndarray, scale: float, density: float
) -> tuple[np.ndarray, np.ndarray]:
    """Events per bin of ``edges`` within the flag's lateral reach less the expected noise, and that
    expected noise."""
    centres = fit.centres
    amplitude = ndimage.maximum_filter1d(_filled(np.sqrt(2.0) * fit.rms, centres), 5)
    flank = np.abs(fit.flank[np.isfinite(fit.flank)])
    margin = 2.0 * (float(np.median(flank)) if len(flank) else scale) + 2.0 * scale
    mids = 0.5 * (edges[1:] + edges[:-1])
    half_at_bins = 1.3 * np.interp(mids, centres, amplitude) + margin
    bin_of = np.clip(np.searchsorted(edges, u, side="right") - 1, 0, len(mids) - 1)
    half = half_at_bins[bin_of]
    off = np.abs(v - np.interp(u, centres, _filled(fit.mean, centres)))
    inside = (off <= half) & (u >= edges[0]) & (u < edges[-1])
    counts = np.bincount(bin_of[inside], minlength=len(mids)).astype(np.float64)
    noise = density * 2 * half_at_bins * np.diff(edges)
    return counts - noise, noise


def _onset(counts: np.ndarray, noise: np.ndarray, start: int) -> int:
    """Lowest bin of the run of activity that reaches bin ``start`` (gaps under 6 bins bridged);
    active: the 5-bin mean stands 3 standard deviations above the noise and at 1 event a bin."""
    smooth = ndimage.uniform_filter1d(counts.astype(np.float64), 5)
    active = smooth >= np.maximum(1.0, 3.0 * np.sqrt(noise / 5.0))
    first, quiet = start, 0
    for i in range(start, -1, -1):
        if active[i]:
            first, quiet = i, 0
        else:
            quiet += 1
            if quiet >= 6:
                break
    return first


def _count_slope(fit: FieldFit, counts_per_length: np.ndarray, scale: float, onset: float) -> float:
    """Events per unit length per unit amplitude above the onset: ``counts = k (amplitude - onset)``,
    fitted on the slices whose amplitude is well measured (1.5 to 5 pixels)."""
    amplitude = np.sqrt(2.0) * fit.rms
    finite = np.isfinite(amplitude)
    good = finite & (amplitude >= 1.5 * scale) & (amplitude <= 5 * scale)
    good &= fit.se < 0.2 * np.where(finite, amplitude, 0)
    if good.sum() < 3:
        good = finite & (amplitude > 2 * scale)
    if not good.any():
        return 1.0
    above = amplitude[good] - onset
    return float(max(np.sum(counts_per_length[good] * above) / np.sum(above**2), 1e-9))


def root_along_axis(
    u: np.ndarray, v: np.ndarray, fit: FieldFit, scale: float, onset: float, noise: float
) -> tuple[float, float]:
    """The root's u and the first moving point's u.

    Args:
        u, v: the flag's events in its frame.
        fit: their motion field.
        scale: size of a pixel, length units.
        onset: amplitude at which pixels start firing, length units.
        noise: noise events per unit area (uniform over the sensor).
    """
    centres = fit.centres
    extent = float(centres[-1] - centres[0])
    edges = np.arange(min(float(u.min()), fit.edges[0]) - 10 * scale, fit.edges[-1] + scale, scale)
    counts, expected = _band_counts(u, v, fit, edges, scale, noise)
    amplitude = np.sqrt(2.0) * fit.rms
    strong = np.flatnonzero(np.isfinite(amplitude) & (amplitude >= 1.5 * scale))
    start_u = centres[strong[0]] if len(strong) else centres[len(centres) // 2]
    first = _onset(counts, expected, int(np.clip(np.searchsorted(edges, start_u) - 1, 0, len(counts) - 1)))
    u_first = float(edges[first])
    per_length = _band_counts(u, v, fit, fit.edges, scale, noise)[0] / np.diff(fit.edges)
    k, h0 = _count_slope(fit, per_length, scale, onset), onset
    bin_ = float(edges[1] - edges[0])
    height = h0 + np.clip(counts, 0, None) / (k * bin_)
    sigma = np.sqrt(np.maximum(counts + 2 * expected, 3.0)) / (k * bin_)
    smooth = ndimage.uniform_filter1d(height, 5)
    after = np.arange(len(height)) >= first
    above = np.flatnonzero(after & (smooth > _FIT_HIGH * scale))
    last = int(above[0]) if len(above) else len(height) - 1
    begin = np.flatnonzero(after & (smooth >= _FIT_LOW * h0))
    begin_ = min(int(begin[0]) if len(begin) else first, last)
    rows = np.arange(begin_, last + 1)
    mids = 0.5 * (edges[rows] + edges[rows + 1])
    if len(rows) < 5:
        return u_first - h0 / max(float((smooth[last] - h0) / max(mids[-1] - u_first, bin_)), 1e-12), u_first
    return _extrapolate(mids, height[rows], sigma[rows], u_first - _REACH * extent, u_first), u_first


def _extrapolate(u: np.ndarray, h: np.ndarray, sigma: np.ndarray, lo: float, hi: float, n: int = 300) -> float:
    """The u where ``h`` extrapolates to zero: ``h^2 = s^2 (b0 + b1 s)``, s = u - root, b >= 0."""
    weight = 1.0 / (2.0 * np.maximum(h, 1e-9) * sigma)
    best, best_root = np.inf, hi
    span = float(u[-1] - lo)
    for root in np.linspace(lo, hi, n):
        s = (u - root) / span
        design = np.column_stack([s**2, s**3]) * weight[:, None]
        _, resid = nnls(design, h**2 * weight)
        if resid < best:
            best, best_root = resid, float(root)
    return best_root


def length_estimates(
    u: np.ndarray, v: np.ndarray, t_us: np.ndarray, fit: FieldFit, refs: References, u_root: float
) -> np.ndarray:
    """One length per window that shows the tip: the arc length, along the field's curve of that
    window, from the root to the window's farthest events near the curve (the third farthest, so a
    stray event cannot make it)."""
    centres = fit.centres
    mean = ndimage.uniform_filter1d(_filled(fit.mean, centres), 5, mode="nearest")
    curves = mean[None, :] + refs.values @ fit.smoothed_coef().T  # (windows, slices)
    slope = np.gradient(curves, centres, axis=1)
    stretch = np.where(centres[None, :] >= u_root, np.sqrt(1.0 + slope**2) - 1.0, 0.0)
    excess = np.cumsum(stretch * np.gradient(centres)[None, :], axis=1)
    step = float(refs.t_us[1] - refs.t_us[0])
    far = u > u_root + 0.5 * (float(u.max()) - u_root)
    window = np.clip(((t_us[far] - refs.t_us[0] + step / 2) // step).astype(np.int64), 0, len(refs.t_us) - 1)
    slice_ = np.clip(np.searchsorted(fit.edges, u[far]) - 1, 0, len(centres) - 1)
    scale = float(np.nanmedian(fit.scale)) if np.isfinite(fit.scale).any() else 1.0
    near = np.abs(v[far] - curves[window, slice_]) < 3.0 * scale
    window, tip_u = window[near], u[far][near]
    order = np.lexsort((tip_u, window))
    window, tip_u = window[order], tip_u[order]
    counts = np.bincount(window, minlength=len(refs.t_us))
    ends = np.cumsum(counts)
    shown = np.flatnonzero(counts >= 5)
    tip = tip_u[ends[shown] - 3]
    at = np.interp(tip, centres, np.arange(len(centres), dtype=np.float64))
    low = np.clip(at.astype(np.int64), 0, len(centres) - 2)
    frac = at - low
    extra = excess[shown, low] * (1 - frac) + excess[shown, low + 1] * frac
    return tip - u_root + extra


def root_onto_sensor(u_root: float, reach: float, on_sensor: Callable[[float], bool] | None) -> float:
    """``u_root``, or the nearest axis position downstream of it, within ``reach``, where
    ``on_sensor`` holds (a pole at the sensor's edge: the extrapolated root may land just off it);
    ``u_root`` when ``on_sensor`` is None (the sensor's size unknown) or holds nowhere there."""
    if on_sensor is None or on_sensor(u_root):
        return u_root
    for u in u_root + np.linspace(0.0, reach, 41)[1:]:
        if on_sensor(float(u)):
            return float(u)
    return u_root
