"""The simulated tunnel the demos and benches share: a controller on a pseudo-terminal that ramps at
3 m/s2 and follows the set-point with a 0.2 s lag, behind the same safety wrapper as a real one."""

from __future__ import annotations

from typing import Any


def simulated_tunnel(ramp_period_s: float = 0.05, **section: Any) -> dict[str, Any]:
    """A ``tunnel:`` section with the simulated driver (more keys of the section in ``section``)."""
    return {
        "driver": "simulated",
        **section,
        "safety": {
            "max_speed_mps": 10,
            "max_ramp_mps2": 2.0,
            "ramp_period_s": ramp_period_s,
            "tolerance_mps": 0.15,
            "settle_timeout_s": 10,
            "poll_period_s": 0.05,
            "keepalive_s": 0.5,
            "watchdog_s": 2.0,
        },
        "sim": {"tau_s": 0.2, "ramp_mps2": 3.0, "watchdog_s": 2.0},
    }
