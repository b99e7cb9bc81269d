"""Flutter of a flag versus wind speed, with hysteresis: the state the live digital twin flaps with.

A flag at rest starts flapping when the speed exceeds the onset speed and, once flapping, stops
only when the speed falls below a lower decay speed (subcritical bifurcation, Virot et al. 2013,
Eloy et al. 2012). While flapping, the target tip amplitude A/L jumps to a finite value at onset,
rises and plateaus (~0.2-0.34) and the frequency rises with speed. The amplitude relaxes to its
target with a time constant and the phase is integrated from the frequency, so the motion stays
continuous when the speed changes. Deterministic: the only randomness (small per-flag jitter of
the critical speeds and the initial phase) comes from the seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np


@dataclass(frozen=True)
class FlutterParams:
    """Flutter curve of one flag.

    Attributes:
        onset_speed_mps: speed above which a flag at rest starts flapping (going up).
        decay_speed_mps: speed below which a flapping flag stops (coming down); < onset.
        amp_onset_over_l: target A/L right at the decay speed (finite: the bifurcation is subcritical).
        amp_plateau_over_l: target A/L far above onset.
        amp_rise_mps: speed scale over which A/L rises from onset to plateau.
        freq_onset_hz: flapping frequency at the decay speed.
        freq_slope_hz_per_mps: frequency increase per m/s above the decay speed.
        tau_amp_s: time constant of the amplitude relaxation.
        jitter_speed_mps: standard deviation of the seeded jitter of both critical speeds.
    """

    onset_speed_mps: float = 5.0
    decay_speed_mps: float = 4.5
    amp_onset_over_l: float = 0.12
    amp_plateau_over_l: float = 0.3
    amp_rise_mps: float = 0.6
    freq_onset_hz: float = 9.0
    freq_slope_hz_per_mps: float = 3.0
    tau_amp_s: float = 0.4
    jitter_speed_mps: float = 0.0

    def __post_init__(self) -> None:
        if not self.decay_speed_mps < self.onset_speed_mps:
            raise ValueError(f"decay speed {self.decay_speed_mps} must be below onset speed {self.onset_speed_mps}")
        if self.tau_amp_s <= 0:
            raise ValueError(f"tau_amp_s must be > 0, got {self.tau_amp_s}")


@dataclass(frozen=True)
class FlutterState:
    """Flapping state at one instant.

    Attributes:
        t_s: time, seconds.
        flapping: True on the flapping branch (between onset and decay the branch is remembered).
        amp_over_l: current tip amplitude A/L (relaxing towards the target).
        frequency_hz: current flapping frequency.
        phase_rad: integrated flapping phase (continuous, unwrapped).
        speed_mps: wind speed used for the last step.
    """

    t_s: float = 0.0
    flapping: bool = False
    amp_over_l: float = 0.0
    frequency_hz: float = 0.0
    phase_rad: float = 0.0
    speed_mps: float = 0.0


def target_amplitude_over_l(speed_mps: float, params: FlutterParams) -> float:
    """Target A/L on the flapping branch at ``speed_mps`` (0 below the decay speed)."""
    excess = speed_mps - params.decay_speed_mps
    if excess < 0:
        return 0.0
    rise = 1.0 - math.exp(-excess / params.amp_rise_mps)
    return params.amp_onset_over_l + (params.amp_plateau_over_l - params.amp_onset_over_l) * rise


def flapping_frequency_hz(speed_mps: float, params: FlutterParams) -> float:
    """Flapping frequency at ``speed_mps`` on the flapping branch."""
    return params.freq_onset_hz + params.freq_slope_hz_per_mps * max(speed_mps - params.decay_speed_mps, 0.0)


def flutter_step(state: FlutterState, speed_mps: float, dt_s: float, params: FlutterParams) -> FlutterState:
    """Advance ``state`` by ``dt_s`` at constant ``speed_mps``; pure."""
    if dt_s < 0:
        raise ValueError(f"dt_s must be >= 0, got {dt_s}")
    flapping = state.flapping
    if not flapping and speed_mps >= params.onset_speed_mps:
        flapping = True
    elif flapping and speed_mps < params.decay_speed_mps:
        flapping = False
    target = target_amplitude_over_l(speed_mps, params) if flapping else 0.0
    relax = 1.0 - math.exp(-dt_s / params.tau_amp_s)
    amp = state.amp_over_l + (target - state.amp_over_l) * relax
    if flapping:
        freq = flapping_frequency_hz(speed_mps, params)
    else:  # decaying oscillation keeps its last frequency while the amplitude dies out
        freq = state.frequency_hz if state.frequency_hz > 0 else params.freq_onset_hz
    phase = (
        state.phase_rad + 2.0 * math.pi * 0.5 * (state.frequency_hz + freq) * dt_s
        if state.frequency_hz > 0
        else state.phase_rad + 2.0 * math.pi * freq * dt_s
    )
    return FlutterState(
        t_s=state.t_s + dt_s, flapping=flapping, amp_over_l=amp, frequency_hz=freq, phase_rad=phase, speed_mps=speed_mps
    )


class FlutterModel:
    """A flag's flutter state driven by a (changing) wind speed; deterministic from ``seed``.

    Args:
        params: the flutter curve.
        seed: draws the jitter of the critical speeds (``params.jitter_speed_mps``) and the initial phase.
    """

    def __init__(self, params: FlutterParams = FlutterParams(), seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        jitter = rng.normal(0.0, params.jitter_speed_mps, 2) if params.jitter_speed_mps > 0 else np.zeros(2)
        onset = params.onset_speed_mps + float(jitter[0])
        decay = min(params.decay_speed_mps + float(jitter[1]), onset - 1e-3)
        self.params = replace(params, onset_speed_mps=onset, decay_speed_mps=decay)
        self.state = FlutterState(phase_rad=float(rng.uniform(0.0, 2.0 * math.pi)))

    def advance(self, speed_mps: float, dt_s: float, max_step_s: float = 0.01) -> FlutterState:
        """Advance by ``dt_s`` at ``speed_mps`` (in sub-steps of at most ``max_step_s``); return the new state."""
        n = max(1, math.ceil(dt_s / max_step_s))
        for _ in range(n):
            self.state = flutter_step(self.state, speed_mps, dt_s / n, self.params)
        return self.state
