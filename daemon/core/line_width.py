"""The focus figure of ``flagtrack aim``: how wide the laser line is, across it, in pixels.

In an image of event counts, the line is found where the counts smoothed by a Gaussian of
``smooth_px`` make a ridge: the Hessian's most negative curvature gives the direction across the
line (its eigenvector, the "normal"), and a ridge point is a local maximum along it. At up to
``max_profiles`` ridge points spread along the line, the profile of the (unsmoothed) counts across
the line is read by bilinear interpolation every ``step_px`` out to ``half_span_px`` on each side,
averaged over ``2 along_px + 1`` parallel profiles 1 px apart along the line. Its full width at half
maximum (peak near the ridge, background the lower of the two ends' medians; crossings interpolated)
is that place's width; the figure is the median over the places. A sharper image of the same line
gives a smaller figure (a Gaussian blur of standard deviation s gives about 2.355 s, plus the pixels').
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LineWidthParams:
    """Settings of :func:`measure_line_width`.

    Attributes:
        smooth_px: Gaussian standard deviation of the smoothing that finds the line and its direction.
        direction_px: the curvatures are averaged over a Gaussian of this standard deviation (a steadier
            direction across the line).
        half_span_px: profiles reach this far on each side of the line (wider lines are not measured).
        step_px: sampling step along a profile.
        along_px: each profile is the mean of ``2 along_px + 1`` parallel ones, 1 px apart along the line.
        max_profiles: at most this many places are measured.
        min_profiles: fewer measured places than this: no figure.
        min_events: fewer events in the image than this: no figure.
        min_anisotropy: a ridge point curves at least this many times more across the line than
            along it (a blob of a few stray events curves as much both ways).
        min_place_events: a place is measured only if its profiles hold at least this many events
            above the background.
        ridge_fraction: ridge points weaker than this fraction of the strongest ones (the median of
            the ``max_profiles // 4`` strongest smoothed counts) are left out (noise, other things).
    """

    smooth_px: float = 1.5
    direction_px: float = 4.0
    half_span_px: float = 20.0
    step_px: float = 0.5
    along_px: int = 7
    max_profiles: int = 200
    min_profiles: int = 5
    min_events: int = 50
    min_anisotropy: float = 2.0
    min_place_events: float = 20.0
    ridge_fraction: float = 0.3

    def __post_init__(self) -> None:
        if not (
            self.smooth_px > 0 and self.direction_px > 0 and self.step_px > 0 and self.half_span_px > 2 * self.step_px
        ):
            raise ValueError("smooth_px, direction_px, step_px must be positive and half_span_px more than two steps")
        if self.along_px < 0 or self.max_profiles < 1 or self.min_profiles < 1 or self.min_events < 0:
            raise ValueError("along_px, min_events must be >= 0 and max_profiles, min_profiles >= 1")
        if self.min_anisotropy < 1 or self.min_place_events < 0:
            raise ValueError("min_anisotropy must be at least 1 and min_place_events at least 0")
        if not 0 <= self.ridge_fraction < 1:
            raise ValueError(f"ridge_fraction must be in [0, 1), got {self.ridge_fraction}")


@dataclass(frozen=True)
class LineWidth:
    """The line's width and where it was measured.

    Attributes:
        width_px: median full width at half maximum across the line, pixels (NaN: not measured).
        spread_px: interquartile range of the places' widths (NaN: not measured).
        centres: (k, 2) x, y of the measured places (pixel centres at integers).
        normals: (k, 2) unit vectors across the line there.
        widths: (k,) width at each place, pixels.
        reason: why there is no figure ("" when there is one).
    """

    width_px: float
    spread_px: float
    centres: np.ndarray
    normals: np.ndarray
    widths: np.ndarray
    reason: str = ""

    @property
    def n_profiles(self) -> int:
        """Places measured."""
        return len(self.widths)


def gaussian_blur(image: np.ndarray, sigma_px: float) -> np.ndarray:
    """``image`` (2-D) convolved with a Gaussian of ``sigma_px`` (zero beyond the edges), float64."""
    radius = max(1, math.ceil(3 * sigma_px))
    offsets = np.arange(-radius, radius + 1)
    kernel = np.exp(-0.5 * (offsets / sigma_px) ** 2)
    kernel /= kernel.sum()
    out = np.asarray(image, dtype=np.float64)
    for axis in (0, 1):
        padded = np.pad(out, [(radius, radius) if a == axis else (0, 0) for a in (0, 1)])
        n = out.shape[axis]
        acc = np.zeros_like(out)
        for i, weight in enumerate(kernel):
            acc += weight * (padded[i : i + n] if axis == 0 else padded[:, i : i + n])
        out = acc
    return out


def box_blur(image: np.ndarray, sigma_px: float, passes: int = 3) -> np.ndarray:
    """About a Gaussian blur of ``sigma_px`` (zero beyond the edges): ``passes`` box filters along each
    axis, in a time that does not grow with ``sigma_px`` (for wide averages)."""
    radius = max(1, round(0.5 * (math.sqrt(12 * sigma_px**2 / passes + 1) - 1)))
    out = np.asarray(image, dtype=np.float64)
    for axis in (0, 1):
        n = out.shape[axis]
        for _ in range(passes):
            padding = [(radius + 1, radius) if a == axis else (0, 0) for a in (0, 1)]
            total = np.cumsum(np.pad(out, padding), axis=axis)
            hi = total[2 * radius + 1 :] if axis == 0 else total[:, 2 * radius + 1 :]
            lo = total[:n] if axis == 0 else total[:, :n]
            out = (hi - lo) / (2 * radius + 1)
    return out


def bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``image`` at float positions (x column, y row; pixel centres at integers), 0 beyond the edges."""
    height, width = image.shape
    padded = np.pad(np.asarray(image, dtype=np.float64), 1)
    x = np.clip(np.asarray(x, dtype=np.float64), -1.0, width) + 1.0
    y = np.clip(np.asarray(y, dtype=np.float64), -1.0, height) + 1.0
    x0 = np.minimum(np.floor(x).astype(np.int64), width)
    y0 = np.minimum(np.floor(y).astype(np.int64), height)
    fx, fy = x - x0, y - y0
    top = padded[y0, x0] * (1 - fx) + padded[y0, x0 + 1] * fx
    bottom = padded[y0 + 1, x0] * (1 - fx) + padded[y0 + 1, x0 + 1] * fx
    return top * (1 - fy) + bottom * fy


def curvatures(smooth: np.ndarray, direction_px: float, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, ...]:
    """(most negative curvature, the other, x and y of the unit vector along the first) of ``smooth``
    at pixels (rows, cols), from its Hessian averaged over about a Gaussian of ``direction_px``."""
    p = np.pad(smooth, 1, mode="edge")
    sxx = p[1:-1, 2:] - 2 * smooth + p[1:-1, :-2]
    syy = p[2:, 1:-1] - 2 * smooth + p[:-2, 1:-1]
    sxy = 0.25 * (p[2:, 2:] - p[2:, :-2] - p[:-2, 2:] + p[:-2, :-2])
    sxx, syy, sxy = (box_blur(h, direction_px)[rows, cols] for h in (sxx, syy, sxy))
    half_trace, root = 0.5 * (sxx + syy), np.hypot(0.5 * (sxx - syy), sxy)
    angle = 0.5 * np.arctan2(2 * sxy, sxx - syy) + 0.5 * math.pi  # across the line
    return half_trace - root, half_trace + root, np.cos(angle), np.sin(angle)


def ridge_points(image: np.ndarray, params: LineWidthParams) -> tuple[np.ndarray, np.ndarray]:
    """((k, 2) x, y of ridge points, (k, 2) unit normals there), spread along the line, at most
    ``max_profiles`` (see the module docstring). The curvatures are computed only around the pixels
    bright enough to be on the line (its bounding box and a margin)."""
    smooth = gaussian_blur(image, params.smooth_px)
    n_top = _n_strongest(params)
    top = np.partition(smooth.ravel(), smooth.size - n_top)[-n_top:] if n_top < smooth.size else smooth
    floor = max(0.5 * params.ridge_fraction * float(np.median(top)), 1e-12)  # cheap first cut
    bright_rows, bright_cols = np.nonzero(smooth >= floor)
    margin = math.ceil(3 * params.direction_px) + 2
    r0, c0 = max(int(bright_rows.min()) - margin, 0), max(int(bright_cols.min()) - margin, 0)
    sub = smooth[r0 : int(bright_rows.max()) + margin + 1, c0 : int(bright_cols.max()) + margin + 1]
    rows, cols = np.nonzero(sub >= floor)
    lam_min, lam_max, nx, ny = curvatures(sub, params.direction_px, rows, cols)
    line_like = (lam_min < 0) & (-lam_min >= params.min_anisotropy * np.abs(lam_max))
    rows, cols, nx, ny = rows[line_like], cols[line_like], nx[line_like], ny[line_like]
    value = sub[rows, cols]
    step_x, step_y = np.rint(nx).astype(np.int64), np.rint(ny).astype(np.int64)  # the nearest pixels across
    padded = np.pad(sub, 1)
    ahead, behind = padded[rows + 1 + step_y, cols + 1 + step_x], padded[rows + 1 - step_y, cols + 1 - step_x]
    ridge = (value >= ahead) & (value >= behind)
    if np.count_nonzero(ridge):  # the line is the brightest ridge: its strongest points set the bar
        strongest = np.sort(value[ridge])[-n_top:]
        ridge &= value >= params.ridge_fraction * float(np.median(strongest))
    rows, cols, nx, ny = rows[ridge] + r0, cols[ridge] + c0, nx[ridge], ny[ridge]
    if len(rows) > params.max_profiles:
        pick = np.unique(np.linspace(0, len(rows) - 1, params.max_profiles).round().astype(np.int64))
        rows, cols, nx, ny = rows[pick], cols[pick], nx[pick], ny[pick]
    centres = np.stack([cols, rows], axis=1).astype(np.float64)
    return centres, np.stack([nx, ny], axis=1)


def _n_strongest(params: LineWidthParams) -> int:
    return max(1, params.max_profiles // 4)


def profile_widths(image: np.ndarray, centres: np.ndarray, normals: np.ndarray, params: LineWidthParams) -> np.ndarray:
    """(k,) full width at half maximum of the count profile across the line at each place (NaN where
    the profile does not fall to half on both sides within ``half_span_px``)."""
    n_steps = round(params.half_span_px / params.step_px)
    u = np.arange(-n_steps, n_steps + 1) * params.step_px
    v = np.arange(-params.along_px, params.along_px + 1, dtype=np.float64)
    nx, ny = normals[:, 0, None, None], normals[:, 1, None, None]
    x = centres[:, 0, None, None] + u[None, None, :] * nx - v[None, :, None] * ny
    y = centres[:, 1, None, None] + u[None, None, :] * ny + v[None, :, None] * nx
    profile = bilinear(image, x, y).mean(axis=1)  # (k, n_u)
    index = np.arange(len(u))
    near = np.abs(u) <= max(3.0, 2 * params.smooth_px)
    peak_at = np.argmax(np.where(near, profile, -np.inf), axis=1)
    peak = profile[np.arange(len(profile)), peak_at]
    ends = max(2, round(3.0 / params.step_px))
    base = np.minimum(np.median(profile[:, :ends], axis=1), np.median(profile[:, -ends:], axis=1))
    half = base + 0.5 * (peak - base)
    below = profile < half[:, None]
    left = np.where(below & (index < peak_at[:, None]), index, -1).max(axis=1)
    right = np.where(below & (index > peak_at[:, None]), index, len(u)).min(axis=1)
    above = np.clip(profile - base[:, None], 0.0, None).sum(axis=1) * params.step_px * len(v)
    ok = (left >= 0) & (right < len(u)) & (peak > base) & (above >= params.min_place_events)
    left, right = np.where(ok, left, 0), np.where(ok, right, 1)
    rows = np.arange(len(profile))
    left_u = _crossing(u, profile, rows, left, left + 1, half)
    right_u = _crossing(u, profile, rows, right - 1, right, half)
    return np.where(ok, right_u - left_u, np.nan)


def _crossing(
    u: np.ndarray, profile: np.ndarray, rows: np.ndarray, i: np.ndarray, j: np.ndarray, level: np.ndarray
) -> np.ndarray:
    """Where the profile crosses ``level`` between samples i and j (linear interpolation)."""
    a, b = profile[rows, i], profile[rows, j]
    span = np.where(b != a, b - a, 1.0)
    return u[i] + (level - a) / span * (u[j] - u[i])


def measure_line_width(image: np.ndarray, params: LineWidthParams = LineWidthParams()) -> LineWidth:
    """The line's width in an image of event counts (height, width); see the module docstring."""
    none = np.zeros((0, 2))
    if float(np.sum(image)) < params.min_events:
        return LineWidth(math.nan, math.nan, none, none, np.zeros(0), reason="too few events")
    centres, normals = ridge_points(image, params)
    widths = profile_widths(image, centres, normals, params) if len(centres) else np.zeros(0)
    ok = np.isfinite(widths)
    centres, normals, widths = centres[ok], normals[ok], widths[ok]
    if len(widths) < params.min_profiles:
        return LineWidth(math.nan, math.nan, centres, normals, widths, reason="no line found")
    q1, median, q3 = np.percentile(widths, [25, 50, 75])
    return LineWidth(float(median), float(q3 - q1), centres, normals, widths)
