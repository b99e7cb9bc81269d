"""The recordings of ``flagtrack bench verdicts``: made from a kinematics seed, kept in a cache folder.

Two independent generators, one flag each (``sample_kinematics(seed)``: L = 300 px at (150, 240),
640 x 480): the event-camera simulator of ``flagtrack simulate`` (ESIM-like: log-intensity
thresholds, per-pixel contrast spread, refractory period) and the slow-photoreceptor sensor of
:mod:`~flagtrack.drivers.sim.photoreceptor` (a first-order low-pass of the log intensity, 20 ms).
The disturbed variants (shot noise, thinning) are made from the simulator's recording when a run
needs them: they are cheap and seeded.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.chain import ChainState

GENERATORS = ("esim", "slow")
"""``esim``: the event-camera simulator; ``slow``: the slow-photoreceptor sensor."""
SLOW_TAU_US = 20_000.0
"""The slow sensor's photoreceptor time constant: about 5 % of the line's events reach the tracker."""
CACHE_VERSION = 1
"""Part of every cached file's name: bumped when a generator's output changes."""
SENSOR_SIZE = (640, 480)
TRUTH_RATE_HZ = 5_000.0


@dataclass(frozen=True)
class Recording:
    """A generated recording and the flag's true centreline.

    Attributes:
        key: its name in the cache (``esim_2_5p``).
        events: ``EVENT_DTYPE`` events, time order.
        truth: the true centreline at ``TRUTH_RATE_HZ`` (joints of a 10-link chain included).
        frequency_hz: the flag's flapping frequency.
        peak_to_peak_over_l: the flag's tip amplitude 2A/L.
    """

    key: str
    events: np.ndarray
    truth: CentrelineBatch
    frequency_hz: float
    peak_to_peak_over_l: float

    def truth_start(self) -> ChainState:
        """The chain through the truth's first joints (a start on the flag)."""
        jx, jy = self.truth.joints_x[0], self.truth.joints_y[0]
        return ChainState(np.arctan2(np.diff(jy), np.diff(jx)))


def recording_key(generator: str, seed: int, periods: float) -> str:
    """The cache name of a recording (``esim_2_5p``)."""
    if generator not in GENERATORS:
        raise ValueError(f"unknown generator {generator!r} (one of {', '.join(GENERATORS)})")
    return f"{generator}_{seed}_{periods:g}p"


def cache_path(folder: Path, key: str) -> Path:
    """Where ``key`` is kept in ``folder``."""
    return folder / f"verdicts_v{CACHE_VERSION}_{key}.npz"


def generate(generator: str, seed: int, periods: float) -> Recording:
    """Make the recording of ``generator`` for kinematics ``seed``, ``periods`` flapping periods long."""
    from flagtrack.drivers.sim.kinematics import sample_kinematics
    from flagtrack.drivers.sim.simulate import truth_batch

    key = recording_key(generator, seed, periods)
    kin = sample_kinematics(seed)
    duration_s = round(periods / kin.frequency_hz, 3)
    if generator == "esim":
        events = _esim_events(seed, duration_s)
    else:
        from flagtrack.drivers.sim.photoreceptor import PhotoreceptorParams, slow_photoreceptor_events

        params = PhotoreceptorParams(tau_us=SLOW_TAU_US)
        events = slow_photoreceptor_events(kin, duration_s, *SENSOR_SIZE, params=params, seed=seed)
    truth = truth_batch(kin, duration_s, TRUTH_RATE_HZ, 101, 10)
    return Recording(key, events, truth, kin.frequency_hz, kin.peak_to_peak_over_l())


def _esim_events(seed: int, duration_s: float) -> np.ndarray:
    """The simulator's events of ``flagtrack simulate --seed SEED`` (plain camera), in memory."""
    from flagtrack.drivers.sim.render import LaserLineScene
    from flagtrack.drivers.sim.scenes import simulate_events
    from flagtrack.drivers.sim.simulate import RecordingSpec, optics_and_kinematics

    spec = RecordingSpec(seed=seed, duration_s=duration_s, width=SENSOR_SIZE[0], height=SENSOR_SIZE[1])
    optics, kin = optics_and_kinematics(spec)
    scene = LaserLineScene(kin, optics, spec.width, spec.height, spec.line)
    chunks = list(simulate_events(scene, 0, round(duration_s * 1e6), spec.dvs, seed=seed, chunk_us=spec.chunk_us))
    return np.concatenate(chunks)


def save(recording: Recording, folder: Path) -> Path:
    """Write ``recording`` into ``folder`` (atomically: a reader never sees half a file)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = cache_path(folder, recording.key)
    partial = path.with_name(f".{path.name}.{os.getpid()}.partial")
    truth = recording.truth
    with open(partial, "wb") as out:
        np.savez(
            out,
            events=recording.events,
            t_s=truth.t_s,
            s=truth.s,
            x=truth.x,
            y=truth.y,
            joints_x=truth.joints_x,
            joints_y=truth.joints_y,
            frequency_hz=recording.frequency_hz,
            peak_to_peak_over_l=recording.peak_to_peak_over_l,
        )
    os.replace(partial, path)
    return path


def load(folder: Path, key: str) -> Recording | None:
    """The recording ``key`` kept in ``folder``, or None when it is not there."""
    path = cache_path(folder, key)
    if not path.is_file():
        return None
    with np.load(path) as data:
        n_t = len(data["t_s"])
        truth = CentrelineBatch(
            t_s=data["t_s"],
            s=data["s"],
            x=data["x"],
            y=data["y"],
            joints_x=data["joints_x"],
            joints_y=data["joints_y"],
            delta_rms=np.full(n_t, np.nan),
            n_events=np.zeros(n_t, np.int64),
        )
        return Recording(key, data["events"], truth, float(data["frequency_hz"]), float(data["peak_to_peak_over_l"]))


def ensure(folder: Path, generator: str, seed: int, periods: float) -> str:
    """Make the recording into ``folder`` unless it is there; return its key."""
    key = recording_key(generator, seed, periods)
    if not cache_path(folder, key).is_file():
        save(generate(generator, seed, periods), folder)
    return key


def with_noise(events: np.ndarray, level: float, seed: int) -> np.ndarray:
    """``events`` with uniform shot noise at the paper's f_snr/f = ``level`` (N/N0 = 1 + level / 37)."""
    from flagtrack.daemon.bench.accuracy_suite.plan import PAPER_NOISE_PER_LEVEL
    from flagtrack.drivers.sim.disruptions import background

    rng = np.random.default_rng(seed)
    return background(events, int(level * PAPER_NOISE_PER_LEVEL * len(events)), rng, *SENSOR_SIZE)


def thinned(events: np.ndarray, keep: float, seed: int) -> np.ndarray:
    """A random ``keep`` share of ``events`` (a sensor that loses the others)."""
    rng = np.random.default_rng(seed)
    return events[rng.random(len(events)) < keep]
