"""The reconstruction at the sensor's beam, readings to lateral displacement, and e(t)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flagtrack.daemon.core.pointsensor import (
    BeamParams,
    beam_lateral,
    compare_signals,
    lateral_to_reading,
    reading_to_lateral,
    recon_at,
)


def test_straight_lines_cross_the_beam_where_geometry_says() -> None:
    s = np.linspace(0, 300, 51)
    slopes = np.array([0.0, 0.1, -0.3])
    x = 150 + np.outer(np.ones(3), s)
    y = 240 + slopes[:, None] * np.outer(np.ones(3), s)
    got = beam_lateral(x, y, (150.0, 240.0), 0.0, 219.0)
    np.testing.assert_allclose(got, slopes * 219.0, atol=1e-9)


def test_a_tilted_rest_frame_is_used() -> None:
    d = np.deg2rad(30.0)
    s = np.linspace(0, 1.0, 21)
    # a line bent 0.05 to the left of a rest direction of 30 degrees, in metres
    xi, eta = s, 0.05 * s
    x = 0.2 + xi * np.cos(d) - eta * np.sin(d)
    y = 0.1 + xi * np.sin(d) + eta * np.cos(d)
    got = beam_lateral(x[None], y[None], (0.2, 0.1), 30.0, 0.73)
    assert got[0] == pytest.approx(0.05 * 0.73)


def test_of_several_crossings_the_sensor_sees_its_own_side_and_none_is_nan() -> None:
    # a curl: the centreline crosses xi = 2 four times, at eta = 0, 1, 3 and 4
    x = np.array([[0, 3, 1, 3, 1.0], [0, 1, 1.5, 1.8, 1.9]])
    y = np.array([[0, 0, 2, 4, 4.0], [0, 0, 0, 0, 0.0]])
    assert beam_lateral(x, y, (0.0, 0.0), 0.0, 2.0, side=1)[0] == pytest.approx(4.0)
    assert beam_lateral(x, y, (0.0, 0.0), 0.0, 2.0, side=-1)[0] == pytest.approx(0.0)
    assert math.isnan(beam_lateral(x, y, (0.0, 0.0), 0.0, 2.0)[1])  # too short to reach the beam


def test_readings_map_to_lateral_and_back() -> None:
    beam = BeamParams(x_over_l=0.73, units_per_reading=1 / 0.6, zero_reading=100.0, direction=-1)
    lateral = np.array([-30.0, 0.0, 45.0, np.nan])
    readings = lateral_to_reading(lateral, beam)
    np.testing.assert_allclose(readings[:3], [118.0, 100.0, 73.0])
    np.testing.assert_allclose(reading_to_lateral(readings, beam), lateral)
    assert beam.side == 1  # the reading shrinks as the flag comes: the sensor is on the positive side
    with pytest.raises(ValueError, match="direction"):
        BeamParams(direction=2)
    with pytest.raises(ValueError, match="x_over_l"):
        BeamParams(x_over_l=1.5)


def test_recon_is_not_interpolated_across_gaps() -> None:
    t = np.array([0.0, 0.001, 0.002, 0.010, 0.011])
    y = np.array([0.0, 1.0, 2.0, 10.0, np.nan])
    got = recon_at(t, y, np.array([0.0005, 0.0015, 0.005, 0.0105, -1.0, 0.02]))
    np.testing.assert_allclose(got[:2], [0.5, 1.5])
    assert np.all(np.isnan(got[2:]))


def test_compare_signals_counts_and_errors() -> None:
    t_recon = np.arange(0.0, 1.0, 0.001)
    y_recon = 30 * np.sin(2 * np.pi * 10 * t_recon)
    t_sensor = np.arange(0.0, 1.2, 0.0005)
    y_sensor = 30 * np.sin(2 * np.pi * 10 * t_sensor) - 1.5  # a constant 1.5 offset (unknown zero)
    y_sensor[::10] = np.nan
    fixed = compare_signals(t_recon, y_recon, t_sensor, y_sensor, 300.0)
    assert fixed.n_samples == len(t_sensor) and fixed.n_valid == len(t_sensor) - len(t_sensor[::10])
    assert fixed.n_compared < fixed.n_valid  # the sensor ran 0.2 s longer than the reconstruction
    assert fixed.error_rms_over_l == pytest.approx(1.5 / 300, rel=0.03)
    assert fixed.error_max_over_l == pytest.approx(1.5 / 300, rel=0.03)
    matched = compare_signals(t_recon, y_recon, t_sensor, y_sensor, 300.0, match_means=True)
    assert matched.bias == pytest.approx(1.5, abs=0.01) and matched.error_rms_over_l < 2e-4
    empty = compare_signals(t_recon, y_recon, t_sensor + 5.0, y_sensor, 300.0)
    assert empty.n_compared == 0 and math.isnan(empty.error_rms_over_l)
