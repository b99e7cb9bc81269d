"""The ``still`` case of ``flagtrack bench verdicts``: the demo's twin, still before and after flapping.

The simulated camera of ``flagtrack demo`` (0.6 events/px^2, 5 kHz of background, onset 4.9 and
decay 4.4 m/s, the flag at rest moving by ``still_amp_over_l``) is fast-forwarded through a speed
profile, one point after the other, and tracked as the demo's tracker does (tau = 1 ms, fed packet
by packet). Each point's figure is e/L RMS, the lateral error where the beam of the demo's sensor
(x/L = 0.73) crosses the chain, against the twin's true flag, after the point has settled.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon.bench.verdict_recordings import CACHE_VERSION, SENSOR_SIZE

ROOT_PX, LENGTH_PX, BEAM_X_OVER_L = (150.0, 240.0), 300.0, 0.73
TAU_S = 0.001
TRUTH_RATE_HZ = 10_000.0
SLICE_US = 4000
STILL_GAP_OVER_L = 0.0005
"""Target: e/L RMS of the still flag coming down within 0.05 % of L of the one going up."""


@dataclass(frozen=True)
class Profile:
    """Speed points (name, m/s, kind: ``still_up``, ``flapping``, ``still_down``), each ``point_s``
    long, scored after ``settle_s``."""

    name: str
    points: tuple[tuple[str, float, str], ...]
    point_s: float
    settle_s: float


PROFILES = {
    "full": Profile(
        "full",
        (
            ("4.0 up", 4.0, "still_up"),
            ("4.5 up", 4.5, "still_up"),
            ("5.5", 5.5, "flapping"),
            ("4.5 down", 4.5, "flapping"),
            ("4.25 down", 4.25, "still_down"),
            ("4.0 down", 4.0, "still_down"),
        ),
        3.5,
        1.5,
    ),
    "quick": Profile(
        "quick", (("4.0 up", 4.0, "still_up"), ("5.5", 5.5, "flapping"), ("4.0 down", 4.0, "still_down")), 2.5, 1.5
    ),
}


def _cache_path(folder: Path, profile: Profile, seed: int) -> Path:
    return folder / f"verdicts_v{CACHE_VERSION}_twin_{seed}_{profile.name}.npz"


def generate(folder: Path, profile: Profile, seed: int) -> Path:
    """Fast-forward the twin through ``profile`` into ``folder`` (once): its events, the end of each
    packet, and the true flag's lateral position at the beam."""
    path = _cache_path(folder, profile, seed)
    if path.is_file():
        return path
    from flagtrack.drivers.camera.simulated import SimulatedCamera, SimulatedCameraConfig, fast_forward
    from flagtrack.drivers.sim.flutter import FlutterParams

    speed = {"mps": profile.points[0][1]}
    config = SimulatedCameraConfig(
        events_per_px2=0.6,
        noise_rate_hz=5000,
        slice_us=SLICE_US,
        seed=seed,
        truth_keep_s=len(profile.points) * profile.point_s + 1.0,
        flutter=FlutterParams(onset_speed_mps=4.9, decay_speed_mps=4.4, tau_amp_s=0.3),
    )
    camera = SimulatedCamera(config, lambda: speed["mps"])
    chunks: list[np.ndarray] = []
    for _, mps, _ in profile.points:
        speed["mps"] = mps
        chunks += fast_forward(camera, profile.point_s)
    _save(path, chunks, camera.truth)
    return path


def _save(path: Path, chunks: list[np.ndarray], truth: Any) -> None:
    """The packets, the end of each, and the true flag at the beam at ``TRUTH_RATE_HZ`` (atomically)."""
    ends_us = SLICE_US * np.arange(1, len(chunks) + 1, dtype=np.int64)
    truth_t_us = np.arange(0, int(ends_us[-1]) + 1, 1e6 / TRUTH_RATE_HZ)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.name}.{os.getpid()}.partial")
    with open(partial, "wb") as out:
        np.savez(
            out,
            events=np.concatenate(chunks),
            sizes=np.array([len(c) for c in chunks], np.int64),
            ends_us=ends_us,
            truth_t_us=truth_t_us,
            truth_lateral=_true_lateral(truth, truth_t_us),
        )
    os.replace(partial, path)


def _true_lateral(truth: Any, t_us: np.ndarray) -> np.ndarray:
    from flagtrack.daemon.core.pointsensor import beam_lateral

    s = np.linspace(0.0, LENGTH_PX, 51)
    out = np.empty(len(t_us))
    for first in range(0, len(t_us), 20_000):
        x, y = truth.positions(t_us[first : first + 20_000], s)
        out[first : first + 20_000] = beam_lateral(x, y, ROOT_PX, 0.0, BEAM_X_OVER_L * LENGTH_PX)
    return out


def _track(path: Path) -> tuple[Any, np.ndarray]:
    """The demo tracker's centrelines over the cached twin, and the beam error of each (px)."""
    from flagtrack.daemon.core.centreline import CentrelineBatch
    from flagtrack.daemon.core.pointsensor import beam_lateral
    from flagtrack.daemon.tracking.section import TrackingConfig
    from flagtrack.daemon.tracking.setup import tracking_setup

    with np.load(path) as data:
        events, sizes, ends_us = data["events"], data["sizes"], data["ends_us"]
        truth_t_us, truth_lateral = data["truth_t_us"], data["truth_lateral"]
    setup = tracking_setup(TrackingConfig(root=ROOT_PX, length=LENGTH_PX, direction_deg=0.0, tau_s=TAU_S))
    tracker = setup.new_tracker(SENSOR_SIZE)
    bounds = np.concatenate([[0], np.cumsum(sizes)])
    batches = [tracker.feed(events[bounds[k] : bounds[k + 1]], int(ends_us[k])) for k in range(len(sizes))]
    batches.append(tracker.finish())
    centrelines = CentrelineBatch.concatenate([b for b in batches if len(b.t_s)])
    lateral = beam_lateral(centrelines.x, centrelines.y, ROOT_PX, 0.0, BEAM_X_OVER_L * LENGTH_PX)
    return centrelines, lateral - np.interp(centrelines.t_s * 1e6, truth_t_us, truth_lateral)


def _rms_over_l(error: np.ndarray) -> float | None:
    return float(np.sqrt(np.nanmean(error**2)) / LENGTH_PX) if np.isfinite(error).any() else None


def evaluate(folder: Path, profile_name: str = "full", seed: int = 0) -> dict[str, Any]:
    """Generate (once) and track the twin through the profile; return the still figures."""
    profile = PROFILES[profile_name]
    centrelines, error = _track(generate(folder, profile, seed))
    t_s = centrelines.t_s
    stale = np.asarray(getattr(centrelines, "stale", np.zeros(len(t_s))), bool)
    lost = np.asarray(centrelines.lost, bool)
    points = []
    settled: dict[str, np.ndarray] = {}
    for k, (name, mps, kind) in enumerate(profile.points):
        rows = (t_s >= k * profile.point_s + profile.settle_s) & (t_s < (k + 1) * profile.point_s)
        settled[kind] = settled.get(kind, np.zeros(len(t_s), bool)) | rows
        points.append(
            {
                "point": name,
                "speed_mps": mps,
                "kind": kind,
                "updates": int(rows.sum()),
                "e_over_l_rms": _rms_over_l(error[rows]),
                "tip_spread_over_l": float(np.std(centrelines.y[rows, -1]) / LENGTH_PX) if rows.any() else None,
                "lost_share": float(lost[rows].mean()) if rows.any() else None,
                "stale_share": float(stale[rows].mean()) if rows.any() else None,
            }
        )
    up, down = (_rms_over_l(error[settled.get(kind, np.zeros(len(t_s), bool))]) for kind in ("still_up", "still_down"))
    gap = None if up is None or down is None else down - up
    return {
        "profile": profile.name,
        "seed": seed,
        "points": points,
        "still_up_e_over_l_rms": up,
        "still_down_e_over_l_rms": down,
        "gap_over_l": gap,
        "target_gap_over_l": STILL_GAP_OVER_L,
        "within_target": gap is not None and abs(gap) <= STILL_GAP_OVER_L,
    }
