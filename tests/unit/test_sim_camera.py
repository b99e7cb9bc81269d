"""Event-camera pixel model: analytic single-pixel cases, refractory period, leak, shot noise, thresholds."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.drivers.sim.dvs import DvsParams, EventCamera


def one_pixel(**kwargs: float) -> EventCamera:
    params = DvsParams(
        **{"contrast_on": 0.25, "contrast_off": 0.25, "sigma_contrast": 0.0, "refractory_us": 0.0, **kwargs}
    )
    camera = EventCamera(1, 1, params, seed=0)
    camera.reset(np.zeros(1), 0.0)
    return camera


def test_ramp_gives_events_at_interpolated_crossings() -> None:
    camera = one_pixel()
    camera.advance(np.array([0]), np.array([1.0]), 1000.0)  # +1 log unit over 1 ms: 4 thresholds
    camera.advance(np.array([0]), np.array([0.5]), 1500.0)  # -0.5 over 0.5 ms
    camera.flush(3000.0)
    events = camera.take()
    events = events[np.argsort(events["t"])]
    np.testing.assert_array_equal(events["t"], [250, 500, 750, 1000, 1250, 1500])
    np.testing.assert_array_equal(events["p"], [1, 1, 1, 1, 0, 0])
    assert len(camera.take()) == 0


def test_refractory_period_delays_and_merges_events() -> None:
    camera = one_pixel(refractory_us=400.0)
    camera.advance(np.array([0]), np.array([1.0]), 1000.0)
    camera.flush(2000.0)
    events = camera.take()
    # fires at 250, blind until 650 (d = 0.4 >= C: fires and resets), blind until 1050 (d = 0.35)
    np.testing.assert_array_equal(np.sort(events["t"]), [250, 650, 1050])
    assert np.all(events["p"] == 1)


def test_leak_makes_a_still_pixel_fire_on_events_at_the_leak_rate() -> None:
    camera = EventCamera(20, 10, DvsParams(leak_rate_hz=50.0, sigma_contrast=0.02), seed=3)
    camera.reset(np.full(200, -1.0), 0.0)
    for t_us in range(100_000, 1_000_001, 100_000):
        camera.flush(float(t_us))
    events = camera.take()
    assert np.all(events["p"] == 1)
    per_pixel = np.bincount(events["y"].astype(int) * 20 + events["x"], minlength=200)
    assert per_pixel.min() >= 49 and per_pixel.max() <= 51  # 50 Hz for 1 s, random phase
    assert 0.3 < np.mean(events["t"] < 500_000) < 0.7


def test_shot_noise_is_poisson_uniform_and_random_polarity() -> None:
    camera = EventCamera(100, 50, DvsParams(shot_noise_hz=20.0), seed=5)
    events = camera.shot_noise(0, 100_000)  # expected 20 * 5000 * 0.1 = 10000
    assert abs(len(events) - 10_000) < 4 * np.sqrt(10_000)
    assert events["t"].min() >= 0 and events["t"].max() < 100_000
    assert events["x"].max() < 100 and events["y"].max() < 50
    assert abs(events["p"].mean() - 0.5) < 0.03
    assert abs(np.mean(events["x"] < 50) - 0.5) < 0.03
    assert len(EventCamera(10, 10, DvsParams(), seed=0).shot_noise(0, 10**6)) == 0


def test_thresholds_spread_per_pixel_and_are_seeded() -> None:
    a = EventCamera(200, 100, DvsParams(contrast_on=0.3, sigma_contrast=0.05), seed=1)
    b = EventCamera(200, 100, DvsParams(contrast_on=0.3, sigma_contrast=0.05), seed=1)
    assert a.c_on.mean() == pytest.approx(0.3, abs=0.003) and a.c_on.std() == pytest.approx(0.05, rel=0.05)
    np.testing.assert_array_equal(a.c_on, b.c_on)
    with pytest.raises(ValueError):
        DvsParams(contrast_on=0.0)


def test_many_events_grow_the_buffer() -> None:
    camera = one_pixel(contrast_on=0.02, contrast_off=0.02)
    camera.advance(np.array([0]), np.array([1600.0]), 1e6)  # 80000 events > the initial 65536 buffer
    events = camera.take()
    assert len(events) == pytest.approx(80_000, abs=1)
    assert np.all(np.diff(events["t"]) >= 0) and events["t"][-1] < 1e6
