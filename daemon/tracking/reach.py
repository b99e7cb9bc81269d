"""The chain's length against its events, sampled while a recording is reconstructed, live, and over a
sweep point's recording (:mod:`.core.chain_reach`)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.chain_reach import ChainReach, ReachProfile
from flagtrack.daemon.core.tracker import PreparedChunk, TrackerParams
from flagtrack.drivers.formats import open_events

if TYPE_CHECKING:
    from flagtrack.daemon.tracking.setup import TrackingSetup

UPDATES_PER_CHUNK = (32, 1)
"""Found updates sampled per chunk of the recording, evenly spread over it: the first while fewer
than :data:`ENOUGH` events are gathered (a short recording has few chunks), then the second."""
ENOUGH = 20_000
EVENTS_PER_UPDATE = 250
"""At most this many of a sampled window's events are placed (evenly strided): on a 10 M-event
recording the sampling takes 82 x 0.2 ms of a 0.25 s reconstruction, within its run-to-run spread."""


class ReachSampler:
    """Gathers, chunk by chunk, the events of a few found updates along their chain.

    Call :meth:`observe` with each prepared chunk and the updates it completed (on the thread that
    advances the chain); :meth:`reach` at the end.
    """

    def __init__(self, params: TrackerParams) -> None:
        chain = params.chain
        band = chain.alpha * float(chain.lengths().max())  # a link's search area
        self._profile = ReachProfile(chain.length, band)
        self._schedule = params.schedule

    def observe(self, chunk: PreparedChunk, batch: CentrelineBatch) -> None:
        """Sample the found updates of ``batch`` whose window lies within ``chunk``'s events."""
        n = len(chunk.t)
        if n == 0 or len(batch.t_s) == 0 or chunk.raw_t is not None:
            return  # (out-of-order times: the chunk's events are not in their windows' order)
        ends_us = self._schedule.window_ends_us(batch.t_s)
        starts_us = 2 * np.floor(batch.t_s * 1e6).astype(np.int64) - ends_us  # (the window is centred)
        inside = (batch.lost == 0) & (batch.stale == 0) & (starts_us >= chunk.t[0]) & (ends_us <= chunk.t[-1])
        candidates = np.flatnonzero(inside)
        if len(candidates) == 0:
            return
        wanted = UPDATES_PER_CHUNK[self._profile.events >= ENOUGH]
        picks = candidates[np.linspace(0, len(candidates) - 1, min(wanted, len(candidates))).astype(int)]
        for j in np.unique(picks):
            lo, hi = np.searchsorted(chunk.t, (starts_us[j], ends_us[j]))
            if hi > lo:
                step = -(-(hi - lo) // EVENTS_PER_UPDATE)
                self._profile.add(chunk.x[lo:hi:step], chunk.y[lo:hi:step], batch.joints_x[j], batch.joints_y[j])

    def reach(self) -> ChainReach | None:
        """Where the events ended along the chain (None: too few to say)."""
        return self._profile.reach()


RECORDING_BYTES = 8 << 20
""":func:`recording_reach` reads at most this much of a recording (about 2 M events of EVT 3.0)."""


def recording_reach(path: Path, updates: CentrelineBatch, setup: TrackingSetup) -> ChainReach | None:
    """The reach of ``updates`` (a live tracker's, on ``path``'s clock) over the first events of the
    recording ``path`` (at most :data:`RECORDING_BYTES`, denoised and mapped as ``setup`` tracks them).

    Raises:
        FormatError: the recording cannot be read.
    """
    sampler = ReachSampler(setup.params)
    window_ends_us = setup.params.schedule.window_ends_us(updates.t_s)
    with open_events(path, chunk_bytes=1 << 20) as reader:
        tracker = setup.new_tracker((reader.info.width or 0, reader.info.height or 0))
        for chunk in reader:
            prepared = tracker.prepare(chunk.events)
            if len(prepared.t):
                lo, hi = np.searchsorted(window_ends_us, (prepared.t[0], prepared.t[-1] + 1))
                sampler.observe(prepared, updates.select(slice(lo, hi)))
            if chunk.byte_offset >= RECORDING_BYTES:
                break
    return sampler.reach()


class LiveReach:
    """The chain's reach over spans of a live stream (the live tracker's check of its length).

    :meth:`observe` samples a prepared chunk at most every ``every_us`` of camera time (a live
    tracker gets many small chunks: this bounds the cost; docs/tracking.md) and, once a span of
    ``span_us`` has passed, judges it and starts the next: it returns the sentence of a chain off
    the flag's length (:meth:`.ChainReach.misfit`), else None.
    """

    def __init__(self, params: TrackerParams, units: str, every_us: int = 100_000, span_us: int = 10_000_000) -> None:
        self._params, self._units = params, units
        self._every_us, self._span_us = every_us, span_us
        self._sampler = ReachSampler(params)
        self._span_start_us: int | None = None
        self._last_us: int | None = None
        self.last = math.nan
        """The reach of the last span judged (a fraction of L), NaN before the first (or when its
        span had too few events to judge)."""

    @property
    def span_s(self) -> float:
        """The span judged at a time, seconds of camera time."""
        return self._span_us / 1e6

    def due(self, now_us: int) -> bool:
        """Whether a chunk ending at ``now_us`` (µs) is to be sampled (or ends a span): a caller that
        tracks with ``Tracker.feed`` prepares only those chunks apart."""
        start = self._span_start_us
        return start is None or now_us < start or self._sampling(now_us) or now_us - start >= self._span_us

    def _sampling(self, now_us: int) -> bool:
        return self._last_us is None or now_us - self._last_us >= self._every_us

    def observe(self, chunk: PreparedChunk, batch: CentrelineBatch) -> str | None:
        """Sample ``chunk`` when due; the misfit of a span that ended here, else None."""
        if len(chunk.t) == 0:
            return None
        now_us = int(chunk.t[-1])
        if self._span_start_us is None or now_us < self._span_start_us:  # (a new stream's clock)
            self.restart(now_us)
        if self._sampling(now_us):
            self._last_us = now_us
            self._sampler.observe(chunk, batch)
        if self._span_start_us is None or now_us - self._span_start_us < self._span_us:
            return None
        reach = self._sampler.reach()
        self.restart(now_us)
        self.last = math.nan if reach is None else reach.reach
        return None if reach is None else reach.misfit(self._params.chain.length, self._units)

    def restart(self, now_us: int | None = None) -> None:
        """Forget the span so far (a new stream; :attr:`last` stays until the next span is judged)."""
        self._sampler = ReachSampler(self._params)
        self._span_start_us, self._last_us = now_us, None
