"""The pieces of :mod:`flagtrack.daemon.core.geometry`: sensor defects and the flag's motion field.

Sensor side (pixels): hot pixels (a count far above every neighbour's) and isolated events (no
neighbouring pixel fired within a short time: shot noise). Motion side (the flag's own frame, u
along the rest axis, v across it): the lateral position of the laser line at a few reference
stations along the flag, sampled in short windows (:func:`references`), and, for every slice of
u, the regression of the events' v on those references (:func:`fit_field`). A flag is an
inextensible line pinned at its root, so its motion has few degrees of freedom: the line's lateral
position anywhere is, to a good approximation, a linear combination of its positions at the
stations. The regression also models the laser line's width: a line moving towards +v fires ON
events on its +v flank and OFF events on its -v flank.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

_TUKEY_C = 4.685


def hot_pixels(counts: np.ndarray, ratio: float, min_count: int) -> np.ndarray:
    """Pixels that fire far more than all their neighbours, (H, W) bool.

    Args:
        counts: (H, W) events per pixel.
        ratio: a hot pixel has more than ``ratio`` times the median and twice the largest count of
            its 8 neighbours.
        min_count: and at least this many events.
    """
    ring = np.ones((3, 3), bool)
    ring[1, 1] = False
    c = counts.astype(np.float64)
    median = ndimage.median_filter(c, footprint=ring, mode="constant")
    largest = ndimage.maximum_filter(c, footprint=ring, mode="constant")
    return (c > ratio * np.maximum(median, 1.0)) & (c > 2.0 * largest) & (c >= min_count)


def supported(
    x: np.ndarray, y: np.ndarray, t_us: np.ndarray, size: tuple[int, int], window_us: int, min_neighbours: int
) -> np.ndarray:
    """Events with at least ``min_neighbours`` of their 8 neighbouring pixels firing in the same
    time slice of ``window_us`` or the slices either side (a moving line lights its neighbours;
    shot noise seldom has any). Bool, one per event."""
    width, height = size
    n_pix = width * height
    slice_ = (t_us // window_us).astype(np.int64)
    pixel = y.astype(np.int64) * width + x.astype(np.int64)
    keys, inverse = np.unique(slice_ * n_pix + pixel, return_inverse=True)
    k_slice, k_pixel = keys // n_pix, keys % n_pix
    kx, ky = k_pixel % width, k_pixel // width
    neighbours = np.zeros(len(keys), np.int32)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dx == 0 and dy == 0:
                continue
            nx, ny = kx + dx, ky + dy
            inside = (nx >= 0) & (nx < width) & (ny >= 0) & (ny < height)
            other = ny * width + nx
            hit = np.zeros(len(keys), bool)
            for ds in (-1, 0, 1):
                wanted = (k_slice + ds) * n_pix + other
                at = np.minimum(np.searchsorted(keys, wanted), len(keys) - 1)
                hit |= keys[at] == wanted
            neighbours += hit & inside
    return neighbours[inverse.reshape(-1)] >= min_neighbours


def group_median(groups: np.ndarray, values: np.ndarray, n_groups: int) -> tuple[np.ndarray, np.ndarray]:
    """Median of ``values`` per integer group in [0, n_groups) (NaN where empty) and the counts."""
    order = np.lexsort((values, groups))
    counts = np.bincount(groups, minlength=n_groups)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    median = np.full(n_groups, np.nan)
    filled = counts > 0
    median[filled] = values[order][start[filled] + counts[filled] // 2]
    return median, counts


@dataclass(frozen=True)
class References:
    """The line's lateral motion at the reference stations, on a regular grid of windows.

    Attributes:
        t_us: (n_w,) window centres.
        values: (n_w, k) reference signals: the principal components of the stations' positions,
            each scaled to unit RMS (so a slice's coefficients are in length units).
        velocity: (n_w, k) their time derivatives, per µs.
        covered: (n_w,) windows where every station had events (the others are interpolated).
    """

    t_us: np.ndarray
    values: np.ndarray
    velocity: np.ndarray
    covered: np.ndarray

    def at(self, t_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, k) reference values and velocities at times ``t_us`` (linear interpolation)."""
        cols = range(self.values.shape[1])
        r = np.column_stack([np.interp(t_us, self.t_us, self.values[:, j]) for j in cols])
        dr = np.column_stack([np.interp(t_us, self.t_us, self.velocity[:, j]) for j in cols])
        return r, dr


def references(
    u: np.ndarray,
    v: np.ndarray,
    t_us: np.ndarray,
    stations: np.ndarray,
    half_band: float,
    window_us: float,
    min_share: float = 0.002,
) -> References | None:
    """The median v of the events near each station (``|u - station| < half_band``) per window,
    gaps interpolated, turned into uncorrelated signals (components below ``min_share`` of the
    motion's variance are dropped). None if a station has events in fewer than 4 windows."""
    t0 = float(t_us.min())
    n_w = max(4, int(np.ceil((float(t_us.max()) - t0 + 1) / window_us)))
    centres = t0 + (np.arange(n_w) + 0.5) * window_us
    raw = np.empty((n_w, len(stations)))
    covered = np.ones(n_w, bool)
    for j, station in enumerate(stations):
        near = np.abs(u - station) < half_band
        window = np.minimum(((t_us[near] - t0) / window_us).astype(np.int64), n_w - 1)
        median, counts = group_median(window, v[near], n_w)
        good = counts >= 3
        if good.sum() < 4:
            return None
        raw[:, j] = np.interp(centres, centres[good], median[good])
        covered &= good
    raw -= raw.mean(axis=0)
    _, sing, vt = np.linalg.svd(raw, full_matrices=False)
    keep = (sing**2 >= min_share * float((sing**2).sum())) & (sing > 0)
    if not keep.any():
        return None
    values = (raw @ vt[keep].T) / (sing[keep] / np.sqrt(n_w))
    velocity = np.gradient(values, centres, axis=0)
    return References(centres, values, velocity, covered)


@dataclass(frozen=True)
class FieldFit:
    """The lateral position of the line per slice of u: ``v = mean + coef . r(t) + flank * s``.

    ``s`` is +1 for an event on the side the line moves to (ON while moving to +v, OFF while moving
    to -v) and -1 otherwise. Rows are slices; NaN where a slice has too few events.

    Attributes:
        edges: (n + 1,) slice edges along u.
        mean: (n,) time-mean lateral position.
        coef: (n, k) coefficients on the references.
        se: (n,) standard error of the motion's amplitude (coefficients' RMS standard error).
        flank: (n,) half-distance between the flanks' events, length units.
        scale: (n,) robust spread of the events around the model.
        count: (n,) events per slice.
    """

    edges: np.ndarray
    mean: np.ndarray
    coef: np.ndarray
    se: np.ndarray
    flank: np.ndarray
    scale: np.ndarray
    count: np.ndarray

    @property
    def centres(self) -> np.ndarray:
        """(n,) slice centres."""
        return 0.5 * (self.edges[1:] + self.edges[:-1])

    @property
    def rms(self) -> np.ndarray:
        """(n,) RMS lateral motion of each slice (the references are orthonormal)."""
        return np.sqrt(np.sum(self.coef**2, axis=1))

    def smoothed_coef(self, width: int = 5) -> np.ndarray:
        """(n, k) coefficients, gaps filled along u and averaged over ``width`` slices."""
        centres = self.centres
        out = np.zeros_like(self.coef)
        good = np.isfinite(self.coef[:, 0])
        if good.sum() >= 2:
            for j in range(self.coef.shape[1]):
                out[:, j] = np.interp(centres, centres[good], self.coef[good, j])
        return ndimage.uniform_filter1d(out, width, axis=0, mode="nearest")


def _robust_lstsq(a: np.ndarray, y: np.ndarray, iterations: int = 3) -> tuple[np.ndarray, np.ndarray, float]:
    """Tukey-weighted least squares: coefficients, their standard errors, the residuals' scale."""
    w = np.ones(len(y))
    coef = np.zeros(a.shape[1])
    scale = 1.0
    for _ in range(iterations):
        sw = np.sqrt(w)
        coef = np.linalg.lstsq(a * sw[:, None], y * sw, rcond=None)[0]
        resid = y - a @ coef
        scale = 1.4826 * float(np.median(np.abs(resid[w > 0]))) + 1e-9
        z = resid / (_TUKEY_C * scale)
        w = np.where(np.abs(z) < 1, (1 - z**2) ** 2, 0.0)
    normal = (a * w[:, None]).T @ a
    try:
        se = np.sqrt(np.clip(np.diag(np.linalg.inv(normal)), 0, None)) * scale
    except np.linalg.LinAlgError:
        se = np.full(a.shape[1], np.inf)
    return coef, se, scale


@dataclass(frozen=True)
class _Slices:
    """Which events fall in which slice of u: an ordering of the events and each slice's bounds in it."""

    order: np.ndarray
    bounds: np.ndarray

    @staticmethod
    def of(u: np.ndarray, edges: np.ndarray) -> _Slices:
        slice_of = np.searchsorted(edges, u, side="right") - 1
        order = np.argsort(slice_of, kind="stable")
        return _Slices(order, np.searchsorted(slice_of[order], np.arange(len(edges))))


def _regress(v: np.ndarray, design: np.ndarray, slices: _Slices, cap: int = 8000) -> tuple[np.ndarray, ...]:
    """Per slice: coefficients of ``v ~ [1, design]``, their standard errors, scale, counts (a slice
    with more than ``cap`` events is evenly thinned to about ``cap``)."""
    count = np.diff(slices.bounds)
    n_slices, n_cols = len(count), design.shape[1] + 1
    coef = np.full((n_slices, n_cols), np.nan)
    se = np.full((n_slices, n_cols), np.nan)
    scale = np.full(n_slices, np.nan)
    for i in np.flatnonzero(count >= 4 * n_cols):
        rows = slices.order[slices.bounds[i] : slices.bounds[i + 1] : max(1, int(count[i]) // cap)]
        a = np.column_stack([np.ones(len(rows)), design[rows]])
        coef[i], se[i], scale[i] = _robust_lstsq(a, v[rows])
    return coef, se, scale, count


def fit_field(
    u: np.ndarray, v: np.ndarray, t_us: np.ndarray, on: np.ndarray, refs: References, edges: np.ndarray
) -> FieldFit:
    """Regress the events' v on the references per slice of u, then again with the flank term (the
    side each event is on, from the first fit's motion and the event's polarity ``on``)."""
    r, dr = refs.at(t_us)
    k = r.shape[1]
    slices = _Slices.of(u, edges)
    coef, se, scale, count = _regress(v, r, slices)
    first = FieldFit(edges, coef[:, 0], coef[:, 1:], se[:, 0], np.zeros(len(count)), scale, count)
    slice_of = np.clip(np.searchsorted(edges, u, side="right") - 1, 0, len(edges) - 2)
    speed = np.sum(first.smoothed_coef()[slice_of] * dr, axis=1)
    side = np.sign(speed) * np.where(on, 1.0, -1.0)
    coef, se, scale, count = _regress(v, np.column_stack([r, side]), slices)
    amplitude_se = np.sqrt(np.mean(se[:, 1 : k + 1] ** 2, axis=1))
    return FieldFit(edges, coef[:, 0], coef[:, 1 : k + 1], amplitude_se, coef[:, k + 1], scale, count)
