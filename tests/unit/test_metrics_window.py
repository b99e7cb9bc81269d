"""A/L over a short window with no known rest frame (the live view's): the mean chord stands for it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flagtrack.daemon.core.metrics import window_amplitude_over_l


@pytest.mark.parametrize("direction_deg", [0.0, 30.0, 90.0, -135.0])
def test_half_peak_to_peak_perpendicular_to_the_mean_chord(direction_deg: float) -> None:
    t = np.arange(0.0, 1.0, 1e-3)
    d = np.deg2rad(direction_deg)
    lateral = 45.0 * np.sin(2 * np.pi * 4.0 * t)  # A = 45 px, L = 300 px: A/L = 0.15
    root_x, root_y = np.full_like(t, 150.0), np.full_like(t, 240.0)
    tip_x = 150.0 + 290.0 * np.cos(d) - lateral * np.sin(d)
    tip_y = 240.0 + 290.0 * np.sin(d) + lateral * np.cos(d)
    assert window_amplitude_over_l(root_x, root_y, tip_x, tip_y, 300.0) == pytest.approx(
        0.15, abs=1e-4
    )  # sampled peaks
    # the x or y of the tip alone would not do it at a slant
    if direction_deg == 30.0:
        assert (tip_y.max() - tip_y.min()) / 2 / 300.0 != pytest.approx(0.15, abs=0.01)


def test_updates_with_nan_are_left_out() -> None:
    t = np.arange(0.0, 0.5, 1e-3)
    tip_y = 240.0 + 30.0 * np.sin(2 * np.pi * 6.0 * t)
    tip_x = np.full_like(t, 440.0)
    tip_x[::7] = np.nan  # updates the tracker had no shape for
    root = np.full_like(t, 150.0), np.full_like(t, 240.0)
    assert window_amplitude_over_l(*root, tip_x, tip_y, 300.0) == pytest.approx(0.1, abs=1e-3)
    assert math.isnan(window_amplitude_over_l(*root, np.full_like(t, np.nan), tip_y, 300.0))
