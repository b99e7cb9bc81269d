"""Polynomial fit and evaluation, the plane frame of a board, the mapping object and its file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from flagtrack.calibration import load_mapping
from flagtrack.calibration.calfile import calibration_to_mapping, read_calibration_file, save_calibration
from flagtrack.calibration.corners import CornerGrid
from flagtrack.calibration.errors import CalibrationError
from flagtrack.calibration.fit import BoardSpec, calibrate_corners, fit_mapping
from flagtrack.calibration.frame import Direction, GridFrame
from flagtrack.calibration.polynomial import Polynomial2D, exponents
from flagtrack.daemon.errors import ConfigError, FormatError
from flagtrack.drivers.sim.optics import tilted_pinhole


def _random_poly(degree: int, seed: int) -> Polynomial2D:
    rng = np.random.default_rng(seed)
    n = len(exponents(degree))
    return Polynomial2D(degree, (300.0, 200.0), 320.0, tuple(rng.normal(size=n)), tuple(rng.normal(size=n)))


def test_exponents_list_every_monomial_once_by_degree() -> None:
    assert exponents(2) == [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)]
    for d in range(1, 8):
        terms = exponents(d)
        assert len(terms) == len(set(terms)) == (d + 1) * (d + 2) // 2
        assert all(i + j <= d for i, j in terms)


@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5, 6, 7])
@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.uint16, np.int64])
def test_compiled_evaluation_matches_the_design_matrix(degree: int, dtype: type) -> None:
    poly = _random_poly(degree, seed=degree)
    rng = np.random.default_rng(1)
    x = rng.integers(0, 640, (13, 77)).astype(dtype)
    y = rng.integers(0, 480, (13, 77)).astype(dtype)
    fx, fy = poly(x, y)
    rx, ry = poly.evaluate_numpy(x, y)
    assert fx.shape == x.shape and fx.dtype == np.float64
    np.testing.assert_allclose(fx, rx, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(fy, ry, rtol=1e-12, atol=1e-12)


def test_fit_recovers_a_polynomial_and_leave_one_out_matches_refits() -> None:
    truth = _random_poly(3, seed=5)
    rng = np.random.default_rng(2)
    x, y = rng.uniform(0, 640, 60), rng.uniform(0, 480, 60)
    tx, ty = truth(x, y)
    fit = Polynomial2D.fit(x, y, tx, ty, 3, truth.centre, truth.scale)
    np.testing.assert_allclose(fit.coef_x, truth.coef_x, atol=1e-9)
    noisy_x = tx + rng.normal(0, 0.01, 60)
    noisy = Polynomial2D.fit(x, y, noisy_x, ty, 3, truth.centre, truth.scale)
    loo_x, _ = noisy.leave_one_out(x, y, noisy_x, ty)
    for k in (0, 17, 59):
        keep = np.arange(60) != k
        refit = Polynomial2D.fit(x[keep], y[keep], noisy_x[keep], ty[keep], 3, truth.centre, truth.scale)
        assert loo_x[k] == pytest.approx(refit(x[k : k + 1], y[k : k + 1])[0][0] - noisy_x[k], abs=1e-9)


def test_jacobian_matches_finite_differences() -> None:
    poly = _random_poly(4, seed=3)
    x, y, h = np.array([100.0, 400.0]), np.array([50.0, 300.0]), 1e-4
    jac = poly.jacobian(x, y)
    dx = (np.stack(poly(x + h, y)) - np.stack(poly(x - h, y))) / (2 * h)
    dy = (np.stack(poly(x, y + h)) - np.stack(poly(x, y - h))) / (2 * h)
    np.testing.assert_allclose(jac[:, :, 0], dx.T, rtol=1e-6)
    np.testing.assert_allclose(jac[:, :, 1], dy.T, rtol=1e-6)


def test_fit_rejects_too_few_points_and_bad_coefficients() -> None:
    x = np.arange(5.0)
    with pytest.raises(ValueError, match="do not determine"):
        Polynomial2D.fit(x, x**2, x, x, 3, (0.0, 0.0), 1.0)
    with pytest.raises(ValueError, match="needs 6 coefficients"):
        Polynomial2D(2, (0.0, 0.0), 1.0, (1.0,) * 5, (1.0,) * 6)


@pytest.mark.parametrize(
    "frame, origin_ij, x_step_ij, y_step_ij",
    [
        (GridFrame(), (0, 0), (1, 0), (0, -1)),
        (GridFrame("bottom-left", Direction.RIGHT), (0, 5), (1, 0), (0, -1)),
        (GridFrame("top-right", Direction.DOWN), (8, 0), (0, 1), (1, 0)),
        (GridFrame("3,2", Direction.LEFT, Direction.UP), (3, 2), (-1, 0), (0, -1)),
    ],
)
def test_frame_puts_the_origin_and_axes_where_asked(
    frame: GridFrame, origin_ij: tuple[int, int], x_step_ij: tuple[int, int], y_step_ij: tuple[int, int]
) -> None:
    plane = GridFrame(frame.origin_corner, frame.x_axis, frame.y_axis, (0.001, -0.002)).plane_coordinates(9, 6, 0.02)
    i0, j0 = origin_ij
    assert plane[j0, i0] == pytest.approx([0.001, -0.002])

    def step(di: int, dj: int) -> np.ndarray:  # one square along (di, dj), or back from the opposite side
        if 0 <= i0 + di < 9 and 0 <= j0 + dj < 6:
            return plane[j0 + dj, i0 + di] - plane[j0, i0]
        return plane[j0, i0] - plane[j0 - dj, i0 - di]

    assert step(*x_step_ij) == pytest.approx([0.02, 0.0])
    assert step(*y_step_ij) == pytest.approx([0.0, 0.02])


def test_frame_errors_name_the_problem() -> None:
    with pytest.raises(ValueError, match="perpendicular"):
        GridFrame(x_axis=Direction.RIGHT, y_axis=Direction.LEFT)
    with pytest.raises(ValueError, match="origin corner must be"):
        GridFrame("middle")
    with pytest.raises(ValueError, match="outside the 9x6 grid"):
        GridFrame("9,0").origin_index(9, 6)


def _tilted_calibration(degree: int = 3):
    """A calibration fitted on the exact corners of a 11x9 board seen by the paper's tilted camera."""
    optics = tilted_pinhole()
    board = BoardSpec((11, 9), 0.02)
    frame = GridFrame("1,4", Direction.RIGHT)
    plane = frame.plane_coordinates(11, 9, 0.02)
    u, v = optics.project(plane[..., 0], plane[..., 1])
    grid = CornerGrid(px=np.stack([u, v], axis=-1), coarse_px=np.stack([u, v], axis=-1), refined=np.ones((9, 11), bool))
    return calibrate_corners(grid, board, frame, degree, (640, 480)), optics


def test_mapping_on_exact_corners_follows_the_camera_and_inverts() -> None:
    cal, optics = _tilted_calibration()
    assert cal.mapping.units == "m"
    assert cal.residuals.max_px < 0.05 and cal.residuals.mean_mm < 0.01
    assert cal.residuals.pixel_size_mm == pytest.approx(0.57, abs=0.05)  # the paper's rig: ~0.42-0.6 mm/px
    xs, ys = np.meshgrid(np.linspace(0.0, 0.18, 7), np.linspace(-0.06, 0.06, 5))
    u, v = optics.project(xs, ys)
    mx, my = cal.mapping.map(u.astype(np.float32), v.astype(np.float32))
    assert np.abs(mx - xs).max() < 1e-4 and np.abs(my - ys).max() < 1e-4  # float32 pixels: ~3e-5 px rounding
    bu, bv = cal.mapping.to_pixels(xs, ys)
    fx, fy = cal.mapping.map(bu, bv)
    assert np.abs(fx - xs).max() < 1e-12 and np.abs(fy - ys).max() < 1e-12


def test_too_few_corners_for_the_degree_is_a_clear_error() -> None:
    px = np.stack(np.meshgrid(np.arange(3.0) * 30, np.arange(3.0) * 30), axis=-1).reshape(-1, 2)
    with pytest.raises(CalibrationError, match=r"too few corners \(9\) for a degree-3 mapping"):
        fit_mapping(px, px * 1e-3, 3, (640, 480))
    grid = np.stack(np.meshgrid(np.arange(6.0) * 30, np.arange(3.0) * 30), axis=-1).reshape(-1, 2)
    with pytest.raises(CalibrationError, match="lower --degree"):
        fit_mapping(grid, grid * 1e-3, 3, (640, 480))  # 18 corners on 3 rows cannot fix v^3
    assert fit_mapping(grid, grid * 1e-3, 1, (640, 480)).degree == 1


def test_calibration_file_round_trip(tmp_path: Path) -> None:
    cal, _ = _tilted_calibration()
    path = save_calibration(cal, tmp_path / "sub" / "cal.yaml")
    data = read_calibration_file(path)
    assert data["degree"] == 3 and data["board"] == {"inner_corners": [11, 9], "square_mm": 20.0}
    assert data["residuals"]["n_corners"] == 99 and data["frame"]["y_axis"] == "up"
    loaded = load_mapping(path)
    assert loaded.units == "m" and loaded.image_size == (640, 480)
    x, y = np.array([10.0, 320.0, 630.0]), np.array([470.0, 240.0, 5.0])
    np.testing.assert_array_equal(np.stack(loaded.map(x, y)), np.stack(cal.mapping.map(x, y)))
    np.testing.assert_allclose(np.stack(loaded.to_pixels(*cal.mapping.map(x, y))), np.stack([x, y]), atol=1e-9)


def _write(tmp_path: Path, data: object) -> Path:
    path = tmp_path / "cal.yaml"
    path.write_text(data if isinstance(data, str) else yaml.safe_dump(data))
    return path


def _bad_files() -> list[tuple[str, object, type, str]]:
    cal, _ = _tilted_calibration()
    good = calibration_to_mapping(cal)
    short = {**good, "forward": {**good["forward"], "x": good["forward"]["x"][:-1]}}
    wrong_terms = {**good, "inverse": {**good["inverse"], "exponents": good["inverse"]["exponents"][::-1]}}
    return [
        ("not yaml", "a: [1, 2\n", FormatError, "not a YAML file"),
        ("other yaml", {"tracker": {"root": [0, 0]}}, FormatError, "not a calibration file"),
        ("new version", {**good, "version": 2}, FormatError, "version 2 is not supported"),
        ("no forward", {k: v for k, v in good.items() if k != "forward"}, FormatError, "missing 'forward'"),
        ("short coefficients", short, FormatError, "bad 'forward' section: a degree-3 polynomial needs 10"),
        ("shuffled exponents", wrong_terms, FormatError, "exponents do not list"),
        ("no size", {**good, "image_size": None}, FormatError, "image_size"),
    ]


@pytest.mark.parametrize("name, content, error, message", _bad_files(), ids=[case[0] for case in _bad_files()])
def test_bad_calibration_files_are_clear_errors(
    tmp_path: Path, name: str, content: object, error: type, message: str
) -> None:
    path = _write(tmp_path, content)
    with pytest.raises(error, match=message) as info:
        load_mapping(path)
    assert str(path) in str(info.value)


def test_a_missing_calibration_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read calibration file"):
        load_mapping(tmp_path / "nope.yaml")


def test_calibration_attrs_summarise_the_file(tmp_path: Path) -> None:
    from flagtrack.calibration import calibration_attrs

    cal, _ = _tilted_calibration()
    path = save_calibration(cal, tmp_path / "cal.yaml")
    attrs = calibration_attrs(path)
    assert attrs["calibration_degree"] == 3
    assert attrs["calibration_max_px"] == pytest.approx(cal.residuals.max_px, abs=1e-6)
    assert yaml.safe_load(attrs["calibration_yaml"])["format"] == "flagtrack-calibration"
