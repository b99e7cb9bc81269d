"""Flutter model: hysteresis of onset, amplitude plateau, frequency rising with speed, continuity."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flagtrack.drivers.sim.flutter import (
    FlutterModel,
    FlutterParams,
    FlutterState,
    flutter_step,
    target_amplitude_over_l,
)


def sweep(model: FlutterModel, speeds: np.ndarray, hold_s: float = 3.0) -> list[FlutterState]:
    return [model.advance(float(u), hold_s) for u in speeds]


def test_onset_going_up_is_above_decay_coming_down() -> None:
    params = FlutterParams()
    up = np.arange(3.0, 8.01, 0.1)
    model = FlutterModel(params, seed=1)
    states_up = sweep(model, up)
    states_down = sweep(model, up[::-1])
    onset = next(u for u, s in zip(up, states_up, strict=True) if s.flapping)
    decay = next(u for u, s in zip(up[::-1], states_down, strict=True) if not s.flapping)
    assert onset == pytest.approx(params.onset_speed_mps, abs=0.051)
    assert decay == pytest.approx(params.decay_speed_mps - 0.1, abs=0.051)  # first speed below decay
    mid = 4.8  # between decay and onset: the branch depends on the history
    assert not states_up[int(round((mid - 3.0) / 0.1))].flapping
    assert states_down[len(up) - 1 - int(round((mid - 3.0) / 0.1))].flapping


def test_amplitude_plateaus_and_frequency_rises() -> None:
    params = FlutterParams()
    amps = [target_amplitude_over_l(u, params) for u in (5.0, 6.0, 7.0, 9.0, 12.0)]
    assert all(b >= a for a, b in zip(amps, amps[1:], strict=False))
    assert 0.2 <= amps[-1] <= 0.34 and amps[-1] - amps[-2] < 0.01
    model = FlutterModel(params, seed=0)
    slow, fast = model.advance(5.5, 5.0), model.advance(8.0, 5.0)
    assert fast.frequency_hz > slow.frequency_hz
    assert slow.amp_over_l == pytest.approx(target_amplitude_over_l(5.5, params), rel=1e-3)
    assert model.advance(2.0, 10.0).amp_over_l < 1e-6


def test_state_is_continuous_when_speed_jumps() -> None:
    params = FlutterParams(tau_amp_s=0.2)
    state = FlutterState()
    dt = 1e-3
    previous = state
    for i in range(3000):
        speed = 4.0 if i < 100 else (9.0 if i < 1500 else 3.0)
        state = flutter_step(previous, speed, dt, params)
        assert abs(state.amp_over_l - previous.amp_over_l) <= 0.5 * dt / params.tau_amp_s + 1e-12
        f_max = max(state.frequency_hz, previous.frequency_hz, params.freq_onset_hz)
        assert 0.0 <= state.phase_rad - previous.phase_rad <= 2 * math.pi * f_max * dt + 1e-12
        previous = state
    assert state.t_s == pytest.approx(3.0)


def test_deterministic_from_seed() -> None:
    params = FlutterParams(jitter_speed_mps=0.1)
    a, b, c = FlutterModel(params, 3), FlutterModel(params, 3), FlutterModel(params, 4)
    assert a.params == b.params and a.state == b.state
    assert c.state.phase_rad != a.state.phase_rad
    assert a.advance(6.0, 1.0) == b.advance(6.0, 1.0)
    with pytest.raises(ValueError):
        FlutterParams(onset_speed_mps=4.0, decay_speed_mps=4.5)
