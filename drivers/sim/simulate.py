"""Simulated recordings on disk: events (EVT 3.0 ``.raw``), ground truth (centreline HDF5), parameters (JSON).

One recording per seed: :func:`simulate_recording`; many on a process pool: :func:`simulate_many`.
A blinking checkerboard for calibration: :func:`simulate_checkerboard`.
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.drivers.formats.centreline import write_centrelines
from flagtrack.drivers.sim.dvs import DvsParams
from flagtrack.drivers.sim.kinematics import FlagKinematics, KinematicsFamily, sample_kinematics
from flagtrack.drivers.sim.optics import PlaneCamera, tilted_pinhole
from flagtrack.drivers.sim.render import LaserLineScene, LineRenderParams
from flagtrack.drivers.sim.scenes import (
    BlinkingPatternScene,
    BlinkParams,
    CheckerboardSpec,
    Scene,
    checkerboard,
    simulate_events,
)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RecordingSpec:
    """Everything that defines one simulated recording (with ``seed``, it is reproducible).

    Attributes:
        seed: draws the kinematics, the pixel thresholds and the noise.
        duration_s: recording length; None draws 3-6 flapping periods from the seed (paper, section 3).
        width, height: sensor size, pixels.
        tilted: look through the paper's tilted pinhole camera (plane in metres) instead of a plain one (px).
        dvs: pixel model parameters.
        line: laser-line look and render step.
        family: kinematics family.
        truth_rate_hz: sampling rate of the ground truth.
        truth_n_s: arc-length samples of the ground truth.
        truth_n_joints: N_j of the truth's joints datasets (truth sampled at N_j + 1 equal steps of s).
        chunk_us: events are generated and written in chunks of this duration.
    """

    seed: int = 0
    duration_s: float | None = None
    width: int = 640
    height: int = 480
    tilted: bool = False
    dvs: DvsParams = DvsParams()
    line: LineRenderParams = LineRenderParams()
    family: KinematicsFamily = field(default_factory=KinematicsFamily)
    truth_rate_hz: float = 5_000.0
    truth_n_s: int = 101
    truth_n_joints: int = 10
    chunk_us: int = 10_000


@dataclass(frozen=True)
class RecordingResult:
    """What :func:`simulate_recording` wrote and how long it took."""

    events_path: str
    truth_path: str
    params_path: str
    n_events: int
    duration_s: float
    wall_s: float

    @property
    def events_per_s(self) -> float:
        """Events generated per second of wall time."""
        return self.n_events / self.wall_s if self.wall_s > 0 else math.inf


def optics_and_kinematics(spec: RecordingSpec) -> tuple[PlaneCamera, FlagKinematics]:
    """The camera and the flag of ``spec``: 300 px flag on a plain camera, or 0.18 m on the tilted one."""
    if spec.tilted:
        optics = tilted_pinhole(spec.width, spec.height)
        return optics, sample_kinematics(spec.seed, spec.family, length=0.18, root=(0.0, 0.0))
    scale = min(spec.width / 640, spec.height / 480)
    optics = PlaneCamera(centre_px=(spec.width / 2 - 0.5, spec.height / 2 - 0.5))
    kin = sample_kinematics(spec.seed, spec.family, length=300.0 * scale, root=(150.0 * scale, spec.height / 2))
    return optics, kin


def recording_duration_s(spec: RecordingSpec, kin: FlagKinematics) -> float:
    """``spec.duration_s`` or 3-6 periods drawn from the seed."""
    if spec.duration_s is not None:
        return float(spec.duration_s)
    periods = np.random.default_rng([spec.seed, 1]).uniform(3.0, 6.0)
    return float(periods / kin.frequency_hz)


def truth_batch(kin: FlagKinematics, duration_s: float, rate_hz: float, n_s: int, n_joints: int) -> CentrelineBatch:
    """Ground truth sampled at ``rate_hz`` over [0, duration_s]."""
    t_s = np.arange(0.0, duration_s + 0.5 / rate_hz, 1.0 / rate_hz)
    s = np.linspace(0.0, kin.length, n_s)
    x, y = kin.positions(t_s, s)
    jx, jy = kin.positions(t_s, np.linspace(0.0, kin.length, n_joints + 1))
    return CentrelineBatch(
        t_s=t_s,
        s=s,
        x=x,
        y=y,
        joints_x=jx,
        joints_y=jy,
        delta_rms=np.full(len(t_s), np.nan),
        n_events=np.zeros(len(t_s), np.int64),
    )


def write_events_file(path: Path, chunks: Iterable[np.ndarray], width: int, height: int) -> tuple[Path, int]:
    """Write ``chunks`` as EVT 3.0 ``.raw`` whose header says flagtrack simulated it."""
    from flagtrack.drivers.formats.raw_file import RawWriter

    n = 0
    path = path.with_suffix(".raw")
    with RawWriter(path, width=width, height=height, encoding="evt3", simulated=True) as writer:
        for chunk in chunks:
            writer.write(chunk)
            n += len(chunk)
    return path, n


def simulate_recording(spec: RecordingSpec, out_dir: str | Path, name: str | None = None) -> RecordingResult:
    """Simulate one recording into ``out_dir``: ``NAME.raw``, ``NAME_truth.h5``, ``NAME.json``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    name = name or f"sim_{spec.seed:05d}"
    optics, kin = optics_and_kinematics(spec)
    duration_s = recording_duration_s(spec, kin)
    t_stop_us = int(round(duration_s * 1e6))
    scene = LaserLineScene(kin, optics, spec.width, spec.height, spec.line)
    start = time.perf_counter()
    chunks = simulate_events(scene, 0, t_stop_us, spec.dvs, seed=spec.seed, chunk_us=spec.chunk_us)
    events_path, n_events = write_events_file(out / name, chunks, spec.width, spec.height)
    wall_s = time.perf_counter() - start
    attrs = recording_attrs(spec, kin, optics, duration_s, events_path, n_events)
    truth_path = out / f"{name}_truth.h5"
    truth = truth_batch(kin, duration_s, spec.truth_rate_hz, spec.truth_n_s, spec.truth_n_joints)
    write_centrelines(truth_path, truth, attrs)
    params_path = out / f"{name}.json"
    params_path.write_text(json.dumps({**attrs, "wall_s": wall_s, "step_us": scene.step_us}, indent=2) + "\n")
    log.info("%s: %d events in %.2f s (%.0f events/s)", name, n_events, wall_s, n_events / max(wall_s, 1e-9))
    return RecordingResult(str(events_path), str(truth_path), str(params_path), n_events, duration_s, wall_s)


def recording_attrs(
    spec: RecordingSpec, kin: FlagKinematics, optics: PlaneCamera, duration_s: float, events_path: Path, n_events: int
) -> dict[str, Any]:
    """Root attributes of the truth file: every parameter, with units."""
    attrs: dict[str, Any] = {
        "source": "flagtrack simulate (ground truth)",
        "units": optics.units,
        "length": kin.length,
        "time_unit": "s",
        "seed": spec.seed,
        "duration_s": duration_s,
        "width": spec.width,
        "height": spec.height,
        "events_file": Path(events_path).name,
        "n_events_file": n_events,
        "peak_to_peak_over_l": kin.peak_to_peak_over_l(),
        "tilted": spec.tilted,
        "truth_rate_hz": spec.truth_rate_hz,
        "n_joints": spec.truth_n_joints,
        "kinematics": kin.to_attrs(),
        "optics": optics.to_attrs(),
        "dvs": spec.dvs.to_attrs(),
        "line": spec.line.to_attrs(),
    }
    for key, value in kin.to_attrs().items():
        attrs[f"kin_{key}"] = value
    for key, value in spec.dvs.to_attrs().items():
        attrs[f"dvs_{key}"] = value
    return attrs


def _run_one(args: tuple[RecordingSpec, str]) -> RecordingResult:
    spec, out_dir = args
    return simulate_recording(spec, out_dir)


def simulate_many(specs: Sequence[RecordingSpec], out_dir: str | Path, jobs: int = 1) -> Iterator[RecordingResult]:
    """Simulate ``specs`` into ``out_dir`` on ``jobs`` processes; yield results as they finish (in order)."""
    if jobs <= 1 or len(specs) <= 1:
        for spec in specs:
            yield simulate_recording(spec, out_dir)
        return
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        yield from pool.map(_run_one, [(spec, str(out_dir)) for spec in specs])


def simulate_checkerboard(
    out_dir: str | Path,
    spec: CheckerboardSpec = CheckerboardSpec(),
    blink: BlinkParams = BlinkParams(),
    n_periods: int = 3,
    width: int = 640,
    height: int = 480,
    optics: PlaneCamera | None = None,
    dvs: DvsParams = DvsParams(),
    seed: int = 0,
    name: str = "checkerboard",
) -> RecordingResult:
    """A blinking checkerboard seen by the (default tilted) camera, plus JSON with the true corners.

    The JSON holds the plane corners and their exact pixel positions (``corners_px``), so the
    calibration can be checked against the truth.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    optics = optics or tilted_pinhole(width, height)
    scene: Scene = BlinkingPatternScene(checkerboard(spec), optics, width, height, blink)
    start = time.perf_counter()
    t_stop = n_periods * blink.period_us
    events_path, n_events = write_events_file(out / name, simulate_events(scene, 0, t_stop, dvs, seed), width, height)
    wall_s = time.perf_counter() - start
    corners = spec.corners()
    u, v = optics.project(corners[:, 0], corners[:, 1])
    params = {
        "source": "flagtrack simulate --checkerboard",
        "events_file": events_path.name,
        "n_events": n_events,
        "width": width,
        "height": height,
        "units": optics.units,
        "inner_corners": list(spec.inner_corners),
        "square": spec.square,
        "origin": list(spec.origin),
        "blink": blink.to_attrs(),
        "n_periods": n_periods,
        "optics": optics.to_attrs(),
        "dvs": dvs.to_attrs(),
        "seed": seed,
        "corners_plane": corners.tolist(),
        "corners_px": np.column_stack([u, v]).tolist(),
    }
    params_path = out / f"{name}.json"
    params_path.write_text(json.dumps(params, indent=2) + "\n")
    return RecordingResult(str(events_path), "", str(params_path), n_events, t_stop * 1e-6, wall_s)
