"""Compiled per-window kernels: sort by distance to the root, chain update, Delta_RMS.

Hot loops of the tracker, in single precision with SIMD bodies (no branches, no Python division
checks). Each window's events are first sorted by their distance ``rho`` to the root into buckets
(a stable counting sort), so that the search area of link k, which lies within ``(1 + alpha) r_k``
of joint k-1, only scans the buckets that can reach it (about a third of the window), and
Delta_RMS (:mod:`.delta_rms`) only compares an event with the areas and centreline segments of
its own ``rho``.

Every scan runs over a whole number of SIMD blocks (``LANES`` events): the sorted buffer is padded
with far-away events, and events scanned beyond a range cannot be inside an area whose ``rho`` range
excludes them, so only zeros are added. Results do not depend on where the stream was cut: a
window's events are the same, in the same order, whatever the chunking.
"""

from __future__ import annotations

import math

import numpy as np

from flagtrack.daemon.core.delta_rms import LANES, lanes_end, window_delta
from flagtrack.daemon.core.evidence import look_back
from flagtrack.daemon.core.jit import njit
from flagtrack.daemon.core.lost import N_BINS, SUPPORTED, count_near, folded, hold, tip_support, verdict, wide_search
from flagtrack.daemon.core.smoothing import smooth_one

_F = np.float32
FAR = 1e18
"""Coordinate of the padding events (outside every area)."""
STARVED = 4
"""The tip lacks support when its two links' final arcs hold fewer than min_events and this many times
fewer than the busiest link (a sparse still flag has few events everywhere; a missed tip has none where
the rest has many; the tip link's own area reaches only its outer part)."""


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def bucket_sort(
    x: np.ndarray,
    y: np.ndarray,
    lo: int,
    hi: int,
    root_x: float,
    root_y: float,
    inv_width: float,
    xs: np.ndarray,
    ys: np.ndarray,
    bucket: np.ndarray,
    offsets: np.ndarray,
) -> None:
    """Stable counting sort of the events ``lo:hi`` by bucket ``floor(rho * inv_width)`` (last = overflow).

    Writes the sorted coordinates to ``xs``, ``ys`` (from 0; the LANES values after the last are set
    to FAR) and the bucket starts to ``offsets`` (n_buckets + 1,). ``bucket`` is int32 scratch.
    """
    n_buckets = len(offsets) - 1
    n = hi - lo
    xw, yw, bw = x[lo:hi], y[lo:hi], bucket[:n]
    rx, ry, inv, top = _F(root_x), _F(root_y), _F(inv_width), _F(n_buckets - 1)
    for i in range(n):
        dx = xw[i] - rx
        dy = yw[i] - ry
        bw[i] = np.int32(min(math.sqrt(dx * dx + dy * dy) * inv, top))
    offsets[:] = 0
    for i in range(n):
        offsets[bw[i] + 1] += 1
    for b in range(n_buckets):
        offsets[b + 1] += offsets[b]
    fill = offsets[:n_buckets].copy()
    for i in range(n):
        b = bw[i]
        j = fill[b]
        xs[j] = xw[i]
        ys[j] = yw[i]
        fill[b] = j + 1
    for i in range(n, n + LANES):
        xs[i] = _F(FAR)
        ys[i] = _F(FAR)


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def arc_sums(
    xs: np.ndarray,
    ys: np.ndarray,
    i0: int,
    i1: int,
    px: float,
    py: float,
    c: float,
    s: float,
    r2_min: float,
    r2_max: float,
    cl2: float,
    c2: float,
    s2: float,
    cl2b: float,
    unit: bool,
) -> tuple[float, float, int]:
    """Sum over the events ``i0:i1`` inside one arc of their unit vectors (``unit``) or offsets.

    Inside: ``r2_min <= d^2 <= r2_max`` from (px, py) and direction within the arc's half-angle of
    (c, s), tested as ``proj |proj| >= cl2 d^2`` (``cl2 = cos(limit) |cos(limit)|``), and within
    a second half-angle of (c2, s2) (``cl2b``; -1 for none: the refining arc inside the area).
    """
    fpx, fpy, fc, fs = _F(px), _F(py), _F(c), _F(s)
    lo2, hi2, fcl2 = _F(r2_min), _F(r2_max), _F(cl2)
    fc2, fs2, fcl2b = _F(c2), _F(s2), _F(cl2b)
    one, zero = _F(1.0), _F(0.0)
    sx, sy = zero, zero
    n = 0
    end = lanes_end(i0, i1)
    xw, yw = xs[i0:end], ys[i0:end]  # slices: indices from 0, so the loop vectorises
    for i in range(len(xw)):
        dx = xw[i] - fpx
        dy = yw[i] - fpy
        d2 = dx * dx + dy * dy
        proj = dx * fc + dy * fs
        proj2 = dx * fc2 + dy * fs2
        inside = (d2 >= lo2) & (d2 <= hi2) & (proj * abs(proj) >= fcl2 * d2) & (proj2 * abs(proj2) >= fcl2b * d2)
        w = one / math.sqrt(d2) if unit else one
        sx += dx * w if inside else zero
        sy += dy * w if inside else zero
        n += 1 if inside else 0
    return float(sx), float(sy), n


@njit(cache=True, nogil=True, error_model="numpy")
def _segment_distance(qx: float, qy: float, ax: float, ay: float, bx: float, by: float) -> float:
    """Distance from (qx, qy) to the segment a-b."""
    dx, dy = bx - ax, by - ay
    l2 = dx * dx + dy * dy
    t = min(max(((qx - ax) * dx + (qy - ay) * dy) / l2, 0.0), 1.0) if l2 > 0.0 else 0.0
    return math.hypot(qx - ax - t * dx, qy - ay - t * dy)


@njit(cache=True, nogil=True, error_model="numpy")
def sector_rho_range(
    px: float, py: float, c: float, s: float, r_in: float, r_out: float, half_angle: float, root_x: float, root_y: float
) -> tuple[float, float]:
    """Smallest and largest distance to the root of the points of a search area.

    The area is the annular sector around (px, py) of radii [r_in, r_out] and directions within
    ``half_angle`` (radians) of (c, s). The range is widened by a few single-precision roundings of
    the coordinates, so that no event the (single-precision) area test takes falls outside it.
    """
    lo, hi = _sector_rho_range(px, py, c, s, r_in, r_out, half_angle, root_x, root_y)
    slack = 1e-6 * (max(abs(px), abs(py), abs(root_x), abs(root_y)) + r_out)
    return max(lo - slack, 0.0), hi + slack


@njit(cache=True, nogil=True, error_model="numpy")
def _sector_rho_range(
    px: float, py: float, c: float, s: float, r_in: float, r_out: float, half_angle: float, root_x: float, root_y: float
) -> tuple[float, float]:
    """:func:`sector_rho_range` without the slack."""
    rx, ry = root_x - px, root_y - py
    d_root = math.hypot(rx, ry)
    d_p = d_root
    hi = d_p + r_out  # triangle inequality; reached when the sector points away from the root
    full = half_angle >= math.pi
    # is the root's direction (seen from the centre) inside the sector's angular range?
    toward = full or (d_root > 0.0 and (rx * c + ry * s) >= d_root * math.cos(half_angle))
    if toward and r_in <= d_root <= r_out:
        return 0.0, hi  # the root is inside the area
    if toward:
        lo = min(abs(d_root - r_in), abs(d_root - r_out))
    else:
        lo = math.inf
    if not full:
        ch, sh = math.cos(half_angle), math.sin(half_angle)
        for sign in (-1.0, 1.0):  # the two radial edges (and so the arcs' end points)
            ux, uy = c * ch - sign * s * sh, s * ch + sign * c * sh
            lo = min(
                lo, _segment_distance(root_x, root_y, px + r_in * ux, py + r_in * uy, px + r_out * ux, py + r_out * uy)
            )
    return lo, hi


@njit(cache=True, nogil=True, error_model="numpy")
def band(offsets: np.ndarray, inv_width: float, rho_lo: float, rho_hi: float) -> tuple[int, int]:
    """Index range of the sorted events whose bucket can hold ``rho`` in [rho_lo, rho_hi]."""
    n_buckets = len(offsets) - 1
    b0 = min(max(int(math.floor(rho_lo * inv_width)), 0), n_buckets - 1)
    b1 = min(max(int(math.floor(rho_hi * inv_width)), 0), n_buckets - 1)
    return offsets[b0], offsets[b1 + 1]


@njit(cache=True, nogil=True, error_model="numpy")
def update_sorted(
    xs: np.ndarray,
    ys: np.ndarray,
    offsets: np.ndarray,
    inv_width: float,
    root_x: float,
    root_y: float,
    angles: np.ndarray,
    lengths: np.ndarray,
    reach: np.ndarray,
    r2_min: np.ndarray,
    r2_max: np.ndarray,
    cl2: float,
    cr2: float,
    half_angle: float,
    min_events: int,
    area: np.ndarray,
    jx: np.ndarray,
    jy: np.ndarray,
    counts: np.ndarray,
) -> None:
    """Update the link directions ``angles`` in place from one window's bucket-sorted events.

    Root to tip, link k takes the events of its arc around joint k (already updated): with the
    paper's rule (``cr2 > 1``) their circular mean; with refining, the mean offset gives a pilot
    direction and the circular mean is taken over the area's events within ``refine`` of it.
    A link whose (final) arc holds fewer than ``min_events`` events keeps its direction.

    Args:
        xs, ys, offsets: the sorted events (padded, see :func:`bucket_sort`) and bucket starts.
        reach: (N_j,) outer radius of each area, (1 + alpha) r_k.
        half_angle: the areas' angle limit, radians.
        area: (N_j, 6) written: centre x, y, previous direction cos, sin, and the smallest and
            largest distance to the root of each area.
        jx, jy: (N_j + 1,) joints written; counts: (N_j,) events in each final arc written.
    """
    px, py = root_x, root_y
    jx[0], jy[0] = px, py
    refine = cr2 <= 1.0
    for k in range(len(angles)):
        c, s = math.cos(angles[k]), math.sin(angles[k])
        rho_lo, rho_hi = sector_rho_range(px, py, c, s, math.sqrt(r2_min[k]), reach[k], half_angle, root_x, root_y)
        area[k, 0], area[k, 1], area[k, 2], area[k, 3], area[k, 4], area[k, 5] = px, py, c, s, rho_lo, rho_hi
        i0, i1 = band(offsets, inv_width, rho_lo, rho_hi)
        sx, sy, n = arc_sums(xs, ys, i0, i1, px, py, c, s, r2_min[k], r2_max[k], cl2, c, s, -1.0, not refine)
        if refine and n > 0:
            norm = math.sqrt(sx * sx + sy * sy)
            if norm > 0.0:
                sx, sy, n = arc_sums(
                    xs, ys, i0, i1, px, py, c, s, r2_min[k], r2_max[k], cl2, sx / norm, sy / norm, cr2, True
                )
        counts[k] = n
        if n >= min_events and (sx != 0.0 or sy != 0.0):
            angles[k] = math.atan2(sy, sx)
            c, s = math.cos(angles[k]), math.sin(angles[k])
        px += lengths[k] * c
        py += lengths[k] * s
        jx[k + 1], jy[k + 1] = px, py


@njit(cache=True, nogil=True, error_model="numpy")
def run_updates(
    x: np.ndarray,
    y: np.ndarray,
    lo_idx: np.ndarray,
    hi_idx: np.ndarray,
    root_x: float,
    root_y: float,
    angles: np.ndarray,
    lengths: np.ndarray,
    r2_min: np.ndarray,
    r2_max: np.ndarray,
    cl2: float,
    cr2: float,
    half_angle: float,
    min_events: int,
    bucket_width: float,
    n_buckets: int,
    group: int,
    length: float,
    rel_tol: float,
    out_jx: np.ndarray,
    out_jy: np.ndarray,
    out_sx: np.ndarray,
    out_sy: np.ndarray,
    out_delta: np.ndarray,
    out_n: np.ndarray,
    lost_cfg: np.ndarray,
    lost_prev: np.ndarray,
    out_lost: np.ndarray,
    t: np.ndarray,
    first: int,
    look_back_us: int,
    look_back_events: int,
    end_us: np.ndarray,
    cum_region: np.ndarray,
    cum_ring: np.ndarray,
    cls: np.ndarray,
    out_stale: np.ndarray,
) -> None:
    """Run K consecutive updates (chain, smoothing, Delta_RMS) on a time-sorted float32 event buffer.

    Args:
        x, y: (n,) float32 event coordinates, time-sorted.
        lo_idx, hi_idx: (K,) index range of each window.
        angles: (N_j,) link directions, radians, carried through the updates in place.
        lengths, r2_min, r2_max, cl2, cr2, half_angle, min_events: the areas (:class:`.chain.AreaGeometry`).
        bucket_width, n_buckets: the rho buckets of the sort; group: buckets per Delta_RMS group.
        length, rel_tol: flag length and tolerance of the smoothed length (relative).
        out_jx, out_jy: (K, N_j + 1) joints (tip shortened); out_sx, out_sy: (K, n_s) centrelines;
        out_delta: (K,) Delta_RMS (NaN if no event in an area); out_n: (K,) events in an area.
        lost_cfg: (13,) loss of track (:mod:`.lost`): enabled (0/1), min_events (also the evidence
            below which an update is stale), min_fit, band^2 (squared length), region rho, re-acquire
            (0/1), cone and refining half-angle (radians), updates held lost after a lost one, stale
            verdict on (0/1), evidence a gathered window aims at (0: no gathering), time constant (µs)
            of the tip link's support (:func:`.lost.tip_support`; 0: not judged), fit below which a
            window is searched again; lost disabled: the paper's update, untouched, and ``out_lost`` zeros.
        lost_prev: (5,) int64, the previous update's verdict, the updates still to hold lost and the
            length of the current lost stretch (:func:`.lost.hold`), and the tip's support
            (:func:`.lost.tip_support`), carried in place.
        out_lost: (K,) uint8 written: 1 where the flag was not found.
        t: (n,) int64 event times, µs; first: the buffer's first live index; look_back_us: how far
            before a window's end its look-back starts (``stale_after_s``, :mod:`.evidence`; searched
            only for the windows that need it), and at most ``look_back_events`` events before the
            window's first (:data:`.evidence.LOOK_BACK_EVENTS`); end_us: (K,) each window's end, µs.
        cum_region, cum_ring, cls: the buffer's prefix counts and their valid range (:func:`.evidence.classify`).
        out_stale: (K,) uint8 written: 1 where the region held less than min_events of evidence over
            the whole look-back (the shape was not measured); such an update is not lost.
    """
    n_links = len(angles)
    n_max = 0
    for w in range(len(lo_idx)):
        n_max = max(n_max, hi_idx[w] - lo_idx[w])
    xs, ys, bucket, inside, best = _scratch(n_max + 2 * LANES)
    offsets = np.empty(n_buckets + 1, dtype=np.int64)
    counts = np.zeros(n_links, dtype=np.int64)
    area = np.empty((n_links, 6))
    reach = np.sqrt(r2_max)
    work = np.empty(4 * (n_links + 1) + 3)
    seg = np.empty((7, out_sx.shape[1] - 1))
    inv_width = 1.0 / bucket_width
    lost_on = lost_cfg[0] != 0.0
    region_end = min(int(lost_cfg[4] * inv_width), n_buckets - 2) + 1  # buckets of the flag's region
    # the ring of whole buckets beyond it, up to the overflow bucket: region area / ring area
    ring_ratio = region_end**2 / max((n_buckets - 1) ** 2 - region_end**2, 1)
    hist = np.zeros(N_BINS, dtype=np.int64)
    n_s = out_sx.shape[1]
    spare = (angles.copy(), np.empty(n_links + 1), np.empty(n_links + 1), np.empty(n_s), np.empty(n_s), np.empty(2))
    stale_on = lost_cfg[9] != 0.0
    need = lost_cfg[1]
    gathers = lost_on and lost_cfg[5] != 0.0  # a chain that may be moved by the detector gathers quiet windows
    target = max(need, lost_cfg[10]) if gathers else need
    geometry = (lengths, reach, r2_min, r2_max, cl2, cr2, half_angle, min_events, length, rel_tol, group)
    for w in range(len(lo_idx)):
        lo, hi = lo_idx[w], hi_idx[w]
        bucket_sort(x, y, lo, hi, root_x, root_y, inv_width, xs, ys, bucket, offsets)
        stale, start = 0, lo
        if stale_on and offsets[region_end] - (offsets[n_buckets - 1] - offsets[region_end]) * ring_ratio < target:
            back = max(first + np.searchsorted(t[first:lo], end_us[w] - look_back_us), lo - look_back_events)
            stale, start = look_back(
                x, y, back, lo, hi, root_x, root_y, inv_width, region_end, n_buckets - 1, cum_region, cum_ring,
                cls, ring_ratio, need, target, gathers,
            )  # fmt: skip
        if start < lo:  # a quiet window gathers its events from further back
            if hi - start + 2 * LANES > len(xs):
                xs, ys, bucket, inside, best = _scratch(2 * (hi - start) + 2 * LANES)
            bucket_sort(x, y, start, hi, root_x, root_y, inv_width, xs, ys, bucket, offsets)
        out_stale[w] = stale
        jx, jy, sx, sy = out_jx[w], out_jy[w], out_sx[w], out_sy[w]
        total, used = _update_measure(
            xs, ys, offsets, bucket_width, root_x, root_y, angles, geometry, area, jx, jy, counts, work, sx, sy, seg,
            inside, best,
        )  # fmt: skip
        lost = 0
        if lost_on and stale:
            lost_prev[3], lost_prev[4] = end_us[w], SUPPORTED  # a quiet region: the tip's support is looked for afresh
        elif lost_on:
            lost, total, used = _judge(
                xs, ys, offsets, bucket_width, root_x, root_y, angles, geometry, area, jx, jy, sx, sy, spare, counts,
                work, seg, inside, best, hist, region_end, ring_ratio, lost_cfg, lost_prev, end_us[w], total, used,
            )  # fmt: skip
        out_lost[w] = lost
        out_n[w] = used
        out_delta[w] = math.sqrt(total / used) if used > 0 else math.nan


@njit(cache=True, nogil=True, error_model="numpy")
def _scratch(size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Work arrays of one window's sorted events: xs, ys, bucket, inside, best."""
    return (
        np.empty(size, dtype=np.float32),
        np.empty(size, dtype=np.float32),
        np.empty(size, dtype=np.int32),
        np.empty(size, dtype=np.uint8),
        np.empty(size, dtype=np.float32),
    )


# inlined (and so at most 30 arguments, or Python passes them as *args): a call between compiled
# functions with this many arrays costs ~0.5 us, 4 % of a window
@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _judge(
    xs: np.ndarray,
    ys: np.ndarray,
    offsets: np.ndarray,
    bucket_width: float,
    root_x: float,
    root_y: float,
    angles: np.ndarray,
    geometry: tuple,
    area: np.ndarray,
    jx: np.ndarray,
    jy: np.ndarray,
    sx: np.ndarray,
    sy: np.ndarray,
    spare: tuple,
    counts: np.ndarray,
    work: np.ndarray,
    seg: np.ndarray,
    inside: np.ndarray,
    best: np.ndarray,
    hist: np.ndarray,
    region_end: int,
    ring_ratio: float,
    lost_cfg: np.ndarray,
    lost_prev: np.ndarray,
    end_us: int,
    total: float,
    used: int,
) -> tuple[int, float, int]:
    """The verdict of one measured update (see :func:`run_updates`), after a wide search of a poorly
    fitting window (whose chain, made in ``spare``, replaces the update's when it fits better);
    (lost, total, used)."""
    min_events = geometry[7]
    n_buckets = len(offsets) - 1
    tip_n, busiest = counts[-2:].sum(), counts.max()
    n_region = offsets[region_end]
    noise = (offsets[n_buckets - 1] - n_region) * ring_ratio
    n_near = count_near(best, n_region, lost_cfg[3])
    fold = folded(angles, lost_cfg[6])
    lost = verdict(n_region, noise, n_near, int(lost_cfg[1]), lost_cfg[2], fold, lost_prev[0])
    poor = verdict(n_region, noise, n_near, int(lost_cfg[1]), max(lost_cfg[2], lost_cfg[12]), fold, lost)
    if poor and lost_cfg[5] != 0.0 and n_region - noise >= lost_cfg[1]:
        searched = _search_again(
            xs, ys, offsets, bucket_width, root_x, root_y, angles, geometry, area, spare, counts, work, seg, inside,
            best, hist, lost_cfg, n_region, noise, n_near, fold,
        )  # fmt: skip
        if searched >= 0:  # the search's chain fits better: it replaces the update's
            trial, t_jx, t_jy, t_sx, t_sy, t_sums = spare
            angles[:] = trial
            jx[:], jy[:], sx[:], sy[:] = t_jx, t_jy, t_sx, t_sy
            lost, total, used = searched, t_sums[0], int(t_sums[1])
            tip_n, busiest = counts[-2:].sum(), counts.max()
    lost_prev[0] = lost
    starved = tip_n < min_events and STARVED * tip_n < busiest  # far fewer than the busiest link
    if tip_support(lost_prev, end_us, not starved, lost_cfg[11]):
        lost = 1  # the tip has lacked events most of the time lately: the sensor misses its motion
    return hold(lost, lost_prev, int(lost_cfg[8])), total, used


@njit(cache=True, nogil=True, error_model="numpy")
def _search_again(
    xs: np.ndarray,
    ys: np.ndarray,
    offsets: np.ndarray,
    bucket_width: float,
    root_x: float,
    root_y: float,
    angles: np.ndarray,
    geometry: tuple,
    area: np.ndarray,
    spare: tuple,
    counts: np.ndarray,
    work: np.ndarray,
    seg: np.ndarray,
    inside: np.ndarray,
    best: np.ndarray,
    hist: np.ndarray,
    lost_cfg: np.ndarray,
    n_region: int,
    noise: float,
    n_near: int,
    fold: bool,
) -> int:
    """A wide search of a poorly fitting window from ``angles``, its chain made in ``spare``: its
    verdict if it fits better than the update's, else -1."""
    lengths, reach, r2_min, r2_max, cl2, cr2, half_angle, min_events, length, rel_tol, group = geometry
    trial, t_jx, t_jy, t_sx, t_sy, t_sums = spare
    trial[:] = angles
    wide_search(
        xs, ys, offsets, 1.0 / bucket_width, root_x, root_y, trial, lengths, r2_min, r2_max, lost_cfg[6],
        lost_cfg[7], min_events, hist,
    )  # fmt: skip
    t_total, t_used = _update_measure(
        xs, ys, offsets, bucket_width, root_x, root_y, trial, geometry, area, t_jx, t_jy, counts, work, t_sx,
        t_sy, seg, inside, best,
    )  # fmt: skip
    t_sums[0], t_sums[1] = t_total, t_used
    t_near = count_near(best, n_region, lost_cfg[3])
    if (t_near > n_near or fold) and not folded(trial, lost_cfg[6]):
        return verdict(n_region, noise, t_near, int(lost_cfg[1]), lost_cfg[2], False, 1)
    return -1


@njit(cache=True, nogil=True, error_model="numpy", inline="always")  # inlined: as _judge
def _update_measure(
    xs: np.ndarray,
    ys: np.ndarray,
    offsets: np.ndarray,
    bucket_width: float,
    root_x: float,
    root_y: float,
    angles: np.ndarray,
    geometry: tuple,
    area: np.ndarray,
    jx: np.ndarray,
    jy: np.ndarray,
    counts: np.ndarray,
    work: np.ndarray,
    sx: np.ndarray,
    sy: np.ndarray,
    seg: np.ndarray,
    inside: np.ndarray,
    best: np.ndarray,
) -> tuple[float, int]:
    """One update of ``angles`` from a window's sorted events, its centreline (sx, sy) and Delta_RMS's
    (sum of squares, events in an area); ``best`` is left with each event's squared distance to it."""
    lengths, reach, r2_min, r2_max, cl2, cr2, half_angle, min_events, length, rel_tol, group = geometry
    inv_width = 1.0 / bucket_width
    update_sorted(
        xs, ys, offsets, inv_width, root_x, root_y, angles, lengths, reach, r2_min, r2_max, cl2, cr2, half_angle,
        min_events, area, jx, jy, counts,
    )  # fmt: skip
    smooth_one(jx, jy, lengths, length, rel_tol, work, sx, sy)
    return window_delta(
        xs, ys, offsets, bucket_width, group, root_x, root_y, area, r2_min, r2_max, cl2, sx, sy, seg, inside, best
    )
