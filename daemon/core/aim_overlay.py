"""What ``flagtrack aim`` draws over the camera image: the configured chain at rest, its search areas,
and the calibration's grid (lines of constant plane x and y), as pixel polylines.

The chain is drawn in the tracker's coordinates (pixels, or the calibration's plane) and carried to
pixels by the calibration's inverse (:class:`InvertibleMapping`, e.g. ``PolynomialMapping``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from flagtrack.daemon.core.chain import ChainParams, ChainState


class InvertibleMapping(Protocol):
    """A pixel -> plane mapping that can also map back (a calibration)."""

    def map(self, x_px: np.ndarray, y_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Plane x, y of pixel positions."""
        ...

    def to_pixels(self, x_m: np.ndarray, y_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel x, y of plane positions."""
        ...


@dataclass(frozen=True)
class ChainOverlay:
    """The chain at rest, in pixels.

    Attributes:
        joints: (N_j + 1, 2) x, y of the joints, root first.
        areas: one closed (n, 2) polyline per link: its search area at rest (an annulus has two).
    """

    joints: np.ndarray
    areas: tuple[np.ndarray, ...]


def _arc(cx: float, cy: float, radius: float, a0: float, a1: float, n: int) -> np.ndarray:
    angles = np.linspace(a0, a1, n)
    return np.stack([cx + radius * np.cos(angles), cy + radius * np.sin(angles)], axis=1)


def search_area(
    cx: float, cy: float, r_in: float, r_out: float, direction_rad: float, half_rad: float
) -> list[np.ndarray]:
    """The closed outline(s) of an arc of radii ``r_in..r_out`` around (cx, cy), ``half_rad`` either side
    of ``direction_rad`` (two circles where it is a whole annulus)."""
    n = max(8, math.ceil(48 * half_rad / math.pi))
    if half_rad >= math.pi:
        return [_arc(cx, cy, r, 0.0, 2 * math.pi, 2 * n) for r in (r_out, r_in)]
    lo, hi = direction_rad - half_rad, direction_rad + half_rad
    outer, inner = _arc(cx, cy, r_out, lo, hi, n), _arc(cx, cy, r_in, hi, lo, n)
    edge = np.linspace(0.0, 1.0, 6)[1:-1, None]  # the radial edges, in steps (a mapping bends them)
    down = outer[-1] + edge * (inner[0] - outer[-1])
    up = inner[-1] + edge * (outer[0] - inner[-1])
    return [np.concatenate([outer, down, inner, up, outer[:1]])]


def chain_overlay(chain: ChainParams, mapping: InvertibleMapping | None = None) -> ChainOverlay:
    """The straight chain along ``chain.direction_deg`` and each link's search area (radii
    ``(1 -+ alpha) r_k`` around joint k-1, ``angle_limit_deg`` either side of the link), in pixels."""
    x, y = ChainState.at_rest(chain).joints(chain)
    direction = math.radians(chain.direction_deg)
    half = math.radians(chain.angle_limit_deg)
    areas: list[np.ndarray] = []
    for k, r in enumerate(chain.lengths()):
        areas += search_area(float(x[k]), float(y[k]), (1 - chain.alpha) * r, (1 + chain.alpha) * r, direction, half)
    joints = np.stack([x, y], axis=1)
    if mapping is not None:
        joints = _to_pixels(mapping, joints)
        areas = [_to_pixels(mapping, area) for area in areas]
    return ChainOverlay(joints, tuple(areas))


def _to_pixels(mapping: InvertibleMapping, points: np.ndarray) -> np.ndarray:
    u, v = mapping.to_pixels(points[:, 0], points[:, 1])
    return np.stack([np.asarray(u, np.float64), np.asarray(v, np.float64)], axis=1)


def nice_step(span: float, n_lines: int) -> float:
    """A step of 1, 2 or 5 times a power of ten giving about ``n_lines`` lines over ``span``."""
    raw = span / max(n_lines, 1)
    power = 10.0 ** math.floor(math.log10(raw))
    return next(m * power for m in (1.0, 2.0, 5.0, 10.0) if m * power >= raw)


@dataclass(frozen=True)
class PlaneGrid:
    """Lines of constant plane x and y over the image: (n, 2) pixel polylines and the step between
    lines in plane units."""

    lines: tuple[np.ndarray, ...]
    step: float


def plane_grid(mapping: InvertibleMapping, width: int, height: int, n_lines: int = 10, samples: int = 200) -> PlaneGrid:
    """The calibration's grid over a ``width`` x ``height`` image: about ``n_lines`` lines each way,
    cut where they leave the image."""
    border_x = np.concatenate([np.linspace(0, width - 1, samples), np.full(samples, width - 1.0),
                               np.linspace(width - 1, 0, samples), np.zeros(samples)])  # fmt: skip
    border_y = np.concatenate([np.zeros(samples), np.linspace(0, height - 1, samples),
                               np.full(samples, height - 1.0), np.linspace(height - 1, 0, samples)])  # fmt: skip
    px, py = (np.asarray(a, np.float64) for a in mapping.map(border_x, border_y))
    if not (np.all(np.isfinite(px)) and np.all(np.isfinite(py))):
        return PlaneGrid((), math.nan)
    x0, x1, y0, y1 = px.min(), px.max(), py.min(), py.max()
    if not (x1 > x0 and y1 > y0):
        return PlaneGrid((), math.nan)
    step = nice_step(max(x1 - x0, y1 - y0), n_lines)
    lines: list[np.ndarray] = []
    along_y, along_x = np.linspace(y0, y1, samples), np.linspace(x0, x1, samples)
    for level in np.arange(math.ceil(x0 / step), math.floor(x1 / step) + 1) * step:
        lines += _inside(_to_pixels(mapping, np.stack([np.full(samples, level), along_y], axis=1)), width, height)
    for level in np.arange(math.ceil(y0 / step), math.floor(y1 / step) + 1) * step:
        lines += _inside(_to_pixels(mapping, np.stack([along_x, np.full(samples, level)], axis=1)), width, height)
    return PlaneGrid(tuple(lines), step)


def _inside(points: np.ndarray, width: int, height: int) -> list[np.ndarray]:
    """The runs of ``points`` (at least two) that lie on the image."""
    ok = np.all(np.isfinite(points), axis=1)
    ok &= (
        (points[:, 0] >= -0.5) & (points[:, 0] <= width - 0.5) & (points[:, 1] >= -0.5) & (points[:, 1] <= height - 0.5)
    )
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    return [points[a:b] for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a >= 2]


@dataclass(frozen=True)
class AimOverlays:
    """Everything drawn over the image that does not change: the chain (None: not configured), the
    calibration's grid (None: no calibration) and the unit the chain's figures are in."""

    chain: ChainOverlay | None = None
    grid: PlaneGrid | None = None
    units: str = "px"
