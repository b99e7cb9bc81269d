"""The ``supervisor:`` section of a rig config."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from flagtrack.daemon.core.onset import OnsetParams
from flagtrack.daemon.sweep.plan import SweepConfig


@dataclass(frozen=True)
class FeedbackConfig:
    """Closed loop holding a target tip amplitude by adjusting the wind speed (PI, rate and bound limited).

    Attributes:
        target_amplitude_over_l: tip amplitude A/L to hold.
        kp_mps: proportional gain, m/s per unit of A/L error.
        ki_mps_per_s: integral gain, m/s per (unit A/L error x second).
        window_s: the amplitude is measured over the last ``window_s`` of centrelines.
        period_s: control period.
        start_speed_mps: speed set before the loop starts.
        settle_s: wait after the start speed is reached before the loop starts.
        min_speed_mps, max_speed_mps: bounds of the commanded speed.
        max_step_mps: largest change per period (rate limit = max_step_mps / period_s).
        duration_s: run this long (0: until stopped).
        max_lost_fraction: the speed is held while more than this fraction of the window's updates
            did not find the flag (their shape is not to be trusted).
    """

    target_amplitude_over_l: float = 0.25
    kp_mps: float = 2.0
    ki_mps_per_s: float = 1.0
    window_s: float = 1.0
    period_s: float = 1.0
    start_speed_mps: float = 5.5
    settle_s: float = 2.0
    min_speed_mps: float = 0.0
    max_speed_mps: float = 10.0
    max_step_mps: float = 0.3
    duration_s: float = 60.0
    max_lost_fraction: float = 0.05

    def __post_init__(self) -> None:
        if not 0 <= self.min_speed_mps <= self.start_speed_mps <= self.max_speed_mps:
            raise ValueError("need min_speed_mps <= start_speed_mps <= max_speed_mps")
        if self.period_s <= 0 or self.window_s <= 0 or self.max_step_mps <= 0 or self.duration_s < 0:
            raise ValueError("period_s, window_s, max_step_mps must be positive and duration_s >= 0")


@dataclass(frozen=True)
class ControlConfig:
    """Mode ``control``: a control law, and speed requests from the bus, inside the safety wrapper.

    Attributes:
        controller: the law, ``FILE.py:FUNCTION`` (``FUNCTION(state) -> speed_mps | None``, None:
            hold), ``pi`` (the built-in PI of the ``feedback:`` section), or None (no law: the speed
            moves only on requests).
        period_s: the law is called at most this often, with the newest flag state, s.
        duration_s: run this long once the loop starts (0: until stopped).
        start_speed_mps: speed set before the loop starts (0: none).
        settle_s: wait after the start speed is reached before the loop starts, s.
        max_faults: the run stops safe after this many faults of the law in a row (it raised,
            returned what is not a speed, or did not return within ``law_timeout_s``).
        law_timeout_s: a call of the law that has not returned after this long is a fault, and each
            further ``law_timeout_s`` it stays out another; its late answer is dropped, s.
        safe_speed_mps: after those faults, the tunnel holds this speed, and no law runs, until the
            run ends (0: the run ends at once, the tunnel ramped to zero).
        requests: take speed requests from the bus (on a secured bus, from operators only).
        record: record the camera and the centrelines of the whole run in the run folder.
    """

    controller: str | None = None
    period_s: float = 0.05
    duration_s: float = 60.0
    start_speed_mps: float = 0.0
    settle_s: float = 0.0
    max_faults: int = 3
    law_timeout_s: float = 1.0
    safe_speed_mps: float = 0.0
    requests: bool = True
    record: bool = True

    def __post_init__(self) -> None:
        if not self.period_s > 0 or self.duration_s < 0 or self.settle_s < 0:
            raise ValueError("period_s must be positive, duration_s and settle_s >= 0")
        if self.max_faults < 1 or self.start_speed_mps < 0 or self.safe_speed_mps < 0:
            raise ValueError("max_faults must be >= 1, start_speed_mps and safe_speed_mps >= 0")
        if not 0 < self.law_timeout_s < math.inf:
            raise ValueError("law_timeout_s must be a positive number of seconds")


@dataclass(frozen=True)
class SupervisorConfig:
    """What the supervisor does and when it gives up.

    Attributes:
        mode: ``monitor`` (publish the flag state only), ``sweep`` (run ``sweep``), ``feedback``,
            ``control`` (a control law and speed requests, ``control``).
        runs_dir: where run folders are made.
        run_name: the run folder's name (default: date and time).
        sweep: the sweep plan (mode ``sweep``).
        onset: the onset/decay detector (docs/tunnel.md for the measured defaults).
        feedback: the closed loop (mode ``feedback``; the law ``pi`` of mode ``control``).
        control: the control loop (mode ``control``).
        silence_timeout_s: no event rate (or a required service gone) for this long: safe state.
        required: services whose disappearance (liveliness) stops the run.
        startup_timeout_s: how long the required services may take to appear.
        publish_interval_s: period of the supervisor and tunnel state messages.
        recorder_timeout_s: how long the recorder may take to acknowledge a command.
        exit_when_done: end the service (and ``flagtrack up``) when the sweep or loop ends.
        suspect_lost_fraction: a point whose updates are lost (or, flapping, stale) more often than this is marked
            ``suspect`` (run log, summary CSV, figure).
        readback_grace_s: during a point's settle and record, how long the tunnel's readback may stay
            out of ``tunnel.safety.tolerance_mps`` (or its link silent) before the point fails, s.
        expected_rate_mev_s: event rate a point is expected to record at, Mev/s (free-space check).
        bytes_per_event: bytes one event takes in a recording (free-space check).
        free_space_margin_mb: free space kept beyond a point's expected size, MB.
        resume_interrupted: on start in sweep mode, decide from the run folders (restart means
            resume: an interrupted run is resumed, a stopped or finished one held, never a new
            sweep on its own; :mod:`~flagtrack.daemon.sweep.restart`). ``flagtrack sweep -c``
            turns it off (a person starts a new run there).
    """

    mode: Literal["monitor", "sweep", "feedback", "control"] = "monitor"
    runs_dir: Path = Path("runs")
    run_name: str | None = None
    sweep: SweepConfig | None = None
    onset: OnsetParams = field(default_factory=OnsetParams)
    feedback: FeedbackConfig = field(default_factory=FeedbackConfig)
    control: ControlConfig = field(default_factory=ControlConfig)
    silence_timeout_s: float = 3.0
    required: tuple[str, ...] = ("camera", "tracker", "recorder")
    startup_timeout_s: float = 20.0
    publish_interval_s: float = 0.2
    recorder_timeout_s: float = 10.0
    exit_when_done: bool = True
    suspect_lost_fraction: float = 0.05
    readback_grace_s: float = 1.0
    expected_rate_mev_s: float = 5.0
    bytes_per_event: float = 2.0
    free_space_margin_mb: float = 50.0
    resume_interrupted: bool = True

    def __post_init__(self) -> None:
        if self.mode == "sweep" and self.sweep is None:
            raise ValueError("mode 'sweep' needs a 'sweep:' section")
        timeouts = (self.silence_timeout_s, self.publish_interval_s, self.startup_timeout_s, self.recorder_timeout_s)
        if min(timeouts) <= 0:
            raise ValueError(
                "silence_timeout_s, publish_interval_s, startup_timeout_s, recorder_timeout_s must be positive, "
                f"got {timeouts}"
            )
        if not 0 <= self.suspect_lost_fraction <= 1:
            raise ValueError(f"suspect_lost_fraction must be in [0, 1], got {self.suspect_lost_fraction}")
        if min(self.readback_grace_s, self.expected_rate_mev_s, self.bytes_per_event, self.free_space_margin_mb) < 0:
            raise ValueError(
                "readback_grace_s, expected_rate_mev_s, bytes_per_event, free_space_margin_mb must be >= 0"
            )
