"""Hold the flag's tip amplitude A/L at a set-point by nudging the wind speed every cycle (docs/control.md)."""

from flagtrack.client import FlagState

setpoint = 0.22  # the A/L to hold (the run's record and figure show it)
GAIN_MPS = 1.0  # speed change per cycle, m/s per unit of A/L error
asked_mps = -1.0  # the last speed asked (-1: none yet)


def law(state: FlagState) -> float | None:
    """The next wind speed in m/s from the flag's state, or None to hold."""
    global asked_mps
    if not state.completes_cycle or state.amplitude_over_l < 0 or state.speed_mps < 0:
        return None  # hold until a whole cycle is measured
    if asked_mps < 0:
        asked_mps = state.speed_mps  # start from the tunnel's readback
    asked_mps += GAIN_MPS * (setpoint - state.amplitude_over_l)
    return asked_mps
