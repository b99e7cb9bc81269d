"""The laser line on the flag, rendered on the pixel grid and fed to the event-camera model.

The lit centreline is a Gaussian ridge (standard deviation ``line_sigma_px`` across it, peak
``peak``) on a uniform ``background``. It is drawn by splatting Gaussians along the projected
polyline every sigma (the sum is the ridge to ~1e-9), into the pixels within 3.5 sigma only.
Render steps are adaptive so that no point of the line moves more than ``max_step_px`` between two
steps (``step_us`` is the shortest step, at the fastest motion); between steps each pixel's log intensity is linear in time (timestamps interpolated). Only
the pixels the line touches at a step or the step before are processed: the rest of the sensor is
constant and is caught up lazily by the camera.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from flagtrack.daemon.core.jit import njit
from flagtrack.drivers.sim.dvs import EventCamera, advance_pixels
from flagtrack.drivers.sim.kinematics import FlagKinematics
from flagtrack.drivers.sim.optics import PlaneCamera


@dataclass(frozen=True)
class LineRenderParams:
    """How the laser line looks and how finely it is rendered in time.

    Attributes:
        line_sigma_px: standard deviation of the line profile across it, pixels.
        peak: intensity of the line centre above the background (relative units).
        background: intensity of the unlit scene.
        max_step_px: largest motion of any point of the line between two render steps, pixels.
        n_s: arc-length samples of the rendered polyline.
    """

    line_sigma_px: float = 1.0
    peak: float = 1.0
    background: float = 0.15
    max_step_px: float = 0.5
    n_s: int = 129

    def __post_init__(self) -> None:
        if self.line_sigma_px <= 0.2 or self.peak <= 0 or self.background <= 0 or self.max_step_px <= 0:
            raise ValueError(f"invalid LineRenderParams {self}")
        if self.n_s < 2:
            raise ValueError("LineRenderParams.n_s must be >= 2")

    def to_attrs(self) -> dict[str, float]:
        """Parameters as a flat mapping."""
        return asdict(self)


@njit(cache=True)
def splat_line(u, v, sigma, peak, width, height, acc, mark, stamp, touched):
    """Add a Gaussian ridge along polyline (u, v) into ``acc``; return the count of touched pixels.

    A pixel first touched at this ``stamp`` is zeroed, marked and listed in ``touched``.
    """
    radius = 3.5 * sigma  # the ridge is cut at 0.2 % of its peak
    inv_2s2 = 0.5 / (sigma * sigma)
    norm = peak / (math.sqrt(2.0 * math.pi) * sigma)
    spacing = sigma  # ripple of the summed ridge ~ exp(-2 pi^2 sigma^2 / spacing^2) ~ 3e-9
    n_touched = 0
    gx = np.empty(int(2 * radius) + 3)
    gy = np.empty(int(2 * radius) + 3)
    for k in range(len(u) - 1):
        du, dv = u[k + 1] - u[k], v[k + 1] - v[k]
        seg = math.sqrt(du * du + dv * dv)
        n_sub = max(1, int(math.ceil(seg / spacing)))
        w = norm * seg / n_sub
        for j in range(n_sub):
            f = (j + 0.5) / n_sub
            pu, pv = u[k] + f * du, v[k] + f * dv
            x0, x1 = max(0, int(math.ceil(pu - radius))), min(width - 1, int(math.floor(pu + radius)))
            y0, y1 = max(0, int(math.ceil(pv - radius))), min(height - 1, int(math.floor(pv + radius)))
            for xx in range(x0, x1 + 1):  # separable Gaussian: 1-D factors once per splat
                gx[xx - x0] = w * math.exp(-(xx - pu) * (xx - pu) * inv_2s2)
            for yy in range(y0, y1 + 1):
                gy[yy - y0] = math.exp(-(yy - pv) * (yy - pv) * inv_2s2)
            for yy in range(y0, y1 + 1):
                row = yy * width
                fy = gy[yy - y0]
                for xx in range(x0, x1 + 1):
                    p = row + xx
                    if mark[p] != stamp:
                        mark[p] = stamp
                        acc[p] = 0.0
                        touched[n_touched] = p
                        n_touched += 1
                    acc[p] += fy * gx[xx - x0]
    return n_touched


@njit(cache=True)
def line_steps(
    us,
    vs,
    t_steps,
    t_prev,
    sigma,
    peak,
    background,
    log_eps,
    width,
    height,
    acc,
    mark,
    stamp,
    prev,
    n_prev,
    cur,
    scratch_i,
    scratch_l,
    level,
    t_upd,
    ref,
    t_ready,
    c_on,
    c_off,
    leak_slope,
    refractory,
    out_t,
    out_i,
    out_p,
    n_out,
):
    """Render the line at each of ``t_steps`` (rows of us, vs) and advance the touched pixels.

    Returns (stamp, n_prev, out_t, out_i, out_p, n_out); ``prev[:n_prev]`` lists the pixels the
    line touches at the last step. ``scratch_i``/``scratch_l`` are work buffers of n_pix.
    """
    log_bg = math.log(background + log_eps)
    for k in range(len(t_steps)):
        t = t_steps[k]
        stamp += 1
        n_cur = splat_line(us[k], vs[k], sigma, peak, width, height, acc, mark, stamp, cur)
        n_stale = 0
        for j in range(n_cur):  # pixels constant since an earlier step: catch up to the previous step
            p = cur[j]
            if t_upd[p] < t_prev:
                scratch_i[n_stale] = p
                scratch_l[n_stale] = level[p]
                n_stale += 1
        out_t, out_i, out_p, n_out = advance_pixels(
            scratch_i[:n_stale],
            scratch_l[:n_stale],
            t_prev,
            level,
            t_upd,
            ref,
            t_ready,
            c_on,
            c_off,
            leak_slope,
            refractory,
            out_t,
            out_i,
            out_p,
            n_out,
        )
        for j in range(n_cur):
            scratch_l[j] = math.log(background + acc[cur[j]] + log_eps)
        out_t, out_i, out_p, n_out = advance_pixels(
            cur[:n_cur],
            scratch_l[:n_cur],
            t,
            level,
            t_upd,
            ref,
            t_ready,
            c_on,
            c_off,
            leak_slope,
            refractory,
            out_t,
            out_i,
            out_p,
            n_out,
        )
        n_left = 0
        for j in range(n_prev):  # the line left these pixels: back to the background
            p = prev[j]
            if mark[p] != stamp:
                scratch_i[n_left] = p
                scratch_l[n_left] = log_bg
                n_left += 1
        out_t, out_i, out_p, n_out = advance_pixels(
            scratch_i[:n_left],
            scratch_l[:n_left],
            t,
            level,
            t_upd,
            ref,
            t_ready,
            c_on,
            c_off,
            leak_slope,
            refractory,
            out_t,
            out_i,
            out_p,
            n_out,
        )
        prev[:n_cur] = cur[:n_cur]
        n_prev = n_cur
        t_prev = t
    return stamp, n_prev, out_t, out_i, out_p, n_out


class LaserLineScene:
    """The lit centreline of a flapping flag seen through ``optics``; implements the Scene protocol.

    Args:
        kinematics: the flag motion (lengths in ``optics.units``).
        optics: plane -> pixel mapping.
        width, height: sensor size, pixels.
        params: line look and render-step size.
    """

    def __init__(
        self,
        kinematics: FlagKinematics,
        optics: PlaneCamera,
        width: int,
        height: int,
        params: LineRenderParams = LineRenderParams(),
    ) -> None:
        self.kinematics, self.optics, self.params = kinematics, optics, params
        self.width, self.height = width, height
        self.s = np.linspace(0.0, kinematics.length, params.n_s)
        self.step_us = max(1, int(params.max_step_px / max(self.max_pixel_speed() * 1e-6, 1e-12)))
        n = width * height
        self._acc, self._mark = np.zeros(n), np.zeros(n, np.int64)
        self._prev, self._cur = np.empty(n, np.int64), np.empty(n, np.int64)
        self._scratch_i, self._scratch_l = np.empty(n, np.int64), np.empty(n)
        self._stamp, self._n_prev, self.t_us = 0, 0, 0.0
        self.n_steps = 0

    def max_pixel_speed(self, n_phase: int = 512) -> float:
        """Largest speed of the projected line over one period, pixels per second."""
        kin = self.kinematics
        phi = np.linspace(0.0, 2.0 * np.pi, n_phase + 1)
        x, y = kin.positions_at_phase(phi, np.linspace(0.0, kin.length, 65))
        u, v = self.optics.project(x, y)
        return float(np.max(np.hypot(np.diff(u, axis=0), np.diff(v, axis=0))) * kin.frequency_hz * n_phase) * 1.05

    def pixels(self, t_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Projected line (u, v), shape (len(t_us), n_s)."""
        x, y = self.kinematics.positions(np.asarray(t_us, dtype=np.float64) * 1e-6, self.s)
        return self.optics.project(x, y)

    def start(self, camera: EventCamera, t_us: int) -> None:
        """Render the line at ``t_us`` and reset ``camera`` to that image."""
        u, v = self.pixels(np.array([t_us]))
        self._stamp += 1
        p = self.params
        self._n_prev = splat_line(
            u[0], v[0], p.line_sigma_px, p.peak, self.width, self.height, self._acc, self._mark, self._stamp, self._prev
        )
        image = np.full(self.width * self.height, p.background)
        touched = self._prev[: self._n_prev]
        image[touched] += self._acc[touched]
        camera.reset(np.log(image + camera.params.log_eps), t_us)
        self.t_us = float(t_us)

    def step_times_us(self, t_us: float, coarse: int = 8) -> np.ndarray:
        """Render-step times in (self.t_us, t_us]: adaptive, so the line moves <= ``max_step_px`` per step.

        The line is sampled every ``coarse`` minimum steps; each coarse interval is cut into as many
        steps as its largest pixel displacement (times 1.25 for curved paths) needs.
        """
        if t_us <= self.t_us:
            return np.empty(0)
        coarse_t = np.arange(self.t_us, t_us, coarse * self.step_us, dtype=np.float64)
        coarse_t = np.append(coarse_t, float(t_us))
        u, v = self.pixels(coarse_t)
        moved = np.max(np.hypot(np.diff(u, axis=0), np.diff(v, axis=0)), axis=1)
        limit = np.maximum(1, np.ceil((coarse_t[1:] - coarse_t[:-1]) / self.step_us))
        n_sub = np.clip(np.ceil(1.25 * moved / self.params.max_step_px), 1, limit).astype(np.int64)
        starts = np.repeat(coarse_t[:-1], n_sub)
        widths = np.repeat(np.diff(coarse_t) / n_sub, n_sub)
        index = np.arange(len(starts)) - np.repeat(np.cumsum(n_sub) - n_sub, n_sub) + 1
        return starts + index * widths

    def advance(self, camera: EventCamera, t_us: int) -> None:
        """Render steps from the last time to ``t_us`` and feed the changes to ``camera``."""
        steps = self.step_times_us(float(t_us))
        if len(steps) == 0:
            return
        steps[-1] = float(t_us)
        self.n_steps += len(steps)
        u, v = self.pixels(steps)
        p, c = self.params, camera
        self._stamp, self._n_prev, c.out_t, c.out_i, c.out_p, c.n_out = line_steps(
            u,
            v,
            steps,
            self.t_us,
            p.line_sigma_px,
            p.peak,
            p.background,
            c.params.log_eps,
            self.width,
            self.height,
            self._acc,
            self._mark,
            self._stamp,
            self._prev,
            self._n_prev,
            self._cur,
            self._scratch_i,
            self._scratch_l,
            c.level,
            c.t_upd,
            c.ref,
            c.t_ready,
            c.c_on,
            c.c_off,
            c.leak_slope,
            float(c.params.refractory_us),
            c.out_t,
            c.out_i,
            c.out_p,
            c.n_out,
        )
        self.t_us = float(t_us)
