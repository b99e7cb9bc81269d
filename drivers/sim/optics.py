"""Mapping from the laser plane to sensor pixels: a homography plus one radial distortion term.

Pixel centres are at integer coordinates (u = column, v = row). A point (X, Y) of the plane maps to
the undistorted pixel ``(u', v') ~ H @ (X, Y, 1)`` and then to ``c + (u' - c) (1 + k1 r^2)`` with
``r = |u' - c| / focal_px`` (normalised image radius). ``PlaneCamera.identity()`` is the plain
camera of the benchmark (plane unit = pixel); ``tilted_pinhole`` builds the paper's rig
(camera 38 deg down from the light-sheet plane, 21 deg upstream; appendix).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PlaneCamera:
    """Plane -> pixel mapping.

    Attributes:
        homography: row-major 3x3 matrix H (9 floats) from plane (X, Y, 1) to undistorted pixels.
        k1: radial distortion coefficient (0: none).
        centre_px: (cx, cy) distortion centre, pixels.
        focal_px: focal length in pixels that normalises the radius of the distortion.
        units: length unit of the plane ("px" or "m").
    """

    homography: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    k1: float = 0.0
    centre_px: tuple[float, float] = (320.0, 240.0)
    focal_px: float = 1000.0
    units: str = "px"

    @staticmethod
    def identity() -> PlaneCamera:
        """Plane coordinates are pixel coordinates."""
        return PlaneCamera()

    @property
    def matrix(self) -> np.ndarray:
        """H as a (3, 3) array."""
        return np.asarray(self.homography, dtype=np.float64).reshape(3, 3)

    def project(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Plane (x, y) -> pixel (u, v), any matching shapes."""
        h = self.matrix
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        w = h[2, 0] * x + h[2, 1] * y + h[2, 2]
        u = (h[0, 0] * x + h[0, 1] * y + h[0, 2]) / w
        v = (h[1, 0] * x + h[1, 1] * y + h[1, 2]) / w
        if self.k1 == 0.0:
            return u, v
        cx, cy = self.centre_px
        scale = 1.0 + self.k1 * ((u - cx) ** 2 + (v - cy) ** 2) / self.focal_px**2
        return cx + (u - cx) * scale, cy + (v - cy) * scale

    def unproject(self, u: np.ndarray, v: np.ndarray, iterations: int = 20) -> tuple[np.ndarray, np.ndarray]:
        """Pixel (u, v) -> plane (x, y): inverse of :meth:`project` (fixed-point undistortion)."""
        u, v = np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64)
        if self.k1 != 0.0:
            cx, cy = self.centre_px
            du, dv = u - cx, v - cy
            uu, vv = du.copy(), dv.copy()
            for _ in range(iterations):
                scale = 1.0 + self.k1 * (uu**2 + vv**2) / self.focal_px**2
                uu, vv = du / scale, dv / scale
            u, v = cx + uu, cy + vv
        h = np.linalg.inv(self.matrix)
        w = h[2, 0] * u + h[2, 1] * v + h[2, 2]
        return (h[0, 0] * u + h[0, 1] * v + h[0, 2]) / w, (h[1, 0] * u + h[1, 1] * v + h[1, 2]) / w

    def to_attrs(self) -> dict[str, object]:
        """Parameters as a flat mapping."""
        return {
            "homography": list(self.homography),
            "k1": self.k1,
            "centre_px": list(self.centre_px),
            "focal_px": self.focal_px,
            "units": self.units,
        }


def tilted_pinhole(
    width: int = 640,
    height: int = 480,
    focal_px: float = 2300.0,
    distance_m: float = 1.02,
    look_at_m: tuple[float, float] = (0.09, 0.0),
    tilt_down_deg: float = 38.0,
    upstream_deg: float = 21.0,
    k1: float = 0.0,
) -> PlaneCamera:
    """Pinhole camera looking at the plane z = 0 (metres) from above at an angle (paper's appendix).

    The flow goes along +X. The camera sits ``distance_m`` from ``look_at_m``, its optical axis
    making ``tilt_down_deg`` with the plane and turned ``upstream_deg`` against the flow. The
    default focal length (35 mm lens, 15 µm pixels) gives ~0.42 mm per pixel as in the paper.

    Returns:
        A :class:`PlaneCamera` in metres whose principal point is the sensor centre.
    """
    elev, azim = math.radians(tilt_down_deg), math.radians(upstream_deg)
    # Direction from the target to the camera: up by the tilt, back (downstream, +X) and sideways.
    back = np.array([math.sin(azim), -math.cos(azim), 0.0])
    to_camera = math.cos(elev) * back + math.sin(elev) * np.array([0.0, 0.0, 1.0])
    target = np.array([look_at_m[0], look_at_m[1], 0.0])
    centre = target + distance_m * to_camera
    forward = -to_camera
    right = np.cross(forward, np.array([0.0, 0.0, 1.0]))
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rot = np.stack([right, down, forward])  # world -> camera axes (x right, y down, z forward)
    trans = -rot @ centre
    k = np.array([[focal_px, 0.0, width / 2 - 0.5], [0.0, focal_px, height / 2 - 0.5], [0.0, 0.0, 1.0]])
    h = k @ np.column_stack([rot[:, 0], rot[:, 1], trans])
    h /= h[2, 2]
    return PlaneCamera(
        homography=tuple(float(v) for v in h.ravel()),
        k1=k1,
        centre_px=(width / 2 - 0.5, height / 2 - 0.5),
        focal_px=focal_px,
        units="m",
    )
