"""The plane frame of a detected board: which corner is the origin, where x and y point.

Corners are named in image terms (:mod:`flagtrack.calibration.corners`): ``(i, j)`` with i from
the left and j from the top. The user picks the origin corner (placed at the flag's root, or at a
known offset from it) and the image direction along which plane x grows (downstream). By default
y is x turned a quarter turn counter-clockwise *as seen on the image*, which makes (x, y, z)
right-handed with z towards the camera, the frame of a camera looking at the plane from its
z > 0 side without a mirror.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import Enum

import numpy as np


class Direction(Enum):
    """An image direction: along +i (right), -i (left), +j (down), -j (up)."""

    RIGHT = "right"
    LEFT = "left"
    UP = "up"
    DOWN = "down"

    @property
    def step(self) -> tuple[int, int]:
        """(di, dj) of one square along this direction."""
        return {"right": (1, 0), "left": (-1, 0), "up": (0, -1), "down": (0, 1)}[self.value]

    def counter_clockwise(self) -> Direction:
        """The direction a quarter turn counter-clockwise on the image (right -> up)."""
        return {
            Direction.RIGHT: Direction.UP,
            Direction.UP: Direction.LEFT,
            Direction.LEFT: Direction.DOWN,
            Direction.DOWN: Direction.RIGHT,
        }[self]


_NAMED_CORNERS = ("top-left", "top-right", "bottom-left", "bottom-right")


@dataclass(frozen=True)
class GridFrame:
    """How board corners become plane coordinates.

    Attributes:
        origin_corner: ``top-left``, ``top-right``, ``bottom-left``, ``bottom-right`` or ``"i,j"``.
        x_axis: image direction of plane +x (downstream).
        y_axis: image direction of plane +y; None: ``x_axis`` turned counter-clockwise on the image.
        origin_offset_m: plane coordinates of the origin corner (its offset from the root), metres.
    """

    origin_corner: str = "top-left"
    x_axis: Direction = Direction.RIGHT
    y_axis: Direction | None = None
    origin_offset_m: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if self.origin_corner not in _NAMED_CORNERS and not re.fullmatch(r"\s*\d+\s*,\s*\d+\s*", self.origin_corner):
            raise ValueError(
                f"origin corner must be one of {', '.join(_NAMED_CORNERS)} or 'i,j', got {self.origin_corner!r}"
            )
        if np.dot(self.x_step, self.y_step) != 0:
            raise ValueError(f"y axis ({self.y_dir.value}) must be perpendicular to x axis ({self.x_axis.value})")

    @property
    def y_dir(self) -> Direction:
        """The effective y direction."""
        return self.y_axis or self.x_axis.counter_clockwise()

    @property
    def x_step(self) -> tuple[int, int]:
        """(di, dj) of one square along plane +x."""
        return self.x_axis.step

    @property
    def y_step(self) -> tuple[int, int]:
        """(di, dj) of one square along plane +y."""
        return self.y_dir.step

    def origin_index(self, n_cols: int, n_rows: int) -> tuple[int, int]:
        """(i, j) of the origin corner on a grid of ``n_cols`` x ``n_rows`` inner corners.

        Raises:
            ValueError: an ``i,j`` outside the grid.
        """
        named = {
            "top-left": (0, 0),
            "top-right": (n_cols - 1, 0),
            "bottom-left": (0, n_rows - 1),
            "bottom-right": (n_cols - 1, n_rows - 1),
        }
        if self.origin_corner in named:
            return named[self.origin_corner]
        i, j = (int(v) for v in self.origin_corner.split(","))
        if not (0 <= i < n_cols and 0 <= j < n_rows):
            raise ValueError(
                f"origin corner {i},{j} is outside the {n_cols}x{n_rows} grid "
                f"(i = 0..{n_cols - 1} from the left, j = 0..{n_rows - 1} from the top)"
            )
        return i, j

    def plane_coordinates(self, n_cols: int, n_rows: int, square_m: float) -> np.ndarray:
        """(n_rows, n_cols, 2) plane (x, y) of every corner ``[j, i]``, metres."""
        i0, j0 = self.origin_index(n_cols, n_rows)
        jj, ii = np.mgrid[0:n_rows, 0:n_cols]
        di, dj = ii - i0, jj - j0
        # plane x counts squares along x_step: (di, dj) . x_step (steps are unit, axis-aligned)
        x = (di * self.x_step[0] + dj * self.x_step[1]) * square_m + self.origin_offset_m[0]
        y = (di * self.y_step[0] + dj * self.y_step[1]) * square_m + self.origin_offset_m[1]
        return np.stack([x, y], axis=-1).astype(np.float64)

    def to_mapping(self) -> dict[str, object]:
        """Plain data for the calibration file."""
        return {
            "origin_corner": self.origin_corner,
            "x_axis": self.x_axis.value,
            "y_axis": self.y_dir.value,
            "origin_offset_mm": [v * 1e3 for v in self.origin_offset_m],
        }
