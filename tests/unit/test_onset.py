"""Onset/decay detector: hysteresis, dwell, robustness to bursts, unknown states, measured defaults."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from flagtrack.daemon.bench.onset_traces import RateModel, detection_delays, false_alarms_per_hour, rate_trace
from flagtrack.daemon.core.onset import FlagState, OnsetDetector, OnsetParams, detect_states, transitions

DT = 0.1
STILL_HZ = 2e4


def trace(*segments: tuple[float, float], seed: int = 0, sigma: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """Concatenated segments of (duration s, rate over STILL_HZ) with log-normal noise, every DT."""
    rng = np.random.default_rng(seed)
    rates = np.concatenate([np.full(int(round(d / DT)), r * STILL_HZ) for d, r in segments])
    rates = rates * np.exp(rng.normal(0.0, sigma, rates.size))
    return np.arange(rates.size) * DT, rates


def first_time(readings: list, state: FlagState, after_s: float = -math.inf) -> float:
    return next(r.t_s for r in readings if r.t_s >= after_s and r.state is state)


def test_learns_baseline_then_still() -> None:
    t, rate = trace((60.0, 1.0))
    readings = detect_states(t, rate)
    p = OnsetParams()
    assert all(r.state is FlagState.UNKNOWN for r in readings if r.t_s < p.learn_s)
    learned_s = p.learn_s + (p.min_samples - 1) * DT  # learning starts once the median is trusted
    assert transitions(readings) == [(pytest.approx(learned_s, abs=1e-9), FlagState.STILL)]
    assert readings[-1].baseline_hz == pytest.approx(STILL_HZ, rel=0.15)
    assert readings[-1].on_rate_hz == pytest.approx(p.on_ratio * readings[-1].baseline_hz)


@pytest.mark.parametrize("ratio", [10.0, 100.0])
def test_onset_delay_is_dwell_plus_half_window(ratio: float) -> None:
    t, rate = trace((20.0, 1.0), (20.0, ratio))
    readings = detect_states(t, rate)
    p = OnsetParams()
    delay = first_time(readings, FlagState.FLAPPING) - 20.0
    # The median crosses once half the window is flapping, then the dwell runs.
    assert p.dwell_on_s <= delay <= p.dwell_on_s + p.window_s / 2 + 2 * DT
    assert [s for _, s in transitions(readings)] == [FlagState.STILL, FlagState.FLAPPING]


def test_hysteresis_keeps_flapping_inside_the_band_and_decays_below() -> None:
    t, rate = trace((10.0, 1.0), (10.0, 10.0), (10.0, 3.0), (10.0, 1.0), sigma=0.05)  # 3x: between off 2x and on 4x
    readings = detect_states(t, rate)
    states = {r.state for r in readings if 22.0 <= r.t_s < 30.0}
    assert states == {FlagState.FLAPPING}
    decay = first_time(readings, FlagState.STILL, after_s=30.0) - 30.0
    p = OnsetParams()
    assert p.dwell_off_s <= decay <= p.dwell_off_s + p.window_s / 2 + 2 * DT


def test_slowly_rising_rate_inside_the_band_does_not_flap() -> None:
    # Before onset the still flag vibrates more as the wind rises: the baseline follows.
    t = np.arange(0.0, 600.0, DT)
    rate = STILL_HZ * np.exp(np.log(3.0) * t / 600.0)  # x3 in 10 min, slower than baseline_tau_s
    readings = detect_states(t, rate)
    assert {r.state for r in readings if r.t_s > 5.0} == {FlagState.STILL}
    assert readings[-1].baseline_hz > 2.5 * STILL_HZ


@pytest.mark.parametrize(("duration_s", "flips"), [(1.0, False), (1.5, False), (4.0, True)])
def test_bursts_shorter_than_the_dwell_are_ignored(duration_s: float, flips: bool) -> None:
    t, rate = trace((10.0, 1.0), (duration_s, 10.0), (10.0, 1.0), sigma=0.05)
    readings = detect_states(t, rate)
    assert any(r.state is FlagState.FLAPPING for r in readings) is flips


def test_gap_and_dead_camera_give_unknown_then_recover() -> None:
    t, rate = trace((10.0, 1.0), (10.0, 10.0), sigma=0.05)
    detector = OnsetDetector()
    for ti, ri in zip(t, rate):
        detector.update(ti, ri)
    assert detector.state is FlagState.FLAPPING
    assert detector.update(22.0, 10 * STILL_HZ).state is FlagState.UNKNOWN  # 2 s without samples
    states = [detector.update(22.0 + k * DT, 10 * STILL_HZ).state for k in range(1, 40)]
    assert states[-1] is FlagState.FLAPPING and FlagState.STILL not in states
    for k in range(40, 60):
        reading = detector.update(22.0 + k * DT, 0.0)  # the camera stops delivering
    assert reading.state is FlagState.UNKNOWN


def test_missing_samples_and_absolute_thresholds() -> None:
    params = OnsetParams(on_rate_hz=1e5, off_rate_hz=5e4)
    detector = OnsetDetector(params)
    assert detector.state is FlagState.STILL  # nothing to learn
    readings = [detector.update(k * DT, 2e5 if k % 2 else math.nan) for k in range(60)]
    assert readings[-1].state is FlagState.FLAPPING
    assert readings[-1].rate_hz == 2e5 and math.isnan(readings[-1].baseline_hz)


def test_bad_input_is_refused() -> None:
    detector = OnsetDetector()
    detector.update(1.0, 10.0)
    with pytest.raises(ValueError, match="backwards"):
        detector.update(0.5, 10.0)
    with pytest.raises(ValueError, match="negative"):
        detector.update(2.0, -1.0)


@pytest.mark.parametrize(
    "changes",
    [{"on_ratio": 2.0, "off_ratio": 2.0}, {"off_ratio": 1.0}, {"on_rate_hz": 1e5}, {"window_s": 0.0},
     {"on_rate_hz": 1e4, "off_rate_hz": 2e4}],
)  # fmt: skip
def test_params_are_checked(changes: dict) -> None:
    with pytest.raises(ValueError):
        OnsetParams(**changes)


def test_synthetic_traces_are_seeded_and_have_the_modelled_ratio() -> None:
    model = RateModel(bursts_per_hour=0.0, walk_per_sqrt_h=0.0)
    t, a = rate_trace(model, 60.0, np.arange(600) >= 300, np.random.default_rng(3))
    _, b = rate_trace(model, 60.0, np.arange(600) >= 300, np.random.default_rng(3))
    assert np.array_equal(a, b) and t[1] - t[0] == pytest.approx(model.dt_s)
    ratio = np.median(a[300:]) / np.median(a[:300])
    assert ratio == pytest.approx(model.flap_ratio, rel=0.2)


def test_defaults_on_the_measurement_traces() -> None:
    """A short version of `flagtrack bench onset` (numbers in docs/tunnel.md)."""
    params = OnsetParams()
    assert false_alarms_per_hour(params, RateModel(), hours=1, seed=11) == 0.0
    delays = detection_delays(params, dataclasses.replace(RateModel(), flap_ratio=10.0), trials=5, seed=12)
    assert delays.missed == 0
    assert delays.onset_p95_s <= params.dwell_on_s + params.window_s
    assert delays.decay_p95_s <= params.dwell_off_s + 2 * params.window_s
