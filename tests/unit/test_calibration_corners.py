"""Corner detection on event-like pseudo-images of a board seen by the paper's tilted camera."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.calibration.corners import detect_corners, order_in_image
from flagtrack.calibration.errors import CalibrationError
from flagtrack.drivers.sim.optics import tilted_pinhole
from flagtrack.drivers.sim.scenes import CheckerboardSpec, checkerboard

pytest.importorskip("cv2", reason="corner detection needs opencv-python-headless")

SPEC = CheckerboardSpec(inner_corners=(11, 9), square=0.02, origin=(-0.02, -0.08))


def event_like_image(spec: CheckerboardSpec, k1: float = 0.0, seed: int = 0) -> np.ndarray:
    """Events per switch of each pixel: lit fraction (3x3 supersampled) through log + thresholds N(0.3, 0.03)."""
    optics = tilted_pinhole(k1=k1)
    vv, uu = np.mgrid[0:480, 0:640].astype(np.float64)
    lit = np.zeros_like(uu)
    for du in (-1 / 3, 0.0, 1 / 3):
        for dv in (-1 / 3, 0.0, 1 / 3):
            lit += checkerboard(spec)(*optics.unproject(uu + du, vv + dv)) / 9
    threshold = np.random.default_rng(seed).normal(0.3, 0.03, lit.shape)
    return np.floor(np.log((0.1 + lit) / 0.1) / threshold)


@pytest.fixture(scope="module")
def image() -> np.ndarray:
    return event_like_image(SPEC)


def _truth_px(spec: CheckerboardSpec, k1: float = 0.0) -> np.ndarray:
    corners = spec.corners()
    u, v = tilted_pinhole(k1=k1).project(corners[:, 0], corners[:, 1])
    return np.column_stack([u, v])


def _errors(found: np.ndarray, truth: np.ndarray) -> np.ndarray:
    d = np.hypot(*(found.reshape(-1, 1, 2) - truth.reshape(1, -1, 2)).transpose(2, 0, 1))
    return d.min(axis=1)


@pytest.mark.parametrize("k1", [0.0, -0.3])
def test_corners_are_found_to_a_few_hundredths_of_a_pixel(k1: float) -> None:
    img = event_like_image(SPEC, k1=k1) if k1 else event_like_image(SPEC)
    grid = detect_corners(img, (11, 9))
    assert grid.shape == (11, 9) and grid.refined.all()
    err = _errors(grid.px, _truth_px(SPEC, k1))
    coarse = _errors(grid.coarse_px, _truth_px(SPEC, k1))
    assert err.mean() < 0.06 and err.max() < 0.2
    assert err.mean() < 0.6 * coarse.mean()  # the model fit beats OpenCV's own positions


def test_grid_is_ordered_left_to_right_and_top_to_bottom(image: np.ndarray) -> None:
    px = detect_corners(image, (9, 11)).px  # the board size in either order
    assert px.shape == (9, 11, 2)
    assert np.all(np.diff(px[..., 0], axis=1) > 10)  # i: to the right
    assert np.all(np.diff(px[..., 1], axis=0) > 10)  # j: downwards
    truth = _truth_px(SPEC).reshape(9, 11, 2)  # plane x right, y up: the first plane row is the bottom one
    assert np.hypot(*(px[-1, 0] - truth[0, 0])) < 0.2


def test_order_in_image_undoes_transposes_and_flips() -> None:
    jj, ii = np.mgrid[0:4, 0:6].astype(float)
    grid = np.stack([100 + 30 * ii + 5 * jj, 50 + 25 * jj - 4 * ii], axis=-1)
    for variant in (grid, grid[::-1], grid[:, ::-1], grid.transpose(1, 0, 2), grid.transpose(1, 0, 2)[::-1, ::-1]):
        np.testing.assert_array_equal(order_in_image(variant), grid)


def test_a_board_of_another_size_is_named(image: np.ndarray) -> None:
    with pytest.raises(CalibrationError, match="shows 11x9 inner corners, not 9x6: give --board 11x9"):
        detect_corners(image, (9, 6))


def test_a_board_partly_out_of_view_is_a_clear_error(image: np.ndarray) -> None:
    cut = image.copy()
    cut[:, 330:] = 0.0
    with pytest.raises(CalibrationError, match="only part of the board is seen"):
        detect_corners(cut, (11, 9))


def test_no_board_is_a_clear_error() -> None:
    noise = np.random.default_rng(0).poisson(2.0, (480, 640)).astype(float)
    with pytest.raises(CalibrationError, match="no 9x6 checkerboard found"):
        detect_corners(noise, (9, 6))
