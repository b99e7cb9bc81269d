"""The incremental tracker: events in (any chunking, time order), centreline updates out.

``Tracker.feed(events)`` denoises and maps the events, buffers them (at most the pending windows'
worth plus the chunk) and returns the updates whose windows are complete, i.e. whose end is covered
by the events seen so far; ``finish()`` returns the last (partial) windows at the end of the stream.
The offline ``flagtrack reconstruct`` and the live tracker service drive the same object, and the
results do not depend on where the stream is cut: the denoise map, the update clock and the chain
angles are the whole state carried between calls.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from flagtrack.daemon.core.buffer import EventBuffer
from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.chain import AreaGeometry, ChainParams, ChainState
from flagtrack.daemon.core.denoise import BackgroundActivityFilter, DenoiseParams
from flagtrack.daemon.core.evidence import LOOK_BACK_EVENTS
from flagtrack.daemon.core.kernels import run_updates
from flagtrack.daemon.core.lost import NEVER, SUPPORTED
from flagtrack.daemon.core.lost_params import LostParams
from flagtrack.daemon.core.mapping import PointMapping
from flagtrack.daemon.core.smoothing import REL_TOL, n_samples
from flagtrack.daemon.core.windows import UpdateClock, WindowSchedule

log = logging.getLogger(__name__)

MAX_SAMPLES = 100_001
"""Most samples of a smoothed centreline (``ds`` at least L / 100 000)."""
_BATCH_UPDATES = 4096  # updates per compiled call (bounds the output arrays) ...
_BATCH_VALUES = 1 << 22  # ... and at most about this many samples and joints in them (long centrelines)
_PREALLOCATE_SLACK_S = 0.01  # events past the windows: a chunk (a gathered call holds a few ms)
_DELTA_GROUP = 4  # rho buckets (of r/4) per Delta_RMS group: about one link length


@dataclass(frozen=True)
class TrackerParams:
    """Everything that defines a reconstruction.

    Attributes:
        chain: chain geometry and search areas.
        schedule: update times and window lengths.
        ds: step of the smoothed centreline; ``None``: L / 50 (the paper).
        denoise: background-activity filter, ``None`` to use every event (the paper).
        max_gap_s: a window without events that starts more than this after the last event is
            not emitted (the chain would not move; keeps a long pause from making millions of
            identical updates); ``None``: emit every window.
        rel_tol: tolerance of the smoothed length, relative to L.
        lost: loss-of-track detection and re-acquisition (the robust method); ``None``: the
            paper's update, every ``lost`` 0.
        stale_after_s: an update whose flag's region held less than ``lost.min_events`` (the
            defaults' without ``lost``) of evidence over the last this many seconds is ``stale``
            (its shape was not measured); the robust method also gathers a quiet window's events
            from that far back (:mod:`.evidence`; at most :data:`.evidence.LOOK_BACK_EVENTS` events
            before the window); ``None``: no stale verdict, every ``stale`` 0.
    """

    chain: ChainParams
    schedule: WindowSchedule
    ds: float | None = None
    denoise: DenoiseParams | None = None
    max_gap_s: float | None = 1.0
    rel_tol: float = REL_TOL
    lost: LostParams | None = None
    stale_after_s: float | None = None

    def __post_init__(self) -> None:
        if self.ds is not None and not self.chain.length / (MAX_SAMPLES - 1) <= self.ds <= self.chain.length:
            raise ValueError(f"ds must be in [L / {MAX_SAMPLES - 1}, L], got {self.ds}")
        if self.max_gap_s is not None and not self.max_gap_s > 0:
            raise ValueError(f"max_gap_s must be positive, got {self.max_gap_s}")
        if self.stale_after_s is not None and not 0 < self.stale_after_s <= 3600:
            raise ValueError(f"stale_after_s must be in (0, 3600] s, got {self.stale_after_s}")

    @property
    def n_s(self) -> int:
        """Samples per centreline."""
        return n_samples(self.chain.length, self.ds if self.ds is not None else self.chain.length / 50)

    @property
    def s(self) -> np.ndarray:
        """(n_s,) arc length of the samples."""
        return np.linspace(0.0, self.chain.length, self.n_s)


@dataclass
class TrackerStats:
    """Counters of a tracker's life (for logs and reports)."""

    events_in: int = 0
    events_kept: int = 0
    events_out_of_order: int = 0
    updates: int = 0
    lost_updates: int = 0
    lost_stretches: int = 0
    stale_updates: int = 0
    first_t_us: int | None = None
    last_t_us: int | None = None


@dataclass(frozen=True)
class PreparedChunk:
    """A chunk denoised and mapped by :meth:`Tracker.prepare`, for :meth:`Tracker.advance`.

    Attributes:
        t, x, y: (n_kept,) the kept events (µs; tracking-plane coordinates).
        n_in: events of the chunk before denoising.
        first_t_us: the chunk's first event time (None when empty).
        t_max_us: latest event time of the stream so far.
        raw_t: the chunk's times when they are not in order (the tracker sorts them in), else None.
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    n_in: int
    first_t_us: int | None
    t_max_us: int
    raw_t: np.ndarray | None


class Tracker:
    """Incremental centreline tracker (the paper's chain, optionally denoised).

    Args:
        params: the reconstruction parameters.
        state: initial chain; ``None``: straight along ``params.chain.direction_deg``.
        mapping: pixel -> tracking-plane mapping applied to every event; ``None``: identity.
        sensor_size: (width, height) in pixels if known (sizes the denoise map up front).
    """

    def __init__(
        self,
        params: TrackerParams,
        state: ChainState | None = None,
        mapping: PointMapping | None = None,
        sensor_size: tuple[int, int] = (0, 0),
    ) -> None:
        self.params = params
        chain = params.chain
        self._angles = np.array((state or ChainState.at_rest(chain)).angles_rad, dtype=np.float64)
        if self._angles.shape != (chain.n_joints,):
            raise ValueError(f"initial state has {self._angles.shape} angles for {chain.n_joints} joints")
        self._geo = AreaGeometry.of(chain)
        self._lost_cfg = _lost_config(params)
        # the last update's verdict, updates to hold lost, lost stretch (carried like the angles)
        self._lost_prev = np.array([0, 0, 0, NEVER, SUPPORTED], dtype=np.int64)
        self._last_lost = 0  # the last update's lost flag (stretches are counted across calls)
        self._mapping = mapping
        self._filter = BackgroundActivityFilter(params.denoise, *sensor_size)
        self._buffer = EventBuffer()
        self._clock: UpdateClock | None = None
        self._t_max_us = np.iinfo(np.int64).min
        self._prepared_t_max_us = self._t_max_us  # the same, for the chunks prepare() has seen
        self._max_step_back_us = 0  # largest step back in time seen in the stream (sensor jitter)
        # (whole µs: the buffer's int64 times are searched with it, and a float would copy them as float64)
        self._look_back_us = 0 if params.stale_after_s is None else round(params.stale_after_s * 1e6)
        self._look_back_events = LOOK_BACK_EVENTS if self._look_back_us else 0  # (and at most this many events)
        # a window ending within this of the last event starts at or before it (see feed)
        self._shortest_window_us = math.floor(min(seg.tau_s for seg in params.schedule.segments) * 1e6)
        self._finished = False
        self.s = params.s
        self._batch_updates = max(1, min(_BATCH_UPDATES, _BATCH_VALUES // (len(self.s) + chain.n_joints + 1)))
        self.stats = TrackerStats()

    def preallocate(self, events_per_s: float) -> None:
        """Allocate the event buffer now for a stream of ``events_per_s``: its look-back and longest
        window, and the buffer's spare room (growing it during the first windows of a fast stream
        costs them tens of milliseconds of fresh memory)."""
        longest_us = max(seg.tau_s for seg in self.params.schedule.segments) * 1e6
        look_back = min(events_per_s * self._look_back_us * 1e-6, self._look_back_events)
        self._buffer.preallocate(math.ceil(look_back + events_per_s * (longest_us * 1e-6 + _PREALLOCATE_SLACK_S)))

    def take_buffer_of(self, old: Tracker) -> None:
        """Track in the event buffer of ``old``, a tracker of an ended stream that is not used again
        (a fresh tracker of the live service: its memory is written already). Call before the first
        feed."""
        if self._clock is not None:
            raise RuntimeError("take_buffer_of() after the first events")
        self._buffer = old._buffer.emptied()
        old._buffer = EventBuffer()

    @property
    def state(self) -> ChainState:
        """The current chain (a copy)."""
        return ChainState(self._angles.copy())

    def feed(self, events: np.ndarray, complete_through_us: int | None = None) -> CentrelineBatch:
        """Take a chunk of time-ordered events (EVENT_DTYPE); return the updates now complete.

        A window is complete once a later event has come, or, sooner, once the source says that
        every event up to ``complete_through_us`` has been fed (a live camera packet's horizon: the
        window ending at the packet's end is published with that packet, not the next one). Only
        windows that start at or before the last event are completed so: one that starts later
        waits for the next event, and at the end of the stream is not emitted, as offline. A
        sensor whose times step back can still send an event before the horizon later: the
        horizon is trusted only up to the largest step back seen so far in the stream. An event
        that comes after its window was taken is counted as out of order and not used, as at a
        chunk boundary offline.
        """
        if self._finished:
            raise RuntimeError("feed() after finish()")
        self._ingest(events)
        return self._run(self._complete_before_us(complete_through_us), None)

    def prepare(self, events: np.ndarray) -> PreparedChunk:
        """First half of :meth:`feed`: denoise and map a chunk into arrays of its own.

        Touches only the noise filter, the mapping and the order check, none of which
        :meth:`advance` uses, so one thread may prepare the next chunk while another advances the
        chain on the last: ``advance(prepare(e), h)`` returns exactly what ``feed(e, h)`` does.
        Chunks must be prepared and advanced in the same order.
        """
        n_in = len(events)
        t = np.empty(n_in, dtype=np.int64)
        x = np.empty(n_in, dtype=np.float32)
        y = np.empty(n_in, dtype=np.float32)
        end, ordered, t_max = self._filter.filter_into(events, t, x, y, 0, self._prepared_t_max_us)
        if self._mapping is not None and end > 0:
            x[:end], y[:end] = self._mapping.map(x[:end], y[:end])
        self._prepared_t_max_us = t_max
        return PreparedChunk(
            t=t[:end],
            x=x[:end],
            y=y[:end],
            n_in=n_in,
            first_t_us=int(events["t"][0]) if n_in else None,
            t_max_us=t_max,
            raw_t=None if ordered else np.array(events["t"]),
        )

    def advance(self, chunk: PreparedChunk, complete_through_us: int | None = None) -> CentrelineBatch:
        """Second half of :meth:`feed`: add a prepared chunk and return the updates now complete."""
        if self._finished:
            raise RuntimeError("feed() after finish()")
        if chunk.n_in:
            stats = self.stats
            if self._clock is None:
                assert chunk.first_t_us is not None
                self._clock = UpdateClock(self.params.schedule, chunk.first_t_us)
                stats.first_t_us = chunk.first_t_us
                self._buffer.last_dropped_t = chunk.first_t_us
            buf, n_kept = self._buffer, len(chunk.t)
            buf.reserve(n_kept)
            buf.t[buf.n : buf.n + n_kept] = chunk.t
            buf.x[buf.n : buf.n + n_kept] = chunk.x
            buf.y[buf.n : buf.n + n_kept] = chunk.y
            buf.n += n_kept
            if chunk.raw_t is not None:
                self._sort_buffer(chunk.raw_t)
            stats.events_in += chunk.n_in
            stats.events_kept += n_kept
            self._t_max_us = chunk.t_max_us
            stats.last_t_us = chunk.t_max_us
        return self._run(self._complete_before_us(complete_through_us), None)

    def _complete_before_us(self, complete_through_us: int | None) -> int:
        """Windows ending before this are complete: the latest event, or later when the source
        vouches for its horizon (``complete_through_us``), at most one shortest window on."""
        complete_before_us = self._t_max_us
        if complete_through_us is not None:
            trusted_us = int(complete_through_us) + 1 - self._max_step_back_us
            complete_before_us = max(complete_before_us, min(trusted_us, self._t_max_us + self._shortest_window_us))
        return complete_before_us

    def skip_to(self, t_us: int) -> int:
        """The stream's events before ``t_us`` will not be fed (a live tracker shed them): the
        pending windows that start before ``t_us`` are dropped, not emitted (a gap, not a shape
        made of part of their events), and the next window is the schedule's first that starts at
        or after it. Returns the windows dropped. Events fed later that are older than ``t_us``
        are out of order, as at a chunk boundary."""
        if self._finished:
            raise RuntimeError("skip_to() after finish()")
        clock, dropped = self._clock, 0
        if clock is None:  # nothing fed yet: the first event starts the schedule, as always
            return 0
        while len(skipped := clock.take(np.iinfo(np.int64).min, int(t_us) - 1, _BATCH_UPDATES)[0]):
            dropped += len(skipped)
        self._buffer.drop_before(t_us)
        self._buffer.last_dropped_t = max(self._buffer.last_dropped_t, int(t_us))  # a pause counts from here
        return dropped

    def finish(self) -> CentrelineBatch:
        """End of stream: return the remaining updates whose windows started before the last event."""
        self._finished = True
        return self._run(self._t_max_us, self._t_max_us)

    def _ingest(self, events: np.ndarray) -> None:
        n_in = len(events)
        if n_in == 0:
            return
        stats = self.stats
        if self._clock is None:
            self._clock = UpdateClock(self.params.schedule, int(events["t"][0]))
            stats.first_t_us = int(events["t"][0])
            self._buffer.last_dropped_t = stats.first_t_us  # pauses count from the stream's start
        buf = self._buffer
        buf.reserve(n_in)
        start = buf.n
        end, ordered, t_max = self._filter.filter_into(events, buf.t, buf.x, buf.y, start, self._t_max_us)
        if self._mapping is not None and end > start:
            mx, my = self._mapping.map(buf.x[start:end], buf.y[start:end])
            buf.x[start:end] = mx
            buf.y[start:end] = my
        buf.n = end
        if not ordered:
            self._sort_buffer(events["t"])
        stats.events_in += n_in
        stats.events_kept += end - start
        self._t_max_us = self._prepared_t_max_us = t_max
        stats.last_t_us = t_max

    def _sort_buffer(self, t: np.ndarray) -> None:
        late = int(np.count_nonzero(t < self._t_max_us)) + int(np.count_nonzero(t[1:] < t[:-1]))
        latest_before = np.maximum.accumulate(np.concatenate([[max(self._t_max_us, int(t[0]))], t[:-1]]))
        step_back_us = int((latest_before - t).max())
        if step_back_us > max(self._max_step_back_us, 1000):
            log.info("event times stepped back by %d µs: windows wait that long past a source's horizon", step_back_us)
        self._max_step_back_us = max(self._max_step_back_us, step_back_us)
        if self.stats.events_out_of_order == 0:
            log.warning("events out of time order; sorting them in (later ones are counted, not logged)")
        self.stats.events_out_of_order += late
        buf = self._buffer
        live = slice(buf.start, buf.n)
        order = np.argsort(buf.t[live], kind="stable")
        for arr in (buf.t, buf.x, buf.y):
            arr[live] = arr[live][order]
        buf.forget_counts()

    def _run(self, complete_before_us: int, started_before_us: int | None) -> CentrelineBatch:
        clock = self._clock
        if clock is None:
            return self._empty()
        batches = []
        while True:
            t_us, lo_us, hi_us = clock.take(complete_before_us, started_before_us, self._batch_updates)
            if len(t_us) == 0:
                break
            batch = self._updates(t_us, lo_us, hi_us)
            if len(batch):
                batches.append(batch)
        next_us = clock.next_window_start_us()
        self._buffer.drop_before(next_us - self._look_back_us, keep=(next_us, self._look_back_events))
        if not batches:
            return self._empty()
        return batches[0] if len(batches) == 1 else CentrelineBatch.concatenate(batches)

    def _updates(self, t_us: np.ndarray, lo_us: np.ndarray, hi_us: np.ndarray) -> CentrelineBatch:
        buf, geo, chain = self._buffer, self._geo, self.params.chain
        times = buf.times
        lo_idx = np.searchsorted(times, lo_us, side="left")
        hi_idx = np.searchsorted(times, hi_us, side="left")
        if self.params.max_gap_s is not None and bool((hi_idx == lo_idx).any()):  # gaps are empty windows
            if len(times):
                previous = np.where(lo_idx > 0, times[np.maximum(lo_idx - 1, 0)], buf.last_dropped_t)
            else:  # every event so far was filtered out (a still flag and sensor noise)
                previous = np.full(len(lo_us), buf.last_dropped_t, dtype=np.float64)
            gap = (hi_idx == lo_idx) & (lo_us - previous > self.params.max_gap_s * 1e6)
            if gap.any():
                keep = ~gap
                t_us, lo_idx, hi_idx, hi_us = t_us[keep], lo_idx[keep], hi_idx[keep], hi_us[keep]
        lo_idx, hi_idx = lo_idx + buf.start, hi_idx + buf.start
        k, n_j, n_s = len(t_us), chain.n_joints, len(self.s)
        jx, jy = np.empty((k, n_j + 1)), np.empty((k, n_j + 1))
        sx, sy = np.empty((k, n_s)), np.empty((k, n_s))
        delta, used, lost = np.empty(k), np.empty(k, dtype=np.int64), np.empty(k, dtype=np.uint8)
        stale = np.empty(k, dtype=np.uint8)
        run_updates(
            buf.x,
            buf.y,
            lo_idx,
            hi_idx,
            float(chain.root[0]),
            float(chain.root[1]),
            self._angles,
            geo.lengths,
            geo.r2_min,
            geo.r2_max,
            geo.cos_limit_signed_sq,
            geo.cos_refine_signed_sq,
            geo.half_angle_rad,
            chain.min_events,
            geo.bucket_width,
            geo.n_buckets,
            _DELTA_GROUP,
            float(chain.length),
            self.params.rel_tol,
            jx,
            jy,
            sx,
            sy,
            delta,
            used,
            self._lost_cfg,
            self._lost_prev,
            lost,
            buf.t,
            buf.start,
            self._look_back_us,
            self._look_back_events,
            hi_us,
            buf.cum_region,
            buf.cum_ring,
            buf.cls,
            stale,
        )
        self.stats.updates += k
        if k:
            self.stats.lost_updates += int(lost.sum())
            self.stats.lost_stretches += int(np.count_nonzero(np.diff(lost, prepend=np.uint8(self._last_lost)) == 1))
            self.stats.stale_updates += int(stale.sum())
            self._last_lost = int(lost[-1])
        return CentrelineBatch(
            t_s=t_us * 1e-6,
            s=self.s,
            x=sx,
            y=sy,
            joints_x=jx,
            joints_y=jy,
            delta_rms=delta,
            n_events=used,
            lost=lost,
            stale=stale,
        )

    def _empty(self) -> CentrelineBatch:
        n_j, n_s = self.params.chain.n_joints, len(self.s)
        return CentrelineBatch(
            t_s=np.empty(0),
            s=self.s,
            x=np.empty((0, n_s)),
            y=np.empty((0, n_s)),
            joints_x=np.empty((0, n_j + 1)),
            joints_y=np.empty((0, n_j + 1)),
            delta_rms=np.empty(0),
            n_events=np.empty(0, dtype=np.int64),
        )


def _lost_config(params: TrackerParams) -> np.ndarray:
    """(13,) float64 the kernel's loss-of-track and stale settings (see :func:`.kernels.run_updates`)."""
    chain = params.chain
    lost = params.lost if params.lost is not None else LostParams()
    lengths = chain.lengths()
    refine_deg = chain.refine_deg if chain.refine_deg is not None else 10.0
    return np.array(
        [
            1.0 if params.lost is not None else 0.0,
            lost.min_events,
            lost.min_fit,
            (lost.band * chain.length) ** 2,
            chain.length + chain.alpha * float(lengths.max()),  # the chain's reach: the flag's region
            1.0 if lost.reacquire else 0.0,
            math.radians(lost.cone_deg),
            math.radians(refine_deg),
            lost.hold_updates,
            1.0 if params.stale_after_s is not None else 0.0,
            lost.gather_events,
            lost.tip_window_s * 1e6,
            lost.search_fit,
        ]
    )


def track(
    events: np.ndarray, params: TrackerParams, state: ChainState | None = None, mapping: PointMapping | None = None
) -> CentrelineBatch:
    """Reconstruct a whole in-memory recording (one feed and finish)."""
    tracker = Tracker(params, state, mapping)
    return CentrelineBatch.concatenate([tracker.feed(events), tracker.finish()])
