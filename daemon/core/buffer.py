"""The tracker's event buffer: time-sorted kept events of the pending windows and their look-back."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

SPARE = 2
"""Free room a grown buffer keeps, in live events: a compaction moves the live events to the front, so
each event is moved about ``1 / SPARE`` times (docs/live.md)."""


def _empty(dtype: type) -> np.ndarray:
    return np.empty(0, dtype=dtype)


@dataclass
class EventBuffer:
    """Time-sorted kept events (t µs, x, y) in ``[start, n)`` of growable arrays.

    Events before ``start`` are dropped; the arrays are compacted only when they need room (each
    event is moved about once however often the front is dropped). ``cum_region``, ``cum_ring`` and
    ``cls`` are the prefix counts of :mod:`.evidence` (valid over the absolute indices ``cls[0]..cls[1]``).
    """

    t: np.ndarray = field(default_factory=lambda: _empty(np.int64))
    x: np.ndarray = field(default_factory=lambda: _empty(np.float32))
    y: np.ndarray = field(default_factory=lambda: _empty(np.float32))
    cum_region: np.ndarray = field(default_factory=lambda: np.zeros(1, dtype=np.int64))
    cum_ring: np.ndarray = field(default_factory=lambda: np.zeros(1, dtype=np.int64))
    cls: np.ndarray = field(default_factory=lambda: np.zeros(2, dtype=np.int64))
    start: int = 0
    n: int = 0
    last_dropped_t: int = np.iinfo(np.int64).min  # latest event dropped from the front (or the stream start)

    @property
    def times(self) -> np.ndarray:
        """(n - start,) the live events' times."""
        return self.t[self.start : self.n]

    def reserve(self, extra: int) -> None:
        """Make room for ``extra`` more events after ``n``: compacting, and growing where the room
        left would then hold fewer than the live events (so that an event is moved at most once on
        average however long the look-back; growing leaves ``SPARE`` times the live events free)."""
        if self.n + extra <= len(self.t):
            return
        live = self.n - self.start
        if 2 * live + extra > len(self.t):
            self._grow(max((1 + SPARE) * live + extra, 1024))
        elif self.start:
            self._compact()

    def preallocate(self, events: int) -> None:
        """Room for ``events`` live events and ``SPARE`` times as many free, its memory written once
        now: the first touch of fresh pages costs the kernel's time, better spent before a stream
        than in its first windows."""
        cap = (1 + SPARE) * max(events, self.n - self.start)
        if cap <= len(self.t):
            return
        self._grow(cap)
        for arr in (self.t, self.x, self.y):
            arr[self.n :] = 0
        for arr in (self.cum_region, self.cum_ring):  # (valid only over cls: the rest is free)
            arr[self.n + 1 :] = 0

    def emptied(self) -> EventBuffer:
        """An empty buffer in this one's memory, for a fresh tracker (this buffer must not be used
        again: its arrays are the new one's)."""
        empty = EventBuffer(self.t, self.x, self.y, self.cum_region, self.cum_ring)
        empty.forget_counts()
        return empty

    def _grow(self, cap: int) -> None:
        """New arrays of ``cap`` events holding the live ones at their front."""
        live = self.n - self.start
        for name in ("t", "x", "y"):
            old = getattr(self, name)
            new = np.empty(cap, dtype=old.dtype)
            new[:live] = old[self.start : self.n]
            setattr(self, name, new)
        self.start, self.n = 0, live
        # the prefix counts are made again where needed (most windows never need them): not copied
        self.cum_region = np.empty(cap + 1, dtype=np.int64)
        self.cum_ring = np.empty(cap + 1, dtype=np.int64)
        self.forget_counts()

    def _compact(self) -> None:
        cut, live = self.start, self.n - self.start
        for arr in (self.t, self.x, self.y):
            arr[:live] = arr[cut : self.n]
        lo, hi = int(self.cls[0]), int(self.cls[1])
        if hi >= cut and hi > lo:
            lo = max(lo, cut)
            self.cum_region[lo - cut : hi - cut + 1] = self.cum_region[lo : hi + 1].copy()
            self.cum_ring[lo - cut : hi - cut + 1] = self.cum_ring[lo : hi + 1].copy()
            self.cls[:] = (lo - cut, hi - cut)
        else:
            self.cls[:] = 0
            self.cum_region[0] = self.cum_ring[0] = 0
        self.start, self.n = 0, live

    def drop_before(self, t_us: float, *, keep: tuple[float, int] | None = None) -> None:
        """Drop the events before ``t_us`` (they stay in the arrays until a compaction); with ``keep``
        = (``at_us``, ``n``), also those more than ``n`` events before the first at or after ``at_us``."""
        cut = int(np.searchsorted(self.times, np.int64(math.ceil(t_us)), side="left"))
        if keep is not None:
            at_us, n = keep
            cut = max(cut, int(np.searchsorted(self.times, np.int64(math.ceil(at_us)), side="left")) - n)
        if cut:
            self.last_dropped_t = int(self.t[self.start + cut - 1])
            self.start += cut

    def forget_counts(self) -> None:
        """The events were reordered: the prefix counts are computed again when next needed."""
        self.cls[:] = self.start
        self.cum_region[self.start] = self.cum_ring[self.start] = 0
