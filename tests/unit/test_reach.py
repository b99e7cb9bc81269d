"""The flag's reach on the sensor (``roi: auto``): the sector around the root, grown by the margin, as
the smallest rectangle of pixels, in pixels and through calibrations (pure geometry)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flagtrack.daemon.core.mapping import AffineMapping
from flagtrack.daemon.core.reach import PixelBox, Reach, pixel_box, search_radius


def sector_distance(reach: Reach, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Distance to the sector, worked out another way: 0 inside (radius and angle), else the distance to
    its outline sampled every 0.05 px-units (arc and both edges)."""
    dx, dy = x - reach.root[0], y - reach.root[1]
    off = np.degrees(np.abs(np.angle(np.exp(1j * (np.arctan2(dy, dx) - math.radians(reach.direction_deg))))))
    inside = (np.hypot(dx, dy) <= reach.radius) & (off <= reach.half_angle_deg)
    half = math.radians(reach.half_angle_deg)
    axis = math.radians(reach.direction_deg)
    n = int(reach.radius * 2 * half / 0.05) + 2
    arc = np.linspace(axis - half, axis + half, n)
    r = np.linspace(0, reach.radius, int(reach.radius / 0.05) + 2)
    ox = np.concatenate([reach.radius * np.cos(arc), r * math.cos(axis - half), r * math.cos(axis + half)])
    oy = np.concatenate([reach.radius * np.sin(arc), r * math.sin(axis - half), r * math.sin(axis + half)])
    best = np.full(x.shape, np.inf)
    for start in range(0, len(ox), 2000):
        px, py = ox[start : start + 2000], oy[start : start + 2000]
        best = np.minimum(best, np.hypot(dx[..., None] - px, dy[..., None] - py).min(axis=-1))
    return np.where(inside, 0.0, best)


def box_of(mask: np.ndarray) -> PixelBox | None:
    rows, columns = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if len(rows) == 0:
        return None
    return PixelBox(int(columns[0]), int(rows[0]), int(columns[-1] - columns[0] + 1), int(rows[-1] - rows[0] + 1))


CASES = [  # root (px), radius, direction, half-angle, margin, sensor
    ((150.0, 240.0), 396.0, 0.0, 90.0, 30.0, (640, 480)),  # the demo rig: the flag to the right
    ((320.0, 20.0), 120.0, 90.0, 90.0, 10.0, (640, 480)),  # hanging down from the top edge
    ((600.0, 300.0), 200.0, 180.0, 90.0, 5.0, (640, 480)),  # pointing left from the right edge
    ((300.0, 200.0), 150.0, -135.0, 45.0, 12.5, (640, 480)),  # a narrow sector up and to the left
    ((300.0, 200.0), 90.0, 37.0, 180.0, 0.0, (640, 480)),  # the whole disc
    ((640.5, 360.2), 400.0, 20.0, 60.0, 40.0, (1280, 720)),
]


@pytest.mark.parametrize("root, radius, direction, half, margin, sensor", CASES)
def test_the_pixel_box_is_the_smallest_holding_every_pixel_in_reach(
    root: tuple[float, float], radius: float, direction: float, half: float, margin: float, sensor: tuple[int, int]
) -> None:
    reach = Reach(root, radius, direction, half, margin)
    rng = np.random.default_rng(7)  # the distance against the sampled outline, at points all over
    x, y = rng.uniform(-100, sensor[0] + 100, 1500), rng.uniform(-100, sensor[1] + 100, 1500)
    np.testing.assert_allclose(reach.distance(x, y), sector_distance(reach, x, y), atol=0.03)
    y_px, x_px = np.mgrid[0 : sensor[1], 0 : sensor[0]].astype(np.float64)
    expected = box_of(reach.contains(x_px, y_px))  # pixel by pixel, against the bounds worked out
    assert pixel_box(reach, image_size=sensor) == expected
    mirrored = AffineMapping(((1.0, 0.0), (0.0, 1.0)), (0.0, 0.0), units="px")  # the same plane, mapped
    assert pixel_box(reach, mirrored, sensor) == expected


@pytest.mark.parametrize("root, radius, direction, half, margin, sensor", CASES)
def test_a_calibration_in_metres_with_y_up_gives_the_box_of_the_same_flag_in_pixels(
    root: tuple[float, float], radius: float, direction: float, half: float, margin: float, sensor: tuple[int, int]
) -> None:
    """A plane of 2 mm per pixel, origin at the sensor's centre, y up: the flag described in metres
    (its direction mirrored) covers the same pixels as described in pixels (to a pixel, at the edge)."""
    scale, cx, cy = 0.002, sensor[0] / 2, sensor[1] / 2
    mapping = AffineMapping(((scale, 0.0), (0.0, -scale)), (-scale * cx, scale * cy))
    plane_root = ((root[0] - cx) * scale, (cy - root[1]) * scale)
    in_metres = Reach(plane_root, radius * scale, -direction, half, margin * scale)
    got = pixel_box(in_metres, mapping, sensor)
    want = pixel_box(Reach(root, radius, direction, half, margin), image_size=sensor)
    assert got is not None and want is not None
    edges = lambda b: (b.x, b.y, b.x + b.width - 1, b.y + b.height - 1)  # noqa: E731
    assert all(abs(a - b) <= 1 for a, b in zip(edges(got), edges(want), strict=True))  # a pixel exactly on the edge


def test_a_nonlinear_calibration_maps_each_pixel_centre() -> None:
    """Barrel-like distortion: the box is that of the pixels whose mapped centres are in reach."""

    class Barrel:
        units = "m"

        def map(self, x_px: np.ndarray, y_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            u, v = (np.asarray(x_px) - 320) / 320, (np.asarray(y_px) - 240) / 320
            k = 1 + 0.2 * (u * u + v * v)
            return 0.5 * u * k, 0.5 * v * k

    reach = Reach((-0.3, 0.0), 0.35, 10.0, 90.0, 0.02)
    y_px, x_px = np.mgrid[0:480:4, 0:640:4].astype(np.float64)  # every 4th pixel, against the outline
    x, y = Barrel().map(x_px, y_px)
    coarse = box_of(sector_distance(reach, x, y) <= 0.02 + 1e-9)
    got = pixel_box(reach, Barrel(), (640, 480))
    assert got is not None and coarse is not None
    assert got.x <= coarse.x * 4 < got.x + 4 and got.y <= coarse.y * 4 < got.y + 4
    assert got.x + got.width - 4 <= (coarse.x + coarse.width - 1) * 4 < got.x + got.width
    assert got.y + got.height - 4 <= (coarse.y + coarse.height - 1) * 4 < got.y + got.height


def test_without_a_sensor_size_the_box_is_cut_at_zero_only() -> None:
    reach = Reach((150.0, 240.0), 396.0, 0.0, 90.0, 30.0)
    assert pixel_box(reach) == PixelBox(120, 0, 576 - 120 + 1, 666 + 1)  # 240 + 396 + 30 = 666
    assert pixel_box(reach, image_size=(640, 480)) == PixelBox(120, 0, 457, 480)


def test_a_reach_off_the_sensor_has_no_box() -> None:
    assert pixel_box(Reach((-500.0, -500.0), 100.0, 0.0, 90.0, 10.0), image_size=(640, 480)) is None
    assert pixel_box(Reach((900.0, 100.0), 100.0, 0.0, 90.0, 10.0), image_size=(640, 480)) is None
    shifted = AffineMapping(((1.0, 0.0), (0.0, 1.0)), (5000.0, 0.0))
    assert pixel_box(Reach((100.0, 100.0), 50.0), shifted, (640, 480)) is None


def test_the_chain_reaches_its_length_plus_its_areas_and_the_background_ring() -> None:
    assert search_radius(300.0, None, 10, 0.6) == pytest.approx(300 + 2 * 1.6 * 30)
    assert search_radius(1.0, (0.5, 0.3, 0.2), 3, 0.5) == pytest.approx(1 + 2 * 1.5 * 0.5)


@pytest.mark.parametrize(
    "kwargs",
    [{"radius": 0.0}, {"margin": -1.0}, {"half_angle_deg": 0.0}, {"half_angle_deg": 181.0}, {"radius": math.nan}],
)
def test_impossible_reaches_are_refused(kwargs: dict) -> None:
    with pytest.raises(ValueError):
        Reach(**{"root": (0.0, 0.0), "radius": 10.0, **kwargs})
