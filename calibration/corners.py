"""Checkerboard inner corners in a pseudo-image: detection, sub-pixel refinement, grid order.

Detection and topology come from OpenCV's ``findChessboardCornersSB`` (a maintained, well-tested
sector-based detector; with ``CALIB_CB_LARGER`` it returns the whole visible grid, so a board of
another size than the one asked for, or a board partly out of view, is recognised and reported).
OpenCV is imported here only, lazily. Each corner is then refined by fitting a blurred-corner
model ``a + b tanh(d1 / s) tanh(d2 / s)`` (d1, d2: signed distances to two lines through the
corner) to the pseudo-image around it, Gaussian-weighted: on simulated event pseudo-images this is
about twice as accurate as ``cornerSubPix`` (docs/calibration.md). The model is point-symmetric
about the corner, so the non-linear response of event counts to the lit fraction of a pixel,
which shifts edges, does not shift corners.

The grid is returned in image terms: ``grid[j, i]`` with i counted from the left (the board axis
closest to the image's rows) and j from the top.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from flagtrack.calibration.errors import CalibrationError
from flagtrack.calibration.pseudo_image import to_uint8

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CornerGrid:
    """Inner corners of a board, ordered in image terms.

    Attributes:
        px: (n_rows, n_cols, 2) sub-pixel (x, y) positions, pixels (pixel centres at integers);
            ``px[j, i]``: column i from the left, row j from the top.
        coarse_px: the same before refinement (OpenCV's positions).
        refined: (n_rows, n_cols) True where the model fit was kept.
    """

    px: np.ndarray
    coarse_px: np.ndarray
    refined: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        """(n_cols, n_rows): inner corners along i (left-right) and j (top-bottom)."""
        return int(self.px.shape[1]), int(self.px.shape[0])


def _cv2() -> Any:
    try:
        import cv2
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise CalibrationError("corner detection needs OpenCV: pip install 'opencv-python-headless>=4.10'") from exc
    return cv2


def find_grid(image_u8: np.ndarray, board: tuple[int, int]) -> np.ndarray:
    """The whole visible grid of a board of ``board`` (n, m) inner corners, as (rows, cols, 2).

    Raises:
        CalibrationError: no board, a board of another size, or a board partly out of view.
    """
    cv2 = _cv2()
    n, m = board
    flags = cv2.CALIB_CB_LARGER | cv2.CALIB_CB_EXHAUSTIVE
    found, corners, meta = cv2.findChessboardCornersSBWithMeta(image_u8, (n, m), flags)
    if found:
        grid = corners.reshape(*meta.shape[:2], 2).astype(np.float64)
        if sorted(grid.shape[:2]) != sorted((n, m)):
            seen = _size_text(grid, n >= m)
            raise CalibrationError(
                f"the board shows {seen} inner corners, not {n}x{m}: give --board {seen} "
                f"(the count of INNER corners: a board of 10x7 squares has 9x6)"
            )
        return grid
    found, corners, meta = cv2.findChessboardCornersSBWithMeta(image_u8, (3, 3), flags)
    grid = corners.reshape(*meta.shape[:2], 2).astype(np.float64) if found else None
    if grid is not None and grid.shape[0] * grid.shape[1] > 9 and _looks_like_board(image_u8, grid):
        seen = _size_text(grid, n >= m)
        if _touches_border(grid, image_u8.shape):
            raise CalibrationError(
                f"only part of the board is seen ({seen} of {n}x{m} inner corners): put the whole board in view"
            )
        raise CalibrationError(
            f"the board shows {seen} inner corners, not {n}x{m}: give --board {seen} "
            f"(the count of INNER corners: a board of 10x7 squares has 9x6)"
        )
    raise CalibrationError(
        f"no {n}x{m} checkerboard found in the pseudo-image (is the board in view, in focus and blinking?)"
    )


def _looks_like_board(image: np.ndarray, grid: np.ndarray) -> bool:
    """True if the squares between the corners alternate dark and light, clearly (no chance grid in noise)."""
    centres = 0.25 * (grid[:-1, :-1] + grid[1:, :-1] + grid[:-1, 1:] + grid[1:, 1:])
    h, w = image.shape[:2]
    values = []
    for cx, cy in centres.reshape(-1, 2):
        x, y = int(round(cx)), int(round(cy))
        values.append(float(image[max(y - 1, 0) : min(y + 2, h), max(x - 1, 0) : min(x + 2, w)].mean()))
    cells = np.asarray(values).reshape(centres.shape[:2])
    jj, ii = np.mgrid[0 : cells.shape[0], 0 : cells.shape[1]]
    even, odd = cells[(ii + jj) % 2 == 0], cells[(ii + jj) % 2 == 1]
    light, dark = (even, odd) if even.mean() > odd.mean() else (odd, even)
    return bool(light.min() > dark.max() and light.min() - dark.max() > 0.25 * float(np.percentile(image, 99)))


def _size_text(grid: np.ndarray, long_first: bool) -> str:
    a, b = sorted(grid.shape[:2], reverse=long_first)
    return f"{a}x{b}"


def _touches_border(grid: np.ndarray, shape: tuple[int, ...]) -> bool:
    """True if the corners one square beyond the grid's edges fall outside the image."""
    h, w = shape[:2]
    beyond = [
        2 * grid[0] - grid[1],
        2 * grid[-1] - grid[-2],
        2 * grid[:, 0] - grid[:, 1],
        2 * grid[:, -1] - grid[:, -2],
    ]
    pts = np.concatenate(beyond)
    return bool(np.any((pts[:, 0] < 0) | (pts[:, 1] < 0) | (pts[:, 0] > w - 1) | (pts[:, 1] > h - 1)))


def order_in_image(grid: np.ndarray) -> np.ndarray:
    """Transpose/flip a (rows, cols, 2) grid so that i runs left to right and j top to bottom."""
    step_cols = np.nanmean(np.diff(grid, axis=1).reshape(-1, 2), axis=0)
    step_rows = np.nanmean(np.diff(grid, axis=0).reshape(-1, 2), axis=0)
    horiz_cols = abs(step_cols[0]) / (np.hypot(*step_cols) + 1e-12)
    horiz_rows = abs(step_rows[0]) / (np.hypot(*step_rows) + 1e-12)
    if horiz_rows > horiz_cols:  # the rows axis is the more horizontal one: make it the columns
        grid = grid.transpose(1, 0, 2)
        step_cols, step_rows = step_rows, step_cols
    if step_cols[0] < 0:
        grid = grid[:, ::-1]
    if step_rows[1] < 0:
        grid = grid[::-1, :]
    angle = math.degrees(math.atan2(abs(step_cols[1]), abs(step_cols[0])))
    if angle > 35.0:
        log.warning(
            "the board is turned %.0f deg in the image: 'left/right/up/down' names are ambiguous; "
            "check the origin and axes on the report figure",
            angle,
        )
    return np.ascontiguousarray(grid)


def _corner_model(q: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    cx, cy, t1, t2, a, b, s = q
    d1 = -math.sin(t1) * (xs - cx) + math.cos(t1) * (ys - cy)
    d2 = -math.sin(t2) * (xs - cx) + math.cos(t2) * (ys - cy)
    return a + b * np.tanh(d1 / s) * np.tanh(d2 / s)


def refine_corner(
    image: np.ndarray, xy: np.ndarray, dir1: np.ndarray, dir2: np.ndarray, radius_px: int
) -> np.ndarray | None:
    """Fit the blurred-corner model around ``xy``; None if the window leaves the image or the fit fails.

    Args:
        image: (H, W) float pseudo-image.
        xy: (2,) starting position, px.
        dir1, dir2: (2,) directions of the board's edges through the corner (image vectors).
        radius_px: half-width of the square window.
    """
    from scipy.optimize import least_squares

    x0, y0 = int(round(xy[0])), int(round(xy[1]))
    h, w = image.shape
    if x0 - radius_px < 0 or y0 - radius_px < 0 or x0 + radius_px >= w or y0 + radius_px >= h:
        return None
    ys, xs = np.mgrid[y0 - radius_px : y0 + radius_px + 1, x0 - radius_px : x0 + radius_px + 1]
    xs, ys = xs.ravel().astype(np.float64), ys.ravel().astype(np.float64)
    values = image[y0 - radius_px : y0 + radius_px + 1, x0 - radius_px : x0 + radius_px + 1].ravel()
    weight = np.sqrt(np.exp(-((xs - xy[0]) ** 2 + (ys - xy[1]) ** 2) / (2 * (radius_px / 2) ** 2)))
    t1, t2 = math.atan2(dir1[1], dir1[0]), math.atan2(dir2[1], dir2[0])
    sign = (
        np.sign(
            np.sum((values - values.mean()) * _corner_model(np.array([xy[0], xy[1], t1, t2, 0.0, 1.0, 1.0]), xs, ys))
        )
        or 1.0
    )
    q0 = np.array([xy[0], xy[1], t1, t2, values.mean(), sign * 0.5 * np.ptp(values), 1.0])
    try:
        fit = least_squares(lambda q: weight * (_corner_model(q, xs, ys) - values), q0, method="lm")
    except (ValueError, np.linalg.LinAlgError):
        return None
    out = fit.x[:2]
    if not fit.success or not np.all(np.isfinite(out)) or np.hypot(*(out - xy)) > 0.25 * radius_px + 1.0:
        return None
    return out


def detect_corners(image: np.ndarray, board: tuple[int, int], refine: bool = True) -> CornerGrid:
    """Inner corners of the ``board`` (n, m) in a pseudo-image, ordered in image terms, sub-pixel.

    Raises:
        CalibrationError: see :func:`find_grid`.
    """
    coarse = order_in_image(find_grid(to_uint8(image), board))
    px = coarse.copy()
    refined = np.zeros(coarse.shape[:2], dtype=bool)
    if refine:
        spacing = min(
            np.nanmin(np.hypot(*np.diff(coarse, axis=1).reshape(-1, 2).T)),
            np.nanmin(np.hypot(*np.diff(coarse, axis=0).reshape(-1, 2).T)),
        )
        radius = int(np.clip(round(0.3 * spacing), 3, 10))
        rows, cols = coarse.shape[:2]
        values = np.asarray(image, dtype=np.float64)
        for j in range(rows):
            for i in range(cols):
                d1 = coarse[j, min(i + 1, cols - 1)] - coarse[j, max(i - 1, 0)]
                d2 = coarse[min(j + 1, rows - 1), i] - coarse[max(j - 1, 0), i]
                out = refine_corner(values, coarse[j, i], d1, d2, radius)
                if out is not None:
                    px[j, i], refined[j, i] = out, True
        if not refined.all():
            log.warning("%d of %d corners kept OpenCV's position (model fit failed)", (~refined).sum(), refined.size)
    return CornerGrid(px=px, coarse_px=coarse, refined=refined)
