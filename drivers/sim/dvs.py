"""Event-camera pixel model in the manner of ESIM / v2e: log-intensity change detection with defects.

Each pixel keeps a reference log intensity. Between two render steps its log intensity is linear
in time; when the difference to the reference reaches +C_on (or -C_off) the pixel emits an ON
(OFF) event at the interpolated crossing time and resets its reference to the current level.
Defects: per-pixel thresholds C ~ N(C0, sigma_C); a refractory period (a pixel is blind after an
event, and fires at the end of it if the change went on meanwhile); leak (the reference drops at
``leak_rate_hz * C_on`` per second, so a still pixel emits spontaneous ON events at
``leak_rate_hz``, as v2e models junction leakage); shot noise (extra events, Poisson in time at
``shot_noise_hz`` per pixel, random polarity, independent of the pixel state).

Only pixels whose intensity changes are processed at each step; the others are caught up lazily
(constant level, leak only) when they change again or at :meth:`EventCamera.flush`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from flagtrack.daemon.core.events import EVENT_DTYPE
from flagtrack.daemon.core.jit import njit


@dataclass(frozen=True)
class DvsParams:
    """Pixel parameters.

    Attributes:
        contrast_on: mean ON threshold C_on, log-intensity units.
        contrast_off: mean OFF threshold C_off, log-intensity units.
        sigma_contrast: pixel-to-pixel standard deviation of both thresholds.
        refractory_us: dead time after each event, µs.
        leak_rate_hz: spontaneous ON events per pixel per second from reference leak (0: none).
        shot_noise_hz: random noise events per pixel per second (0: none).
        log_eps: offset added to the intensity before the log.
    """

    contrast_on: float = 0.3
    contrast_off: float = 0.3
    sigma_contrast: float = 0.03
    refractory_us: float = 10.0
    leak_rate_hz: float = 0.0
    shot_noise_hz: float = 0.0
    log_eps: float = 1e-3

    def __post_init__(self) -> None:
        for name in ("contrast_on", "contrast_off"):
            if getattr(self, name) <= 0:
                raise ValueError(f"DvsParams.{name} must be > 0")
        for name in ("sigma_contrast", "refractory_us", "leak_rate_hz", "shot_noise_hz", "log_eps"):
            if getattr(self, name) < 0:
                raise ValueError(f"DvsParams.{name} must be >= 0")

    def to_attrs(self) -> dict[str, float]:
        """Parameters as a flat mapping."""
        return asdict(self)


@njit(cache=True)
def grow_buffers(out_t: np.ndarray, out_i: np.ndarray, out_p: np.ndarray, n_out: int, need: int):
    """Return buffers holding at least ``need`` events (the first ``n_out`` kept)."""
    if need <= len(out_t):
        return out_t, out_i, out_p
    size = max(need, 2 * len(out_t))
    new_t, new_i, new_p = np.empty(size, np.float64), np.empty(size, np.int64), np.empty(size, np.uint8)
    new_t[:n_out] = out_t[:n_out]
    new_i[:n_out] = out_i[:n_out]
    new_p[:n_out] = out_p[:n_out]
    return new_t, new_i, new_p


@njit(cache=True)
def advance_pixels(
    idx,
    new_levels,
    t1,
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
    """Move pixels ``idx`` from their last update to ``t1``, log level linear in time towards ``new_levels``.

    Returns (out_t, out_i, out_p, n_out): the event buffers (grown when needed) and their fill.
    The pixel body is written out here, not called per pixel: a numba call with many array
    arguments costs ~250 ns per pixel in reference counting.
    """
    for j in range(len(idx)):
        p = idx[j]
        new_level = new_levels[j]
        t0 = t_upd[p]
        if t1 <= t0:
            continue
        l0 = level[p]
        con, coff = c_on[p], c_off[p]
        d = l0 - ref[p]
        need = n_out + int((abs(d) + abs(new_level - l0) + leak_slope[p] * (t1 - t0)) / min(con, coff)) + 2
        if need > len(out_t):
            out_t, out_i, out_p = grow_buffers(out_t, out_i, out_p, n_out, need)
        slope = (new_level - l0) / (t1 - t0) + leak_slope[p]
        t = t0
        tr = t_ready[p]
        while True:
            if t < tr:  # blind until the refractory period ends
                if tr >= t1:
                    d += slope * (t1 - t)
                    break
                d += slope * (tr - t)
                t = tr
            if d >= con or d <= -coff:  # the change went on while blind: fire now and reset
                out_t[n_out] = t
                out_i[n_out] = p
                out_p[n_out] = 1 if d > 0 else 0
                n_out += 1
                d = 0.0
                tr = t + refractory
                continue
            if slope > 0.0:
                tc = t + (con - d) / slope
            elif slope < 0.0:
                tc = t + (-coff - d) / slope
            else:
                break
            if tc >= t1:
                d += slope * (t1 - t)
                break
            out_t[n_out] = tc
            out_i[n_out] = p
            out_p[n_out] = 1 if slope > 0.0 else 0
            n_out += 1
            d = 0.0
            t = tc
            tr = tc + refractory
        ref[p] = new_level - d
        level[p] = new_level
        t_upd[p] = t1
        t_ready[p] = tr
    return out_t, out_i, out_p, n_out


@njit(cache=True)
def pending_pixels(level, ref, t_ready, t_upd, c_on, c_off, out):
    """Pixels that may still fire at constant level without leak (blind at their last update or at a threshold).

    Writes them into ``out``; returns their count.
    """
    n = 0
    for p in range(len(level)):
        d = level[p] - ref[p]
        if t_ready[p] > t_upd[p] or d >= c_on[p] - 1e-9 or d <= -c_off[p] + 1e-9:
            out[n] = p
            n += 1
    return n


class EventCamera:
    """State of a ``width`` x ``height`` event sensor; scenes feed it log-intensity changes.

    Attributes (numpy arrays over flat pixel index ``y * width + x``): ``level`` log intensity at
    ``t_upd`` (µs), ``ref`` reference, ``t_ready`` end of refractory period, ``c_on``/``c_off``
    thresholds, ``leak_slope`` reference drop per µs. Events accumulate in an internal buffer
    until :meth:`take`.
    """

    def __init__(self, width: int, height: int, params: DvsParams = DvsParams(), seed: int = 0) -> None:
        self.width, self.height, self.params = width, height, params
        self.rng = np.random.default_rng(seed)
        n = width * height
        self.c_on = np.maximum(self.rng.normal(params.contrast_on, params.sigma_contrast, n), 0.02)
        self.c_off = np.maximum(self.rng.normal(params.contrast_off, params.sigma_contrast, n), 0.02)
        self.leak_slope = params.leak_rate_hz * 1e-6 * self.c_on
        self.level = np.zeros(n)
        self.ref = np.zeros(n)
        self.t_upd = np.zeros(n)
        self.t_ready = np.full(n, -np.inf)
        self.all_pixels = np.arange(n, dtype=np.int64)
        self._pending = np.empty(n, dtype=np.int64)
        self.out_t, self.out_i = np.empty(1 << 16), np.empty(1 << 16, np.int64)
        self.out_p, self.n_out = np.empty(1 << 16, np.uint8), 0

    def reset(self, log_image: np.ndarray, t_us: float) -> None:
        """Start at ``t_us`` seeing ``log_image`` (flat, n_pix); leak phases are random per pixel."""
        self.level[:] = log_image
        phase = self.rng.random(len(self.level)) if self.params.leak_rate_hz > 0 else 0.0
        self.ref[:] = self.level - phase * self.c_on
        self.t_upd[:] = t_us
        self.t_ready[:] = -np.inf
        self.n_out = 0

    def advance(self, idx: np.ndarray, new_levels: np.ndarray, t_us: float) -> None:
        """Move pixels ``idx`` (int64) linearly from their last level to ``new_levels`` at ``t_us``.

        The ramp starts at each pixel's last update.
        """
        self._run(np.asarray(idx, dtype=np.int64), np.asarray(new_levels, dtype=np.float64), t_us)

    def flush(self, t_us: float) -> None:
        """Bring every pixel that may still fire to ``t_us`` at constant level.

        Without leak only pixels blind at their last update or at a threshold can fire; with leak, all.
        """
        if self.params.leak_rate_hz > 0:
            idx = self.all_pixels
        else:
            n = pending_pixels(self.level, self.ref, self.t_ready, self.t_upd, self.c_on, self.c_off, self._pending)
            idx = self._pending[:n]
        self._run(idx, self.level[idx], t_us)

    def _run(self, idx: np.ndarray, new_levels: np.ndarray, t_us: float) -> None:
        self.out_t, self.out_i, self.out_p, self.n_out = advance_pixels(
            idx,
            new_levels,
            float(t_us),
            self.level,
            self.t_upd,
            self.ref,
            self.t_ready,
            self.c_on,
            self.c_off,
            self.leak_slope,
            float(self.params.refractory_us),
            self.out_t,
            self.out_i,
            self.out_p,
            self.n_out,
        )

    def take(self) -> np.ndarray:
        """Return the buffered events (unsorted EVENT_DTYPE) and empty the buffer."""
        n = self.n_out
        events = np.empty(n, dtype=EVENT_DTYPE)
        events["t"] = np.floor(self.out_t[:n]).astype(np.int64)
        events["x"] = self.out_i[:n] % self.width
        events["y"] = self.out_i[:n] // self.width
        events["p"] = self.out_p[:n]
        self.n_out = 0
        return events

    def shot_noise(self, t0_us: int, t1_us: int) -> np.ndarray:
        """Noise events in [t0_us, t1_us): Poisson count, uniform pixel and time, random polarity."""
        rate = self.params.shot_noise_hz * self.width * self.height
        n = int(self.rng.poisson(rate * (t1_us - t0_us) * 1e-6)) if rate > 0 else 0
        events = np.empty(n, dtype=EVENT_DTYPE)
        events["t"] = self.rng.integers(t0_us, t1_us, n) if n else 0
        events["x"] = self.rng.integers(0, self.width, n) if n else 0
        events["y"] = self.rng.integers(0, self.height, n) if n else 0
        events["p"] = self.rng.integers(0, 2, n) if n else 0
        return events
