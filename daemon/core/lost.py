"""Loss of track: is the flag found in an update, and a wide search that finds it again.

Compiled helpers of :func:`.kernels.run_updates` for the robust method (:class:`.lost_params.LostParams`).
The verdict uses what the update measures anyway: Delta_RMS's distance of each window event to the
smoothed centreline (:func:`.delta_rms.window_delta` leaves it in ``best``), counted over the events
within the chain's reach of the root, less the background expected there (the density of the events
in the ring just outside that reach, times the region's area). The search (:func:`wide_search`) rebuilds the chain root to tip
from one window: for each link, the direction histogram of the events at the link's distance from
its (new) first joint, within a wide cone, gives the densest direction, refined by a circular mean.
"""

from __future__ import annotations

import math

import numpy as np

from flagtrack.daemon.core.jit import njit

N_BINS = 72
"""Direction bins of the search (5 degrees)."""
HOLD_AFTER = 5
"""Lost stretches shorter than this many updates are not held (a blip of noise is not a loss)."""
NEVER = np.iinfo(np.int64).min
"""No window yet (the carried time of the tip link's last judged window)."""
SUPPORTED = 1_000_000_000
"""Full support of the tip (the carried share of its support, in parts per billion)."""


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def count_near(best: np.ndarray, n: int, band2: float) -> int:
    """Number of the first ``n`` entries of ``best`` (squared distances, float32) at most ``band2``."""
    lim = np.float32(band2)
    count = 0
    bw = best[:n]
    for i in range(len(bw)):
        count += 1 if bw[i] <= lim else 0
    return count


@njit(cache=True, nogil=True, error_model="numpy")
def folded(angles: np.ndarray, max_bend_rad: float) -> bool:
    """Whether a link turns by more than ``max_bend_rad`` from the one before it (a chain folded back)."""
    for k in range(1, len(angles)):  # noqa: SIM110 - numba compiles no any() of a generator
        if abs(_wrap(angles[k] - angles[k - 1])) > max_bend_rad:
            return True
    return False


@njit(cache=True, nogil=True, error_model="numpy")
def verdict(
    n_region: int, noise: float, n_near: int, min_events: int, min_fit: float, fold: bool, previous: int
) -> int:
    """1 if the flag is lost in this update: enough events in its region, and too few near the
    chain or the chain folded.

    ``noise``: the region's expected background events (from the ring around it), taken off its
    count. No event in the region: found (a still flag); fewer than ``min_events`` left: ``previous``.
    """
    if n_region == 0:
        return 0
    signal = n_region - noise
    if signal < min_events:
        return previous
    return 1 if fold or n_near < min_fit * signal else 0


@njit(cache=True, nogil=True, error_model="numpy")
def hold(lost: int, state: np.ndarray, max_hold: int) -> int:
    """The update's reported flag: a found update right after a stretch of lost ones (of at least
    :data:`HOLD_AFTER`) is still said lost, for as many updates as the stretch lasted, at most
    ``max_hold`` (the chain may be on something else for a while); ``state[1:3]`` (updates to
    hold, stretch length) is carried."""
    if lost:
        state[2] += 1
        state[1] = min(max_hold, state[2]) if state[2] >= HOLD_AFTER else 0
        return 1
    state[2] = 0
    if state[1] > 0:
        state[1] -= 1
        return 1
    return 0


@njit(cache=True, nogil=True, error_model="numpy")
def tip_support(state: np.ndarray, end_us: int, supported: bool, tau_us: float) -> bool:
    """Whether the tip has lacked support (too few events in its links' arcs) most of the time lately.

    ``state[3:5]``: the end of the last judged window (µs; :data:`NEVER` at first) and the share of
    windows with support, an exponential average over ``tau_us`` of time in parts per billion
    (full at first), carried. The free end of a flapping flag moves most and makes the most
    events; a sensor that sees its middle but not its tip (a slow photoreceptor, a tip out of view)
    leaves the tip's shape remembered, not measured. ``tau_us`` 0: never.
    """
    if state[3] == NEVER:
        state[3], state[4] = end_us, SUPPORTED
    if tau_us <= 0.0:
        return False
    keep = math.exp(-max(end_us - state[3], 0) / tau_us)
    share = keep * state[4] + (1.0 - keep) * (SUPPORTED if supported else 0)
    state[3], state[4] = end_us, int(share)
    return share < 0.5 * SUPPORTED


@njit(cache=True, nogil=True, error_model="numpy")
def _wrap(a: float) -> float:
    """``a`` (radians) wrapped to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True, nogil=True, error_model="numpy")
def wide_search(
    xs: np.ndarray,
    ys: np.ndarray,
    offsets: np.ndarray,
    inv_width: float,
    root_x: float,
    root_y: float,
    angles: np.ndarray,
    lengths: np.ndarray,
    r2_min: np.ndarray,
    r2_max: np.ndarray,
    cone_rad: float,
    refine_rad: float,
    min_events: int,
    hist: np.ndarray,
) -> None:
    """Rebuild the link directions ``angles`` in place from one window's bucket-sorted events.

    Root to tip, link k takes the events at distance (1 +- alpha) r_k of its first joint whose
    direction is within ``cone_rad`` of link k-1's new direction (any direction for the first
    link); the densest ``2 refine_rad`` sector of their direction histogram, then the circular mean
    of the events within ``refine_rad`` of it, gives the link's direction. A link with fewer than
    ``min_events`` such events continues the previous one with its old bend (the first keeps its
    direction). ``hist`` is (N_BINS,) int64 scratch.
    """
    n_buckets = len(offsets) - 1
    px, py = root_x, root_y
    old_prev = angles[0]
    bin_w = 2.0 * math.pi / N_BINS
    half = max(int(refine_rad / bin_w), 1)
    cos_refine = math.cos(refine_rad)
    for k in range(len(angles)):
        old = angles[k]
        ref = angles[k - 1] if k > 0 else old
        reach = math.sqrt(r2_max[k])
        d_p = math.hypot(px - root_x, py - root_y)
        b0 = min(max(int(math.floor(max(d_p - reach, 0.0) * inv_width)), 0), n_buckets - 1)
        b1 = min(max(int(math.floor((d_p + reach) * inv_width)), 0), n_buckets - 1)
        i0, i1 = offsets[b0], offsets[b1 + 1]
        hist[:] = 0
        for i in range(i0, i1):
            dx, dy = xs[i] - px, ys[i] - py
            d2 = dx * dx + dy * dy
            if d2 < r2_min[k] or d2 > r2_max[k]:
                continue
            a = math.atan2(dy, dx)
            if k > 0 and abs(_wrap(a - ref)) > cone_rad:
                continue
            hist[min(int((a + math.pi) / bin_w), N_BINS - 1)] += 1
        peak, top = -1, 0
        for b in range(N_BINS):
            c = 0
            for j in range(-half, half + 1):
                c += hist[(b + j) % N_BINS]
            if c > top:
                peak, top = b, c
        new = ref + (old - old_prev) if k > 0 else old
        if top >= min_events:
            pc, ps = math.cos(-math.pi + (peak + 0.5) * bin_w), math.sin(-math.pi + (peak + 0.5) * bin_w)
            sx, sy, n = 0.0, 0.0, 0
            for i in range(i0, i1):
                dx, dy = xs[i] - px, ys[i] - py
                d2 = dx * dx + dy * dy
                if d2 < r2_min[k] or d2 > r2_max[k]:
                    continue
                d = math.sqrt(d2)
                if dx * pc + dy * ps >= cos_refine * d:
                    sx += dx / d
                    sy += dy / d
                    n += 1
            if n > 0 and (sx != 0.0 or sy != 0.0):
                new = math.atan2(sy, sx)
        old_prev = old
        angles[k] = new
        px += lengths[k] * math.cos(new)
        py += lengths[k] * math.sin(new)
