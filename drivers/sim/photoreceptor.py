"""A second, independent event generator: a sensor whose photoreceptor is slow.

Unlike the event-camera simulator (:mod:`~flagtrack.drivers.sim.dvs`, which thresholds the log
intensity itself), each pixel here thresholds a first-order low-pass of its log intensity (time
constant ``tau_us``): a photoreceptor too slow for the line, as in dim light. Its events are few
(about 5 % of an ideal pixel's at 20 ms) and trail the line. The line is rendered its own way too:
a Gaussian ridge along the flag, brute force over the pixels of the flag's envelope, at a fixed
time step. Pure: arrays in, events out (``EVENT_DTYPE``, time order), seeded.

Pixels the line has left, whose filtered level can no longer reach a threshold, are skipped and
caught up exactly (an exponential decay) when the line comes back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flagtrack.daemon.core.events import EVENT_DTYPE
from flagtrack.daemon.core.jit import njit
from flagtrack.drivers.sim.dvs import grow_buffers
from flagtrack.drivers.sim.quickline import LineKinematics

_BLOCK_STEPS = 512  # time steps whose line positions are computed at once


@dataclass(frozen=True)
class PhotoreceptorParams:
    """The slow sensor and the line it sees.

    Attributes:
        tau_us: photoreceptor time constant, µs (0: an instantaneous photoreceptor).
        step_us: simulation time step, µs (events are spread uniformly within it).
        line_sigma_px: Gaussian half-width of the line across it, pixels.
        background: intensity around the line (the line's crest adds 1).
        contrast: mean threshold C on the filtered log intensity (both polarities).
        sigma_contrast: pixel-to-pixel standard deviation of C (C is kept >= 0.1).
        n_s: samples of the line along the flag.
        margin_px: pixels simulated beyond the flag's envelope.
    """

    tau_us: float = 20_000.0
    step_us: float = 10.0
    line_sigma_px: float = 1.0
    background: float = 0.15
    contrast: float = 0.3
    sigma_contrast: float = 0.03
    n_s: int = 160
    margin_px: int = 8

    def __post_init__(self) -> None:
        if not (math.isfinite(self.tau_us) and self.tau_us >= 0):
            raise ValueError("PhotoreceptorParams.tau_us must be finite and >= 0")
        for name in ("step_us", "line_sigma_px", "background", "contrast"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"PhotoreceptorParams.{name} must be finite and > 0")
        if self.sigma_contrast < 0 or self.n_s < 2 or self.margin_px < 0:
            raise ValueError("PhotoreceptorParams: sigma_contrast >= 0, n_s >= 2, margin_px >= 0")


@dataclass(frozen=True)
class _Box:
    """The simulated pixels: columns x0..x0+w-1, rows y0..y0+h-1 of the sensor."""

    x0: int
    y0: int
    w: int
    h: int


def _envelope(kin: LineKinematics, duration_s: float, width: int, height: int, margin: int, n_s: int) -> _Box:
    """The sensor pixels the flag can reach during the recording, plus ``margin``."""
    t_s = np.linspace(0.0, duration_s, 401)
    x, y = kin.positions(t_s, np.linspace(0.0, kin.length, n_s))
    x0, x1 = max(0, int(np.floor(x.min())) - margin), min(width - 1, int(np.ceil(x.max())) + margin)
    y0, y1 = max(0, int(np.floor(y.min())) - margin), min(height - 1, int(np.ceil(y.max())) + margin)
    if x1 < x0 or y1 < y0:
        raise ValueError("the flag never crosses the sensor")
    return _Box(x0, y0, x1 - x0 + 1, y1 - y0 + 1)


@dataclass(frozen=True)
class _PixelState:
    """Per-pixel arrays of the box (the kernel updates them in place).

    ``lists`` rows: pixels touched by the line at this step, at the previous one, pending (may still
    fire at the background level), the next pending; ``counts``: the fill of the first three."""

    acc: np.ndarray
    level: np.ndarray
    ref: np.ndarray
    contrast: np.ndarray
    last: np.ndarray
    stamp: np.ndarray
    lists: np.ndarray
    counts: np.ndarray

    @classmethod
    def at_rest(cls, n_px: int, params: PhotoreceptorParams, rng: np.random.Generator) -> _PixelState:
        """Every pixel settled on the background; thresholds drawn from ``rng``."""
        u_bg = math.log(params.background + 1e-3)
        return cls(
            acc=np.zeros(n_px),
            level=np.full(n_px, u_bg),
            ref=np.full(n_px, u_bg),
            contrast=np.maximum(rng.normal(params.contrast, params.sigma_contrast, n_px), 0.1),
            last=np.zeros(n_px, np.int64),
            stamp=np.full(n_px, -1, np.int64),
            lists=np.empty((4, n_px), np.int64),
            counts=np.zeros(3, np.int64),
        )

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The arrays in the kernel's order."""
        return (self.acc, self.level, self.ref, self.contrast, self.last, self.stamp, self.lists, self.counts)


def slow_photoreceptor_events(
    kin: LineKinematics,
    duration_s: float,
    width: int = 640,
    height: int = 480,
    params: PhotoreceptorParams = PhotoreceptorParams(),
    seed: int = 0,
) -> np.ndarray:
    """The events of ``kin`` over ``[0, duration_s)`` seen by the slow sensor (``EVENT_DTYPE``, time order)."""
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError("duration_s must be finite and > 0")
    box = _envelope(kin, duration_s, width, height, params.margin_px, params.n_s)
    rng = np.random.default_rng(seed)
    state = _PixelState.at_rest(box.w * box.h, params, rng)
    jitter = rng.random(100_003)
    gain = 1.0 - math.exp(-params.step_us / params.tau_us) if params.tau_us > 0 else 1.0
    s = np.linspace(0.0, kin.length, params.n_s)
    n_steps = int(math.ceil(duration_s * 1e6 / params.step_us))
    out_t, out_i, out_p, n_out = np.empty(1 << 16), np.empty(1 << 16, np.int64), np.empty(1 << 16, np.uint8), 0
    for first in range(0, n_steps, _BLOCK_STEPS):
        steps = np.arange(first, min(first + _BLOCK_STEPS, n_steps))
        x, y = kin.positions(steps * params.step_us * 1e-6, s)
        x, y = np.ascontiguousarray(x - box.x0), np.ascontiguousarray(y - box.y0)
        line = (box.w, box.h, params.line_sigma_px, params.step_us, params.background, gain)
        out_t, out_i, out_p, n_out = _run_steps(x, y, first, *line, *state.arrays(), jitter, out_t, out_i, out_p, n_out)
    return _to_events(out_t[:n_out], out_i[:n_out], out_p[:n_out], box)


def _to_events(t_us: np.ndarray, index: np.ndarray, polarity: np.ndarray, box: _Box) -> np.ndarray:
    order = np.argsort(t_us, kind="stable")
    events = np.empty(len(order), dtype=EVENT_DTYPE)
    events["t"] = np.floor(t_us[order]).astype(np.int64)
    events["x"] = index[order] % box.w + box.x0
    events["y"] = index[order] // box.w + box.y0
    events["p"] = polarity[order]
    return events


@njit(cache=True)
def _splat(u, v, w, h, sigma, acc, touched):
    """Add the polyline (u, v), in box pixels, to ``acc`` as a Gaussian ridge of crest 1 across it;
    write the pixels it lights first into ``touched``; return their count."""
    r = 3.5 * sigma
    inv = 0.5 / (sigma * sigma)
    norm = 1.0 / (math.sqrt(2.0 * math.pi) * sigma)
    gx = np.empty(int(2.0 * r) + 3)
    n = 0
    for k in range(len(u) - 1):
        du, dv = u[k + 1] - u[k], v[k + 1] - v[k]
        seg = math.sqrt(du * du + dv * dv)
        parts = max(1, int(math.ceil(seg / sigma)))
        weight = seg / parts * norm
        for q in range(parts):
            f = (q + 0.5) / parts
            pu, pv = u[k] + f * du, v[k] + f * dv
            xa, xb = max(0, int(math.ceil(pu - r))), min(w - 1, int(math.floor(pu + r)))
            ya, yb = max(0, int(math.ceil(pv - r))), min(h - 1, int(math.floor(pv + r)))
            for xx in range(xa, xb + 1):
                gx[xx - xa] = math.exp(-((xx - pu) ** 2) * inv)
            for yy in range(ya, yb + 1):
                gy = weight * math.exp(-((yy - pv) ** 2) * inv)
                for xx in range(xa, xb + 1):
                    p = yy * w + xx
                    if acc[p] == 0.0:
                        touched[n] = p
                        n += 1
                    acc[p] += gy * gx[xx - xa]
    return n


@njit(cache=True)
def _run_steps(
    u,
    v,
    first,
    w,
    h,
    sigma,
    step_us,
    bg,
    gain,
    acc,
    level,
    ref,
    contrast,
    last,
    stamp,
    lists,
    counts,
    jitter,
    out_t,
    out_i,
    out_p,
    n_out,
):
    """Advance the pixels through the steps ``first, first + 1, ...`` (one row of ``u``, ``v`` each).

    A pixel is updated at a step when the line lights it now or lit it at the step before, or when
    its filtered level may still cross a threshold; any other pixel's level only decays towards the
    background, which is applied in one go when it is next updated. Returns the event buffers and fill.
    """
    u_bg = math.log(bg + 1e-3)
    decay = 1.0 - gain
    for row in range(u.shape[0]):
        k = first + row
        n_prev, n_pending = counts[1], counts[2]
        n_touched = _splat(u[row], v[row], w, h, sigma, acc, lists[0])
        n_next = 0
        for part in range(3):
            count = n_touched if part == 0 else (n_prev if part == 1 else n_pending)
            for j in range(count):
                p = lists[part, j]
                if stamp[p] == k:
                    continue
                stamp[p] = k
                if k - 1 > last[p]:  # idle since: decayed towards the background
                    level[p] = u_bg + (level[p] - u_bg) * decay ** (k - 1 - last[p])
                last[p] = k
                target = math.log(bg + acc[p] + 1e-3) if acc[p] != 0.0 else u_bg
                level[p] += (target - level[p]) * gain
                d = level[p] - ref[p]
                c = contrast[p]
                if abs(d) >= c:
                    need = n_out + int(abs(d) / c) + 2
                    if need > len(out_t):
                        out_t, out_i, out_p = grow_buffers(out_t, out_i, out_p, n_out, need)
                    while d >= c or d <= -c:
                        out_t[n_out] = k * step_us + jitter[(n_out * 7919) % len(jitter)] * step_us
                        out_i[n_out] = p
                        out_p[n_out] = 1 if d > 0 else 0
                        ref[p] += c if d > 0 else -c
                        d = level[p] - ref[p]
                        n_out += 1
                if acc[p] == 0.0 and abs(u_bg - ref[p]) > c + 1e-9:  # at exactly C, only in infinite time
                    lists[3, n_next] = p
                    n_next += 1
        for j in range(n_touched):  # the line moves on: this step's pixels are the previous ones
            p = lists[0, j]
            acc[p] = 0.0
            lists[1, j] = p
        for j in range(n_next):
            lists[2, j] = lists[3, j]
        counts[1], counts[2] = n_touched, n_next
    return out_t, out_i, out_p, n_out
