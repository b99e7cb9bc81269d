"""From a blinking-board recording to a pixel -> plane mapping with its residuals.

:func:`calibrate_events` chains the steps: blink detection and pseudo-image
(:mod:`~flagtrack.calibration.pseudo_image`), corners (:mod:`~flagtrack.calibration.corners`),
plane coordinates of the corners (:mod:`~flagtrack.calibration.frame`), least-squares polynomial
fits pixel -> plane and plane -> pixel, residuals.

Residuals are reported in millimetres on the plane and in pixels: a plane residual r is turned
into the pixel displacement ``J^-1 r`` (J: the mapping's Jacobian at the corner), so "pixel
equivalent" means the same thing anywhere on a tilted view. Leave-one-out residuals (each corner
predicted by the fit without it, exact from the hat matrix) tell how well the mapping predicts
points it was not fitted on, which the plain residuals of an over-fitted polynomial hide.
"""

from __future__ import annotations

import datetime
import logging
from dataclasses import dataclass, field

import numpy as np

from flagtrack.calibration.corners import CornerGrid, detect_corners
from flagtrack.calibration.errors import CalibrationError
from flagtrack.calibration.frame import GridFrame
from flagtrack.calibration.mapping import PolynomialMapping
from flagtrack.calibration.polynomial import Polynomial2D, exponents
from flagtrack.calibration.pseudo_image import BlinkSearch, BlinkSummary, BlinkTiming, detect_blink, pseudo_image

log = logging.getLogger(__name__)

DEFAULT_DEGREE = 3
"""Measured on the paper's tilted view (docs/calibration.md): degree 2 leaves up to ~1 px of model
error, degree 3 ~0.05 px (far below corner noise), higher degrees only fit more noise."""


@dataclass(frozen=True)
class BoardSpec:
    """The checkerboard shown on the screen.

    Attributes:
        inner_corners: (n, m) inner corners (a board of 10 x 7 squares has 9 x 6).
        square_m: side of one square on the plane, metres.
    """

    inner_corners: tuple[int, int] = (9, 6)
    square_m: float = 0.02

    def __post_init__(self) -> None:
        if min(self.inner_corners) < 2:
            raise ValueError(f"a board needs at least 2x2 inner corners, got {self.inner_corners}")
        if not self.square_m > 0:
            raise ValueError("BoardSpec.square_m must be > 0")


@dataclass(frozen=True)
class Residuals:
    """Fit quality, over the corners. ``*_mm`` on the plane, ``*_px`` pixel equivalents."""

    n_corners: int
    mean_mm: float
    max_mm: float
    rms_mm: float
    mean_px: float
    max_px: float
    loo_mean_mm: float
    loo_max_mm: float
    loo_mean_px: float
    loo_max_px: float
    inverse_max_px: float
    pixel_size_mm: float

    def to_mapping(self) -> dict[str, float | int]:
        """Plain data, rounded for reading."""
        return {k: (round(v, 6) if isinstance(v, float) else v) for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class Calibration:
    """A calibration: the mapping, what it was fitted on, how well it fits.

    Attributes:
        mapping: the pixel -> plane mapping.
        board: the board.
        frame: origin and axes of the plane frame.
        corners_px: (n_rows, n_cols, 2) detected corners in image order, pixels.
        plane_m: (n_rows, n_cols, 2) their plane coordinates, metres.
        residuals: summary of the fit.
        residual_m: (n_rows, n_cols, 2) plane residual vectors mapping(corner) - plane, metres.
        blink: blink timing summary (None if not from a recording).
        source: the recording.
        created: ISO 8601 time of the fit.
    """

    mapping: PolynomialMapping
    board: BoardSpec
    frame: GridFrame
    corners_px: np.ndarray
    plane_m: np.ndarray
    residuals: Residuals
    residual_m: np.ndarray
    blink: BlinkSummary | None = None
    source: str | None = None
    created: str = field(default_factory=lambda: datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"))


def fit_mapping(
    corners_px: np.ndarray, plane_m: np.ndarray, degree: int, image_size: tuple[int, int]
) -> PolynomialMapping:
    """Least-squares pixel -> plane and plane -> pixel polynomials of total ``degree``.

    Args:
        corners_px: (n, 2) pixel positions.
        plane_m: (n, 2) plane positions, metres.
        degree: total degree (>= 1).
        image_size: (width, height), pixels: sets the input normalisation.

    Raises:
        CalibrationError: too few corners (or corners in too few rows/columns) for the degree.
    """
    n_terms = len(exponents(degree))
    n = len(corners_px)
    if n < n_terms + 2:
        raise CalibrationError(
            f"too few corners ({n}) for a degree-{degree} mapping ({n_terms} coefficients "
            f"per axis, at least {n_terms + 2} corners needed): use a board with more corners "
            f"or a lower --degree"
        )
    width, height = image_size
    centre_px = ((width - 1) / 2.0, (height - 1) / 2.0)
    lo, hi = plane_m.min(axis=0), plane_m.max(axis=0)
    centre_m = (float((lo[0] + hi[0]) / 2), float((lo[1] + hi[1]) / 2))
    scale_m = float(max(hi - lo) / 2) or 1.0
    try:
        forward = Polynomial2D.fit(
            corners_px[:, 0],
            corners_px[:, 1],
            plane_m[:, 0],
            plane_m[:, 1],
            degree,
            centre_px,
            max(width, height) / 2.0,
        )
        inverse = Polynomial2D.fit(
            plane_m[:, 0], plane_m[:, 1], corners_px[:, 0], corners_px[:, 1], degree, centre_m, scale_m
        )
    except ValueError as exc:
        raise CalibrationError(f"{exc}: use a board with more corners per side or a lower --degree") from exc
    if n < 2 * n_terms:
        log.warning("%d corners for %d coefficients per axis: the residuals understate the error", n, n_terms)
    return PolynomialMapping(forward, inverse, (width, height))


def residuals(mapping: PolynomialMapping, corners_px: np.ndarray, plane_m: np.ndarray) -> tuple[Residuals, np.ndarray]:
    """Residual summary and (n, 2) plane residual vectors (metres) of ``mapping`` on the corners."""
    u, v = corners_px[:, 0], corners_px[:, 1]
    fx, fy = mapping.map(u, v)
    res_m = np.column_stack([fx - plane_m[:, 0], fy - plane_m[:, 1]])
    jac = mapping.forward.jacobian(u, v)
    inv_jac = np.linalg.inv(jac)
    res_px = np.einsum("nab,nb->na", inv_jac, res_m)
    lx, ly = mapping.forward.leave_one_out(u, v, plane_m[:, 0], plane_m[:, 1])
    loo_m = np.column_stack([lx, ly])
    loo_px = np.einsum("nab,nb->na", inv_jac, loo_m)
    ix, iy = mapping.inverse(plane_m[:, 0], plane_m[:, 1])
    dist_mm, dist_px = np.hypot(*res_m.T) * 1e3, np.hypot(*res_px.T)
    loo_mm, loo_pxd = np.hypot(*loo_m.T) * 1e3, np.hypot(*loo_px.T)
    summary = Residuals(
        n_corners=len(corners_px),
        mean_mm=float(dist_mm.mean()),
        max_mm=float(dist_mm.max()),
        rms_mm=float(np.sqrt(np.mean(dist_mm**2))),
        mean_px=float(dist_px.mean()),
        max_px=float(dist_px.max()),
        loo_mean_mm=float(loo_mm.mean()),
        loo_max_mm=float(loo_mm.max()),
        loo_mean_px=float(loo_pxd.mean()),
        loo_max_px=float(loo_pxd.max()),
        inverse_max_px=float(np.hypot(ix - u, iy - v).max()),
        pixel_size_mm=float(np.median(mapping.pixel_size_m(u, v)) * 1e3),
    )
    return summary, res_m


def calibrate_corners(
    grid: CornerGrid, board: BoardSpec, frame: GridFrame, degree: int, image_size: tuple[int, int]
) -> Calibration:
    """Fit the mapping on detected corners (plane coordinates from ``board`` and ``frame``).

    Raises:
        CalibrationError: an origin corner outside the grid, too few corners for the degree.
    """
    n_cols, n_rows = grid.shape
    try:
        plane = frame.plane_coordinates(n_cols, n_rows, board.square_m)
    except ValueError as exc:
        raise CalibrationError(str(exc)) from exc
    px_flat, plane_flat = grid.px.reshape(-1, 2), plane.reshape(-1, 2)
    mapping = fit_mapping(px_flat, plane_flat, degree, image_size)
    summary, res_m = residuals(mapping, px_flat, plane_flat)
    return Calibration(
        mapping=mapping,
        board=board,
        frame=frame,
        corners_px=grid.px,
        plane_m=plane,
        residuals=summary,
        residual_m=res_m.reshape(plane.shape),
    )


def calibrate_events(
    events: np.ndarray,
    image_size: tuple[int, int],
    board: BoardSpec,
    frame: GridFrame = GridFrame(),
    degree: int = DEFAULT_DEGREE,
    search: BlinkSearch = BlinkSearch(),
    source: str | None = None,
) -> tuple[Calibration, np.ndarray, BlinkTiming]:
    """Calibrate from the events of a blinking board (EVENT_DTYPE, time-sorted).

    Returns:
        (calibration, pseudo-image (H, W), blink timing).

    Raises:
        CalibrationError: no blinking, no board, a board of another size or partly seen, too few corners.
    """
    width, height = image_size
    timing = detect_blink(events["t"], events["p"], search)
    image = pseudo_image(events, width, height, timing)
    grid = detect_corners(image, board.inner_corners)
    cal = calibrate_corners(grid, board, frame, degree, image_size)
    cal = Calibration(**{**cal.__dict__, "blink": timing.to_attrs(), "source": source})
    r = cal.residuals
    log.info(
        "%d corners, degree %d: residual mean %.3f mm (%.3f px), max %.3f mm (%.3f px)",
        r.n_corners,
        degree,
        r.mean_mm,
        r.mean_px,
        r.max_mm,
        r.max_px,
    )
    return cal, image, timing
