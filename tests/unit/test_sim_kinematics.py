"""The benchmark kinematics family: inextensible, deterministic, spanning the paper's 2A/L and lambda/L."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.drivers.sim.kinematics import FlagKinematics, KinematicsFamily, sample_kinematics, with_peak_to_peak


@pytest.mark.parametrize("seed", [0, 7, 42])
def test_length_is_constant_and_root_fixed(seed: int) -> None:
    kin = sample_kinematics(seed)
    x, y = kin.positions(np.linspace(0.0, 2.0 / kin.frequency_hz, 9), np.linspace(0.0, kin.length, 2001))
    lengths = np.hypot(np.diff(x, axis=1), np.diff(y, axis=1)).sum(axis=1)
    np.testing.assert_allclose(lengths, kin.length, rtol=1e-6)
    np.testing.assert_allclose(x[:, 0], kin.root[0], atol=1e-12)
    np.testing.assert_allclose(y[:, 0], kin.root[1], atol=1e-12)
    # tangent has unit norm everywhere: the local speed along s
    speed = np.hypot(np.gradient(x, axis=1), np.gradient(y, axis=1)) / (kin.length / 2000)
    assert np.all(np.abs(speed[:, 1:-1] - 1.0) < 1e-4)


def test_positions_at_other_samples_agree() -> None:
    kin = FlagKinematics(amp_rad=1.0, wavelength_over_l=1.5)
    fine_x, fine_y = kin.positions(np.array([0.013]), np.linspace(0, kin.length, 1201))
    x, y = kin.positions(np.array([0.013]), np.linspace(0, kin.length, 1201)[::37])
    np.testing.assert_allclose(x, fine_x[:, ::37], atol=1e-9)
    np.testing.assert_allclose(y, fine_y[:, ::37], atol=1e-9)
    coarse_x, _ = kin.positions_at_phase(kin.phase(np.array([0.013])), np.linspace(0, kin.length, 1201), n_fine=64)
    np.testing.assert_allclose(coarse_x, fine_x, atol=1e-5 * kin.length)


def test_family_spans_the_paper_ranges() -> None:
    family = KinematicsFamily()
    kins = [sample_kinematics(seed, family) for seed in range(250)]
    p2p = np.array([k.peak_to_peak_over_l(n_phase=128) for k in kins])
    lam = np.array([k.wavelength_over_l for k in kins])
    assert p2p.min() >= 0.085 and p2p.max() <= 1.05
    assert p2p.min() < 0.12 and p2p.max() > 1.0  # the whole span is used
    assert lam.min() >= 1.5 and lam.max() <= 3.0 and lam.min() < 1.6 and lam.max() > 2.9
    assert np.histogram(p2p, bins=4, range=(0.085, 1.05))[0].min() > 20
    weights = np.array([k.w_travel for k in kins])
    assert weights.min() < 0.1 and weights.max() > 0.9
    np.testing.assert_allclose([k.w_travel + k.w_standing for k in kins], 1.0)


def test_sampling_is_deterministic() -> None:
    assert sample_kinematics(11) == sample_kinematics(11)
    assert sample_kinematics(11) != sample_kinematics(12)


def test_amplitude_solve_hits_the_target() -> None:
    kin = with_peak_to_peak(FlagKinematics(), 0.6)
    assert kin is not None and kin.peak_to_peak_over_l() == pytest.approx(0.6, abs=1e-4)
    assert with_peak_to_peak(FlagKinematics(), 1.9, max_amp_rad=1.3) is None


def test_attrs_roundtrip_and_speed() -> None:
    kin = sample_kinematics(5)
    assert FlagKinematics.from_attrs({**kin.to_attrs(), "unknown": 1}) == kin
    # max speed is at least the tip's mean lateral speed (2 * peak-to-peak * f)
    assert kin.max_speed() >= 2 * kin.peak_to_peak_over_l() * kin.length * kin.frequency_hz * 0.99
