"""The flag's evidence over time: how many events the flag's region had lately (stale and gathering).

Compiled helpers of :func:`.kernels.run_updates`. An event is in the flag's region when its distance
to the root falls in a bucket below the region's end (the buckets of :func:`.kernels.bucket_sort`,
the same single-precision arithmetic), and in the noise ring when it falls between the region's end
and the overflow bucket; the region's evidence over a span of events is its count less the ring's
count times the ratio of their areas (the background expected in the region). Prefix counts over
the tracker's buffer are computed lazily, only for the updates whose own window holds too little
evidence, and each event at most once while it stays in the buffer (``cls`` holds the range of
buffer indices whose prefix counts are valid).
"""

from __future__ import annotations

import math

import numpy as np

from flagtrack.daemon.core.jit import njit

_F = np.float32

LOOK_BACK_EVENTS = 1 << 16
"""At most this many events before a window's first are searched for its evidence, and kept for it:
a region with too little evidence among the sensor's last 65 536 events is stale even where
``stale_after_s`` reaches further back. Only a stream above 0.65 Mev/s (with the default 0.1 s) is
cut so; it bounds the memory the look-back holds and moves at any event rate."""


@njit(cache=True, nogil=True, error_model="numpy")
def classify(
    x: np.ndarray,
    y: np.ndarray,
    start: int,
    end: int,
    root_x: float,
    root_y: float,
    inv_width: float,
    region_end: int,
    ring_end: int,
    cum_region: np.ndarray,
    cum_ring: np.ndarray,
    cls: np.ndarray,
) -> None:
    """Make the prefix counts valid over the buffer indices ``[start, end]``.

    ``cum_region[i]`` / ``cum_ring[i]`` count the region's / ring's events among the buffer's events
    before index ``i`` (from an arbitrary base: only differences are used); ``cls`` (2,) int64 is the
    index range ``[lo, hi]`` where they are valid, extended here (restarted at ``start`` when it does
    not reach it).
    """
    if start < cls[0] or start > cls[1]:
        cls[0], cls[1] = start, start
        cum_region[start] = 0
        cum_ring[start] = 0
    rx, ry, inv, top = _F(root_x), _F(root_y), _F(inv_width), _F(ring_end)
    r, g = cum_region[cls[1]], cum_ring[cls[1]]
    for i in range(cls[1], end):
        dx = x[i] - rx
        dy = y[i] - ry
        b = np.int32(min(math.sqrt(dx * dx + dy * dy) * inv, top))
        r += 1 if b < region_end else 0
        g += 1 if region_end <= b < ring_end else 0
        cum_region[i + 1] = r
        cum_ring[i + 1] = g
    cls[1] = max(cls[1], end)


@njit(cache=True, nogil=True, error_model="numpy")
def evidence(cum_region: np.ndarray, cum_ring: np.ndarray, i0: int, i1: int, ring_ratio: float) -> float:
    """The region's evidence among the buffer's events ``i0:i1`` (classified): its events less the
    ring's times ``ring_ratio``."""
    return float(cum_region[i1] - cum_region[i0]) - float(cum_ring[i1] - cum_ring[i0]) * ring_ratio


@njit(cache=True, nogil=True, error_model="numpy")
def gather_start(
    cum_region: np.ndarray, cum_ring: np.ndarray, back: int, lo: int, hi: int, ring_ratio: float, need: float
) -> int:
    """The latest start ``i0`` in ``[back, lo]`` whose span ``i0:hi`` holds ``need`` evidence (a
    binary search: evidence grows, nearly always, as the start moves back); ``back`` if none does."""
    if evidence(cum_region, cum_ring, back, hi, ring_ratio) < need:
        return back
    a, b = back, lo  # evidence(a) >= need; find the largest such start
    while a < b:
        mid = (a + b + 1) // 2
        if evidence(cum_region, cum_ring, mid, hi, ring_ratio) >= need:
            a = mid
        else:
            b = mid - 1
    return a


@njit(cache=True, nogil=True, error_model="numpy")
def look_back(
    x: np.ndarray,
    y: np.ndarray,
    back: int,
    lo: int,
    hi: int,
    root_x: float,
    root_y: float,
    inv_width: float,
    region_end: int,
    ring_end: int,
    cum_region: np.ndarray,
    cum_ring: np.ndarray,
    cls: np.ndarray,
    ring_ratio: float,
    need: float,
    target: float,
    gathers: bool,
) -> tuple[int, int]:
    """(stale, start) of a window ``lo:hi`` whose own events hold less than ``target`` evidence.

    Stale (1) when the look-back ``back:hi`` holds less than ``need``; otherwise, when ``gathers``,
    ``start`` is where the gathered window begins (the latest start with ``target`` evidence, or
    ``back``), else ``lo``.
    """
    classify(x, y, back, hi, root_x, root_y, inv_width, region_end, ring_end, cum_region, cum_ring, cls)
    if evidence(cum_region, cum_ring, back, hi, ring_ratio) < need:
        return 1, lo
    if gathers and back < lo:
        return 0, gather_start(cum_region, cum_ring, back, lo, hi, ring_ratio, target)
    return 0, lo
