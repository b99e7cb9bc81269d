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
from flagtrack.daemon.core.jit import njit


class LineKinematics(Protocol):
    """A moving inextensible line: positions at arc lengths ``s`` and times ``t_s``."""

    @property
    def length(self) -> float:
        """The line's length (read-only, so frozen dataclasses and properties satisfy it)."""
        ...

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
        wave = self.w_travel * np.sin(k * s_row - omega * t) + (1 - self.w_travel) * np.sin(k * s_row) * np.cos(
            omega * t
        )
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
        edges_us = np.unique(
            np.minimum(np.arange(chunk_start, chunk_stop + params.slice_us, params.slice_us), chunk_stop)
        )
        x, y = kinematics.positions(edges_us * 1e-6, s)
        yield _chunk_events(x, y, edges_us.astype(np.float64), ds, width, height, params, rng)


def _chunk_events(
    x: np.ndarray,
    y: np.ndarray,
    edges_us: np.ndarray,
    ds: float,
    width: int,
    height: int,
    params: QuickLineParams,
    rng: np.random.Generator,
) -> np.ndarray:
    """Line and noise events of every slice between consecutive rows of x, y (positions at ``edges_us``)."""
    x0, y0 = x[:-1], y[:-1]
    tx, ty, dx, dy, normal_motion = _slice_geometry(np.ascontiguousarray(x), np.ascontiguousarray(y))
    counts = rng.poisson(np.abs(normal_motion) * ds * params.events_per_px2 * (1.0 - params.drop_fraction))
    noise = (
        rng.poisson(params.noise_rate_hz * np.diff(edges_us) * 1e-6)
        if params.noise_rate_hz > 0
        else np.zeros(len(edges_us) - 1, dtype=np.int64)
    )
    n_line, n_noise = int(counts.sum()), int(noise.sum())
    uniforms = rng.random((3, n_line))
    spread = np.abs(rng.normal(0.0, params.line_width_px, n_line))
    noise_uniforms = rng.random((4, n_noise))
    events = np.empty(n_line + n_noise, dtype=EVENT_DTYPE)
    n = _fill_events(
        x0,
        y0,
        dx,
        dy,
        tx,
        ty,
        normal_motion,
        counts,
        noise,
        edges_us,
        ds,
        width,
        height,
        uniforms,
        spread,
        noise_uniforms,
        events["t"],
        events["x"],
        events["y"],
        events["p"],
    )
    return events[:n]


@njit(cache=True, nogil=True)
def _slice_geometry(x, y):
    """Unit tangent (tx, ty) at the slice starts (rows of x, y but the last; np.gradient along s),
    displacement (dx, dy) to the next row, and its component along the normal (-ty, tx)."""
    n_rows, n_s = x.shape[0] - 1, x.shape[1]
    tx, ty = np.empty((n_rows, n_s)), np.empty((n_rows, n_s))
    dx, dy, normal_motion = np.empty((n_rows, n_s)), np.empty((n_rows, n_s)), np.empty((n_rows, n_s))
    for i in range(n_rows):
        for j in range(n_s):
            lo, hi = max(j - 1, 0), min(j + 1, n_s - 1)
            gx, gy = (x[i, hi] - x[i, lo]) / (hi - lo), (y[i, hi] - y[i, lo]) / (hi - lo)
            norm = np.hypot(gx, gy) + 1e-12
            tx[i, j], ty[i, j] = gx / norm, gy / norm
            dx[i, j], dy[i, j] = x[i + 1, j] - x[i, j], y[i + 1, j] - y[i, j]
            normal_motion[i, j] = dx[i, j] * -ty[i, j] + dy[i, j] * tx[i, j]
    return tx, ty, dx, dy, normal_motion


@njit(cache=True, nogil=True)
def _fill_events(
    x0,
    y0,
    dx,
    dy,
    tx,
    ty,
    normal_motion,
    counts,
    noise,
    edges_us,
    ds,
    width,
    height,
    uniforms,
    spread,
    noise_uniforms,
    out_t,
    out_x,
    out_y,
    out_p,
):
    """Fill the events slice by slice, each slice sorted by time; return how many are on the sensor.

    Line events: one per count of each (slice, sample) cell, at a random time in the slice and a
    random place along the sample's stretch of line, on the leading (ON) or trailing (OFF) edge,
    spread across the line. Noise events: uniform in time, pixel and polarity.
    """
    k = 0  # next output
    u = 0  # next line random draw
    v = 0  # next noise random draw
    n_slices, n_s = counts.shape
    for i in range(n_slices):
        t0, t1 = edges_us[i], edges_us[i + 1]
        first = k
        for j in range(n_s):
            sign = 1.0 if normal_motion[i, j] >= 0 else -1.0
            for _ in range(counts[i, j]):
                frac, along, lead = uniforms[0, u], (uniforms[1, u] - 0.5) * ds, uniforms[2, u] < 0.5
                offset = spread[u] * (1.0 if lead else -1.0) * sign
                u += 1
                rx = np.rint(x0[i, j] + frac * dx[i, j] + along * tx[i, j] - offset * ty[i, j])
                ry = np.rint(y0[i, j] + frac * dy[i, j] + along * ty[i, j] + offset * tx[i, j])
                if rx < 0 or ry < 0 or rx >= width or ry >= height:
                    continue
                out_t[k] = np.int64(np.floor(t0 + frac * (t1 - t0)))
                out_x[k], out_y[k], out_p[k] = np.uint16(rx), np.uint16(ry), 1 if lead else 0
                k += 1
        for _ in range(noise[i]):
            out_t[k] = np.int64(np.floor(t0 + noise_uniforms[0, v] * (t1 - t0)))
            out_x[k] = np.uint16(min(int(noise_uniforms[1, v] * width), width - 1))
            out_y[k] = np.uint16(min(int(noise_uniforms[2, v] * height), height - 1))
            out_p[k] = 1 if noise_uniforms[3, v] < 0.5 else 0
            v += 1
            k += 1
        if k - first > 1:
            order = np.argsort(out_t[first:k], kind="mergesort")
            t_s, x_s, y_s, p_s = (
                out_t[first:k][order],
                out_x[first:k][order],
                out_y[first:k][order],
                out_p[first:k][order],
            )
            out_t[first:k], out_x[first:k], out_y[first:k], out_p[first:k] = t_s, x_s, y_s, p_s
    return k
