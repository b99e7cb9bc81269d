"""Rendered scenes through the camera model: the laser line on the flag, optics, blinking checkerboard."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.drivers.sim.dvs import DvsParams
from flagtrack.drivers.sim.kinematics import FlagKinematics, sample_kinematics
from flagtrack.drivers.sim.optics import PlaneCamera, tilted_pinhole
from flagtrack.drivers.sim.render import LaserLineScene
from flagtrack.drivers.sim.scenes import (
    BlinkingPatternScene,
    BlinkParams,
    CheckerboardSpec,
    checkerboard,
    simulate_events,
)


def line_events(
    kin: FlagKinematics,
    t_stop_us: int,
    dvs: DvsParams = DvsParams(),
    seed: int = 0,
    optics: PlaneCamera | None = None,
    width: int = 640,
    height: int = 480,
) -> tuple[LaserLineScene, np.ndarray]:
    scene = LaserLineScene(kin, optics or PlaneCamera.identity(), width, height)
    chunks = list(simulate_events(scene, 0, t_stop_us, dvs, seed=seed, chunk_us=5_000))
    return scene, np.concatenate(chunks)


def distances_to_line(scene: LaserLineScene, events: np.ndarray) -> np.ndarray:
    s = np.linspace(0, scene.kinematics.length, 1501)
    out = []
    for ev in events:
        u, v = scene.optics.project(*scene.kinematics.positions(np.array([ev["t"] * 1e-6]), s))
        out.append(np.min(np.hypot(u[0] - ev["x"], v[0] - ev["y"])))
    return np.array(out)


def test_line_events_lie_on_the_moving_line_and_are_sorted() -> None:
    kin = sample_kinematics(3)
    scene, events = line_events(kin, 20_000)
    assert len(events) > 20_000
    assert np.all(np.diff(events["t"]) >= 0) and events["t"][0] >= 0 and events["t"][-1] < 20_000
    dist = distances_to_line(scene, events[:: max(1, len(events) // 300)])
    assert np.median(dist) < 2.0 and np.percentile(dist, 95) < 3.5
    assert 0.4 < events["p"].mean() < 0.6
    # timestamps are interpolated between render steps, not snapped to them
    assert np.mean(events["t"] % scene.step_us == 0) < 0.2
    assert scene.step_us * scene.max_pixel_speed() * 1e-6 <= 0.5 + 1e-9
    fresh = LaserLineScene(kin, PlaneCamera.identity(), 640, 480)
    steps = fresh.step_times_us(20_000.0)
    u, v = fresh.pixels(np.concatenate([[0.0], steps]))
    assert np.max(np.hypot(np.diff(u, axis=0), np.diff(v, axis=0))) <= 0.5  # adaptive steps, line moves <= 0.5 px
    assert steps[-1] == 20_000.0 and np.all(np.diff(steps) > 0) and len(steps) < 20_000 / fresh.step_us


def test_same_seed_same_events_and_a_still_flag_is_silent() -> None:
    kin = sample_kinematics(8)
    _, a = line_events(kin, 5_000, seed=2)
    _, b = line_events(kin, 5_000, seed=2)
    np.testing.assert_array_equal(a, b)
    _, still = line_events(FlagKinematics(amp_rad=0.0), 5_000)
    assert len(still) == 0


def test_higher_thresholds_give_fewer_events_and_noise_adds_events() -> None:
    kin = sample_kinematics(4)
    _, low = line_events(kin, 10_000, DvsParams(contrast_on=0.2, contrast_off=0.2))
    _, high = line_events(kin, 10_000, DvsParams(contrast_on=0.5, contrast_off=0.5))
    assert len(high) < 0.7 * len(low)
    _, noisy = line_events(kin, 10_000, DvsParams(contrast_on=0.2, contrast_off=0.2, shot_noise_hz=5.0))
    expected_noise = 5.0 * 640 * 480 * 0.01
    assert abs(len(noisy) - len(low) - expected_noise) < 5 * np.sqrt(expected_noise)


def test_tilted_optics_roundtrip_and_see_the_flag() -> None:
    optics = tilted_pinhole(k1=-0.1)
    x, y = np.meshgrid(np.linspace(-0.05, 0.25, 7), np.linspace(-0.1, 0.1, 5))
    u, v = optics.project(x, y)
    back_x, back_y = optics.unproject(u, v)
    np.testing.assert_allclose(back_x, x, atol=1e-9)
    np.testing.assert_allclose(back_y, y, atol=1e-9)
    kin = sample_kinematics(1, length=0.18, root=(0.0, 0.0))
    px, py = optics.project(*kin.positions(np.linspace(0, 0.1, 11), np.linspace(0, 0.18, 50)))
    assert px.min() > 0 and px.max() < 639 and py.min() > 0 and py.max() < 479
    mm_per_px = 0.18e3 / np.hypot(*np.diff(optics.project(np.array([0.0, 0.18]), np.array([0.0, 0.0])), axis=1)).item()
    assert 0.3 < mm_per_px < 0.7  # paper: 0.42 mm per pixel, foreshortened by the tilt
    # the line is rendered through the same optics: events close to the projected line
    scene, events = line_events(kin, 5_000, optics=optics)
    dist = distances_to_line(scene, events[:: max(1, len(events) // 200)])
    assert len(events) > 1000 and np.median(dist) < 2.0


def test_blinking_checkerboard_fires_on_white_squares_at_switches() -> None:
    spec = CheckerboardSpec(inner_corners=(5, 4), square=30.0, origin=(200.0, 150.0))
    optics = PlaneCamera.identity()
    blink = BlinkParams(period_us=20_000, ramp_us=400)
    scene = BlinkingPatternScene(checkerboard(spec), optics, 640, 480, blink)
    events = np.concatenate(list(simulate_events(scene, 0, 40_000, DvsParams(), seed=1)))
    phase = events["t"] % 10_000
    assert np.all(phase < 1_000)  # only at the switches (ramp plus refractory delays)
    on = events[(events["t"] % 20_000) < 10_000]
    assert on["p"].mean() > 0.99 and events[(events["t"] % 20_000) >= 10_000]["p"].mean() < 0.01
    white = scene.white.reshape(480, 640)
    assert np.all(white[events["y"], events["x"]] > 0)
    fired = np.zeros((480, 640), bool)
    fired[events["y"], events["x"]] = True
    assert fired.sum() == pytest.approx(np.count_nonzero(white > 0.2), rel=0.1)
    # corners: square (i + j even) is white; the first inner corner is at the origin
    pattern = checkerboard(spec)
    assert pattern(np.array([199.0]), np.array([149.0]))[0] == 1.0
    assert pattern(np.array([201.0]), np.array([149.0]))[0] == 0.0
    assert len(spec.corners()) == 20 and tuple(spec.corners()[0]) == (200.0, 150.0)


def test_event_cloud_is_within_two_pixels_of_the_truth() -> None:
    from flagtrack.daemon.core.metrics import cloud_distance

    kin = sample_kinematics(6)
    _, events = line_events(kin, 10_000)
    s = np.linspace(0, kin.length, 201)
    for centre_us in (2_000, 5_000, 8_000):
        window = events[np.abs(events["t"] - centre_us) <= 150]
        x, y = kin.positions(np.array([centre_us * 1e-6]), s)
        assert len(window) > 100
        assert cloud_distance(window["x"], window["y"], x[0], y[0]) < 2.0
