"""Sensor defects applied to a quickline event stream, and the test recordings of the tracker.

Small pure functions (seeded generators, no global state) that make a clean synthetic stream look
like a real sensor's: hot pixels firing on their own at kHz rates (placed where the line sweeps, so
that they fall in the tracker's search areas), a per-pixel spread of the contrast threshold (a
per-pixel keep probability), a refractory period, timestamp jitter and uniform background events.
Also the kinematics, initial chains and error measures the tracker tests share (a rigid rotation,
tip and shape errors), kept here so that tests do not depend on ``daemon/core/metrics.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.chain import ChainState
from flagtrack.daemon.core.events import EVENT_DTYPE
from flagtrack.drivers.sim.quickline import LineKinematics, QuickLineParams, WavyFlag, line_events

WIDTH, HEIGHT = 640, 480


@dataclass(frozen=True)
class Rotation:
    """A straight line of ``length`` rotating rigidly about its root: theta = dir + amp sin(2 pi f t)."""

    length: float = 200.0
    root: tuple[float, float] = (100.0, 240.0)
    direction_deg: float = 0.0
    frequency_hz: float = 20.0
    amp_rad: float = 0.4

    def positions(self, t_s: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        theta = (
            np.deg2rad(self.direction_deg)
            + self.amp_rad
            * np.sin(2 * np.pi * self.frequency_hz * np.atleast_1d(np.asarray(t_s, dtype=np.float64)))[:, None]
        )
        s_row = np.asarray(s, dtype=np.float64)[None, :]
        return self.root[0] + s_row * np.cos(theta), self.root[1] + s_row * np.sin(theta)


KINEMATICS: dict[str, LineKinematics] = {
    "rotation": Rotation(),
    "travelling": WavyFlag(w_travel=1.0),
    "standing": WavyFlag(w_travel=0.0),
    "mixed": WavyFlag(w_travel=0.5, amp_rad=0.7, wavelength_over_l=1.5, frequency_hz=15.0),
}


HOT_RATE_HZ = (1000.0, 5000.0)


def swept_pixels(
    kin: LineKinematics, n_root: int, n_tip: int, rng: np.random.Generator, max_offset_px: float = 3.0
) -> np.ndarray:
    """(n_root + n_tip, 2) int64 pixels (x, y) on and next to the path the line sweeps.

    ``n_root`` pixels near the root (arc length 0.05-0.2 L: inside the search areas of the first
    two links, where the flag hardly moves and real events are few) and ``n_tip`` near the tip
    (0.8-1 L), each where the line passes at a random phase of the flapping, shifted along the
    line's normal by up to ``max_offset_px``. No two are neighbours (isolated hot pixels, as on a
    real sensor: a neighbour's event would let a hot pixel's events through the denoiser).
    """
    period_s = 1.0 / kin.frequency_hz  # type: ignore[attr-defined]
    bands = [(0.05, 0.2)] * n_root + [(0.8, 1.0)] * n_tip
    pixels: list[tuple[int, int]] = []
    for lo, hi in bands:
        while True:
            s = rng.uniform(lo, hi) * kin.length
            x, y = kin.positions(np.array([rng.uniform(0.0, period_s)]), np.array([s - 0.5, s + 0.5]))
            tx, ty = np.diff(x[0])[0], np.diff(y[0])[0]
            shift = rng.uniform(-max_offset_px, max_offset_px) / np.hypot(tx, ty)
            pix = (int(round(x[0].mean() - ty * shift)), int(round(y[0].mean() + tx * shift)))
            if all(max(abs(pix[0] - a), abs(pix[1] - b)) > 1 for a, b in pixels):
                pixels.append(pix)
                break
    return np.array(pixels, dtype=np.int64)


def hot_pixels(
    events: np.ndarray, pixels: np.ndarray, rate_hz: tuple[float, float], rng: np.random.Generator
) -> np.ndarray:
    """Add Poisson trains at ``pixels`` ((n, 2) x, y), each at a rate drawn in ``rate_hz``."""
    t0, t1 = int(events["t"][0]), int(events["t"][-1]) + 1
    parts = [events]
    for x, y in pixels:
        rate = rng.uniform(*rate_hz)
        n = rng.poisson(rate * (t1 - t0) * 1e-6)
        hot = np.empty(n, dtype=EVENT_DTYPE)
        hot["t"] = np.sort(rng.integers(t0, t1, n))
        hot["x"] = x
        hot["y"] = y
        hot["p"] = rng.integers(0, 2, n)
        parts.append(hot)
    merged = np.concatenate(parts)
    return merged[np.argsort(merged["t"], kind="stable")]


def background_noise(
    events: np.ndarray, n: int, rng: np.random.Generator, width: int = WIDTH, height: int = HEIGHT
) -> np.ndarray:
    """Add ``n`` events at uniform random times (over the events' span), pixels and polarities."""
    noise = np.empty(n, dtype=EVENT_DTYPE)
    noise["t"] = rng.integers(int(events["t"][0]), int(events["t"][-1]) + 1, n)
    noise["x"] = rng.integers(0, width, n)
    noise["y"] = rng.integers(0, height, n)
    noise["p"] = rng.integers(0, 2, n)
    merged = np.concatenate([events, noise])
    return merged[np.argsort(merged["t"], kind="stable")]


def threshold_spread(
    events: np.ndarray,
    keep_mean: float,
    keep_sd: float,
    rng: np.random.Generator,
    width: int = WIDTH,
    height: int = HEIGHT,
) -> np.ndarray:
    """Keep each event with its pixel's probability, drawn once per pixel ~ N(keep_mean, keep_sd) in [0, 1]."""
    keep_p = np.clip(rng.normal(keep_mean, keep_sd, (height, width)), 0.0, 1.0)
    p = keep_p[events["y"].astype(np.int64) % height, events["x"].astype(np.int64) % width]
    return events[rng.random(len(events)) < p]


@njit
def _refractory_mask(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, period_us: int, width: int, height: int
) -> np.ndarray:
    last = np.full(width * height, -(1 << 62), dtype=np.int64)
    keep = np.zeros(len(t), dtype=np.bool_)
    for i in range(len(t)):
        pix = (np.int64(y[i]) % height) * width + np.int64(x[i]) % width
        if t[i] - last[pix] >= period_us:
            keep[i] = True
            last[pix] = t[i]
    return keep


def refractory(events: np.ndarray, period_us: int, width: int = WIDTH, height: int = HEIGHT) -> np.ndarray:
    """Drop the events of a pixel that come within ``period_us`` of its previous emitted event."""
    return events[_refractory_mask(events["t"], events["x"], events["y"], period_us, width, height)]


def jitter(events: np.ndarray, sigma_us: float, rng: np.random.Generator) -> np.ndarray:
    """Add N(0, sigma_us) to every timestamp (rounded), then restore time order."""
    out = events.copy()
    out["t"] = np.maximum(out["t"] + np.rint(rng.normal(0.0, sigma_us, len(out))).astype(np.int64), 0)
    return out[np.argsort(out["t"], kind="stable")]


def hot_pixel_positions(name: str, seed: int = 1) -> np.ndarray:
    """(8, 2) the hot pixels of the test recordings of kinematics ``name``: 4 near the root and 4
    near the tip of the path it sweeps (:func:`swept_pixels`), seeded by ``seed`` and the name."""
    return swept_pixels(KINEMATICS[name], 4, 4, np.random.default_rng([seed + 2000, list(KINEMATICS).index(name)]))


def sensor_defects(events: np.ndarray, pixels: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The tests' defective sensor: threshold spread, 100 µs refractory, 30 µs jitter, and hot
    pixels at ``pixels`` firing at 1-5 kHz."""
    events = threshold_spread(events, 0.8, 0.15, rng)
    events = refractory(events, 100)
    events = jitter(events, 30.0, rng)
    return hot_pixels(events, pixels, HOT_RATE_HZ, rng)


CONDITIONS = ("clean", "noisy", "defects", "noisy+defects")


def recording(
    name: str, condition: str, duration_s: float = 0.15, events_per_px2: float = 20.0, seed: int = 1
) -> tuple[LineKinematics, np.ndarray]:
    """A test recording: kinematics ``name`` under ``condition`` (one of :data:`CONDITIONS`).

    ``noisy``: 10 % of the line events dropped and as many uniform noise events as there are
    clean line events; ``defects``: the clean line through :func:`sensor_defects`, with the hot
    pixels of :func:`hot_pixel_positions`;
    ``noisy+defects``: the noisy line (10 % dropped) through the defective sensor, plus as many
    uniform noise events as in ``noisy``.
    """
    if condition not in CONDITIONS:
        raise ValueError(f"unknown condition {condition!r}")
    kin = KINEMATICS[name]
    t1 = int(duration_s * 1e6)
    params = QuickLineParams(events_per_px2=events_per_px2)
    n_clean = 0
    if condition in ("noisy", "noisy+defects"):
        n_clean = sum(len(e) for e in line_events(kin, 0, t1, WIDTH, HEIGHT, params, seed=seed))
        params = QuickLineParams(
            events_per_px2=events_per_px2,
            drop_fraction=0.1,
            noise_rate_hz=n_clean / duration_s if condition == "noisy" else 0.0,
        )
    events = np.concatenate(list(line_events(kin, 0, t1, WIDTH, HEIGHT, params, seed=seed)))
    if condition in ("defects", "noisy+defects"):
        rng = np.random.default_rng(seed + 1000)
        events = sensor_defects(events, hot_pixel_positions(name, seed), rng)
        if condition == "noisy+defects":
            events = background_noise(events, n_clean, rng)
    return kin, events


def initial_state(kin: LineKinematics, t_s: float, n_joints: int = 10) -> ChainState:
    """The chain of the true centreline at ``t_s``: link k along the chord between the true points
    at arc lengths (k - 1) L / N_j and k L / N_j (equal links, as the tracker's default)."""
    x, y = kin.positions(np.array([t_s]), np.linspace(0.0, kin.length, n_joints + 1))
    return ChainState(np.arctan2(np.diff(y[0]), np.diff(x[0])))


def tip_and_shape_errors(batch: CentrelineBatch, kin: LineKinematics) -> tuple[float, float]:
    """(delta_RMS / L, max_t epsilon_RMS / L) of a reconstruction against the true kinematics."""
    length = kin.length
    x_ref, y_ref = kin.positions(batch.t_s, batch.s)
    tip = np.hypot(batch.x[:, -1] - x_ref[:, -1], batch.y[:, -1] - y_ref[:, -1])
    d2 = (batch.x - x_ref) ** 2 + (batch.y - y_ref) ** 2
    eps = np.sqrt(np.trapezoid(d2, batch.s, axis=1) / length)
    return float(np.sqrt(np.mean(tip**2)) / length), float(eps.max() / length)
