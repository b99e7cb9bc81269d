"""Clock synchronisation of a point sensor with the camera: trigger pulses, wall-clock prior, cross-correlation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flagtrack.daemon.core.sync import ClockSync, SyncParams, coarse_offset_us, trigger_sync, xcorr_sync


def pulses(n: int = 40, period_us: int = 50_000, start_us: int = 1_000_000) -> np.ndarray:
    return start_us + period_us * np.arange(n, dtype=np.int64)


@pytest.mark.parametrize("offset_us", [3_000.0, -4_250.0, 0.0, 17_500.0])
def test_trigger_recovers_the_offset_to_the_stamps_jitter(offset_us: float) -> None:
    rng = np.random.default_rng(1)
    cam = pulses()
    sensor = np.round(cam + offset_us + rng.normal(0, 1.0, len(cam))).astype(np.int64)
    sync = trigger_sync(cam, sensor, prior_offset_us=offset_us + 8_000)  # a rough prior within half a period
    assert sync.method == "trigger" and sync.n == len(cam)
    assert abs(sync.offset_us - offset_us) < 1.5
    assert 0.05 < sync.uncertainty_us < 1.0
    assert abs(sync.offset_us - offset_us) < 5 * sync.uncertainty_us


def test_trigger_fits_drift_and_maps_sensor_times_back_to_the_camera() -> None:
    cam = pulses(100, 100_000, 0)
    drift = 80e-6  # the sensor clock runs 80 ppm fast
    sensor = np.round(cam * (1 + drift) + 2_500).astype(np.int64)
    sync = trigger_sync(cam, sensor)
    assert sync.drift_ppm == pytest.approx(80.0, abs=0.5)
    t_cam = np.array([123_456.0, 9_000_000.0])
    back = sync.to_camera_us(t_cam * (1 + drift) + 2_500)
    np.testing.assert_allclose(back, t_cam, atol=1.0)


def test_trigger_skips_missing_and_stray_pulses() -> None:
    cam = pulses()
    sensor = cam + 3_000
    sensor = np.delete(sensor, [3, 4, 17])  # lost by the sensor
    cam_seen = np.concatenate([np.delete(cam, [10, 30]), [cam[5] + 20_000]])  # lost by the camera, one glitch
    sync = trigger_sync(cam_seen, sensor, prior_offset_us=0.0)
    assert sync.method == "trigger" and sync.n == len(cam) - 5
    assert sync.offset_us == pytest.approx(3_000.0, abs=0.01)


def test_trigger_without_pulses_says_so() -> None:
    sync = trigger_sync(np.zeros(0), pulses())
    assert sync.method == "none" and not sync.ok and "no trigger pulses" in sync.note
    assert sync.to_camera_us(np.array([5.0]))[0] == 5.0  # no estimate: one clock


def test_trigger_offset_is_only_known_modulo_the_period() -> None:
    cam = pulses(period_us=10_000)
    sync = trigger_sync(cam, cam + 7_000, prior_offset_us=0.0)  # prior 7 ms off, period 10 ms: wrong pulse
    assert sync.offset_us == pytest.approx(-3_000.0)
    assert "far from the prior" in sync.note or abs(sync.offset_us) < 0.25 * 10_000


def test_coarse_follows_a_camera_slower_than_real_time() -> None:
    wall_ns = np.arange(0, 10_000_000_000, 50_000_000, dtype=np.int64) + 1_700_000_000 * 10**9
    camera_t = (wall_ns - wall_ns[0]) // 4000  # a quarter of real time, in µs
    sensor_wall = wall_ns[::3] + 7_000_000  # arrives later, fewer batches
    sensor_t = np.interp(sensor_wall, wall_ns, camera_t) + 5_000
    sync = coarse_offset_us(sensor_t, sensor_wall, camera_t, wall_ns)
    assert sync.method == "coarse" and sync.offset_us == pytest.approx(5_000, abs=1)
    assert sync.uncertainty_us >= 1000.0
    assert coarse_offset_us(np.zeros(0), np.zeros(0), camera_t, wall_ns).method == "none"


def flapping(t_s: np.ndarray, f_hz: float = 12.0) -> np.ndarray:
    return 60.0 * np.sin(2 * np.pi * f_hz * t_s) + 8.0 * np.sin(2 * np.pi * 3 * f_hz * t_s + 0.4)


@pytest.mark.parametrize("offset_us", [3_000.0, -6_400.0])
def test_xcorr_recovers_the_offset_within_a_fraction_of_an_update(offset_us: float) -> None:
    rng = np.random.default_rng(7)
    t_recon = np.arange(0.0, 2.0, 1e-3)
    y_recon = flapping(t_recon) + rng.normal(0, 0.3, len(t_recon))
    t_sensor_us = np.arange(0, 2_000_000, 1000) + offset_us  # sensor clock
    y_sensor = flapping((t_sensor_us - offset_us) * 1e-6) + rng.normal(0, 0.6, len(t_sensor_us))
    y_sensor[100:160] = np.nan  # a dropout
    sync = xcorr_sync(t_recon, y_recon, t_sensor_us, y_sensor, prior_offset_us=offset_us + 4_000)
    assert sync.method == "xcorr" and sync.quality > 0.99
    assert abs(sync.offset_us - offset_us) < 20.0  # the update interval is 1000 µs
    assert sync.uncertainty_us < 20.0 and sync.n == 8
    assert abs(sync.offset_us - offset_us) < 6 * sync.uncertainty_us + 2


def test_xcorr_refuses_what_it_cannot_know() -> None:
    t_recon = np.arange(0.0, 1.0, 1e-3)
    t_sensor = np.arange(0, 1_000_000, 1000)
    still = xcorr_sync(t_recon, np.zeros(len(t_recon)), t_sensor, np.random.default_rng(0).normal(0, 1, len(t_sensor)))
    assert still.method == "none" and "constant" in still.note
    flipped = xcorr_sync(t_recon, flapping(t_recon), t_sensor, -flapping(t_sensor * 1e-6), max_lag_us=10_000)
    assert flipped.method == "none" and "direction" in flipped.note
    edge = xcorr_sync(t_recon, flapping(t_recon), t_sensor + 7_000.0, flapping(t_sensor * 1e-6), max_lag_us=5_000)
    assert edge.method == "none" and "edge" in edge.note
    few = xcorr_sync(t_recon[:10], flapping(t_recon[:10]), t_sensor, flapping(t_sensor * 1e-6))
    assert few.method == "none" and "too few" in few.note


def test_sync_params_are_checked() -> None:
    with pytest.raises(ValueError, match="min_correlation"):
        SyncParams(min_correlation=1.5)
    with pytest.raises(ValueError, match="blocks"):
        SyncParams(blocks=1)
    assert ClockSync("none").ok is False and math.isnan(ClockSync("none").offset_us)
