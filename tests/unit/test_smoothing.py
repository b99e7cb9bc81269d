"""Smoothing: makima equals scipy's, the smoothed length is L to 1e-6 L, the tip keeps its direction."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import Akima1DInterpolator

from flagtrack.daemon.core.chain import joint_positions
from flagtrack.daemon.core.smoothing import makima, n_samples, smooth_chains


@pytest.mark.parametrize("seed", range(5))
def test_makima_matches_scipy(seed: int) -> None:
    rng = np.random.default_rng(seed)
    u = np.concatenate([[0.0], np.cumsum(rng.uniform(0.3, 2.0, 10))])
    v = rng.normal(size=11)
    v[4:6] = v[3]  # flat stretch: the weights' special cases
    uq = np.linspace(0.0, u[-1], 777)
    expected = Akima1DInterpolator(u, v, method="makima")(uq)
    np.testing.assert_allclose(makima(u, v, uq), expected, rtol=0, atol=1e-12)


def _random_chains(n: int, bend_sd: float, seed: int, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    jx, jy = [], []
    for _ in range(n):
        angles = rng.uniform(-np.pi, np.pi) + np.cumsum(rng.normal(0.0, bend_sd, len(lengths)))
        x, y = joint_positions(3.0, -2.0, angles, lengths)
        jx.append(x)
        jy.append(y)
    return np.array(jx), np.array(jy)


@pytest.mark.parametrize("bend_sd", [0.0, 0.05, 0.3, 0.7])
@pytest.mark.parametrize("n_s", [51, 37])
def test_smoothed_length_is_exact_and_tip_keeps_direction(bend_sd: float, n_s: int) -> None:
    lengths = np.full(10, 20.0)
    jx, jy = _random_chains(50, bend_sd, seed=int(bend_sd * 100) + n_s, lengths=lengths)
    x, y, sjx, sjy = smooth_chains(jx, jy, lengths, 200.0, n_s)
    polyline = np.hypot(np.diff(x, axis=1), np.diff(y, axis=1)).sum(axis=1)
    assert np.all(np.abs(polyline - 200.0) <= 1e-6 * 200.0)
    # root fixed, first N_j - 1 joints untouched, tip on the original tip link
    np.testing.assert_array_equal(sjx[:, :-1], jx[:, :-1])
    np.testing.assert_array_equal(sjy[:, :-1], jy[:, :-1])
    tip_dir = np.arctan2(jy[:, -1] - jy[:, -2], jx[:, -1] - jx[:, -2])
    new_dir = np.arctan2(sjy[:, -1] - sjy[:, -2], sjx[:, -1] - sjx[:, -2])
    np.testing.assert_allclose(np.angle(np.exp(1j * (new_dir - tip_dir))), 0.0, atol=1e-9)
    assert np.allclose(x[:, 0], 3.0) and np.allclose(y[:, 0], -2.0)
    np.testing.assert_allclose(x[:, -1], sjx[:, -1], atol=1e-12)
    if bend_sd > 0:
        tip_link = np.hypot(sjx[:, -1] - sjx[:, -2], sjy[:, -1] - sjy[:, -2])
        assert np.all(tip_link < 20.0 + 1e-9) and np.any(tip_link < 20.0 - 1e-6)  # shortened


def test_samples_are_makima_through_the_shortened_joints() -> None:
    lengths = np.array([12.0, 18.0, 25.0, 20.0, 25.0])
    jx, jy = _random_chains(3, 0.4, seed=3, lengths=lengths)
    x, y, sjx, sjy = smooth_chains(jx, jy, lengths, float(lengths.sum()), 41)
    for k in range(3):
        u = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(sjx[k]), np.diff(sjy[k])))])
        uq = np.linspace(0.0, u[-1], 41)
        np.testing.assert_allclose(x[k], Akima1DInterpolator(u, sjx[k], method="makima")(uq), atol=1e-9)
        np.testing.assert_allclose(y[k], Akima1DInterpolator(u, sjy[k], method="makima")(uq), atol=1e-9)


def test_straight_chain_gives_evenly_spaced_straight_line() -> None:
    jx, jy = joint_positions(0.0, 0.0, np.full(10, np.pi / 6), np.full(10, 20.0))
    x, y, _, _ = smooth_chains(jx, jy, np.full(10, 20.0), 200.0, 51)
    s = np.linspace(0, 200.0, 51)
    np.testing.assert_allclose(x[0], s * np.cos(np.pi / 6), atol=1e-9)
    np.testing.assert_allclose(y[0], s * np.sin(np.pi / 6), atol=1e-9)


@pytest.mark.parametrize(("length", "ds", "expected"), [(200.0, 4.0, 51), (200.0, 3.0, 68), (1.0, 2.0, 2)])
def test_n_samples(length: float, ds: float, expected: int) -> None:
    assert n_samples(length, ds) == expected
