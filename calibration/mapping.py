"""The calibrated pixel -> plane mapping that the tracker applies to every event.

:class:`PolynomialMapping` implements ``flagtrack.daemon.core.mapping.PointMapping``: ``map``
takes pixel coordinates (pixel centres at integers, any numeric dtype) and returns float64 plane
coordinates in metres. ``to_pixels`` is its inverse (for drawing): the fitted inverse polynomial,
polished by Newton steps on the forward one so that ``map(to_pixels(p)) == p`` to ~1e-12 m.
"""

from __future__ import annotations

import numpy as np

from flagtrack.calibration.polynomial import Polynomial2D


class PolynomialMapping:
    """Pixel -> plane (metres) by a polynomial, and back.

    Args:
        forward: pixel -> plane polynomial.
        inverse: plane -> pixel polynomial (the starting point of :meth:`to_pixels`).
        image_size: (width, height) of the sensor the calibration was made on, pixels.
    """

    units = "m"

    def __init__(self, forward: Polynomial2D, inverse: Polynomial2D, image_size: tuple[int, int]) -> None:
        self.forward = forward
        self.inverse = inverse
        self.image_size = (int(image_size[0]), int(image_size[1]))

    @property
    def degree(self) -> int:
        """Total degree of the forward polynomial."""
        return self.forward.degree

    def map(self, x_px: np.ndarray, y_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Plane (x, y) in metres of pixel positions (arrays of one shape, any numeric dtype)."""
        return self.forward(x_px, y_px)

    def to_pixels(self, x_m: np.ndarray, y_m: np.ndarray, newton_steps: int = 3) -> tuple[np.ndarray, np.ndarray]:
        """Pixel (x, y) of plane points in metres: inverse polynomial, then Newton steps on :meth:`map`."""
        x_m, y_m = np.asarray(x_m, np.float64), np.asarray(y_m, np.float64)
        u, v = self.inverse(x_m, y_m)
        for _ in range(newton_steps):
            fx, fy = self.forward(u, v)
            jac = self.forward.jacobian(u, v)
            det = jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]
            ok = np.abs(det) > 1e-300
            det = np.where(ok, det, 1.0)
            rx, ry = x_m - fx, y_m - fy
            du = (jac[..., 1, 1] * rx - jac[..., 0, 1] * ry) / det
            dv = (-jac[..., 1, 0] * rx + jac[..., 0, 0] * ry) / det
            u, v = u + np.where(ok, du, 0.0), v + np.where(ok, dv, 0.0)
        return u, v

    def pixel_size_m(self, x_px: np.ndarray, y_px: np.ndarray) -> np.ndarray:
        """Effective pixel size sqrt(|det J|) of the mapping at pixel positions, metres."""
        jac = self.forward.jacobian(x_px, y_px)
        return np.sqrt(np.abs(jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]))

    def to_attrs(self) -> dict[str, object]:
        """Flat summary for output attributes."""
        return {
            "calibration_units": self.units,
            "calibration_degree": self.degree,
            "calibration_image_size": list(self.image_size),
        }
