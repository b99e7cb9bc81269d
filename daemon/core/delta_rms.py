"""Delta_RMS: RMS distance of a window's events in the search areas to the smoothed centreline.

Compiled, on the window's events sorted by distance ``rho`` to the root (see :mod:`.kernels`): per
group of ``rho`` buckets, an event is tested only against the search areas and the centreline
segments whose distance to the root can match its own, with an exact fallback, so the result is
the exact distance to the polyline of the centreline samples. Scans cover whole SIMD blocks of
``LANES`` events of the padded buffer (the padding is far from everything).
"""

from __future__ import annotations

import math

import numpy as np

from flagtrack.daemon.core.jit import njit

_F = np.float32
LANES = 16
"""Scans cover multiples of this many events (the sorted buffers are padded with as many)."""
_BIG = np.float32(1e30)  # "no candidate segment yet" (finite: the kernels assume no infinities)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def lanes_end(i0: int, i1: int) -> int:
    """``i1`` rounded up so that ``i1 - i0`` is a multiple of LANES."""
    return i0 + ((i1 - i0 + LANES - 1) // LANES) * LANES


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _mark_inside(
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
    inside: np.ndarray,
) -> None:
    """OR into ``inside`` (uint8, indexed like xs) whether each event lies in the arc (as :func:`arc_sums`)."""
    fpx, fpy, fc, fs = _F(px), _F(py), _F(c), _F(s)
    lo2, hi2, fcl2 = _F(r2_min), _F(r2_max), _F(cl2)
    end = lanes_end(i0, i1)
    xw, yw, iw = xs[i0:end], ys[i0:end], inside[i0:end]
    for i in range(len(xw)):
        dx = xw[i] - fpx
        dy = yw[i] - fpy
        d2 = dx * dx + dy * dy
        proj = dx * fc + dy * fs
        hit = (d2 >= lo2) & (d2 <= hi2) & (proj * abs(proj) >= fcl2 * d2)
        iw[i] |= np.uint8(hit)


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _nearest_segment(
    xs: np.ndarray,
    ys: np.ndarray,
    i0: int,
    i1: int,
    ax: float,
    ay: float,
    dx: float,
    dy: float,
    inv_l2: float,
    best: np.ndarray,
) -> None:
    """Lower ``best`` (indexed like xs) to each event's squared distance to the segment (ax, ay) + [0, 1] (dx, dy)."""
    fax, fay, fdx, fdy, finv = _F(ax), _F(ay), _F(dx), _F(dy), _F(inv_l2)
    zero, one = _F(0.0), _F(1.0)
    end = lanes_end(i0, i1)
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
def window_delta(
    xs: np.ndarray,
    ys: np.ndarray,
    offsets: np.ndarray,
    width: float,
    group: int,
    root_x: float,
    root_y: float,
    area: np.ndarray,
    r2_min: np.ndarray,
    r2_max: np.ndarray,
    cl2: float,
    sx: np.ndarray,
    sy: np.ndarray,
    seg: np.ndarray,
    inside: np.ndarray,
    best: np.ndarray,
) -> tuple[float, int]:
    """Sum of squared distances to the centreline (sx, sy) of the window's events in a search area.

    Per group of ``group`` buckets, only the areas and centreline segments whose distance to the
    root can match the group's are tested; an event farther than the margin from every candidate
    segment is measured against the whole centreline, so the result is exact.

    Args:
        xs, ys, offsets: the bucket-sorted, padded events; width: bucket width.
        area: (N_j, 6) centre, previous direction and rho range of each area (:func:`update_sorted`).
        sx, sy: (n_s,) float64 centreline samples; seg: (7, n_s - 1) scratch.
        inside, best: uint8 and float32 scratch indexed like xs.

    Returns:
        (sum of squared distances, number of events in an area).
    """
    n_areas, n_seg, n_buckets = area.shape[0], len(sx) - 1, len(offsets) - 1
    margin = max(_segments(sx, sy, root_x, root_y, seg), width)
    limit = margin * margin
    n = offsets[n_buckets]
    inside[: lanes_end(0, n)] = 0
    best[: lanes_end(0, n)] = _BIG
    total, count = 0.0, 0
    for b0 in range(0, n_buckets, group):
        b1 = min(b0 + group, n_buckets)
        i0, i1 = offsets[b0], offsets[b1]
        if i1 == i0:
            continue
        lo_rho = b0 * width
        hi_rho = b1 * width if b1 < n_buckets else math.inf
        for k in range(n_areas):
            if area[k, 4] <= hi_rho and area[k, 5] >= lo_rho:
                _mark_inside(
                    xs, ys, i0, i1, area[k, 0], area[k, 1], area[k, 2], area[k, 3], r2_min[k], r2_max[k], cl2, inside
                )
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
