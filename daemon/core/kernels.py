"""Compiled per-window kernels: sort by distance to the root, chain update, Delta_RMS.

Hot loops of the tracker, in single precision with SIMD bodies (no branches, no Python division
checks). Each window's events are first sorted by their distance ``rho`` to the root into buckets
(a stable counting sort), so that the search area of link k, which lies within ``(1 + alpha) r_k``
of joint k-1, only scans the buckets that can reach it (about a third of the window), and
Delta_RMS only compares an event with the areas and centreline segments of its own ``rho``.

Every scan runs over a whole number of SIMD blocks (``LANES`` events): the sorted buffer is padded
with far-away events, and events scanned beyond a range cannot be inside an area whose ``rho`` range
excludes them, so only zeros are added. Results do not depend on where the stream was cut: a
window's events are the same, in the same order, whatever the chunking.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from flagtrack.daemon.core.smoothing import smooth_one

_F = np.float32
LANES = 16
"""Scans cover multiples of this many events (pad the sorted buffers with as many)."""
FAR = 1e18
"""Coordinate of the padding events (outside every area)."""
_BIG = np.float32(1e30)  # "no candidate segment yet" (finite: the kernels assume no infinities)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _up(i0: int, i1: int) -> int:
    """``i1`` rounded up so that ``i1 - i0`` is a multiple of LANES."""
    return i0 + ((i1 - i0 + LANES - 1) // LANES) * LANES


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def bucket_sort(x: np.ndarray, y: np.ndarray, lo: int, hi: int, root_x: float, root_y: float, inv_width: float,
                xs: np.ndarray, ys: np.ndarray, bucket: np.ndarray, offsets: np.ndarray) -> None:
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
def arc_sums(xs: np.ndarray, ys: np.ndarray, i0: int, i1: int, px: float, py: float, c: float, s: float,
             r2_min: float, r2_max: float, cl2: float, unit: bool) -> tuple[float, float, int]:
    """Sum over the events ``i0:i1`` inside one arc of their unit vectors (``unit``) or offsets.

    Inside: ``r2_min <= d^2 <= r2_max`` from (px, py) and direction within the arc's half-angle of
    (c, s), tested as ``proj |proj| >= cl2 d^2`` (``cl2 = cos(limit) |cos(limit)|``).
    """
    fpx, fpy, fc, fs = _F(px), _F(py), _F(c), _F(s)
    lo2, hi2, fcl2 = _F(r2_min), _F(r2_max), _F(cl2)
    one, zero = _F(1.0), _F(0.0)
    sx, sy = zero, zero
    n = 0
    end = _up(i0, i1)
    xw, yw = xs[i0:end], ys[i0:end]  # slices: indices from 0, so the loop vectorises
    for i in range(len(xw)):
        dx = xw[i] - fpx
        dy = yw[i] - fpy
        d2 = dx * dx + dy * dy
        proj = dx * fc + dy * fs
        inside = (d2 >= lo2) & (d2 <= hi2) & (proj * abs(proj) >= fcl2 * d2)
        w = one / math.sqrt(d2) if unit else one
        sx += dx * w if inside else zero
        sy += dy * w if inside else zero
        n += 1 if inside else 0
    return float(sx), float(sy), n


@njit(cache=True, nogil=True, error_model="numpy")
def band(offsets: np.ndarray, inv_width: float, rho_lo: float, rho_hi: float) -> tuple[int, int]:
    """Index range of the sorted events whose bucket can hold ``rho`` in [rho_lo, rho_hi]."""
    n_buckets = len(offsets) - 1
    b0 = min(max(int(math.floor(rho_lo * inv_width)), 0), n_buckets - 1)
    b1 = min(max(int(math.floor(rho_hi * inv_width)), 0), n_buckets - 1)
    return offsets[b0], offsets[b1 + 1]


@njit(cache=True, nogil=True, error_model="numpy")
def update_sorted(xs: np.ndarray, ys: np.ndarray, offsets: np.ndarray, inv_width: float, root_x: float,
                  root_y: float, angles: np.ndarray, lengths: np.ndarray, reach: np.ndarray, r2_min: np.ndarray,
                  r2_max: np.ndarray, cl2: float, cr2: float, min_events: int, area: np.ndarray,
                  jx: np.ndarray, jy: np.ndarray, counts: np.ndarray) -> None:
    """Update the link directions ``angles`` in place from one window's bucket-sorted events.

    Root to tip, link k takes the events of its arc around joint k (already updated): with the
    paper's rule (``cr2 > 1``) their circular mean; with refining, the mean offset gives a pilot
    direction and the circular mean is taken over the arc of half-angle ``refine`` around it.
    A link whose (final) arc holds fewer than ``min_events`` events keeps its direction.

    Args:
        xs, ys, offsets: the sorted events (padded, see :func:`bucket_sort`) and bucket starts.
        reach: (N_j,) outer radius of each area, (1 + alpha) r_k.
        area: (N_j, 4) written: centre x, y and previous direction cos, sin of each area.
        jx, jy: (N_j + 1,) joints written; counts: (N_j,) events in each final arc written.
    """
    px, py = root_x, root_y
    jx[0], jy[0] = px, py
    refine = cr2 <= 1.0
    for k in range(len(angles)):
        c, s = math.cos(angles[k]), math.sin(angles[k])
        area[k, 0], area[k, 1], area[k, 2], area[k, 3] = px, py, c, s
        rho = math.sqrt((px - root_x) ** 2 + (py - root_y) ** 2)
        i0, i1 = band(offsets, inv_width, rho - reach[k], rho + reach[k])
        sx, sy, n = arc_sums(xs, ys, i0, i1, px, py, c, s, r2_min[k], r2_max[k], cl2, not refine)
        if refine and n > 0:
            norm = math.sqrt(sx * sx + sy * sy)
            if norm > 0.0:
                sx, sy, n = arc_sums(xs, ys, i0, i1, px, py, sx / norm, sy / norm, r2_min[k], r2_max[k], cr2, True)
        counts[k] = n
        if n >= min_events and (sx != 0.0 or sy != 0.0):
            angles[k] = math.atan2(sy, sx)
            c, s = math.cos(angles[k]), math.sin(angles[k])
        px += lengths[k] * c
        py += lengths[k] * s
        jx[k + 1], jy[k + 1] = px, py


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _mark_inside(xs: np.ndarray, ys: np.ndarray, i0: int, i1: int, px: float, py: float, c: float, s: float,
                 r2_min: float, r2_max: float, cl2: float, inside: np.ndarray) -> None:
    """OR into ``inside`` (uint8, indexed like xs) whether each event lies in the arc (as :func:`arc_sums`)."""
    fpx, fpy, fc, fs = _F(px), _F(py), _F(c), _F(s)
    lo2, hi2, fcl2 = _F(r2_min), _F(r2_max), _F(cl2)
    end = _up(i0, i1)
    xw, yw, iw = xs[i0:end], ys[i0:end], inside[i0:end]
    for i in range(len(xw)):
        dx = xw[i] - fpx
        dy = yw[i] - fpy
        d2 = dx * dx + dy * dy
        proj = dx * fc + dy * fs
        hit = (d2 >= lo2) & (d2 <= hi2) & (proj * abs(proj) >= fcl2 * d2)
        iw[i] |= np.uint8(hit)


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _nearest_segment(xs: np.ndarray, ys: np.ndarray, i0: int, i1: int, ax: float, ay: float, dx: float, dy: float,
                     inv_l2: float, best: np.ndarray) -> None:
    """Lower ``best`` (indexed like xs) to each event's squared distance to the segment (ax, ay) + [0, 1] (dx, dy)."""
    fax, fay, fdx, fdy, finv = _F(ax), _F(ay), _F(dx), _F(dy), _F(inv_l2)
    zero, one = _F(0.0), _F(1.0)
    end = _up(i0, i1)
    xw, yw, bw = xs[i0:end], ys[i0:end], best[i0:end]
    for i in range(len(xw)):
        px = xw[i] - fax
        py = yw[i] - fay
        t = min(max((px * fdx + py * fdy) * finv, zero), one)
        ex = px - t * fdx
        ey = py - t * fdy
        bw[i] = min(bw[i], ex * ex + ey * ey)


@njit(cache=True, nogil=True, error_model="numpy")
def _polyline_d2(x: float, y: float, sx: np.ndarray, sy: np.ndarray) -> float:
    """Exact squared distance from (x, y) to the polyline (sx, sy) (the slow fallback)."""
    best = math.inf
    for q in range(len(sx) - 1):
        dx, dy = sx[q + 1] - sx[q], sy[q + 1] - sy[q]
        l2 = dx * dx + dy * dy
        px, py = x - sx[q], y - sy[q]
        t = min(max((px * dx + py * dy) / l2, 0.0), 1.0) if l2 > 0.0 else 0.0
        best = min(best, (px - t * dx) ** 2 + (py - t * dy) ** 2)
    return best


@njit(cache=True, nogil=True, error_model="numpy")
def _segments(sx: np.ndarray, sy: np.ndarray, root_x: float, root_y: float, seg: np.ndarray) -> float:
    """Fill seg (7, n_s - 1): rho range, start, direction, 1/length^2; return 2x the longest segment."""
    longest = 0.0
    for q in range(len(sx) - 1):
        r0 = math.sqrt((sx[q] - root_x) ** 2 + (sy[q] - root_y) ** 2)
        r1 = math.sqrt((sx[q + 1] - root_x) ** 2 + (sy[q + 1] - root_y) ** 2)
        dx, dy = sx[q + 1] - sx[q], sy[q + 1] - sy[q]
        l2 = dx * dx + dy * dy
        seg[0, q] = min(r0, r1) - 0.5 * math.sqrt(l2)  # no point of the segment is nearer the root
        seg[1, q] = max(r0, r1)
        seg[2, q], seg[3, q], seg[4, q], seg[5, q] = sx[q], sy[q], dx, dy
        seg[6, q] = 1.0 / l2 if l2 > 0.0 else 0.0
        longest = max(longest, math.sqrt(l2))
    return 2.0 * longest


@njit(cache=True, nogil=True, error_model="numpy")
def window_delta(xs: np.ndarray, ys: np.ndarray, offsets: np.ndarray, width: float, group: int, root_x: float,
                 root_y: float, area: np.ndarray, reach: np.ndarray, r2_min: np.ndarray, r2_max: np.ndarray,
                 cl2: float, sx: np.ndarray, sy: np.ndarray, seg: np.ndarray, inside: np.ndarray,
                 best: np.ndarray) -> tuple[float, int]:
    """Sum of squared distances to the centreline (sx, sy) of the window's events in a search area.

    Per group of ``group`` buckets, only the areas and centreline segments whose distance to the
    root can match the group's are tested; an event farther than the margin from every candidate
    segment is measured against the whole centreline, so the result is exact.

    Args:
        xs, ys, offsets: the bucket-sorted, padded events; width: bucket width.
        area: (N_j, 4) centre and previous direction of each area (from :func:`update_sorted`).
        sx, sy: (n_s,) float64 centreline samples; seg: (7, n_s - 1) scratch.
        inside, best: uint8 and float32 scratch indexed like xs.

    Returns:
        (sum of squared distances, number of events in an area).
    """
    n_areas, n_seg, n_buckets = area.shape[0], len(sx) - 1, len(offsets) - 1
    margin = max(_segments(sx, sy, root_x, root_y, seg), width)
    limit = margin * margin
    n = offsets[n_buckets]
    inside[:_up(0, n)] = 0
    best[:_up(0, n)] = _BIG
    total, count = 0.0, 0
    for b0 in range(0, n_buckets, group):
        b1 = min(b0 + group, n_buckets)
        i0, i1 = offsets[b0], offsets[b1]
        if i1 == i0:
            continue
        lo_rho = b0 * width
        hi_rho = b1 * width if b1 < n_buckets else math.inf
        for k in range(n_areas):
            rho_k = math.sqrt((area[k, 0] - root_x) ** 2 + (area[k, 1] - root_y) ** 2)
            if rho_k - reach[k] <= hi_rho and rho_k + reach[k] >= lo_rho:
                _mark_inside(xs, ys, i0, i1, area[k, 0], area[k, 1], area[k, 2], area[k, 3], r2_min[k], r2_max[k],
                             cl2, inside)
        n_in = 0
        iw = inside[i0:i1]
        for i in range(len(iw)):
            n_in += iw[i]
        if n_in == 0:
            continue
        for q in range(n_seg):
            if seg[1, q] >= lo_rho - margin and seg[0, q] <= hi_rho + margin:
                _nearest_segment(xs, ys, i0, i1, seg[2, q], seg[3, q], seg[4, q], seg[5, q], seg[6, q], best)
        part, far = _masked_sum(inside[i0:i1], best[i0:i1], limit)
        total += part
        count += n_in
        if far:  # events farther than the margin from every candidate: measure them exactly
            for i in range(i0, i1):
                if inside[i] and not best[i] <= limit:
                    total += _polyline_d2(float(xs[i]), float(ys[i]), sx, sy)
        # (a padded scan may have marked events of the next group: truly, so they are kept)
    return total, count


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _masked_sum(inside: np.ndarray, best: np.ndarray, limit: float) -> tuple[float, int]:
    """(sum of ``best`` where ``inside`` and ``best <= limit``, number inside above it); vectorised."""
    total = _F(0.0)
    far = 0
    flimit = _F(limit)
    for i in range(len(inside)):
        hit = inside[i] != 0
        near = best[i] <= flimit
        total += best[i] if hit & near else _F(0.0)
        far += 1 if hit & ~near else 0
    return float(total), far


@njit(cache=True, nogil=True, error_model="numpy")
def run_updates(x: np.ndarray, y: np.ndarray, lo_idx: np.ndarray, hi_idx: np.ndarray, root_x: float,
                root_y: float, angles: np.ndarray, lengths: np.ndarray, r2_min: np.ndarray, r2_max: np.ndarray,
                cl2: float, cr2: float, min_events: int, bucket_width: float, n_buckets: int, group: int,
                length: float, rel_tol: float, out_jx: np.ndarray, out_jy: np.ndarray, out_sx: np.ndarray,
                out_sy: np.ndarray, out_delta: np.ndarray, out_n: np.ndarray) -> None:
    """Run K consecutive updates (chain, smoothing, Delta_RMS) on a time-sorted float32 event buffer.

    Args:
        x, y: (n,) float32 event coordinates, time-sorted.
        lo_idx, hi_idx: (K,) index range of each window.
        angles: (N_j,) link directions, radians, carried through the updates in place.
        lengths, r2_min, r2_max, cl2, cr2, min_events: the areas (see :class:`.chain.AreaGeometry`).
        bucket_width, n_buckets: the rho buckets of the sort; group: buckets per Delta_RMS group.
        length, rel_tol: flag length and tolerance of the smoothed length (relative).
        out_jx, out_jy: (K, N_j + 1) joints (tip shortened); out_sx, out_sy: (K, n_s) centrelines;
        out_delta: (K,) Delta_RMS (NaN if no event in an area); out_n: (K,) events in an area.
    """
    n_links = len(angles)
    n_max = 0
    for w in range(len(lo_idx)):
        n_max = max(n_max, hi_idx[w] - lo_idx[w])
    size = n_max + 2 * LANES
    xs, ys = np.empty(size, dtype=np.float32), np.empty(size, dtype=np.float32)
    bucket, inside, best = np.empty(size, dtype=np.int32), np.empty(size, dtype=np.uint8), np.empty(size, dtype=np.float32)
    offsets = np.empty(n_buckets + 1, dtype=np.int64)
    counts = np.zeros(n_links, dtype=np.int64)
    area = np.empty((n_links, 4))
    reach = np.sqrt(r2_max)
    work = np.empty(4 * (n_links + 1) + 3)
    seg = np.empty((7, out_sx.shape[1] - 1))
    inv_width = 1.0 / bucket_width
    for w in range(len(lo_idx)):
        bucket_sort(x, y, lo_idx[w], hi_idx[w], root_x, root_y, inv_width, xs, ys, bucket, offsets)
        jx, jy = out_jx[w], out_jy[w]
        update_sorted(xs, ys, offsets, inv_width, root_x, root_y, angles, lengths, reach, r2_min, r2_max,
                      cl2, cr2, min_events, area, jx, jy, counts)
        smooth_one(jx, jy, lengths, length, rel_tol, work, out_sx[w], out_sy[w])
        total, used = window_delta(xs, ys, offsets, bucket_width, group, root_x, root_y, area, reach, r2_min,
                                   r2_max, cl2, out_sx[w], out_sy[w], seg, inside, best)
        out_n[w] = used
        out_delta[w] = math.sqrt(total / used) if used > 0 else math.nan


@njit(cache=True, nogil=True, error_model="numpy")
def time_order(t: np.ndarray, previous: int) -> tuple[bool, int]:
    """(whether ``t`` is non-decreasing and starts at or after ``previous``, max of ``t`` and previous)."""
    ordered = True
    last = previous
    top = previous
    for i in range(len(t)):
        ti = np.int64(t[i])
        ordered &= ti >= last
        last = ti
        top = max(top, ti)
    return ordered, top
