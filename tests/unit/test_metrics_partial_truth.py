"""compare() against a truth lacking joints or Delta_RMS: those metrics are not available, with the reason;
the joint error and the Delta_RMS figures where the truth has them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.metrics import compare, joint_error


def series(
    t_s: np.ndarray, n_s: int = 21, n_joints: int = 4, shift: float = 0.0, delta_rms: float = math.nan
) -> CentrelineBatch:
    s = np.linspace(0.0, 1.0, n_s)
    x = np.broadcast_to(s[None, :], (len(t_s), n_s)).copy()
    y = 0.1 * s[None, :] * np.sin(2 * np.pi * (3 * t_s[:, None] - s[None, :])) + shift
    sj = np.linspace(0.0, 1.0, n_joints + 1)
    jx = np.broadcast_to(sj[None, :], (len(t_s), n_joints + 1)).copy()
    jy = 0.1 * sj[None, :] * np.sin(2 * np.pi * (3 * t_s[:, None] - sj[None, :])) + shift
    return CentrelineBatch(t_s, s, x, y, jx, jy, np.full(len(t_s), delta_rms), np.zeros(len(t_s), np.int64))


def test_joint_error_interpolates_the_truth_in_time_on_the_common_span() -> None:
    truth = series(np.linspace(0.0, 1.0, 2001))
    recon = series(np.linspace(-0.5, 0.8, 131), shift=0.02)  # starts before the truth
    t, error = joint_error(recon, truth)
    assert t[0] >= 0 and len(t) == np.count_nonzero(recon.t_s >= -1e-9)
    np.testing.assert_allclose(error, 0.02, atol=2e-4)  # linear interpolation of the truth in time
    with pytest.raises(ValueError, match="the truth has 3 joints, the reconstruction 5"):
        joint_error(recon, series(np.linspace(0.0, 1.0, 11), n_joints=2))


def test_what_the_truth_lacks_is_not_available_and_the_rest_is_computed() -> None:
    t = np.linspace(0.0, 1.0, 400)
    recon, truth = series(t, shift=0.01, delta_rms=0.003), series(t, delta_rms=0.002)
    full = compare(recon, truth)
    assert full.not_available == {}
    assert full.joint_rms_over_l == pytest.approx(0.01)
    assert full.cloud_rms_over_l == pytest.approx(0.003) and full.cloud_rms_ref_over_l == pytest.approx(0.002)
    bare = compare(recon, truth, truth_has_joints=False, truth_has_delta_rms=False)
    assert bare.not_available == {
        "joint_rms_over_l": "the truth has no joints",
        "cloud_rms_ref_over_l": "the truth has no Delta_RMS",
    }
    assert math.isnan(bare.joint_rms_over_l) and math.isnan(bare.cloud_rms_ref_over_l)
    for name in ("delta_rms_over_l", "max_eps_rms_over_l", "twi", "twi_ref", "cloud_rms_over_l"):
        assert getattr(bare, name) == getattr(full, name)


def test_a_truth_whose_delta_rms_is_all_nan_says_so() -> None:
    t = np.linspace(0.0, 1.0, 100)
    result = compare(series(t), series(t))  # a simulator's truth: Delta_RMS NaN throughout
    assert result.not_available == {
        "cloud_rms_ref_over_l": "the truth's Delta_RMS has no finite value in the common span"
    }
