"""The flag's geometry from synthetic event arrays (quickline flags, hot pixels, noise, a plane map)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flagtrack.daemon.core.events import EVENT_DTYPE
from flagtrack.daemon.core.geometry import NoFlagError, find_geometry
from flagtrack.daemon.core.geometry_field import hot_pixels, supported
from flagtrack.daemon.core.mapping import AffineMapping, on_sensor
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

SIZE = (640, 480)


def flag_events(kin, duration_us: int = 150_000, seed: int = 0) -> np.ndarray:
    return np.concatenate(list(line_events(kin, 0, duration_us, *SIZE, QuickLineParams(events_per_px2=4.0), seed=seed)))


def root_error(found, root, length: float) -> float:
    return math.hypot(found.root[0] - root[0], found.root[1] - root[1]) / length


def turn_deg(a: float, b: float) -> float:
    return (a - b + 180.0) % 360.0 - 180.0


@pytest.mark.parametrize(
    ("root", "direction_deg"),
    [((120.0, 240.0), 0.0), ((520.0, 120.0), 135.0), ((320.0, 440.0), -90.0), ((420.0, 60.0), 100.0)],
)
def test_root_direction_and_length_within_the_targets(root, direction_deg) -> None:
    """Any root, any direction (right, up-left, up, down): root within 2 % of L, direction within
    2 degrees (the tracker's: from +x towards +y, y down the image), length within 3 %."""
    kin = WavyFlag(length=200.0, root=root, direction_deg=direction_deg, amp_rad=0.8)
    found = find_geometry(flag_events(kin), SIZE)
    assert root_error(found, root, 200.0) < 0.02
    assert abs(turn_deg(found.direction_deg, direction_deg)) < 2.0
    assert -180.0 <= found.direction_deg < 180.0  # (-90 as -90, not 270; 0 either side of 0, not 359.9)
    assert abs(found.length / 200.0 - 1.0) < 0.03
    assert found.frequency_hz == pytest.approx(20.0, rel=0.05)
    assert found.hot_pixels == ()


def test_a_hot_pixel_is_neither_the_root_nor_the_tip() -> None:
    kin = WavyFlag(length=200.0, root=(150.0, 240.0), amp_rad=0.8)
    events = flag_events(kin)
    rng = np.random.default_rng(1)
    hot = []
    for x, y in ((140, 240), (362, 240), (250, 250)):  # behind the root, beyond the tip, on the flag
        n = 600  # 4 kHz over 0.15 s
        part = np.zeros(n, dtype=EVENT_DTYPE)
        part["t"], part["x"], part["y"], part["p"] = np.sort(rng.integers(0, 150_000, n)), x, y, 1
        hot.append(part)
    merged = np.concatenate([events, *hot])
    found = find_geometry(merged[np.argsort(merged["t"], kind="stable")], SIZE)
    assert {(140, 240), (362, 240), (250, 250)} <= set(found.hot_pixels)
    assert root_error(found, (150.0, 240.0), 200.0) < 0.02
    assert abs(found.length / 200.0 - 1.0) < 0.03


def test_shot_noise_does_not_move_the_root() -> None:
    kin = WavyFlag(length=200.0, root=(150.0, 240.0), direction_deg=10.0, amp_rad=0.8)
    noisy = QuickLineParams(events_per_px2=4.0, noise_rate_hz=640 * 480 * 2.0)  # 2 Hz a pixel
    events = np.concatenate(list(line_events(kin, 0, 150_000, *SIZE, noisy)))
    found = find_geometry(events, SIZE)
    assert root_error(found, (150.0, 240.0), 200.0) < 0.02
    assert abs(turn_deg(found.direction_deg, 10.0)) < 2.0


def test_a_small_motion_says_the_root_is_extrapolated_and_by_how_much() -> None:
    """The root is then extrapolated past the first moving point: the warning says so, and the true
    root lies between the reported one and that point (``root_gap`` along the direction)."""
    kin = WavyFlag(length=200.0, root=(150.0, 240.0), amp_rad=0.12)
    found = find_geometry(flag_events(kin), SIZE)
    assert abs(turn_deg(found.direction_deg, 0.0)) < 2.0
    assert any("barely moves" in w for w in found.warnings())
    along = (150.0 - found.root[0]) * math.cos(math.radians(found.direction_deg))
    along += (240.0 - found.root[1]) * math.sin(math.radians(found.direction_deg))
    assert -0.02 * 200 < along < found.root_gap + 0.02 * 200
    assert found.amplitude < 0.2 * found.length


class _PlaneFlag:
    """A flag moving in the plane, seen through the inverse of ``mapping`` (pixels)."""

    def __init__(self, kin: WavyFlag, mapping: AffineMapping) -> None:
        self.kin, self.length = kin, kin.length
        self.inverse = np.linalg.inv(mapping.matrix)
        self.offset = mapping.offset

    def positions(self, t_s: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x, y = self.kin.positions(t_s, s)
        dx, dy = x - self.offset[0], y - self.offset[1]
        (a, b), (c, d) = self.inverse
        return a * dx + b * dy, c * dx + d * dy


def test_with_a_mapping_the_geometry_is_in_the_plane() -> None:
    """A map that is not a similarity (x and y scaled differently, sheared): the figures are the
    plane's, not the pixels' ones scaled."""
    mapping = AffineMapping(((0.0010, 0.0002), (0.0, 0.0014)), (-0.05, -0.3))
    kin = WavyFlag(length=0.25, root=(0.07, 0.05), direction_deg=20.0, amp_rad=0.8)
    per_px2 = QuickLineParams(events_per_px2=4.0 / 0.0012)  # quickline's arc steps are in metres here
    events = np.concatenate(list(line_events(_PlaneFlag(kin, mapping), 0, 150_000, *SIZE, per_px2)))
    found = find_geometry(events, SIZE, mapping)
    assert root_error(found, (0.07, 0.05), 0.25) < 0.02
    assert abs(turn_deg(found.direction_deg, 20.0)) < 2.0
    assert abs(found.length / 0.25 - 1.0) < 0.03
    assert 0.0009 < found.px_size < 0.0013


def test_noise_only_and_empty_are_no_flag() -> None:
    rng = np.random.default_rng(0)
    noise = np.zeros(200_000, dtype=EVENT_DTYPE)
    noise["t"] = np.sort(rng.integers(0, 1_000_000, len(noise)))
    noise["x"], noise["y"] = rng.integers(0, 640, len(noise)), rng.integers(0, 480, len(noise))
    with pytest.raises(NoFlagError):
        find_geometry(noise, SIZE)
    with pytest.raises(NoFlagError, match="too few"):
        find_geometry(np.zeros(0, dtype=EVENT_DTYPE), SIZE)


def test_a_motion_that_does_not_repeat_is_no_flag() -> None:
    """Under one period of the 20 Hz flag (30 ms) nothing shows a flapping flag: refused, not guessed;
    the same flag over three periods is found."""
    kin = WavyFlag(length=200.0, root=(150.0, 240.0), amp_rad=0.8)
    with pytest.raises(NoFlagError, match="nothing flaps"):
        find_geometry(flag_events(kin, duration_us=30_000), SIZE)
    assert find_geometry(flag_events(kin), SIZE).periods >= 2


class _Stretching:
    """A line that flaps as a flag does but stretches and shrinks (0.6-1.0 L, at 7 Hz) as no flag can."""

    def __init__(self, kin: WavyFlag) -> None:
        self.kin, self.length = kin, kin.length

    def positions(self, t_s: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x, y = self.kin.positions(t_s, s)
        scale = 0.8 + 0.2 * np.sin(2 * np.pi * 7.0 * np.atleast_1d(t_s))[:, None]
        return self.kin.root[0] + (x - self.kin.root[0]) * scale, self.kin.root[1] + (y - self.kin.root[1]) * scale


def test_what_cannot_be_a_flag_is_refused_by_what_it_does() -> None:
    """A far end moving under 4 pixels, a line whose length changes from window to window, a root
    off the sensor (the tracker would refuse it): each refused with its reason. The same root is
    kept where the sensor's size is unknown (the events' extent does not bound the sensor)."""
    with pytest.raises(NoFlagError, match=r"moves \d\.\d pixels peak to peak, under 4"):
        find_geometry(flag_events(WavyFlag(length=200.0, root=(150.0, 240.0), amp_rad=0.02)), SIZE)
    stretching = _Stretching(WavyFlag(length=200.0, root=(150.0, 240.0), amp_rad=0.8))
    with pytest.raises(NoFlagError, match="length changes from window to window"):
        find_geometry(flag_events(stretching, duration_us=300_000), SIZE)
    off = flag_events(WavyFlag(length=200.0, root=(-20.0, 240.0), amp_rad=0.8))
    with pytest.raises(NoFlagError, match="off the 640 x 480 sensor"):
        find_geometry(off, SIZE)
    assert find_geometry(off, (0, 0)).root[0] < 0


def test_a_pole_at_the_sensors_edge_is_a_flag_with_its_root_on_the_edge() -> None:
    """The root extrapolated a little off the sensor (the pole at its edge, a small motion) is put on
    the edge, and said; the figures stay within their targets."""
    found = find_geometry(flag_events(WavyFlag(length=200.0, root=(5.0, 240.0), amp_rad=0.15)), SIZE)
    assert -0.5 <= found.root[0] < 1.0 and root_error(found, (5.0, 240.0), 200.0) < 0.05
    assert any("off the sensor and is put at its edge" in w for w in found.warnings())
    assert found.root_pulled > 0


def test_on_sensor_through_a_mapping_and_without() -> None:
    """Pixel centres at whole coordinates (half a pixel of border); through a mapping, the sensor's
    outline mapped to the plane; a mapping that cannot place the outline gives no verdict (True)."""
    assert on_sensor(-0.5, 0.0, 640, 480) and not on_sensor(-0.6, 0.0, 640, 480)
    assert on_sensor(639.5, 479.5, 640, 480) and not on_sensor(320.0, 480.0, 640, 480)
    mapping = AffineMapping(((0.001, 0.0002), (0.0, 0.0014)), (-0.05, -0.3))  # sheared, scaled
    inside = mapping.map(np.array([320.0]), np.array([240.0]))
    outside = mapping.map(np.array([-3.0]), np.array([240.0]))
    assert on_sensor(float(inside[0][0]), float(inside[1][0]), 640, 480, mapping)
    assert not on_sensor(float(outside[0][0]), float(outside[1][0]), 640, 480, mapping)

    class Nowhere:
        def map(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return np.full(np.shape(x), np.nan), np.full(np.shape(y), np.nan)

    assert on_sensor(1e9, 1e9, 640, 480, Nowhere())


def test_hot_pixels_are_those_far_above_every_neighbour() -> None:
    counts = np.full((20, 20), 50)
    counts[5, 5] = 400  # hot
    counts[10, 10:12] = 400  # two bright neighbours: a bright spot, not a lone hot pixel
    counts[15, 15] = 120  # brighter, not hot
    found = hot_pixels(counts, 4.0, 10)
    assert np.argwhere(found).tolist() == [[5, 5]]


def test_support_keeps_a_line_and_drops_a_lone_event() -> None:
    t = np.array([0, 10, 20, 30, 500_000], dtype=np.int64)
    x = np.array([10, 11, 12, 13, 40])
    y = np.array([10, 10, 10, 10, 40])
    kept = supported(x, y, t, (64, 64), 1000, 1)
    assert kept.tolist() == [True, True, True, True, False]
