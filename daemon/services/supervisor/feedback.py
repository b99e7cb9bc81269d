"""A PI controller of the tip amplitude through the wind speed, with bound and rate limits (pure)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from flagtrack.daemon.services.supervisor.section import FeedbackConfig


@dataclass(frozen=True)
class ControllerState:
    """Integral of the error and the last command."""

    integral_s: float = 0.0
    speed_mps: float = 0.0


def measured_amplitude(amplitude_over_l: float, lost_fraction: float, cfg: FeedbackConfig) -> float:
    """The window's amplitude for :func:`control_step`, or NaN (hold) while the flag is lost in more
    than ``cfg.max_lost_fraction`` of its updates."""
    if math.isfinite(lost_fraction) and lost_fraction > cfg.max_lost_fraction:
        return math.nan
    return amplitude_over_l


def control_step(state: ControllerState, amplitude_over_l: float, dt_s: float, cfg: FeedbackConfig) -> ControllerState:
    """Next speed command from the measured amplitude (NaN: hold the speed).

    The command is clamped to the speed bounds and moves at most ``max_step_mps`` per step; the
    integral stops growing while the command is saturated (anti wind-up).
    """
    if not math.isfinite(amplitude_over_l):
        return state
    error = cfg.target_amplitude_over_l - amplitude_over_l
    integral = state.integral_s + error * dt_s
    wanted = cfg.start_speed_mps + cfg.kp_mps * error + cfg.ki_mps_per_s * integral
    step = max(-cfg.max_step_mps, min(cfg.max_step_mps, wanted - state.speed_mps))
    command = max(cfg.min_speed_mps, min(cfg.max_speed_mps, state.speed_mps + step))
    if command != wanted:  # saturated by rate or bounds: do not wind the integral up
        integral = state.integral_s
    return ControllerState(integral, command)
