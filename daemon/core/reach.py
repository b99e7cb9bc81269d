"""Where the tracked flag can be: its reach on the sensor, for masking everything else (``roi: auto``).

The chain's links all lie within ``L`` of the root, their search areas reach ``alpha r_k`` further,
and the loss-of-track verdict weighs the events of a ring beyond them as the background (the
chain's buckets, :mod:`.chain`): the tracker looks no further than ``L + 2 (1 + alpha) r_max``
from the root (:func:`search_radius`). A flag in a flow trails downstream of its root, so the reach
is a sector of that radius around the rest direction (a half-disc by default; 180 degrees either
side: the whole disc), plus a margin for what the geometry and the calibration get wrong. A pixel is
in the reach when its centre, mapped to the tracking plane (pixels, or a calibration's units), lies
within the margin of the sector; :func:`pixel_box` is the smallest rectangle of pixels holding them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flagtrack.daemon.core.mapping import PointMapping


@dataclass(frozen=True)
class Reach:
    """A sector around the flag's root, in the tracking plane's units, and a margin around it.

    Attributes:
        root: (x, y) of the root.
        radius: the sector's radius.
        direction_deg: its axis, the flag's rest direction (degrees from +x towards +y).
        half_angle_deg: its half-angle, degrees (180: the whole disc).
        margin: distance around the sector that is still in the reach.
    """

    root: tuple[float, float]
    radius: float
    direction_deg: float = 0.0
    half_angle_deg: float = 90.0
    margin: float = 0.0

    def __post_init__(self) -> None:
        values = (*self.root, self.radius, self.direction_deg, self.half_angle_deg, self.margin)
        if not all(math.isfinite(v) for v in values):
            raise ValueError("root, radius, direction, half-angle and margin must be finite")
        if self.radius <= 0 or self.margin < 0 or not 0 < self.half_angle_deg <= 180:
            raise ValueError("radius must be > 0, margin >= 0 and the half-angle in (0, 180] degrees")

    def distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Distance of each point (x, y) to the sector (0 inside it), same shape as ``x``."""
        dx = np.asarray(x, dtype=np.float64) - self.root[0]
        dy = np.asarray(y, dtype=np.float64) - self.root[1]
        r = np.hypot(dx, dy)
        outward = np.maximum(r - self.radius, 0.0)
        if self.half_angle_deg >= 180:
            return outward
        axis = math.radians(self.direction_deg)
        off_axis = np.abs(np.angle(np.exp(1j * (np.arctan2(dy, dx) - axis))))
        inside = off_axis <= math.radians(self.half_angle_deg)
        edges = [self._edge_distance(dx, dy, axis + s * math.radians(self.half_angle_deg)) for s in (-1, 1)]
        return np.where(inside, outward, np.minimum(*edges))

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Whether each point lies within ``margin`` of the sector (bool, same shape as ``x``)."""
        return self.distance(x, y) <= self.margin

    def _edge_distance(self, dx: np.ndarray, dy: np.ndarray, angle: float) -> np.ndarray:
        """Distance to the straight edge of the sector from the root along ``angle`` (radians)."""
        ux, uy = math.cos(angle), math.sin(angle)
        along = np.clip(dx * ux + dy * uy, 0.0, self.radius)
        return np.hypot(dx - along * ux, dy - along * uy)

    def bounds(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) of the reach (the sector grown by the margin)."""
        axis, half = self.direction_deg, self.half_angle_deg
        angles = [axis - half, axis + half] + [
            90.0 * k for k in range(-4, 5) if abs((90.0 * k - axis + 180.0) % 360.0 - 180.0) <= half
        ]
        xs = [self.root[0]] + [self.root[0] + self.radius * math.cos(math.radians(a)) for a in angles]
        ys = [self.root[1]] + [self.root[1] + self.radius * math.sin(math.radians(a)) for a in angles]
        return min(xs) - self.margin, min(ys) - self.margin, max(xs) + self.margin, max(ys) + self.margin


def search_radius(length: float, link_lengths: tuple[float, ...] | None, n_joints: int, alpha: float) -> float:
    """How far from the root the tracker looks: ``L + 2 (1 + alpha) r_max`` (its links' search areas
    and the background ring of the loss-of-track verdict), in the units of ``length``."""
    longest = max(link_lengths) if link_lengths else length / n_joints
    return length + 2.0 * (1.0 + alpha) * longest


@dataclass(frozen=True)
class PixelBox:
    """A rectangle of whole pixels: columns ``x .. x + width - 1``, rows ``y .. y + height - 1``."""

    x: int
    y: int
    width: int
    height: int

    @property
    def area_px(self) -> int:
        return self.width * self.height

    def as_dict(self) -> dict[str, int]:
        return {"x": self.x, "y": self.y, "width": self.width, "height": self.height}


def pixel_box(
    reach: Reach, mapping: PointMapping | None = None, image_size: tuple[int, int] | None = None
) -> PixelBox | None:
    """The smallest rectangle of pixels whose centres lie in ``reach``, or None if no pixel does.

    Without a mapping the reach is in pixels: the rectangle is its bounds to whole pixels, cut at 0
    (not at the sensor's far edges when ``image_size`` is None). With a mapping (pixel -> plane) the
    pixel centres of the ``image_size`` (width, height) sensor are mapped and tested one by one.
    """
    if mapping is None:
        x0, y0, x1, y1 = reach.bounds()
        right, bottom = math.floor(x1), math.floor(y1)
        if image_size is not None:
            right, bottom = min(right, image_size[0] - 1), min(bottom, image_size[1] - 1)
        left, top = max(math.ceil(x0), 0), max(math.ceil(y0), 0)
        if right < left or bottom < top:
            return None
        return PixelBox(left, top, right - left + 1, bottom - top + 1)
    if image_size is None:
        raise ValueError("a mapped reach needs the sensor's size")
    width, height = image_size
    x_px, y_px = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    x, y = mapping.map(x_px.ravel(), y_px.ravel())
    inside = reach.contains(x, y).reshape(height, width)
    columns, rows = np.flatnonzero(inside.any(axis=0)), np.flatnonzero(inside.any(axis=1))
    if len(columns) == 0:
        return None
    return PixelBox(int(columns[0]), int(rows[0]), int(columns[-1] - columns[0] + 1), int(rows[-1] - rows[0] + 1))
