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

import statistics
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flagtrack.daemon.schema import EventPacket

_FIRST_NS_PER_EVENT = 40.0  # the cost model's start: about the tracker's cost per event on 2 vCPUs
_FIRST_NS_PER_CALL = 300_000.0  # and per call (decoding, the chain's per-window work, publication)
_SAMPLES = 31  # the cost model is the median of the last this many calls (a preempted call is one of them)
_CALL_SHARE = 8  # a call takes at most this fraction of the budget (see LatencyBudget.room)
_MIN_EVENTS_MEASURED = 2_000
_STEP = 0.02  # how much the share of packets shed evenly moves per call (see LatencyBudget.steer)
_MAX_GATHERED = 4096  # packets looked at per call at most (shed ones included)  # calls with fewer events measure the per-call cost, not the per-event one


@dataclass
class LatencyBudget:
    """Whether a packet can still be published within ``max_lag_ms`` of its arrival at the camera.

    The cost of tracking packets is a per-call and a per-event time, each the median of the last
    calls that measured it (wall time: a tracker kept from its core is slower, and its updates
    later; the median, so that one call preempted for long does not shed the next ones). The
    prediction only chooses which packets to take: a packet later than the budget is shed whatever
    the model says, so a model that guesses low sheds late, never less.
    """

    max_lag_ms: float
    ready_ns: int = 0  # packets sent before the tracker was ready (loading its kernels) are never shed
    ns_per_event: float = _FIRST_NS_PER_EVENT
    ns_per_call: float = _FIRST_NS_PER_CALL
    fraction: float = 0.0  # share of the packets shed evenly while the tracker cannot keep up
    _credit: float = 0.0
    _per_event: deque[float] = field(default_factory=lambda: deque(maxlen=_SAMPLES), repr=False)
    _per_call: deque[float] = field(default_factory=lambda: deque(maxlen=_SAMPLES), repr=False)

    @property
    def max_lag_ns(self) -> float:
        return self.max_lag_ms * 1e6

    def cost_ns(self, events: int) -> float:
        """Expected wall time to track ``events`` in one call and publish their updates."""
        return self.ns_per_call + self.ns_per_event * events

    def too_late(self, packet: EventPacket, now_ns: int) -> bool:
        """Whether ``packet``, tracked alone now, would be published later than the budget allows
        (an end of stream never is: its last windows are the stream's; nor a packet that queued up
        while the tracker started: a start is not a backlog)."""
        if packet.end_of_stream or packet.sent_ns < self.ready_ns:
            return False
        return now_ns + self.cost_ns(packet.n_events) - packet.sent_ns > self.max_lag_ns

    def steer(self, lag_ns: int) -> None:
        """Move the share of packets shed evenly (:attr:`fraction`) by the lag of the oldest packet
        waiting: up while it is past half the budget (the tracker cannot keep up: its backlog would
        exceed the budget), down while under it: the share settles where the lag stays about half
        the budget, and is 0 whenever the tracker keeps up."""
        step = _STEP if lag_ns > self.max_lag_ns / 2 else -_STEP
        self.fraction = min(1.0, max(0.0, self.fraction + step))

    def sheds(self, packet: EventPacket, now_ns: int) -> bool:
        """Whether to shed ``packet``: too late (:meth:`too_late`), or, while it waited more than half
        the budget, one in every ``1 / fraction`` packets, spread evenly (gaps of a packet here and
        there keep the chain on the flag, where a run of skipped packets loses it)."""
        if self.too_late(packet, now_ns):
            return True
        if self.fraction <= 0 or packet.end_of_stream or packet.sent_ns < self.ready_ns:
            return False
        if now_ns - packet.sent_ns <= self.max_lag_ns / 2:
            return False
        self._credit += self.fraction
        if self._credit < 1.0:
            return False
        self._credit -= 1.0
        return True

    def room(self, oldest_sent_ns: int, events: int, now_ns: int) -> bool:
        """Whether a call with ``events`` in all, the oldest packet sent at ``oldest_sent_ns``, still
        publishes within the budget, and takes at most an eighth of it: the packets that come
        meanwhile wait for it, so a long call would leave them too late (shed in bursts), where
        short ones shed a packet here and there when the tracker cannot keep up."""
        cost = self.cost_ns(events)
        return cost <= self.max_lag_ns / _CALL_SHARE and now_ns + cost - oldest_sent_ns <= self.max_lag_ns

    def measured(self, events: int, elapsed_ns: int) -> None:
        """Learn from a call that tracked ``events`` and published them in ``elapsed_ns``."""
        if events >= _MIN_EVENTS_MEASURED:
            self._per_event.append(max(elapsed_ns - self.ns_per_call, 0) / events)
            self.ns_per_event = float(statistics.median(self._per_event))  # (numpy's: 28 µs a call, this 2)
        else:
            self._per_call.append(max(elapsed_ns - self.ns_per_event * events, 0))
            self.ns_per_call = float(statistics.median(self._per_call))


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


def gather(
    first: EventPacket, recv: Callable[..., EventPacket | None], budget: LatencyBudget | None, cfg: Any
) -> tuple[list[EventPacket], frozenset[int], EventPacket | None]:
    """``first`` and the packets queued behind it (``recv(timeout_s=...)``), to be tracked in one
    call; the indices of those to shed (:meth:`LatencyBudget.sheds`); and one more received that
    there is no room for within the budget, held for the next call (or None).

    ``cfg`` (a ``TrackerServiceConfig``): at most ``max_coalesce`` packets are taken; a call with
    fewer than ``gather_events`` events and less than ``gather_ms`` of camera time waits for more
    until ``gather_ms`` after ``first`` reached the camera (a long packet is tracked at once).
    """
    batch: list[EventPacket] = []
    shed: set[int] = set()
    events, oldest_ns, more = 0, 0, first
    if budget is not None:
        budget.steer(time.time_ns() - first.sent_ns)
    gather_until_ns = first.sent_ns + int(cfg.gather_ms * 1e6)
    gather_us = cfg.gather_ms * 1e3 - 1  # camera time: a packet's last µs is t_last_us
    while True:
        now_ns = time.time_ns()
        if budget is not None and budget.sheds(more, now_ns):
            shed.add(len(batch))
        elif (
            budget is not None
            and events
            and not budget.room(min(oldest_ns, more.sent_ns), events + more.n_events, now_ns)
        ):
            return batch, frozenset(shed), more  # no room: the next call takes it (or sheds it)
        else:
            oldest_ns = min(oldest_ns, more.sent_ns) if events else more.sent_ns
            events += max(more.n_events, 1)
        batch.append(more)
        if len(batch) - len(shed) >= cfg.max_coalesce or len(batch) >= _MAX_GATHERED or more.end_of_stream:
            break
        gathered = events >= cfg.gather_events or more.t_last_us - first.t_first_us >= gather_us
        wait_ns = 0 if gathered else gather_until_ns - time.time_ns()
        if (more := recv(timeout_s=max(wait_ns, 0) * 1e-9)) is None:  # type: ignore[assignment]
            break
    return batch, frozenset(shed), None
