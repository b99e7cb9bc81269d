"""One task of the accuracy benchmark: simulate the recording, read it back, track, compare with the truth.

Runs in a worker process. The recording goes through the real files (EVT 3.0 ``.raw`` written by the
simulator, decoded by ``flagtrack.drivers.formats``; truth HDF5), then every tracking variant runs on
the decoded events with the core :class:`~flagtrack.daemon.core.tracker.Tracker`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon.bench.accuracy_suite.plan import (
    LOSS_THRESHOLD,
    METHODS,
    PAPER_JOINTS,
    PAPER_TAU_OVER_T,
    SETTLE_PERIODS,
    START_ON_TRUTH,
    Task,
    Variant,
)
from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.metrics import align, compare, rms, trapezoid


@dataclass(frozen=True)
class Outcome:
    """What one task produced: one row per tracking variant, and the recording's figures."""

    task: Task
    rows: tuple[dict[str, Any], ...]
    n_events: int
    duration_s: float
    sim_wall_s: float


def at_paper_params(variant: Variant) -> bool:
    """N_j = 10 and tau/T = 5e-3 (the runs whose travelling-wave index is reported)."""
    return variant.joints == PAPER_JOINTS and math.isclose(variant.tau_over_t, PAPER_TAU_OVER_T)


def tracking_config(variant: Variant, attrs: dict[str, Any]) -> Any:
    """The :class:`TrackingConfig` of a variant for a recording (truth attributes give root, L, f)."""
    from flagtrack.daemon.tracking.section import TrackingConfig
    from flagtrack.daemon.typed_yaml import from_mapping

    tau_s = variant.tau_over_t / float(attrs["kin_frequency_hz"])
    values = {
        **METHODS[variant.method],
        "root": [float(v) for v in attrs["kin_root"]],
        "length": float(attrs["length"]),
        "direction_deg": float(attrs["kin_direction_deg"]),
        "joints": variant.joints,
        "tau_s": tau_s,
        "t_start_s": tau_s / 2,
    }
    return from_mapping(TrackingConfig, values, key="tracker")


def loss_time_cycles(t_s: np.ndarray, delta_over_l: np.ndarray, frequency_hz: float) -> float:
    """First time, in flapping cycles, at which delta/L exceeds the loss threshold; NaN if never."""
    over = np.flatnonzero(np.asarray(delta_over_l) > LOSS_THRESHOLD)
    return float(t_s[over[0]] * frequency_hz) if len(over) else math.nan


def score(
    recon: CentrelineBatch, truth: CentrelineBatch, attrs: dict[str, Any], with_twi: bool = True
) -> dict[str, float]:
    """Metrics of one reconstruction, measured after the settling time (lengths over L).

    ``with_twi``: also the travelling-wave indices (``metrics.compare``; an SVD over every update, the
    costly part with short windows); otherwise only the tip and shape errors (same formulas).
    """
    f, length = float(attrs["kin_frequency_hz"]), float(attrs["length"])
    recon = recon.select(recon.t_s >= SETTLE_PERIODS / f)
    pair = align(recon, truth)
    delta = np.hypot(pair.x[:, -1] - pair.x_ref[:, -1], pair.y[:, -1] - pair.y_ref[:, -1])
    out = {
        "delta_rms_over_l": rms(delta) / length,
        "t_loss_cycles": loss_time_cycles(pair.t_s, delta / length, f),
        "evaluated_cycles": float(pair.t_s[-1] - pair.t_s[0]) * f,
        "max_delta_over_l": float(np.max(delta)) / length,
    }
    if with_twi:
        c = compare(recon, truth, length)
        out.update(
            max_eps_rms_over_l=c.max_eps_rms_over_l,
            twi=c.twi,
            twi_ref=c.twi_ref,
            twi_abs_error=c.twi_abs_error,
            twi_rel_error=c.twi_abs_error / c.twi_ref if c.twi_ref > 0 else math.nan,
        )
    else:
        sq = (pair.x - pair.x_ref) ** 2 + (pair.y - pair.y_ref) ** 2
        eps = np.sqrt(trapezoid(sq, pair.s) / (pair.s[-1] - pair.s[0]))
        out.update(
            max_eps_rms_over_l=float(np.nanmax(eps)) / length,
            twi=math.nan,
            twi_ref=math.nan,
            twi_abs_error=math.nan,
            twi_rel_error=math.nan,
        )
    return out


def initial_state(truth: CentrelineBatch, n_joints: int) -> Any:
    """The chain through the truth's first centreline at equal arc-length steps (every method starts on the flag)."""
    from flagtrack.daemon.core.chain import ChainState

    s_k = np.linspace(truth.s[0], truth.s[-1], n_joints + 1)
    x, y = np.interp(s_k, truth.s, truth.x[0]), np.interp(s_k, truth.s, truth.y[0])
    return ChainState(np.arctan2(np.diff(y), np.diff(x)))


def track_events(
    events: np.ndarray, config: Any, size: tuple[int, int], state: Any = None
) -> tuple[CentrelineBatch, int]:
    """Reconstruct in-memory events from ``state``; returns the centrelines and the events the filter kept."""
    from flagtrack.daemon.core.tracker import Tracker

    tracker = Tracker(config.tracker_params(), state=state, sensor_size=size)
    batch = CentrelineBatch.concatenate([tracker.feed(events), tracker.finish()])
    return batch, tracker.stats.events_kept


def read_recording(events_path: str | Path, truth_path: str | Path) -> tuple[np.ndarray, CentrelineBatch, dict]:
    """Decode the event file and read the truth file."""
    from flagtrack.drivers.formats import open_events
    from flagtrack.drivers.formats.centreline import read_centrelines

    truth, attrs = read_centrelines(truth_path)
    with open_events(events_path) as reader:
        parts = [chunk.events for chunk in reader]
    events = np.concatenate(parts) if parts else np.empty(0)
    return events, truth, attrs


def recording_spec(task: Task) -> Any:
    """The simulator's :class:`RecordingSpec` of a task (duration from its cycles and frequency)."""
    from flagtrack.drivers.sim.dvs import DvsParams
    from flagtrack.drivers.sim.simulate import RecordingSpec, optics_and_kinematics

    spec = RecordingSpec(seed=task.seed, width=task.width, height=task.height)
    _, kin = optics_and_kinematics(spec)
    duration = None if task.cycles is None else task.cycles / kin.frequency_hz
    if task.part == "lost":  # the disruptions end at 0.45 s: a few periods after that
        from flagtrack.daemon.bench.accuracy_suite.disruptions import MIN_DURATION_S

        duration = max(duration or 0.0, MIN_DURATION_S + 3.0 / kin.frequency_hz)
    dvs = DvsParams(leak_rate_hz=task.leak_over_f * kin.frequency_hz, shot_noise_hz=task.shot_noise_hz)
    return RecordingSpec(seed=task.seed, duration_s=duration, width=task.width, height=task.height, dvs=dvs)


def run_task(task: Task, work_dir: str, keep_files: bool = False) -> Outcome:
    """Simulate ``task``'s recording into ``work_dir``, track every variant, score; delete the files."""
    from flagtrack.drivers.sim.simulate import simulate_recording

    result = simulate_recording(recording_spec(task), work_dir, name=task.name)
    events, truth, attrs = read_recording(result.events_path, result.truth_path)
    rows = []
    if task.part == "lost":
        from flagtrack.daemon.bench.accuracy_suite.disruptions import lost_rows

        base = {**task_columns(task, attrs, result.n_events), "width": task.width, "height": task.height}
        runs = [(v, tracking_config(v, attrs), initial_state(truth, v.joints)) for v in task.variants]
        rows = lost_rows(events, truth, attrs, runs, base)
    for variant in task.variants if task.part != "lost" else ():
        config = tracking_config(variant, attrs)
        start = time.perf_counter()
        state = initial_state(truth, variant.joints) if START_ON_TRUTH else None
        batch, kept = track_events(events, config, (task.width, task.height), state)
        wall = time.perf_counter() - start
        rows.append(
            {
                **task_columns(task, attrs, result.n_events),
                "method": variant.method,
                "joints": variant.joints,
                "tau_over_t": variant.tau_over_t,
                "events_kept": kept,
                "track_wall_s": wall,
                **score(batch, truth, attrs, with_twi=at_paper_params(variant)),
            }
        )
    if not keep_files:
        for path in (result.events_path, result.truth_path, result.params_path):
            Path(path).unlink(missing_ok=True)
    return Outcome(task, tuple(rows), result.n_events, result.duration_s, result.wall_s)


def task_columns(task: Task, attrs: dict[str, Any], n_events: int) -> dict[str, Any]:
    """Columns describing the recording (same for each of its variants)."""
    return {
        "name": task.name,
        "part": task.part,
        "kinematics": task.kinematics,
        "seed": task.seed,
        "level": task.level,
        "frequency_hz": float(attrs["kin_frequency_hz"]),
        "wavelength_over_l": float(attrs["kin_wavelength_over_l"]),
        "w_travel": float(attrs["kin_w_travel"]),
        "peak_to_peak_over_l": float(attrs["peak_to_peak_over_l"]),
        "duration_s": float(attrs["duration_s"]),
        "leak_rate_hz": float(attrs["dvs_leak_rate_hz"]),
        "shot_noise_hz": float(attrs["dvs_shot_noise_hz"]),
        "n_events": n_events,
    }
