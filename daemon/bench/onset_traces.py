"""How the onset detector's defaults were measured: synthetic event-rate traces and scores.

Traces: the rate is sampled every ``dt_s`` (as the supervisor does from the event stream); a
still flag gives a low rate with slow drift (log random walk), correlated log-normal
fluctuations and bursts (someone walks by, a vibration: 2-10x for up to 1 s), a flapping flag
multiplies it by ``flap_ratio`` (10-100, 5 for a weak near-onset flutter); event counting adds
Poisson noise. Scores: false alarms per hour on still traces, missed detections, and detection
delays of onset (still -> flapping) and decay (flapping -> still).

``flagtrack bench onset`` (about a minute) prints the table of docs/tunnel.md.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from flagtrack.daemon.core.onset import FlagState, OnsetDetector, OnsetParams


@dataclass(frozen=True)
class RateModel:
    """Synthetic event-rate traces.

    Attributes:
        dt_s: sampling period of the rate, s.
        still_hz: rate of a still flag at the start, events/s.
        flap_ratio: flapping rate over still rate.
        sigma: standard deviation of the log-rate fluctuations.
        corr_s: correlation time of the fluctuations, s.
        walk_per_sqrt_h: standard deviation of the log-rate drift after one hour.
        bursts_per_hour: disturbance bursts per hour.
        burst_ratio: range of the burst rate multipliers.
        burst_s: range of burst durations, s.
    """

    dt_s: float = 0.1
    still_hz: float = 2e4
    flap_ratio: float = 10.0
    sigma: float = 0.35
    corr_s: float = 0.5
    walk_per_sqrt_h: float = 0.7
    bursts_per_hour: float = 120.0
    burst_ratio: tuple[float, float] = (2.0, 10.0)
    burst_s: tuple[float, float] = (0.05, 1.0)


def rate_trace(
    model: RateModel, duration_s: float, flapping: np.ndarray | None, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) and rates (events/s) of a trace; ``flapping`` is a bool per sample (or None)."""
    n = int(round(duration_s / model.dt_s))
    t = np.arange(n) * model.dt_s
    a = math.exp(-model.dt_s / model.corr_s)
    shocks = rng.normal(0.0, model.sigma * math.sqrt(1 - a * a), n)
    noise, _ = lfilter([1.0], [1.0, -a], shocks, zi=[a * rng.normal(0.0, model.sigma)])  # AR(1)
    walk = np.cumsum(rng.normal(0.0, model.walk_per_sqrt_h * math.sqrt(model.dt_s / 3600.0), n))
    log_rate = math.log(model.still_hz) + walk + noise
    if flapping is not None:
        log_rate = log_rate + np.where(flapping, math.log(model.flap_ratio), 0.0)
    n_bursts = rng.poisson(model.bursts_per_hour * duration_s / 3600.0)
    for start in rng.uniform(0.0, duration_s, n_bursts):
        stop = start + rng.uniform(*model.burst_s)
        inside = (t >= start) & (t < stop)
        log_rate[inside] += math.log(rng.uniform(*model.burst_ratio))
    counts = rng.poisson(np.exp(log_rate) * model.dt_s)
    return t, counts / model.dt_s


def false_alarms_per_hour(
    params: OnsetParams, model: RateModel, hours: float, seed: int, *, flapping: bool = False
) -> float:
    """Wrong changes per hour: to flapping on still traces, or back to still on flapping traces.

    One-hour pieces with a fresh detector each. On still traces the detector learns its baseline
    as in use; on flapping traces it is given the still baseline and the first (true) change to
    flapping is not counted.
    """
    rng = np.random.default_rng(seed)
    pieces = int(math.ceil(hours))
    alarms = 0
    for _ in range(pieces):
        n = int(round(3600.0 / model.dt_s))
        t, rate = rate_trace(model, 3600.0, np.full(n, flapping), rng)
        detector = OnsetDetector(params, baseline_hz=model.still_hz if flapping else None)
        onset_seen = False
        for ti, ri in zip(t.tolist(), rate.tolist()):
            reading = detector.update(ti, ri)
            if not reading.changed:
                continue
            if flapping and not onset_seen and reading.state is FlagState.FLAPPING:
                onset_seen = True
            elif reading.state is (FlagState.STILL if flapping else FlagState.FLAPPING):
                alarms += 1
    return alarms / pieces


@dataclass(frozen=True)
class Delays:
    """Detection delays over many trials, s (median and 95th percentile) and misses."""

    onset_median_s: float
    onset_p95_s: float
    decay_median_s: float
    decay_p95_s: float
    missed: int
    trials: int


def detection_delays(params: OnsetParams, model: RateModel, trials: int, seed: int, limit_s: float = 20.0) -> Delays:
    """Still for 30 s, flapping for 30 s, still for 30 s; delays of the two changes."""
    rng = np.random.default_rng(seed)
    t_on, t_off, total = 30.0, 60.0, 90.0
    onset, decay, missed = [], [], 0
    for _ in range(trials):
        n = int(round(total / model.dt_s))
        t_grid = np.arange(n) * model.dt_s
        t, rate = rate_trace(model, total, (t_grid >= t_on) & (t_grid < t_off), rng)
        detector = OnsetDetector(params)
        readings = [detector.update(ti, ri) for ti, ri in zip(t.tolist(), rate.tolist())]
        on = [r.t_s - t_on for r in readings if r.t_s >= t_on and r.state is FlagState.FLAPPING]
        off = [r.t_s - t_off for r in readings if r.t_s >= t_off and r.state is FlagState.STILL]
        if not on or on[0] > limit_s or not off or off[0] > limit_s:
            missed += 1
            continue
        onset.append(on[0])
        decay.append(off[0])
    q = lambda v, p: float(np.percentile(v, p)) if v else math.nan  # noqa: E731
    return Delays(q(onset, 50), q(onset, 95), q(decay, 50), q(decay, 95), missed, trials)


def report(params: OnsetParams, hours: float = 20.0, trials: int = 40, seed: int = 1) -> list[str]:
    """Table rows: false alarms/h on still traces, and delays for flapping ratios 4-100."""
    base = RateModel()
    fa = false_alarms_per_hour(params, base, hours, seed)
    fd = false_alarms_per_hour(params, base, hours, seed + 1, flapping=True)
    fd_steady = false_alarms_per_hour(
        params, dataclasses.replace(base, walk_per_sqrt_h=0.0), hours, seed + 2, flapping=True
    )
    rows = [f"false onsets: {fa:.2f} per hour over {hours:g} h of still traces (bursts {base.bursts_per_hour:g}/h, "
            f"2-10x, up to {base.burst_s[1]:g} s; log-rate sigma {base.sigma:g}, drift {base.walk_per_sqrt_h:g}/sqrt(h))",
            f"false decays: {fd:.2f} per hour over {hours:g} h of flapping traces (ratio {base.flap_ratio:g}); "
            f"{fd_steady:.2f} per hour without the slow drift"]  # fmt: skip
    rows.append("flap ratio | onset delay median / p95 (s) | decay delay median / p95 (s) | missed")
    for ratio in (5.0, 10.0, 30.0, 100.0):
        d = detection_delays(params, dataclasses.replace(base, flap_ratio=ratio), trials, seed + int(ratio))
        rows.append(f"{ratio:10g} | {d.onset_median_s:6.2f} / {d.onset_p95_s:6.2f} | "
                    f"{d.decay_median_s:6.2f} / {d.decay_p95_s:6.2f} | {d.missed}/{d.trials}")  # fmt: skip
    return rows


GRID: dict[str, OnsetParams] = {
    "defaults": OnsetParams(),
    "window 0.5 s": OnsetParams(window_s=0.5),
    "window 2 s": OnsetParams(window_s=2.0),
    "dwell_on 0.5 s": OnsetParams(dwell_on_s=0.5),
    "dwell_on 1 s": OnsetParams(dwell_on_s=1.0),
    "dwell_on 3 s": OnsetParams(dwell_on_s=3.0),
    "dwell_off 0.5 s": OnsetParams(dwell_off_s=0.5),
    "on x3 / off x1.5": OnsetParams(on_ratio=3.0, off_ratio=1.5),
    "on x6 / off x3": OnsetParams(on_ratio=6.0, off_ratio=3.0),
}
