"""Accuracy and dynamics metrics of centreline series (Raynaud & Mulleners 2024, sections 3-4).

- tip error delta(t) and its RMS; shape error eps_RMS(t) along the arc length and its maximum;
- travelling-wave index by complex orthogonal decomposition (Feeny 2013) of the lateral
  displacement;
- Delta_RMS: RMS distance of an event cloud to a polyline;
- tip amplitude A/L (also over a short window with no known rest frame) and flapping frequency f.

Two series are compared on their common time span: the truth is interpolated (linearly in time,
linearly along s) at the reconstruction's times and arc lengths. A truth need only have times, arc
lengths and centrelines; the metrics that need more of it (its chain joints, its Delta_RMS) are
reported as not available, with the reason, when it lacks them. Pure numpy/scipy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import hilbert

from flagtrack.daemon.core.centreline import CentrelineBatch


@dataclass(frozen=True)
class AlignedPair:
    """Reconstruction and truth on the same times and arc lengths.

    Attributes:
        t_s: (n_t,) common times.
        s: (n_s,) common arc lengths.
        x, y: (n_t, n_s) reconstruction.
        x_ref, y_ref: (n_t, n_s) truth.
    """

    t_s: np.ndarray
    s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    x_ref: np.ndarray
    y_ref: np.ndarray


def _interp_weights(grid: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Left indices and weights of linear interpolation of ``grid`` (sorted) at ``at`` (inside)."""
    i0 = np.clip(np.searchsorted(grid, at, side="right") - 1, 0, max(len(grid) - 2, 0))
    if len(grid) < 2:
        return i0, np.zeros_like(at, dtype=np.float64)
    w = (at - grid[i0]) / (grid[i0 + 1] - grid[i0])
    return i0, np.clip(w, 0.0, 1.0)


def resample_s(values: np.ndarray, s: np.ndarray, s_new: np.ndarray) -> np.ndarray:
    """Linear resampling of (n_t, n_s) ``values`` from arc lengths ``s`` to ``s_new``."""
    if len(s) == len(s_new) and np.allclose(s, s_new, rtol=0, atol=1e-12 * max(1.0, float(np.abs(s).max()))):
        return values
    i0, w = _interp_weights(s, s_new)
    return values[:, i0] * (1 - w) + values[:, np.minimum(i0 + 1, len(s) - 1)] * w


def resample_t(values: np.ndarray, t_s: np.ndarray, t_new: np.ndarray) -> np.ndarray:
    """Linear resampling of (n_t, ...) ``values`` from times ``t_s`` to ``t_new`` (inside the span)."""
    i0, w = _interp_weights(t_s, t_new)
    w = w.reshape(-1, *([1] * (values.ndim - 1)))
    return values[i0] * (1 - w) + values[np.minimum(i0 + 1, len(t_s) - 1)] * w


def common_rows(recon: CentrelineBatch, truth: CentrelineBatch, time_tol_s: float = 1e-9) -> np.ndarray:
    """(n_t,) bool: the updates of ``recon`` inside the truth's time span (the times :func:`align` keeps)."""
    return (recon.t_s >= truth.t_s[0] - time_tol_s) & (recon.t_s <= truth.t_s[-1] + time_tol_s)


def align(recon: CentrelineBatch, truth: CentrelineBatch, time_tol_s: float = 1e-9) -> AlignedPair:
    """Put ``truth`` on the reconstruction's times (within the truth's span) and arc lengths.

    Raises:
        ValueError: the two series share no time.
    """
    keep = common_rows(recon, truth, time_tol_s)
    if not np.any(keep):
        raise ValueError(
            f"no common time: reconstruction {recon.t_s[:1]}..{recon.t_s[-1:]} s, truth {truth.t_s[0]}..{truth.t_s[-1]} s"
        )
    t_common = recon.t_s[keep]
    s_common = recon.s[recon.s <= truth.s[-1] * (1 + 1e-9) + 1e-12]
    x = resample_s(recon.x[keep], recon.s, s_common)
    y = resample_s(recon.y[keep], recon.s, s_common)
    xr = resample_t(resample_s(truth.x, truth.s, s_common), truth.t_s, t_common)
    yr = resample_t(resample_s(truth.y, truth.s, s_common), truth.t_s, t_common)
    return AlignedPair(t_common, s_common, x, y, xr, yr)


def trapezoid(values: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Trapezoid integral of (n_t, n_s) ``values`` over ``s`` along the last axis, (n_t,)."""
    return np.sum(0.5 * (values[:, 1:] + values[:, :-1]) * np.diff(s), axis=1)


def tip_error(recon: CentrelineBatch, truth: CentrelineBatch) -> tuple[np.ndarray, np.ndarray]:
    """Tip distance delta(t) on the common times; returns (t_s, delta), both (n_t,)."""
    pair = align(recon, truth)
    return pair.t_s, np.hypot(pair.x[:, -1] - pair.x_ref[:, -1], pair.y[:, -1] - pair.y_ref[:, -1])


def rms(values: np.ndarray) -> float:
    """Root mean square ignoring NaN (NaN if nothing is finite)."""
    values = np.asarray(values, dtype=np.float64)
    finite = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(finite**2))) if len(finite) else float("nan")


def eps_rms(recon: CentrelineBatch, truth: CentrelineBatch) -> tuple[np.ndarray, np.ndarray]:
    """Shape error eps_RMS(t) = sqrt(1/L int |r - r_ref|^2 ds) (trapezoid over the common s).

    Returns (t_s, eps), both (n_t,), L being the common arc-length span.
    """
    pair = align(recon, truth)
    sq = (pair.x - pair.x_ref) ** 2 + (pair.y - pair.y_ref) ** 2
    span = pair.s[-1] - pair.s[0]
    if span <= 0:
        return pair.t_s, np.sqrt(sq[:, 0])
    return pair.t_s, np.sqrt(trapezoid(sq, pair.s) / span)


def lateral_displacement(x: np.ndarray, y: np.ndarray, root: tuple[float, float], direction_deg: float) -> np.ndarray:
    """Displacement perpendicular to the rest direction (positive to its left), same shape as ``x``."""
    d = np.deg2rad(direction_deg)
    return -(np.asarray(x) - root[0]) * np.sin(d) + (np.asarray(y) - root[1]) * np.cos(d)


def rest_frame(batch: CentrelineBatch) -> tuple[tuple[float, float], float]:
    """Root (time mean of the first sample) and rest direction (mean root-to-tip chord), degrees."""
    root = (float(np.nanmean(batch.x[:, 0])), float(np.nanmean(batch.y[:, 0])))
    chord_x = float(np.nanmean(batch.x[:, -1] - batch.x[:, 0]))
    chord_y = float(np.nanmean(batch.y[:, -1] - batch.y[:, 0]))
    return root, float(np.degrees(np.arctan2(chord_y, chord_x)))


def travelling_wave_index(lateral: np.ndarray) -> float:
    """Travelling-wave index of a (n_t, n_s) lateral displacement (uniform time sampling).

    Complex orthogonal decomposition: the time mean is removed, the analytic signal in time is
    taken (Hilbert transform), the complex modes come from the SVD, and the index is the inverse
    condition number of [Re, Im] of the dominant spatial mode: 1 for a pure travelling wave, 0
    for a pure standing wave.
    """
    lateral = np.asarray(lateral, dtype=np.float64)
    if lateral.ndim != 2 or lateral.shape[0] < 4 or lateral.shape[1] < 2:
        raise ValueError(f"travelling_wave_index needs (n_t >= 4, n_s >= 2) samples, got {lateral.shape}")
    if not np.all(np.isfinite(lateral)):
        raise ValueError("travelling_wave_index: lateral displacement has NaN or inf")
    centred = lateral - lateral.mean(axis=0, keepdims=True)
    analytic = hilbert(centred, axis=0)
    _, _, vh = np.linalg.svd(analytic, full_matrices=False)
    mode = vh[0].conj()
    sv = np.linalg.svd(np.column_stack([mode.real, mode.imag]), compute_uv=False)
    return float(sv[1] / sv[0]) if sv[0] > 0 else 0.0


def travelling_wave_index_in_time(t_s: np.ndarray, lateral: np.ndarray, gap_factor: float = 5.0) -> float:
    """Travelling-wave index of (n_t, n_s) ``lateral`` sampled at times ``t_s`` (n_t,), over its longest
    run of updates without a gap (a step over ``gap_factor`` median steps), resampled on a uniform
    time grid (the modes need one); NaN when that run is short (< 16 updates) or not finite."""
    t_s, lateral = np.asarray(t_s, dtype=np.float64), np.asarray(lateral, dtype=np.float64)
    run = longest_run(t_s, gap_factor)
    t_run, lateral_run = t_s[run], lateral[run]
    if len(t_run) < 16 or lateral.ndim != 2 or lateral.shape[1] < 2 or not np.all(np.isfinite(lateral_run)):
        return math.nan
    uniform_t = np.linspace(t_run[0], t_run[-1], len(t_run))
    resampled = np.stack([np.interp(uniform_t, t_run, lateral_run[:, k]) for k in range(lateral.shape[1])], axis=1)
    return float(travelling_wave_index(resampled))


def longest_run(t_s: np.ndarray, gap_factor: float = 5.0) -> slice:
    """The longest stretch of updates without a gap (a step over ``gap_factor`` times the median step)."""
    steps = np.diff(t_s)
    if len(steps) == 0:
        return slice(0, len(t_s))
    breaks = np.flatnonzero(steps > gap_factor * np.median(steps)) + 1
    edges = np.concatenate([[0], breaks, [len(t_s)]])
    k = int(np.argmax(np.diff(edges)))
    return slice(int(edges[k]), int(edges[k + 1]))


def cloud_distance(
    events_x: np.ndarray, events_y: np.ndarray, line_x: np.ndarray, line_y: np.ndarray, block: int = 4096
) -> float:
    """Delta_RMS: RMS distance of events to the polyline (line_x, line_y), distance to segments.

    Args:
        events_x, events_y: (n,) event positions, same unit as the line.
        line_x, line_y: (m,) polyline vertices, m >= 1.
        block: events processed at once (bounds memory to block * m).
    """
    ex, ey = np.asarray(events_x, dtype=np.float64), np.asarray(events_y, dtype=np.float64)
    lx, ly = np.asarray(line_x, dtype=np.float64), np.asarray(line_y, dtype=np.float64)
    if len(ex) == 0:
        return float("nan")
    if len(lx) == 1:
        return float(np.sqrt(np.mean((ex - lx[0]) ** 2 + (ey - ly[0]) ** 2)))
    ax, ay = lx[:-1], ly[:-1]
    dx, dy = lx[1:] - ax, ly[1:] - ay
    len2 = np.maximum(dx * dx + dy * dy, 1e-300)
    total = 0.0
    for start in range(0, len(ex), block):
        px, py = ex[start : start + block, None], ey[start : start + block, None]
        u = np.clip(((px - ax) * dx + (py - ay) * dy) / len2, 0.0, 1.0)
        d2 = (px - ax - u * dx) ** 2 + (py - ay - u * dy) ** 2
        total += float(d2.min(axis=1).sum())
    return float(np.sqrt(total / len(ex)))


def tip_amplitude_over_l(tip_lateral: np.ndarray, length: float, robust: bool = False) -> float:
    """Tip amplitude A/L: half the peak-to-peak of the tip lateral displacement over L.

    With ``robust``, sqrt(2) times the standard deviation (exact for a sinusoid, insensitive to outliers).
    """
    values = np.asarray(tip_lateral, dtype=np.float64)
    values = values[np.isfinite(values)]
    if len(values) == 0:
        return float("nan")
    if robust:
        return float(np.sqrt(2.0) * np.std(values) / length)
    return float((values.max() - values.min()) / 2.0 / length)


def window_amplitude_over_l(
    root_x: np.ndarray, root_y: np.ndarray, tip_x: np.ndarray, tip_y: np.ndarray, length: float
) -> float:
    """A/L of a short window of updates when the rest frame is not known (a live view).

    Half the peak-to-peak of the tip's displacement perpendicular to the window's mean root-to-tip
    chord (the rest direction of a flag flapping about it), over ``length``. Arguments are (n,)
    positions of the root and the tip, one per update; updates with a NaN are left out. NaN if none is left.
    """
    root_x, root_y = np.asarray(root_x, dtype=np.float64), np.asarray(root_y, dtype=np.float64)
    tip_x, tip_y = np.asarray(tip_x, dtype=np.float64), np.asarray(tip_y, dtype=np.float64)
    ok = np.isfinite(root_x) & np.isfinite(root_y) & np.isfinite(tip_x) & np.isfinite(tip_y)
    if not np.any(ok):
        return float("nan")
    root = (float(root_x[ok].mean()), float(root_y[ok].mean()))
    direction = float(np.degrees(np.arctan2(np.mean(tip_y[ok] - root_y[ok]), np.mean(tip_x[ok] - root_x[ok]))))
    return tip_amplitude_over_l(lateral_displacement(tip_x[ok], tip_y[ok], root, direction), length)


def flapping_frequency_hz(t_s: np.ndarray, signal: np.ndarray, pad: int = 8, gap_factor: float = 5.0) -> float:
    """Dominant frequency of ``signal`` (e.g. tip lateral displacement), Hz, with sub-bin refinement.

    The signal is resampled on a uniform grid (median step), its mean removed, Hann-windowed and
    zero-padded ``pad`` times; the spectral peak is refined by a parabola through the log magnitudes
    of the three bins around it. Gaps (steps over ``gap_factor`` median steps, e.g. dropped packets)
    are set to zero rather than bridged: the peak stays where the flapping is, since the flag
    keeps its phase across a gap.
    """
    t_s, signal = np.asarray(t_s, dtype=np.float64), np.asarray(signal, dtype=np.float64)
    ok = np.isfinite(signal)
    t_s, signal = t_s[ok], signal[ok]
    if len(t_s) < 8:
        return float("nan")
    dt = float(np.median(np.diff(t_s)))
    if not dt > 0:
        return float("nan")
    grid = np.arange(t_s[0], t_s[-1] + 0.5 * dt, dt)
    right = np.clip(np.searchsorted(t_s, grid), 1, len(t_s) - 1)
    in_gap = t_s[right] - t_s[right - 1] > gap_factor * dt
    uniform = np.interp(grid, t_s, signal) - signal.mean()
    uniform[in_gap] = 0.0
    uniform *= np.hanning(len(uniform))
    n_fft = pad * len(uniform)
    mag = np.abs(np.fft.rfft(uniform, n_fft))
    k = int(np.argmax(mag[1:]) + 1)
    if k + 1 >= len(mag):
        return float(k / (n_fft * dt))
    a, b, c = np.log(mag[k - 1 : k + 2] + 1e-300)
    denom = a - 2 * b + c
    shift = 0.5 * (a - c) / denom if denom != 0 else 0.0
    return float((k + shift) / (n_fft * dt))


@dataclass(frozen=True)
class Comparison:
    """Summary of a reconstruction against the truth (lengths over L).

    ``joint_rms_over_l``: RMS over the common times and the joints of the distance between the two
    chains' joints. ``cloud_rms_over_l`` and ``cloud_rms_ref_over_l``: RMS over the common span of the
    reconstruction's and the truth's Delta_RMS (their events' distance to their centreline). Those
    that need what the truth lacks are NaN, their name in ``not_available`` with the reason.
    """

    delta_rms_over_l: float
    max_eps_rms_over_l: float
    twi: float
    twi_ref: float
    n_common: int
    t_start_s: float
    t_stop_s: float
    length: float
    joint_rms_over_l: float = math.nan
    cloud_rms_over_l: float = math.nan
    cloud_rms_ref_over_l: float = math.nan
    not_available: dict[str, str] = field(default_factory=dict)

    @property
    def twi_abs_error(self) -> float:
        """|I - I_ref|."""
        return abs(self.twi - self.twi_ref)


def joint_error(recon: CentrelineBatch, truth: CentrelineBatch) -> tuple[np.ndarray, np.ndarray]:
    """RMS over the joints of the distance between the reconstruction's and the truth's chain joints.

    Args:
        recon, truth: series with the same number of joints (N_j + 1 columns); the truth is
            interpolated in time at the reconstruction's times inside its span.

    Returns:
        (t_s, error), both (n_t,) on the common times; NaN where the reconstruction had no chain.

    Raises:
        ValueError: the numbers of joints differ.
    """
    if recon.joints_x.shape[1] != truth.joints_x.shape[1]:
        raise ValueError(
            f"the truth has {truth.joints_x.shape[1]} joints, the reconstruction {recon.joints_x.shape[1]}"
        )
    rows = common_rows(recon, truth)
    t_common = recon.t_s[rows]
    jx = resample_t(truth.joints_x, truth.t_s, t_common)
    jy = resample_t(truth.joints_y, truth.t_s, t_common)
    sq = (recon.joints_x[rows] - jx) ** 2 + (recon.joints_y[rows] - jy) ** 2
    return t_common, np.sqrt(np.mean(sq, axis=1))


def compare(
    recon: CentrelineBatch,
    truth: CentrelineBatch,
    length: float | None = None,
    *,
    truth_has_joints: bool = True,
    truth_has_delta_rms: bool = True,
) -> Comparison:
    """delta_RMS/L, max eps_RMS/L and travelling-wave indices of ``recon`` against ``truth``; where the truth
    has them, the joints' RMS error/L and the truth's Delta_RMS/L (beside the reconstruction's).

    Both indices use the same common times and arc lengths and the truth's rest frame.

    Args:
        recon, truth: the series.
        length: L; None: the truth's arc-length span.
        truth_has_joints, truth_has_delta_rms: whether the truth's joints and Delta_RMS are data (a truth
            from another simulator may have neither; what stands in their place is then not read).
    """
    pair = align(recon, truth)
    length = float(length if length is not None else truth.s[-1] - truth.s[0])
    delta = np.hypot(pair.x[:, -1] - pair.x_ref[:, -1], pair.y[:, -1] - pair.y_ref[:, -1])
    sq = (pair.x - pair.x_ref) ** 2 + (pair.y - pair.y_ref) ** 2
    span = pair.s[-1] - pair.s[0]
    eps = np.sqrt(trapezoid(sq, pair.s) / span) if span > 0 else np.sqrt(sq[:, 0])
    root, direction = rest_frame(truth)
    rows = np.all(np.isfinite(pair.x) & np.isfinite(pair.y), axis=1)  # updates the tracker had no shape for
    twi = travelling_wave_index(lateral_displacement(pair.x[rows], pair.y[rows], root, direction))
    twi_ref = travelling_wave_index(lateral_displacement(pair.x_ref[rows], pair.y_ref[rows], root, direction))
    not_available: dict[str, str] = {}
    joint_rms = math.nan
    if not truth_has_joints:
        not_available["joint_rms_over_l"] = "the truth has no joints"
    else:
        try:
            joint_rms = rms(joint_error(recon, truth)[1]) / length
        except ValueError as exc:
            not_available["joint_rms_over_l"] = str(exc)
    t0, t1 = float(pair.t_s[0]), float(pair.t_s[-1])
    cloud_ref = math.nan
    if not truth_has_delta_rms:
        not_available["cloud_rms_ref_over_l"] = "the truth has no Delta_RMS"
    else:
        cloud_ref = rms(truth.delta_rms[(truth.t_s >= t0) & (truth.t_s <= t1)]) / length
        if not math.isfinite(cloud_ref):
            not_available["cloud_rms_ref_over_l"] = "the truth's Delta_RMS has no finite value in the common span"
    return Comparison(
        delta_rms_over_l=rms(delta) / length,
        max_eps_rms_over_l=float(np.nanmax(eps)) / length,
        twi=twi,
        twi_ref=twi_ref,
        n_common=len(pair.t_s),
        t_start_s=t0,
        t_stop_s=t1,
        length=length,
        joint_rms_over_l=joint_rms,
        cloud_rms_over_l=rms(recon.delta_rms[common_rows(recon, truth)]) / length,
        cloud_rms_ref_over_l=cloud_ref,
        not_available=not_available,
    )
