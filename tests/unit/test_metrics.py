"""Metrics on analytic cases: travelling-wave index, tip and shape errors, cloud distance, amplitude, frequency."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.metrics import (
    align,
    cloud_distance,
    compare,
    eps_rms,
    flapping_frequency_hz,
    lateral_displacement,
    rest_frame,
    tip_amplitude_over_l,
    tip_error,
    travelling_wave_index,
)


def waves(
    w_travel: float, n_s: int = 21, per_period: int = 20, periods: int = 5, amp: float = 1.0, wavelengths: float = 1.0
) -> np.ndarray:
    """w sin(ks - wt) + (1 - w) sin(ks) cos(wt) on s in [0, wavelengths], t over whole periods."""
    s = np.linspace(0.0, wavelengths, n_s, endpoint=False)[None, :]
    t = (np.arange(per_period * periods) / per_period)[:, None]
    k, w = 2 * np.pi, 2 * np.pi
    return amp * (w_travel * np.sin(k * s - w * t) + (1 - w_travel) * np.sin(k * s) * np.cos(w * t))


def test_pure_travelling_wave_has_index_one_on_a_coarse_grid() -> None:
    assert travelling_wave_index(waves(1.0, n_s=11, per_period=12)) == pytest.approx(1.0, abs=0.02)
    # not whole periods nor whole wavelengths: the Hilbert edges and the grid cost a little
    s = np.linspace(0.0, 1.3, 15)[None, :]
    t = np.linspace(0.0, 4.7, 90)[:, None]
    assert travelling_wave_index(np.sin(2 * np.pi * (s - t))) == pytest.approx(1.0, abs=0.1)


def test_pure_standing_wave_has_index_zero() -> None:
    assert travelling_wave_index(waves(0.0)) < 1e-6
    assert travelling_wave_index(waves(0.0, n_s=7, per_period=9, periods=3, wavelengths=0.7)) < 1e-6


@pytest.mark.parametrize("w_travel", [0.1, 0.25, 0.5, 0.75, 0.9])
def test_mixed_wave_index_matches_theory(w_travel: float) -> None:
    # mode = (a + b) sin ks + i a cos ks with a = w, b = 1 - w: index = a / (a + b) = w
    assert travelling_wave_index(waves(w_travel)) == pytest.approx(w_travel, abs=1e-3)


def test_index_is_invariant_to_amplitude_and_time_sampling() -> None:
    base = travelling_wave_index(waves(0.3, per_period=20))
    assert travelling_wave_index(waves(0.3, per_period=20, amp=1e3)) == pytest.approx(base, abs=1e-9)
    assert travelling_wave_index(waves(0.3, per_period=57, periods=3)) == pytest.approx(base, abs=1e-3)
    lateral = waves(0.3) + 5.0  # a static offset (time mean) changes nothing
    assert travelling_wave_index(lateral) == pytest.approx(base, abs=1e-9)


def test_index_rejects_bad_input() -> None:
    with pytest.raises(ValueError):
        travelling_wave_index(np.zeros((3, 5)))
    bad = waves(0.5)
    bad[3, 2] = np.nan
    with pytest.raises(ValueError):
        travelling_wave_index(bad)


def batch(t_s: np.ndarray, s: np.ndarray, x: np.ndarray, y: np.ndarray) -> CentrelineBatch:
    n = len(t_s)
    return CentrelineBatch(
        t_s=t_s,
        s=s,
        x=x,
        y=y,
        joints_x=x[:, ::10],
        joints_y=y[:, ::10],
        delta_rms=np.full(n, np.nan),
        n_events=np.zeros(n, np.int64),
    )


def moving_line(t_s: np.ndarray, s: np.ndarray, speed: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    x = np.broadcast_to(s[None, :], (len(t_s), len(s))).copy()
    y = np.broadcast_to(speed * t_s[:, None], (len(t_s), len(s))).copy()
    return x, y


def test_tip_and_shape_error_of_a_shifted_line_with_other_sampling() -> None:
    s_truth, t_truth = np.linspace(0, 100, 201), np.linspace(0, 1, 1001)
    truth = batch(t_truth, s_truth, *moving_line(t_truth, s_truth))
    s_rec, t_rec = np.linspace(0, 100, 51), np.linspace(-0.2, 0.8, 37)  # starts before the truth
    x, y = moving_line(t_rec, s_rec)
    recon = batch(t_rec, s_rec, x + 3.0, y + 4.0)
    t, delta = tip_error(recon, truth)
    assert t[0] >= 0 and len(t) == np.count_nonzero(t_rec >= 0)
    np.testing.assert_allclose(delta, 5.0, atol=1e-9)
    _, eps = eps_rms(recon, truth)
    np.testing.assert_allclose(eps, 5.0, atol=1e-9)


def test_shape_error_integrates_along_arc_length() -> None:
    s, t = np.linspace(0, 1, 401), np.linspace(0, 1, 5)
    truth = batch(t, s, *moving_line(t, s))
    x, y = moving_line(t, s)
    recon = batch(t, s, x, y + 0.3 * s[None, :])  # error a s / L: eps = a / sqrt(3)
    _, eps = eps_rms(recon, truth)
    np.testing.assert_allclose(eps, 0.3 / np.sqrt(3), rtol=1e-5)


def test_align_rejects_disjoint_times() -> None:
    s, t = np.linspace(0, 1, 5), np.linspace(0, 1, 5)
    truth = batch(t, s, *moving_line(t, s))
    with pytest.raises(ValueError, match="no common time"):
        align(batch(t + 5, s, *moving_line(t, s)), truth)


def test_cloud_distance_uses_segments_not_vertices() -> None:
    line_x, line_y = np.array([0.0, 100.0]), np.array([0.0, 0.0])
    assert cloud_distance(np.array([50.0]), np.array([2.0]), line_x, line_y) == pytest.approx(2.0)
    assert cloud_distance(np.array([103.0]), np.array([4.0]), line_x, line_y) == pytest.approx(5.0)
    ex, ey = np.array([10.0, 50.0, -3.0]), np.array([1.0, -2.0, 0.0])
    expected = np.sqrt((1 + 4 + 9) / 3)
    assert cloud_distance(ex, ey, line_x, line_y, block=2) == pytest.approx(expected)
    bent_x, bent_y = np.array([0.0, 10.0, 10.0]), np.array([0.0, 0.0, 10.0])
    assert cloud_distance(np.array([9.0]), np.array([5.0]), bent_x, bent_y) == pytest.approx(1.0)
    assert np.isnan(cloud_distance(np.array([]), np.array([]), line_x, line_y))


def test_frequency_with_sub_bin_refinement_and_amplitude() -> None:
    t = np.arange(0, 0.437, 1e-3)  # 7.56 periods: the peak falls between bins
    signal = 0.2 * np.sin(2 * np.pi * 17.3 * t + 0.4)
    assert flapping_frequency_hz(t, signal) == pytest.approx(17.3, abs=0.05)
    jittered = np.sort(t + np.random.default_rng(1).uniform(-2e-4, 2e-4, len(t)))
    assert flapping_frequency_hz(jittered, 0.2 * np.sin(2 * np.pi * 17.3 * jittered)) == pytest.approx(17.3, abs=0.1)
    assert tip_amplitude_over_l(signal * 300, 300.0) == pytest.approx(0.2, rel=1e-3)
    assert tip_amplitude_over_l(signal * 300, 300.0, robust=True) == pytest.approx(0.2, rel=0.03)


def test_frequency_across_gaps_of_dropped_data() -> None:
    """A 1.5 s record with three 0.3-0.5 s holes (a twin that skipped ahead, packets dropped): no
    stretch holds even five periods, yet the peak stays at the flapping frequency."""
    t = np.arange(0, 1.5, 5e-4)
    kept = ~(((t > 0.2) & (t < 0.55)) | ((t > 0.62) & (t < 0.95)) | ((t > 1.0) & (t < 1.45)))
    t, signal = t[kept], 40 * np.sin(2 * np.pi * 12.7 * t[kept] + 1.0) + 25.0  # an offset too
    assert flapping_frequency_hz(t, signal) == pytest.approx(12.7, abs=0.3)


def test_lateral_displacement_and_rest_frame() -> None:
    assert lateral_displacement(np.array([1.0]), np.array([5.0]), (0.0, 0.0), 0.0)[0] == pytest.approx(5.0)
    assert lateral_displacement(np.array([3.0]), np.array([0.0]), (1.0, 0.0), 90.0)[0] == pytest.approx(-2.0)
    s, t = np.linspace(0, 10, 11), np.linspace(0, 1, 3)
    root, direction = rest_frame(batch(t, s, np.tile(5 + s, (3, 1)), np.tile(7 + s, (3, 1))))
    assert root == pytest.approx((5.0, 7.0)) and direction == pytest.approx(45.0)


def test_compare_of_truth_with_itself() -> None:
    t, s = np.linspace(0, 0.4, 400), np.linspace(0, 1, 30)
    lat = 0.1 * waves(0.6, n_s=30, per_period=100, periods=4)
    truth = batch(t, s, np.tile(s, (400, 1)), lat)
    result = compare(truth, truth)
    assert result.delta_rms_over_l == 0 and result.max_eps_rms_over_l == 0
    assert result.twi == pytest.approx(result.twi_ref) and 0.3 < result.twi < 0.9
    assert result.n_common == 400 and result.length == pytest.approx(1.0)
