"""Calibration hook: a mapping from sensor pixels to the tracking plane's coordinates.

The tracker works in whatever coordinates the events carry. A :class:`PointMapping` (for example
the polynomial R^2 -> R^2 calibration of ``flagtrack.calibration``) turns the pixel of every event
into float coordinates (metres) before tracking. An event at integer pixel (x, y) is the pixel whose
centre is at (x, y) (the OpenCV convention), so the identity mapping is exact in pixels.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np


class PointMapping(Protocol):
    """Maps pixel coordinates to tracking coordinates, elementwise."""

    def map(self, x_px: np.ndarray, y_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return float64 x, y arrays of the same shape as ``x_px``, ``y_px`` (float pixel centres)."""
        ...


class IdentityMapping:
    """Pixels stay pixels (the default)."""

    units = "px"

    def map(self, x_px: np.ndarray, y_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(x_px, dtype=np.float64), np.asarray(y_px, dtype=np.float64)


class AffineMapping:
    """``(x, y) -> A (x, y) + b``: a scaled, rotated, shifted plane (tests, simple rigs).

    Args:
        matrix: 2x2 nested sequence A.
        offset: (b_x, b_y).
        units: unit of the output coordinates (``"m"`` by default).
    """

    def __init__(
        self, matrix: tuple[tuple[float, float], tuple[float, float]], offset: tuple[float, float], units: str = "m"
    ) -> None:
        self.matrix = np.asarray(matrix, dtype=np.float64)
        self.offset = np.asarray(offset, dtype=np.float64)
        self.units = units

    def map(self, x_px: np.ndarray, y_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.asarray(x_px, dtype=np.float64)
        y = np.asarray(y_px, dtype=np.float64)
        (a, b), (c, d) = self.matrix
        return a * x + b * y + self.offset[0], c * x + d * y + self.offset[1]


def on_sensor(x: float, y: float, width: int, height: int, mapping: PointMapping | None = None) -> bool:
    """Whether the point (x, y), in the mapping's units (pixels without one), lies on a ``width`` x
    ``height`` sensor (pixel centres at whole coordinates; with a mapping, inside the sensor's
    outline mapped to the plane; True when the mapping cannot place that outline: no verdict)."""
    if mapping is None:
        return bool(-0.5 <= x <= width - 0.5 and -0.5 <= y <= height - 0.5)
    u = np.linspace(-0.5, width - 0.5, 65)
    v = np.linspace(-0.5, height - 0.5, 65)
    px = np.concatenate([u, np.full(65, width - 0.5), u[::-1], np.full(65, -0.5)]).astype(np.float32)
    py = np.concatenate([np.full(65, -0.5), v, np.full(65, height - 0.5), v[::-1]]).astype(np.float32)
    ox, oy = (np.asarray(a, dtype=np.float64) for a in mapping.map(px, py))
    if not (np.isfinite(ox).all() and np.isfinite(oy).all()):
        return True
    x0, y0, x1, y1 = ox, oy, np.roll(ox, -1), np.roll(oy, -1)
    crosses = (y0 > y) != (y1 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        at = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
    return bool(np.count_nonzero(crosses & (x < at)) % 2)
