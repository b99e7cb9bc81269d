"""The live tracker's latency budget (``tracker.max_lag_ms``): which queued packets it sheds, and
what each update then says about it.

The tracker sheds its own work, never the recording: a packet whose updates could not be published
within the budget of its arrival at the camera (``sent_ns``), at the tracker's measured cost, is
skipped whole, before decoding (the recorder and the camera's rates still have every byte). The
core tracker restarts its windows after it (:meth:`~flagtrack.daemon.core.tracker.Tracker.skip_to`):
windows that overlap skipped camera time are gaps, not shapes made of part of their events. The
first update after a skip carries in ``shed`` the fraction of the camera time since the update
before it that was skipped. Below the budget nothing is shed, and the updates are those of
``flagtrack reconstruct``. Measurements and the policies compared: docs/live.md.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from flagtrack.daemon.schema import EventPacket

_FIRST_NS_PER_EVENT = 40.0  # the cost model's start: about the tracker's cost per event on 2 vCPUs
_FIRST_NS_PER_CALL = 300_000.0  # and per call (decoding, the chain's per-window work, publication)
_SMOOTHING = 0.2  # weight of each new measurement
_MIN_EVENTS_MEASURED = 2_000  # calls with fewer events measure the per-call cost, not the per-event one


@dataclass
class LatencyBudget:
    """Whether a packet can still be published within ``max_lag_ms`` of its arrival at the camera.

    The cost of tracking packets is a per-call and a per-event time, both measured as the tracker
    works (wall time: a tracker kept from its core is slower, and its updates later).
    """

    max_lag_ms: float
    ns_per_event: float = _FIRST_NS_PER_EVENT
    ns_per_call: float = _FIRST_NS_PER_CALL

    @property
    def max_lag_ns(self) -> float:
        return self.max_lag_ms * 1e6

    def cost_ns(self, events: int) -> float:
        """Expected wall time to track ``events`` in one call and publish their updates."""
        return self.ns_per_call + self.ns_per_event * events

    def too_late(self, packet: EventPacket, now_ns: int) -> bool:
        """Whether ``packet``, tracked alone now, would be published later than the budget allows
        (an end of stream never is: its last windows are the stream's)."""
        return not packet.end_of_stream and now_ns + self.cost_ns(packet.n_events) - packet.sent_ns > self.max_lag_ns

    def room(self, oldest_sent_ns: int, events: int, now_ns: int) -> bool:
        """Whether a call with ``events`` in all, the oldest packet sent at ``oldest_sent_ns``, still
        publishes within the budget (queued packets are tracked together up to this)."""
        return now_ns + self.cost_ns(events) - oldest_sent_ns <= self.max_lag_ns

    def measured(self, events: int, elapsed_ns: int) -> None:
        """Learn from a call that tracked ``events`` and published them in ``elapsed_ns``."""
        if events >= _MIN_EVENTS_MEASURED:
            per_event = max(elapsed_ns - self.ns_per_call, 0) / events
            self.ns_per_event += _SMOOTHING * (per_event - self.ns_per_event)
        else:
            per_call = max(elapsed_ns - self.ns_per_event * events, 0)
            self.ns_per_call += _SMOOTHING * (per_call - self.ns_per_call)


@dataclass
class ShedSpans:
    """Camera time the tracker skipped, ``[lo_us, hi_us)``, until the updates after it say so."""

    lo_us: list[int] = field(default_factory=list)
    hi_us: list[int] = field(default_factory=list)
    last_t_s: float | None = None  # the last update's time, this stream
    packets: int = 0  # skipped since the service started
    events: int = 0

    def add(self, lo_us: int, hi_us: int, events: int) -> None:
        """``[lo_us, hi_us)`` of camera time, ``events`` events, were skipped."""
        self.packets += 1
        self.events += events
        if hi_us <= lo_us:
            return
        if self.hi_us and lo_us <= self.hi_us[-1]:  # continues the last span
            self.hi_us[-1] = max(self.hi_us[-1], hi_us)
        else:
            self.lo_us.append(lo_us)
            self.hi_us.append(hi_us)

    def fractions(self, t_s: np.ndarray, window_ends_us: Callable[[np.ndarray], np.ndarray]) -> np.ndarray | None:
        """(n,) the fraction of the time of each update at ``t_s`` (from the end of the window before
        it to the end of its own; ``window_ends_us`` gives the ends) that was skipped; ``None`` when
        none was (the common case: nothing computed)."""
        if len(t_s) == 0:
            return None
        last_t_s, self.last_t_s = self.last_t_s, float(t_s[-1])
        if not self.lo_us:
            return None
        lo, hi = np.array(self.lo_us), np.array(self.hi_us)
        ends = np.asarray(window_ends_us(np.asarray(t_s)), dtype=np.int64)
        first = int(window_ends_us(np.array([last_t_s]))[0]) if last_t_s is not None else int(lo[0])
        starts = np.concatenate([[min(first, int(ends[0]) - 1)], ends[:-1]])
        overlap = np.clip(np.minimum(ends[:, None], hi) - np.maximum(starts[:, None], lo), 0, None).sum(axis=1)
        fractions = np.clip(overlap / np.maximum(ends - starts, 1), 0.0, 1.0).astype(np.float32)
        kept = hi > ends[-1]  # spans the updates have not passed yet stay for the next ones
        self.lo_us, self.hi_us = lo[kept].tolist(), hi[kept].tolist()
        return fractions

    def end_stream(self) -> None:
        """A stream ended (or a new one began): its spans are done with."""
        self.lo_us, self.hi_us, self.last_t_s = [], [], None
