"""The simulated rig of the end-to-end tests, as one function: a light twin camera, the tracker, the
recorder, a tunnel (simulated in-process, or a controller on a pty) and a sweeping supervisor, with an
optional point sensor. It returns the rig's YAML mapping; :func:`rig_yaml` writes it to a file for the
commands, ``from_mapping(RigConfig, ...)`` makes it the config of an in-process rig."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import yaml

TWIN = {"events_per_px2": 0.5, "noise_rate_hz": 5000, "max_lag_s": 1.0}
"""A light twin (``camera.simulated``): the rig shares the machine's 2 cores with the tests."""
FLUTTER = {"onset_speed_mps": 4.9, "decay_speed_mps": 4.4, "tau_amp_s": 0.15}
"""The twin flag starts flapping at 4.9 m/s and stops below 4.4 m/s, within 0.15 s."""
SAFETY = {"max_speed_mps": 8, "max_ramp_mps2": 4.0, "ramp_period_s": 0.05, "tolerance_mps": 0.15,
          "settle_timeout_s": 3.0, "poll_period_s": 0.05, "keepalive_s": 0.25, "watchdog_s": 1.0}  # fmt: skip
"""``tunnel.safety``: quick ramps and settling for short sweeps."""
SWEEP_TUNNEL = {"tau_s": 0.1, "ramp_mps2": 6.0, "watchdog_s": 1.0}
"""``tunnel.sim``: the simulated controller's response (as :data:`tests.fakes.tunnel.SWEEP_SIM`)."""
SWEEP = {"speeds": [4.0, 5.5], "branches": ["up", "down"], "settle_s": 0.5, "record_s": 1.0}
"""Three points: 4.0 up (still), 5.5 up (flapping), 4.0 down (still)."""
SENSOR = {
    "id": "om70",
    "driver": "simulated",
    "units": "mm",
    "simulated": {"rate_hz": 1000, "noise_over_l": 0.002, "latency_ms": 2.0, "clock_offset_ms": 3.0},
    "beam": {"x_over_l": 0.73, "units_per_reading": 1 / 0.6, "zero_reading": 100.0, "direction": -1},
}
"""The simulated point sensor at x/L = 0.73, its clock 3 ms ahead of the camera's."""


def simulated_rig(
    tmp_path: Path,
    name: str,
    sweep: dict[str, Any] = SWEEP,
    *,
    tau_s: float = 0.002,
    twin: dict[str, Any] | None = None,
    flutter: bool = True,
    tunnel_port: str | None = None,
    recorder: dict[str, Any] | None = None,
    supervisor: dict[str, Any] | None = None,
    sensor: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The rig ``name`` sweeping ``sweep``, its files under ``tmp_path`` (``rec/``, ``runs/run``).

    Args:
        tau_s: the tracker's time constant.
        twin: more keys of ``camera.simulated`` (``time_scale``, ``trigger_period_ms``, ...).
        flutter: the twin flag flaps above 4.9 m/s (:data:`FLUTTER`); else it follows its default.
        tunnel_port: the tunnel is an ASCII controller on this pty (else simulated in the rig).
        recorder, supervisor: more keys of these sections (they replace the defaults' keys).
        sensor: a point sensor section (e.g. :data:`SENSOR`), run as the rig's fifth service.
    """
    simulated = {**TWIN, **(twin or {}), **({"flutter": FLUTTER} if flutter else {})}
    if tunnel_port is None:
        tunnel = {"driver": "simulated", "safety": SAFETY, "sim": SWEEP_TUNNEL}
    else:
        tunnel = {"driver": "ascii", "port": tunnel_port, "timeout_s": 0.3, "safety": SAFETY}
    rig: dict[str, Any] = {
        "rig": name,
        "camera": {"adapter": "simulated", "packet_us": 4000, "simulated": simulated},
        "tracker": {"root": [150, 240], "length": 300, "tau_s": tau_s},
        "recorder": {"directory": str(tmp_path / "rec"), **(recorder or {})},
        "tunnel": tunnel,
        "supervisor": {
            "mode": "sweep",
            "runs_dir": str(tmp_path / "runs"),
            "run_name": "run",
            "onset": {"learn_s": 1.0},
            "silence_timeout_s": 2.0,
            "sweep": sweep,
            **(supervisor or {}),
        },
        "services": ["camera", "tracker", "recorder", "supervisor"],
    }
    if sensor is not None:
        rig["sensor"] = sensor
        rig["services"].append("sensor")
    return copy.deepcopy(rig)  # the caller may change it; the constants above stay as they are


def rig_yaml(tmp_path: Path, rig: dict[str, Any]) -> Path:
    """Write ``rig`` to ``tmp_path/rig.yaml`` and return the path."""
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig))
    return path
