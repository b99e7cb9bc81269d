"""The runs of ``flagtrack bench verdicts``: which recording, which start, which method; each tracked
and scored against the truth (found / lost / stale of every update, and how far it is off the flag).

An update is *off* when eps_RMS (the RMS distance of its centreline to the truth's) is more than
``OFF_OVER_L`` of L; it is *found* when it says neither lost nor stale. A tracker without ``stale``
(before issue 30) counts as never stale.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon.bench import verdict_recordings as recordings

POOLED_CASES = ("acq", "noise", "weak")
OFF_OVER_L = 0.05
NOISE_LEVEL = 30.0
THIN_KEEP = 0.05
ROOT_PX, LENGTH_PX = (150.0, 240.0), 300.0
TAU_OVER_T = 5e-3
KINEMATICS_SEEDS = (2, 11, 5, 26, 9, 15)
"""The first kinematics seeds (2A/L 0.27, 0.15, 0.48, 0.59, 0.92, 0.99); more continue from 27."""


def kinematics_seeds(n: int) -> tuple[int, ...]:
    """The first ``n`` kinematics seeds."""
    extra = tuple(range(27, 27 + max(0, n - len(KINEMATICS_SEEDS))))
    return (KINEMATICS_SEEDS + extra)[:n]


@dataclass(frozen=True)
class RunSpec:
    """One tracking run.

    Attributes:
        case: one of ``verdicts.CASES`` (not ``still``).
        group: the figure it counts in: ``clean``, ``clean_paper``, ``acq``, ``noise``,
            ``weak_thinned``, ``weak_slow``.
        generator, seed, periods: the recording (:mod:`verdict_recordings`).
        change: ``none``, ``noise`` (f_snr/f = 30) or ``thin`` (5 % kept).
        start: ``truth`` (on the flag), ``rest`` (straight on the rest line), ``+90`` / ``-90`` (the
            truth turned by that about the root), ``across`` (straight, 90 degrees off the rest line).
        method: ``robust`` or ``paper``.
    """

    case: str
    group: str
    generator: str
    seed: int
    periods: float
    change: str = "none"
    start: str = "truth"
    method: str = "robust"

    @property
    def key(self) -> str:
        """The recording's cache key."""
        return recordings.recording_key(self.generator, self.seed, self.periods)

    @property
    def name(self) -> str:
        """A short label (``acq esim_2_5p from +90``)."""
        change = "" if self.change == "none" else f" {self.change}"
        method = "" if self.method == "robust" else f" ({self.method})"
        return f"{self.case} {self.key}{change} from {self.start}{method}"


def plan(cases: tuple[str, ...], seeds: tuple[int, ...], periods: float) -> list[RunSpec]:
    """The runs of ``cases`` over ``seeds``."""
    runs: list[RunSpec] = []
    for seed in seeds:
        esim: dict[str, Any] = {"generator": "esim", "seed": seed, "periods": periods}
        if "clean" in cases:
            runs += [RunSpec("clean", "clean", **esim), RunSpec("clean", "clean_paper", **esim, method="paper")]
        if "acq" in cases:
            runs += [RunSpec("acq", "acq", **esim, start=start) for start in ("+90", "-90", "across")]
        if "noise" in cases:
            runs.append(RunSpec("noise", "noise", **esim, change="noise"))
        if "weak" in cases:
            slow = {**esim, "generator": "slow"}
            runs += [RunSpec("weak", "weak_thinned", **esim, change="thin", start=s) for s in ("truth", "rest")]
            runs += [RunSpec("weak", "weak_slow", **slow, start=s) for s in ("truth", "rest")]
    return runs


def _initial_state(spec: RunSpec, recording: recordings.Recording) -> Any:
    from flagtrack.daemon.core.chain import ChainState

    if spec.start == "rest":
        return None
    truth = recording.truth_start()
    if spec.start == "truth":
        return truth
    if spec.start == "across":
        return ChainState(np.full(len(truth.angles_rad), np.deg2rad(90.0)))
    return ChainState(np.asarray(truth.angles_rad) + np.deg2rad(float(spec.start)))


def _events(spec: RunSpec, recording: recordings.Recording) -> np.ndarray:
    if spec.change == "noise":
        return recordings.with_noise(recording.events, NOISE_LEVEL, spec.seed)
    if spec.change == "thin":
        return recordings.thinned(recording.events, THIN_KEEP, spec.seed)
    return recording.events


def track(spec: RunSpec, recording: recordings.Recording) -> Any:
    """Track the run's events with the public tracking set-up; return the centrelines."""
    from flagtrack.daemon.core.centreline import CentrelineBatch
    from flagtrack.daemon.core.tracker import Tracker
    from flagtrack.daemon.tracking.section import Method, TrackingConfig
    from flagtrack.daemon.tracking.setup import tracking_setup

    config = TrackingConfig(
        root=ROOT_PX,
        length=LENGTH_PX,
        tau_s=TAU_OVER_T / recording.frequency_hz,
        method=Method(spec.method),
    )
    setup = tracking_setup(config)
    tracker = Tracker(setup.params, _initial_state(spec, recording), setup.mapping, recordings.SENSOR_SIZE)
    return CentrelineBatch.concatenate([tracker.feed(_events(spec, recording)), tracker.finish()])


def score(spec: RunSpec, recording: recordings.Recording, centrelines: Any) -> dict[str, Any]:
    """The run's figures: updates, off the flag, found while off, lost, stale."""
    from flagtrack.daemon.core.metrics import eps_rms

    t_s, eps = eps_rms(centrelines, recording.truth)
    keep = np.isin(centrelines.t_s, t_s)
    lost = np.asarray(centrelines.lost, bool)[keep]
    stale = np.asarray(getattr(centrelines, "stale", np.zeros(len(centrelines.t_s))), bool)[keep]
    eps_over_l = eps / LENGTH_PX
    off = eps_over_l > OFF_OVER_L
    return {
        **asdict(spec),
        "name": spec.name,
        "peak_to_peak_over_l": recording.peak_to_peak_over_l,
        "updates": int(len(eps)),
        "off": int(off.sum()),
        "found_off": int((off & ~lost & ~stale).sum()),
        "lost": int(lost.sum()),
        "stale": int(stale.sum()),
        "lost_or_stale": int((lost | stale).sum()),
        "eps_max_over_l": float(eps_over_l.max()),
        "eps_median_over_l": float(np.median(eps_over_l)),
    }


def run_one(spec: RunSpec, folder: Path) -> dict[str, Any]:
    """Load the run's recording from ``folder``, track it, score it (a process pool's task)."""
    recording = recordings.load(folder, spec.key)
    if recording is None:
        raise FileNotFoundError(recordings.cache_path(folder, spec.key))
    return score(spec, recording, track(spec, recording))


def _share(part: int, whole: int) -> float | None:
    return part / whole if whole else None


def summarise(rows: list[dict[str, Any]], key: str, values: tuple[str, ...]) -> dict[str, Any]:
    """Totals and shares of the rows whose ``key`` is in ``values``."""
    chosen = [row for row in rows if row[key] in values]
    totals = {name: sum(row[name] for row in chosen) for name in ("updates", "off", "found_off", "lost_or_stale")}
    found_shares = [row["found_off"] / row["off"] for row in chosen if row["off"]]
    bad_shares = [row["lost_or_stale"] / row["updates"] for row in chosen if row["updates"]]
    return {
        "runs": len(chosen),
        **totals,
        "found_while_off": _share(totals["found_off"], totals["off"]),
        "found_while_off_range": [min(found_shares), max(found_shares)] if found_shares else None,
        "lost_or_stale_share": _share(totals["lost_or_stale"], totals["updates"]),
        "lost_or_stale_range": [min(bad_shares), max(bad_shares)] if bad_shares else None,
        "eps_max_over_l": max((row["eps_max_over_l"] for row in chosen), default=None),
    }
