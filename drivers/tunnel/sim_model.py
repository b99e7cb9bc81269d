"""The physics and firmware of the simulated tunnel, with time passed in (no clock, no I/O).

The controller ramps its internal set-point toward the commanded one at ``ramp_mps2``; the air
speed follows that ramped set-point as a first-order system of time constant ``tau_s``. If no
valid command arrives for ``watchdog_s`` while the fan runs, the controller trips: command zero,
fan stopped, fault ``WATCHDOG`` (cleared by the next set-point). Fault injection: ``stall_mps``
caps the air speed (a blocked fan: the readback never reaches a higher set-point).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Literal

log = logging.getLogger(__name__)

WATCHDOG_FAULT = "WATCHDOG"


@dataclass(frozen=True)
class SimParams:
    """The simulated tunnel (config ``tunnel.sim``).

    Attributes:
        protocol: what it speaks on its pseudo-terminal: ``ascii`` (the default line protocol)
            or ``modbus`` (RTU, with the register map of ``tunnel.modbus``).
        tau_s: time constant of the air speed, s.
        ramp_mps2: the controller's own set-point ramp limit, m/s per second.
        max_speed_mps: set-points above are refused, m/s.
        watchdog_s: no valid command for this long while running -> ramp to zero, s.
        initial_speed_mps: speed (and set-point) when the simulation starts, m/s.
        tick_s: integration and polling step, s.
    """

    protocol: Literal["ascii", "modbus"] = "ascii"
    tau_s: float = 1.5
    ramp_mps2: float = 2.0
    max_speed_mps: float = 20.0
    watchdog_s: float = 5.0
    initial_speed_mps: float = 0.0
    tick_s: float = 0.005

    def __post_init__(self) -> None:
        for name in ("tau_s", "ramp_mps2", "max_speed_mps", "watchdog_s", "tick_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive")
        if not 0 <= self.initial_speed_mps <= self.max_speed_mps:
            raise ValueError("initial_speed_mps must be within 0..max_speed_mps")


class TunnelModel:
    """State of the simulated controller and fan; advance it with :meth:`advance` (not thread-safe).

    Args:
        params: the simulation parameters.
        now_s: the current time on the caller's clock, s.
    """

    def __init__(self, params: SimParams, now_s: float) -> None:
        self.params = params
        self.setpoint_mps = params.initial_speed_mps
        self.running = params.initial_speed_mps > 0
        self.ramped_mps = params.initial_speed_mps
        self.speed_mps = params.initial_speed_mps
        self.fault: str | None = None
        self.stall_mps: float | None = None
        self.watchdog_trips = 0
        self.valid_commands = 0
        self._t_s = now_s
        self._last_valid_s = now_s

    def advance(self, now_s: float) -> None:
        """Integrate the dynamics up to ``now_s`` (and trip the watchdog if it is due)."""
        dt = max(0.0, now_s - self._t_s)
        self._t_s = now_s
        if self._active() and now_s - self._last_valid_s > self.params.watchdog_s:
            self.setpoint_mps, self.running, self.fault = 0.0, False, WATCHDOG_FAULT
            self.watchdog_trips += 1
            log.warning("simulated tunnel: no valid command for %.2f s, watchdog ramps to zero", self.params.watchdog_s)
        target = self.setpoint_mps if self.running else 0.0
        step = self.params.ramp_mps2 * dt
        self.ramped_mps += max(-step, min(step, target - self.ramped_mps))
        limit = self.ramped_mps if self.stall_mps is None else min(self.ramped_mps, self.stall_mps)
        self.speed_mps += (limit - self.speed_mps) * (1.0 - math.exp(-dt / self.params.tau_s))

    def touch(self, now_s: float) -> None:
        """Record a valid command (feeds the watchdog)."""
        self._last_valid_s = now_s
        self.valid_commands += 1

    def set_setpoint(self, speed_mps: float, *, run: bool | None = True) -> None:
        """Accept a set-point (m/s) and, unless ``run`` is None, start/stop the fan.

        Raises:
            ValueError: the set-point is negative, not finite, or above ``max_speed_mps``.
        """
        if not math.isfinite(speed_mps) or not 0 <= speed_mps <= self.params.max_speed_mps:
            raise ValueError("out of range")
        self.setpoint_mps = speed_mps
        if run is not None:
            self.set_running(run)

    def set_running(self, run: bool) -> None:
        """Start (clears a watchdog fault) or stop the fan."""
        self.running = run
        if run and self.fault == WATCHDOG_FAULT:
            self.fault = None

    def stop(self) -> None:
        """Set-point zero and fan stopped."""
        self.setpoint_mps, self.running = 0.0, False

    def _active(self) -> bool:
        return self.running and self.setpoint_mps > 0
