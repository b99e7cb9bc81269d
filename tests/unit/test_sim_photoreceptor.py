"""The slow-photoreceptor generator: each pixel thresholds a first-order low-pass of its log intensity.

A still line lights its pixels at once; a pixel on it then fires ON events at the times the low-pass
crosses each threshold, k C = Delta (1 - exp(-t / tau)); when the line leaves, the same pixel fires
as many OFF events while it decays, though the line no longer touches it; a pixel lit again after
resting fires as it did the first time (its idle decay is caught up exactly). On a flapping flag,
a 20 ms photoreceptor keeps a few per cent of an instantaneous one's events.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from flagtrack.drivers.sim.kinematics import sample_kinematics
from flagtrack.drivers.sim.photoreceptor import PhotoreceptorParams, slow_photoreceptor_events

TAU_US = 2000.0
EXACT = PhotoreceptorParams(tau_us=TAU_US, sigma_contrast=0.0, margin_px=4)  # C = 0.3 at every pixel
CENTRE = (40, 30)  # a pixel on the line while it is at y = 30


@dataclass(frozen=True)
class HoppingLine:
    """A horizontal line from x = 20 to 60, at y = 30, or at y = 80 during ``away_s`` (start, stop)."""

    away_s: tuple[float, float] = (1.0, 1.0)
    length: float = 40.0

    def positions(self, t_s: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        t = np.asarray(t_s, dtype=np.float64)[:, None]
        away = (t >= self.away_s[0]) & (t < self.away_s[1])
        x = np.broadcast_to(20.0 + np.asarray(s)[None, :], (len(t), len(s)))
        return x.copy(), np.broadcast_to(np.where(away, 80.0, 30.0), (len(t), len(s))).copy()


def _at(events: np.ndarray, pixel: tuple[int, int]) -> np.ndarray:
    return events[(events["x"] == pixel[0]) & (events["y"] == pixel[1])]


def _crossing_us(start: float, levels: np.ndarray, end: float) -> np.ndarray:
    """When a low-pass going from ``start`` to ``end`` (log units above the background) crosses ``levels``."""
    return -TAU_US * np.log((end - levels) / (end - start))


C = 0.3
DELTA = math.log(0.15 + 1.0 + 1e-3) - math.log(0.15 + 1e-3)  # the crest pixel lit: 2.03, six steps of C


def test_a_lit_pixel_fires_as_its_low_pass_crosses_each_threshold() -> None:
    events = slow_photoreceptor_events(HoppingLine(), 0.02, 100, 100, EXACT, seed=1)
    centre = _at(events, CENTRE)
    assert len(centre) == 6 and np.all(centre["p"] == 1)
    expected = _crossing_us(0.0, C * np.arange(1, 7), DELTA)
    np.testing.assert_allclose(centre["t"], expected, atol=2 * EXACT.step_us, rtol=0.01)
    assert np.all(events["p"] == 1)  # nothing ever decays
    assert set(np.unique(events["y"])) <= set(range(27, 34))  # within 3.5 sigma of the line


def test_a_pixel_the_line_left_decays_and_fires_off_events() -> None:
    line = HoppingLine(away_s=(0.02, 1.0))  # at y = 30 for 10 tau, then away
    centre = _at(slow_photoreceptor_events(line, 0.04, 100, 100, EXACT, seed=1), CENTRE)
    off = centre[centre["p"] == 0]
    assert np.sum(centre["p"] == 1) == 6
    assert len(off) == 5  # down to C above the background: the last step of C needs infinite time
    expected = _crossing_us(DELTA, C * np.arange(5, 0, -1), 0.0)
    np.testing.assert_allclose(off["t"] - 20_000, expected, atol=2 * EXACT.step_us, rtol=0.01)


def test_a_pixel_lit_again_after_resting_starts_from_its_decayed_level() -> None:
    line = HoppingLine(away_s=(0.02, 0.06))  # back at 60 ms, after 20 tau away (not updated meanwhile)
    centre = _at(slow_photoreceptor_events(line, 0.08, 100, 100, EXACT, seed=1), CENTRE)
    again = centre[centre["t"] >= 60_000]
    assert len(again) == 5 and np.all(again["p"] == 1)  # from C above the background up to 6 C
    expected = _crossing_us(0.0, C * np.arange(2, 7), DELTA)  # not from where it was when last updated
    np.testing.assert_allclose(again["t"] - 60_000, expected, atol=2 * EXACT.step_us, rtol=0.01)


def test_a_slow_photoreceptor_keeps_few_of_a_flapping_flags_events() -> None:
    kin = sample_kinematics(11)
    slow = slow_photoreceptor_events(kin, 0.06, seed=4)
    ideal = slow_photoreceptor_events(kin, 0.06, params=PhotoreceptorParams(tau_us=0.0), seed=4)
    assert 0.005 < len(slow) / len(ideal) < 0.15
    for events in (slow, ideal):
        assert np.all(np.diff(events["t"]) >= 0) and events["t"][0] >= 0 and events["t"][-1] < 60_000
        assert events["x"].max() < 640 and events["y"].max() < 480
    x, y = kin.positions(np.array([0.0, 0.03]), np.linspace(0, kin.length, 200))
    lo_x, hi_x = x.min() - 10, 640  # the flag flaps to the right of its root
    assert np.all((ideal["x"] >= lo_x) & (ideal["x"] <= hi_x))
    repeat = slow_photoreceptor_events(kin, 0.06, seed=4)
    assert np.array_equal(repeat, slow)
    assert not np.array_equal(slow_photoreceptor_events(kin, 0.06, seed=5), slow)


@pytest.mark.parametrize(
    "changes", [{"tau_us": -1.0}, {"tau_us": math.nan}, {"step_us": 0.0}, {"contrast": -0.3}, {"n_s": 1}]
)
def test_parameters_out_of_range_are_refused(changes: dict) -> None:
    with pytest.raises(ValueError, match="PhotoreceptorParams"):
        PhotoreceptorParams(**changes)


def test_a_duration_that_is_not_positive_is_refused() -> None:
    with pytest.raises(ValueError, match="duration_s"):
        slow_photoreceptor_events(HoppingLine(), 0.0)
