"""``flagtrack aim``'s pure parts: the image of the last window, the rate, hot pixels, the line width
(the focus figure) on synthetic lines of known blur, and the chain and grid drawn over the image."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flagtrack.daemon.core.aim import (
    AimAccumulator,
    AimParams,
    HotPixelParams,
    display_levels,
    find_hot_pixels,
)
from flagtrack.daemon.core.aim_overlay import chain_overlay, nice_step, plane_grid
from flagtrack.daemon.core.chain import ChainParams
from flagtrack.daemon.core.events import make_events
from flagtrack.daemon.core.line_width import LineWidthParams, measure_line_width

W, H = 640, 480


def events_at(t_us: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return make_events(t_us, x, y, np.ones(len(t_us)))


def line_points(sigma_px: float, n: int, rng: np.random.Generator, angle_deg: float = 0.0, curved: bool = False):
    """n points along a 300 px line (or a quarter circle of radius 200 px) through the middle of the
    sensor, spread across it by a Gaussian of ``sigma_px``, as float pixel positions."""
    s = rng.uniform(0.0, 1.0, n)
    d = rng.normal(0.0, sigma_px, n)
    if curved:
        phi = math.radians(200.0) + s * math.pi / 2
        return 420 + (200 + d) * np.cos(phi), 300 + (200 + d) * np.sin(phi)
    a = math.radians(angle_deg)
    along = (s - 0.5) * 300
    return W / 2 + along * math.cos(a) - d * math.sin(a), H / 2 + along * math.sin(a) + d * math.cos(a)


def count_image(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    image = np.zeros((H, W))
    xi, yi = np.rint(x).astype(int), np.rint(y).astype(int)
    ok = (xi >= 0) & (xi < W) & (yi >= 0) & (yi < H)
    np.add.at(image, (yi[ok], xi[ok]), 1)
    return image


# -- the image of the last window ------------------------------------------------------------------


@pytest.mark.parametrize("t_until_extra_us", [None, 0, 3_000])
def test_the_image_holds_exactly_the_events_of_the_last_window(t_until_extra_us: int | None) -> None:
    """Events every 37 µs over 50 ms, each on its own pixel, pushed in uneven pieces: the image counts
    exactly those of [t_end - 10 ms, t_end), t_end the end the camera vouches for."""
    t = np.arange(0, 50_000, 37, dtype=np.int64) + 1_000_000
    index = np.arange(len(t))
    events = events_at(t, index % W, index // W)
    acc = AimAccumulator(AimParams(W, H, window_ms=10.0))
    cuts = [0, 1, 7, 400, 401, 999, len(t)]
    for a, b in zip(cuts, cuts[1:], strict=False):
        until = None if t_until_extra_us is None else int(t[b - 1]) + 1 + t_until_extra_us
        acc.push(events[a:b], until)
    t_end = int(t[-1]) + 1 + (t_until_extra_us or 0)
    assert acc.t_end_us == t_end
    image = acc.window_image()
    expected = (t >= t_end - 10_000) & (t < t_end)
    assert image.dtype == np.uint32 and image.shape == (H, W)
    assert int(image.sum()) == np.count_nonzero(expected)
    np.testing.assert_array_equal(image.ravel()[: len(t)], expected.astype(np.uint32))
    assert acc.frame().image.sum() == image.sum()


def test_events_outside_the_sensor_are_counted_and_left_out() -> None:
    acc = AimAccumulator(AimParams(W, H))
    acc.push(events_at(np.array([10, 20, 30]), np.array([5, W, 7]), np.array([5, 5, H + 3])))
    assert acc.n_outside == 2 and acc.n_events == 1 and acc.window_image().sum() == 1


def test_the_rate_is_that_of_the_last_second() -> None:
    """100 kev/s for 2 s then 300 kev/s for 1.5 s: the rate is 300 kev/s over 0.9-1 s."""
    t = np.concatenate([np.arange(0, 2_000_000, 10), np.arange(2_000_000, 3_500_000, 10 / 3)]).astype(np.int64)
    acc = AimAccumulator(AimParams(W, H, rate_window_s=1.0, bin_ms=100.0))
    for piece in np.array_split(np.arange(len(t)), 97):
        acc.push(events_at(t[piece], piece % W, (piece // W) % H))
    frame = acc.frame()
    assert 0.9 <= frame.rate_span_s <= 1.0
    assert frame.rate_hz == pytest.approx(300_000, rel=0.01)
    assert frame.n_events == len(t)


def test_a_quiet_camera_moves_the_rate_window_on() -> None:
    """The camera vouches for 3 s more without events: the rate falls to 0."""
    acc = AimAccumulator(AimParams(W, H))
    acc.push(events_at(np.arange(0, 1_000_000, 100), np.zeros(10_000), np.zeros(10_000)))
    assert acc.frame().rate_hz == pytest.approx(10_000, rel=0.01)
    acc.push(events_at(np.zeros(0), np.zeros(0), np.zeros(0)), t_until_us=4_000_000)
    frame = acc.frame()
    assert frame.rate_hz == 0.0 and frame.image.sum() == 0 and frame.n_events == 10_000


@pytest.mark.parametrize(
    "kwargs",
    [dict(width=0), dict(window_ms=0.0), dict(rate_window_s=-1.0), dict(bin_ms=math.nan), dict(bin_ms=2_000.0)],
)
def test_bad_settings_are_refused(kwargs: dict) -> None:
    settings = dict(width=W, height=H) | kwargs
    with pytest.raises(ValueError):
        AimParams(**settings)


# -- hot pixels ------------------------------------------------------------------------------------

HOT = {(5, 7): 300.0, (320, 240): 20_000.0, (100, 400): 1_000.0, (101, 400): 2_000.0, (639, 479): 150.0}
"""(x, y): rate in Hz. (320, 240) is on the line; (100, 400) and (101, 400) are a pair; (639, 479) a corner."""


def _hot_pixel_scene(rng: np.random.Generator, span_s: float) -> np.ndarray:
    """Counts over ``span_s``: 1 Hz background, a sharp horizontal line and a diagonal one (each
    pixel 500 Hz, so their ends are as busy as the hot pixel at (5, 7)), and the hot pixels of HOT."""
    counts = rng.poisson(1.0 * span_s, (H, W)).astype(np.int64)
    counts[240, 200:440] += rng.poisson(500 * span_s, 240)
    d = np.arange(150)
    counts[50 + d, 300 + d] += rng.poisson(500 * span_s, 150)
    for (x, y), rate in HOT.items():
        counts[y, x] += rng.poisson(rate * span_s)
    return counts


def test_hot_pixels_are_found_and_nothing_else() -> None:
    rng = np.random.default_rng(7)
    hot = find_hot_pixels(_hot_pixel_scene(rng, 2.0), 2.0, HotPixelParams(factor=10.0, min_rate_hz=20.0))
    found = {(int(x), int(y)): float(r) for x, y, r in zip(hot.x, hot.y, hot.rate_hz, strict=True)}
    assert set(found) == set(HOT)
    for pixel, rate in HOT.items():  # the line's 500 Hz sits under (320, 240)
        assert found[pixel] == pytest.approx(rate + (500 if pixel == (320, 240) else 0), rel=0.15)
    assert list(hot.rate_hz) == sorted(hot.rate_hz, reverse=True)


def test_a_hot_pixel_below_the_minimum_rate_is_not_listed() -> None:
    counts = np.zeros((H, W), dtype=np.int64)
    counts[10, 10] = 30  # 15 Hz over 2 s, nothing around it
    assert len(find_hot_pixels(counts, 2.0, HotPixelParams(min_rate_hz=20.0))) == 0
    assert len(find_hot_pixels(counts, 2.0, HotPixelParams(min_rate_hz=10.0))) == 1


def test_hot_pixels_come_through_the_accumulator_and_stay_out_of_the_picture() -> None:
    """Events of the scene over 1 s: the frame lists the hot pixels with their rates, and the grey
    levels do not let a hot pixel set the white."""
    rng = np.random.default_rng(3)
    counts = _hot_pixel_scene(rng, 1.0)
    flat = np.repeat(np.arange(H * W), counts.ravel())
    flat = flat[rng.permutation(len(flat))]  # the pixels in any order over time
    events = events_at(np.sort(rng.integers(0, 1_000_000, len(flat))), flat % W, flat // W)
    acc = AimAccumulator(AimParams(W, H, window_ms=1000.0))
    for piece in np.array_split(events, 10):
        acc.push(piece)
    frame = acc.frame()
    assert {(int(x), int(y)) for x, y in zip(frame.hot.x, frame.hot.y, strict=True)} == set(HOT)
    assert frame.rate_hz == pytest.approx(len(events) / frame.rate_span_s)
    levels = display_levels(frame.image, frame.hot)
    line = np.concatenate([levels[240, 300:320], levels[240, 321:340]])
    assert line.min() > 0 and levels[240, 320] <= line.max()  # the hot pixel on the line shows as the line
    assert levels[7, 5] < line.min()  # the one in the dark stays dark


# -- the focus figure ------------------------------------------------------------------------------

SIGMAS = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0)


def expected_fwhm(sigma_px: float) -> float:
    """FWHM of a Gaussian line of ``sigma_px`` seen through square pixels (variance 1/12 added)."""
    return 2.3548 * math.sqrt(sigma_px**2 + 1 / 12)


@pytest.mark.parametrize(
    ("angle_deg", "curved"), [(0.0, False), (30.0, False), (63.0, False), (90.0, False), (0, True)]
)
def test_the_line_width_grows_with_the_blur_and_measures_it(angle_deg: float, curved: bool) -> None:
    """The same 20 000 events spread across the line by a Gaussian of s: the figure goes up with s
    at every angle (and on a curved line), and is the line's FWHM within 12 % from s = 1 px."""
    widths = []
    for k, sigma in enumerate(SIGMAS):
        x, y = line_points(sigma, 20_000, np.random.default_rng(k), angle_deg, curved)
        result = measure_line_width(count_image(x, y))
        assert result.reason == "" and result.n_profiles >= 100
        widths.append(result.width_px)
        if sigma >= 1.0:
            assert result.width_px == pytest.approx(expected_fwhm(sigma), rel=0.12)
    assert all(a < b for a, b in zip(widths, widths[1:], strict=False)), widths


def test_the_line_width_grows_with_the_blur_in_noise_and_sparse_events() -> None:
    """4 000 events on the line and 3 000 stray ones: still larger for a blurrier line."""
    widths = []
    for k, sigma in enumerate((0.7, 1.5, 3.0)):
        rng = np.random.default_rng(10 + k)
        x, y = line_points(sigma, 4_000, rng, 20.0)
        noise = rng.integers(0, [W, H], (3_000, 2))
        image = count_image(np.concatenate([x, noise[:, 0]]), np.concatenate([y, noise[:, 1]]))
        widths.append(measure_line_width(image).width_px)
    assert widths[0] < widths[1] < widths[2], widths


def test_the_line_width_is_measured_across_the_line_where_it_is() -> None:
    x, y = line_points(1.5, 20_000, np.random.default_rng(1), 30.0)
    result = measure_line_width(count_image(x, y))
    a = math.radians(30.0)
    along_line, across_line = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    assert np.all(np.abs((result.centres - [W / 2, H / 2]) @ across_line) <= 2.0)  # on the line
    tilt = np.abs(result.normals @ along_line)  # across it, but at its very ends (+-150 px)
    inside = np.abs((result.centres - [W / 2, H / 2]) @ along_line) < 140
    assert np.count_nonzero(inside) >= 150 and tilt[inside].max() < 0.2 and np.median(tilt) < 0.03


@pytest.mark.parametrize(("n_noise", "reason"), [(30, "too few events"), (3_000, "no line found")])
def test_no_line_no_figure(n_noise: int, reason: str) -> None:
    noise = np.random.default_rng(2).integers(0, [W, H], (n_noise, 2))
    result = measure_line_width(count_image(noise[:, 0], noise[:, 1]))
    assert math.isnan(result.width_px) and result.reason == reason


def test_the_focus_figure_comes_through_the_accumulator_without_a_hot_pixel() -> None:
    """A line of s = 2 px in events of the last 5 ms, a hot pixel on it: the figure is the line's."""
    rng = np.random.default_rng(4)
    x, y = line_points(2.0, 20_000, rng, 10.0)
    t = np.sort(rng.integers(0, 5_000, len(x)))
    events = events_at(t, np.rint(x), np.rint(y))
    hot = events_at(np.arange(0, 5_000, 2), np.full(2_500, W // 2), np.full(2_500, H // 2))
    merged = np.concatenate([events, hot])
    acc = AimAccumulator(AimParams(W, H, window_ms=5.0))
    acc.push(merged[np.argsort(merged["t"], kind="stable")])
    frame = acc.frame()
    assert (W // 2, H // 2) in {(int(a), int(b)) for a, b in zip(frame.hot.x, frame.hot.y, strict=True)}
    assert frame.line.width_px == pytest.approx(expected_fwhm(2.0), rel=0.12)


def test_line_width_settings_are_checked() -> None:
    with pytest.raises(ValueError):
        LineWidthParams(half_span_px=0.5)
    with pytest.raises(ValueError):
        LineWidthParams(ridge_fraction=1.0)


# -- what is drawn over the image ------------------------------------------------------------------


class ScaleMapping:
    """Pixels to metres by a scale and a rotation (as a calibration would), and back."""

    def __init__(self, m_per_px: float, angle_deg: float = 0.0) -> None:
        self.k, self.a = m_per_px, math.radians(angle_deg)

    def map(self, x_px: np.ndarray, y_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c, s = math.cos(self.a), math.sin(self.a)
        x, y = np.asarray(x_px, float), np.asarray(y_px, float)
        return self.k * (c * x - s * y), self.k * (s * x + c * y)

    def to_pixels(self, x_m: np.ndarray, y_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c, s = math.cos(self.a), math.sin(self.a)
        x, y = np.asarray(x_m, float) / self.k, np.asarray(y_m, float) / self.k
        return c * x + s * y, -s * x + c * y


def test_the_chain_and_its_search_areas_are_where_the_tracker_looks() -> None:
    chain = ChainParams(
        root=(150.0, 240.0), length=300.0, n_joints=10, direction_deg=20.0, alpha=0.6, angle_limit_deg=60.0
    )
    overlay = chain_overlay(chain)
    assert overlay.joints.shape == (11, 2)
    np.testing.assert_allclose(overlay.joints[0], [150.0, 240.0])
    a = math.radians(20.0)
    np.testing.assert_allclose(overlay.joints[-1], [150 + 300 * math.cos(a), 240 + 300 * math.sin(a)])
    assert len(overlay.areas) == 10
    for k, area in enumerate(overlay.areas):
        np.testing.assert_allclose(area[0], area[-1])  # closed
        d = area - overlay.joints[k]
        r = np.hypot(d[:, 0], d[:, 1])
        assert r.min() == pytest.approx(0.4 * 30.0) and r.max() == pytest.approx(1.6 * 30.0)
        off = np.degrees(np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - a))))
        assert off.min() == pytest.approx(-60.0) and off.max() == pytest.approx(60.0)


def test_a_whole_annulus_is_two_circles() -> None:
    overlay = chain_overlay(ChainParams(root=(0.0, 0.0), length=10.0, n_joints=1, alpha=0.5, angle_limit_deg=180.0))
    assert len(overlay.areas) == 2
    radii = sorted(float(np.hypot(*area.T).mean()) for area in overlay.areas)
    assert radii == pytest.approx([5.0, 15.0])


def test_a_calibrated_chain_is_drawn_in_pixels() -> None:
    """A chain given in metres through a calibration lands where the same chain in pixels does."""
    mapping = ScaleMapping(0.0005, angle_deg=5.0)
    root_m = mapping.map(np.array(150.0), np.array(240.0))
    in_m = ChainParams(root=(float(root_m[0]), float(root_m[1])), length=0.15, direction_deg=25.0)
    in_px = ChainParams(root=(150.0, 240.0), length=300.0, direction_deg=20.0)
    np.testing.assert_allclose(chain_overlay(in_m, mapping).joints, chain_overlay(in_px).joints, atol=1e-9)


def test_the_calibration_grid_is_lines_of_constant_plane_coordinates() -> None:
    """0.5 mm per pixel: 640 x 480 px is 0.32 x 0.24 m, lines every 0.05 m, i.e. every 100 px."""
    grid = plane_grid(ScaleMapping(0.0005), W, H, n_lines=10)
    assert grid.step == pytest.approx(0.05)
    vertical = [line for line in grid.lines if np.ptp(line[:, 0]) < 1e-6]
    horizontal = [line for line in grid.lines if np.ptp(line[:, 1]) < 1e-6]
    assert sorted(round(float(line[0, 0])) for line in vertical) == [0, 100, 200, 300, 400, 500, 600]
    assert sorted(round(float(line[0, 1])) for line in horizontal) == [0, 100, 200, 300, 400]
    assert len(vertical) + len(horizontal) == len(grid.lines)
    for line in grid.lines:  # cut to the image
        assert line[:, 0].min() >= -0.5 and line[:, 0].max() <= W - 0.5
        assert line[:, 1].min() >= -0.5 and line[:, 1].max() <= H - 0.5


def test_a_rotated_calibration_grid_is_cut_at_the_image_edges() -> None:
    grid = plane_grid(ScaleMapping(0.0005, angle_deg=30.0), W, H)
    assert len(grid.lines) >= 8
    mapping = ScaleMapping(0.0005, angle_deg=30.0)
    for line in grid.lines:
        px, py = mapping.map(line[:, 0], line[:, 1])
        assert np.ptp(px) < 1e-9 or np.ptp(py) < 1e-9  # each line keeps one plane coordinate
        assert line[:, 0].min() >= -0.5 and line[:, 0].max() <= W - 0.5


@pytest.mark.parametrize(("span", "n", "step"), [(0.32, 10, 0.05), (640, 10, 100), (7.0, 10, 1.0), (0.9, 4, 0.5)])
def test_grid_steps_are_round_numbers(span: float, n: int, step: float) -> None:
    assert nice_step(span, n) == pytest.approx(step)
