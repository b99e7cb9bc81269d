"""A fast generator of event streams from a moving line, for tests and speed benchmarks.

Not a camera model (see the event-camera simulator for that): events are drawn where the line
sweeps across pixels, in proportion to the area it sweeps, ON on its leading edge and OFF on its
trailing edge, with a Gaussian spread across the line. It is exact about where the line is, so
trackers can be tested against the known centreline, and fast enough to make 10^7-event files.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from flagtrack.daemon.core.events import EVENT_DTYPE


class LineKinematics(Protocol):
    """A moving inextensible line: positions at arc lengths ``s`` and times ``t_s``."""

    length: float

    def positions(self, t_s: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return x, y of shape (len(t_s), len(s)) in the events' length unit."""
        ...


@dataclass(frozen=True)
class WavyFlag:
    """Inextensible flag whose tangent angle is a travelling plus a standing wave.

    theta(s, t) = dir + env(s) * [w_travel sin(k s - w t) + (1 - w_travel) sin(k s) cos(w t)],
    env(s) = amp_rad * (0.25 + 0.75 s / L), k = 2 pi / (wavelength_over_l L); x, y are integrals
    of (cos theta, sin theta) ds from the root, so the length is exactly ``length``.
    """

    length: float = 200.0
    root: tuple[float, float] = (100.0, 240.0)
    direction_deg: float = 0.0
    frequency_hz: float = 20.0
    amp_rad: float = 0.5
    wavelength_over_l: float = 2.0
    w_travel: float = 0.8

    def angles(self, t_s: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Tangent angle, radians, shape (len(t_s), len(s))."""
        t = np.asarray(t_s, dtype=np.float64)[:, None]
        s_row = np.asarray(s, dtype=np.float64)[None, :]
        k = 2 * np.pi / (self.wavelength_over_l * self.length)
        omega = 2 * np.pi * self.frequency_hz
        env = self.amp_rad * (0.25 + 0.75 * s_row / self.length)
        wave = self.w_travel * np.sin(k * s_row - omega * t) + (1 - self.w_travel) * np.sin(k * s_row) * np.cos(omega * t)
        return np.deg2rad(self.direction_deg) + env * wave

    def positions(self, t_s: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """x, y at arc lengths ``s`` (sorted, starting at 0 for exactness) and times ``t_s``."""
        s = np.asarray(s, dtype=np.float64)
        fine = np.linspace(0.0, self.length, 401)
        theta = self.angles(np.atleast_1d(t_s), fine)
        ds = np.diff(fine)[None, :]
        dx = 0.5 * (np.cos(theta[:, 1:]) + np.cos(theta[:, :-1])) * ds
        dy = 0.5 * (np.sin(theta[:, 1:]) + np.sin(theta[:, :-1])) * ds
        zero = np.zeros((theta.shape[0], 1))
        x_fine = self.root[0] + np.concatenate([zero, np.cumsum(dx, axis=1)], axis=1)
        y_fine = self.root[1] + np.concatenate([zero, np.cumsum(dy, axis=1)], axis=1)
        pos = np.clip(s / (fine[1] - fine[0]), 0, len(fine) - 1 - 1e-9)
        i0 = pos.astype(np.int64)
        w = pos - i0
        x = x_fine[:, i0] * (1 - w) + x_fine[:, i0 + 1] * w
        y = y_fine[:, i0] * (1 - w) + y_fine[:, i0 + 1] * w
        return x, y


@dataclass(frozen=True)
class QuickLineParams:
    """How events are drawn from the moving line.

    Attributes:
        events_per_px2: events per pixel area swept by the line (sets the event rate).
        line_width_px: standard deviation of the spread across the line, pixels.
        slice_us: time step at which the line is sampled (positions are interpolated within).
        n_s: arc-length samples along the line.
        noise_rate_hz: background events per second over the whole sensor (uniform, random p).
        drop_fraction: fraction of line events removed at random.
    """

    events_per_px2: float = 2.0
    line_width_px: float = 0.8
    slice_us: int = 50
    n_s: int = 200
    noise_rate_hz: float = 0.0
    drop_fraction: float = 0.0


def line_events(
    kinematics: LineKinematics,
    t_start_us: int,
    t_stop_us: int,
    width: int,
    height: int,
    params: QuickLineParams = QuickLineParams(),
    seed: int = 0,
    chunk_us: int = 20_000,
) -> Iterator[np.ndarray]:
    """Yield time-sorted event arrays covering [t_start_us, t_stop_us), one per ``chunk_us``.

    Events outside the sensor are discarded; x, y are the pixel whose centre is nearest.
    """
    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, kinematics.length, params.n_s)
    ds = s[1] - s[0]
    for chunk_start in range(t_start_us, t_stop_us, chunk_us):
        chunk_stop = min(chunk_start + chunk_us, t_stop_us)
        edges_us = np.arange(chunk_start, chunk_stop + params.slice_us, params.slice_us)
        edges_us = np.minimum(edges_us, chunk_stop)
        edges_us = np.unique(edges_us)
        x, y = kinematics.positions(edges_us * 1e-6, s)
        parts = [_slice_events(x, y, edges_us, ds, params, rng)]
        if params.noise_rate_hz > 0:
            parts.append(_noise(chunk_start, chunk_stop, width, height, params.noise_rate_hz, rng))
        events = np.concatenate(parts)
        inside = (events["x"] < width) & (events["y"] < height)
        events = events[inside]
        yield events[np.argsort(events["t"], kind="stable")]


def _slice_events(
    x: np.ndarray, y: np.ndarray, edges_us: np.ndarray, ds: float, params: QuickLineParams, rng: np.random.Generator
) -> np.ndarray:
    """Events for every slice between consecutive rows of x, y (positions at ``edges_us``)."""
    x0, y0, x1, y1 = x[:-1], y[:-1], x[1:], y[1:]
    tx, ty = np.gradient(x0, axis=1), np.gradient(y0, axis=1)
    norm = np.hypot(tx, ty) + 1e-12
    nx, ny = -ty / norm, tx / norm
    swept = np.abs((x1 - x0) * nx + (y1 - y0) * ny) * ds  # px^2 swept per sample, per slice
    counts = rng.poisson(swept * params.events_per_px2 * (1.0 - params.drop_fraction))
    slice_idx, s_idx = np.nonzero(counts)
    reps = counts[slice_idx, s_idx]
    slice_idx, s_idx = np.repeat(slice_idx, reps), np.repeat(s_idx, reps)
    n = len(slice_idx)
    frac = rng.random(n)
    t0, t1 = edges_us[:-1][slice_idx], edges_us[1:][slice_idx]
    along = (rng.random(n) - 0.5) * ds
    px = x0[slice_idx, s_idx] + frac * (x1 - x0)[slice_idx, s_idx] + along * (tx / norm)[slice_idx, s_idx]
    py = y0[slice_idx, s_idx] + frac * (y1 - y0)[slice_idx, s_idx] + along * (ty / norm)[slice_idx, s_idx]
    moving_sign = np.sign(((x1 - x0) * nx + (y1 - y0) * ny)[slice_idx, s_idx])
    leading = rng.random(n) < 0.5  # half the events on each edge of the lit line
    offset = np.abs(rng.normal(0.0, params.line_width_px, n)) * np.where(leading, 1.0, -1.0) * moving_sign
    px += offset * nx[slice_idx, s_idx]
    py += offset * ny[slice_idx, s_idx]
    events = np.empty(n, dtype=EVENT_DTYPE)
    events["t"] = np.floor(t0 + frac * (t1 - t0)).astype(np.int64)
    px_r, py_r = np.rint(px), np.rint(py)
    ok = (px_r >= 0) & (py_r >= 0)
    events["x"] = np.where(ok, px_r, 65535).astype(np.uint16)
    events["y"] = np.where(ok, py_r, 65535).astype(np.uint16)
    events["p"] = leading.astype(np.uint8)
    return events


def _noise(t0: int, t1: int, width: int, height: int, rate_hz: float, rng: np.random.Generator) -> np.ndarray:
    n = rng.poisson(rate_hz * (t1 - t0) * 1e-6)
    events = np.empty(n, dtype=EVENT_DTYPE)
    events["t"] = rng.integers(t0, t1, n)
    events["x"] = rng.integers(0, width, n)
    events["y"] = rng.integers(0, height, n)
    events["p"] = rng.integers(0, 2, n)
    return events
