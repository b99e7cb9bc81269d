"""The latency budget's decisions and the shed fraction each update carries (no timing: fixed clocks)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from flagtrack.daemon.core.windows import WindowSchedule
from flagtrack.daemon.schema import EventPacket
from flagtrack.daemon.services.tracker import TrackerServiceConfig
from flagtrack.daemon.services.tracker_budget import LatencyBudget, ShedSpans, gather

ENDS = WindowSchedule.uniform(2.5e-4).window_ends_us


def _packet(sent_ns: int, n_events: int = 1000, end: bool = False) -> EventPacket:
    return EventPacket("cam0", 0, 0, 999, n_events, 640, 480, "evt3", sent_ns, end_of_stream=end)


def test_a_packet_is_too_late_when_its_updates_would_come_after_the_budget() -> None:
    budget = LatencyBudget(50.0, ns_per_event=40.0, ns_per_call=200_000.0)
    now = 10**12
    cost = 200_000 + 40 * 1000  # 0.24 ms for a packet of 1000 events
    assert not budget.too_late(_packet(now - 49_000_000), now)
    assert not budget.too_late(_packet(now - 50_000_000 + cost), now)  # exactly within
    assert budget.too_late(_packet(now - 50_000_000 + cost - 1), now)
    assert not budget.too_late(_packet(now - 10**9, end=True), now)  # an end of stream is never shed
    budget.ready_ns = now - 10**8
    assert not budget.too_late(_packet(now - 10**8 - 1), now)  # nor what queued before the tracker was ready
    assert budget.too_late(_packet(now - 10**8), now)
    # a call of many packets: as many as can still be published within the budget of the oldest, and
    # at most an eighth of the budget's work (6.25 ms)
    assert budget.room(now - 40_000_000, 100_000, now)  # 40 ms late + 4.2 ms of work
    assert not budget.room(now - 47_000_000, 100_000, now)  # 47 + 4.2 ms
    assert not budget.room(now, 200_000, now)  # 8.2 ms of work: too long a call


def test_the_cost_model_learns_from_the_calls() -> None:
    budget = LatencyBudget(50.0, ns_per_event=40.0, ns_per_call=200_000.0)
    for _ in range(50):
        budget.measured(100_000, 200_000 + 100_000 * 80)  # 80 ns per event
    assert budget.ns_per_event == pytest.approx(80.0)
    for _ in range(10):
        budget.measured(100_000, 10**9)  # a few calls preempted for a second: not the cost of the next ones
    assert budget.ns_per_event == pytest.approx(80.0)
    for _ in range(50):
        budget.measured(0, 500_000)  # empty calls measure the fixed cost
    assert budget.ns_per_call == pytest.approx(500_000.0)


def test_updates_carry_the_share_of_their_time_that_was_skipped() -> None:
    spans = ShedSpans()
    assert spans.fractions(np.array([125e-6, 375e-6, 625e-6, 875e-6]), ENDS) is None  # windows end 250..1000
    spans.add(1000, 3000, 5000)  # [1000, 3000) µs skipped: windows ending 1250..3000 were gaps
    got = spans.fractions(np.array([3125e-6, 3375e-6]), ENDS)  # windows [3000, 3250), [3250, 3500)
    assert got is not None and got.dtype == np.float32
    np.testing.assert_allclose(got, [2000 / 2250, 0.0])  # from 1000 (the last end) to 3250, 2000 skipped
    assert spans.fractions(np.array([3625e-6]), ENDS) is None  # passed: nothing left to say
    assert (spans.packets, spans.events) == (1, 5000)


def test_a_span_longer_than_the_updates_so_far_is_shared_across_calls() -> None:
    spans = ShedSpans()
    spans.fractions(np.array([125e-6]), ENDS)  # one update, window ending at 250
    spans.add(250, 2000, 10)
    spans.add(2000, 4000, 10)  # continues the span
    np.testing.assert_allclose(spans.fractions(np.array([2125e-6]), ENDS), [1.0])  # [250, 2250): all skipped
    np.testing.assert_allclose(spans.fractions(np.array([4125e-6]), ENDS), [1750 / 2000])  # [2250, 4250)
    spans.end_stream()
    assert spans.fractions(np.array([125e-6]), ENDS) is None


def test_a_skip_before_any_update_counts_from_its_own_start() -> None:
    spans = ShedSpans()
    spans.add(0, 1000, 10)
    np.testing.assert_allclose(spans.fractions(np.array([1125e-6]), ENDS), [1000 / 1250])


class _Queue:
    """Packets to hand out, and the timeouts each receive was given."""

    def __init__(self, packets: list[EventPacket]) -> None:
        self.packets, self.timeouts = list(packets), []

    def recv(self, timeout_s: float) -> EventPacket | None:
        self.timeouts.append(timeout_s)
        return self.packets.pop(0) if self.packets else None


def _cfg(**values: float) -> TrackerServiceConfig:
    return TrackerServiceConfig(**{"max_coalesce": 64, "gather_ms": 4.0, "gather_events": 20_000, **values})


def test_without_a_budget_every_queued_packet_is_taken_up_to_max_coalesce() -> None:
    now = time.time_ns()
    queue = _Queue([_packet(now - 10**12, 30_000) for _ in range(10)])
    batch, shed, held = gather(_packet(now - 10**12, 30_000), queue.recv, None, _cfg(max_coalesce=8))
    assert (len(batch), shed, held) == (8, frozenset(), None) and len(queue.packets) == 3


def test_the_late_front_is_shed_and_what_has_no_room_is_held() -> None:
    now = time.time_ns()
    budget = LatencyBudget(400_000.0, ns_per_event=1e6, ns_per_call=0.0)  # 1 s per 1000 events, 400 s of budget
    old = [_packet(now - 1000 * 10**9) for _ in range(3)]  # 1000 s late
    fresh = [_packet(now) for _ in range(60)]  # 1 s of work each: 50 fit in an eighth of the budget
    queue = _Queue(old[1:] + fresh)
    batch, shed, held = gather(old[0], queue.recv, budget, _cfg(max_coalesce=100))
    assert shed == {0, 1, 2} and len(batch) == 53 and held is fresh[50]


def test_a_call_with_few_events_waits_for_more_and_one_with_enough_does_not() -> None:
    now = time.time_ns() + 10**10  # (sent "in 10 s": its gathering deadline is far ahead whatever the load)
    few = _Queue([_packet(now, 1000) for _ in range(3)])
    gather(_packet(now, 1000), few.recv, None, _cfg())
    assert all(timeout > 0 for timeout in few.timeouts)  # 1000 events a packet: it waits for the next
    enough = _Queue([_packet(now, 30_000) for _ in range(3)])
    gather(_packet(now, 30_000), enough.recv, None, _cfg())
    assert enough.timeouts == [0.0, 0.0, 0.0, 0.0]  # (the last: is there more?)
    sent_ns = time.time_ns()
    none = _Queue([_packet(sent_ns, 1000)])
    gather(_packet(sent_ns, 1000), none.recv, None, _cfg(gather_ms=0.0))
    assert none.timeouts == [0.0, 0.0]


def test_a_tracker_that_cannot_keep_up_sheds_single_packets_evenly_not_runs() -> None:
    budget = LatencyBudget(50.0, ns_per_event=10.0, ns_per_call=0.0)
    now = 10**12
    for _ in range(25):  # the oldest packet waited 30 ms: past half the budget, call after call
        budget.steer(30_000_000)
    assert budget.fraction == pytest.approx(0.5)
    waited = [budget.sheds(_packet(now - 30_000_000), now) for _ in range(40)]
    assert sum(waited) == 20 and not any(a and b for a, b in zip(waited, waited[1:]))  # every other one
    assert not any(budget.sheds(_packet(now - 20_000_000), now) for _ in range(40))  # under half the budget: none
    for _ in range(25):
        budget.steer(20_000_000)  # caught up (under half the budget): back to shedding nothing
    assert budget.fraction == 0.0
    assert not any(budget.sheds(_packet(now - 30_000_000), now) for _ in range(40))


def test_a_call_holding_gather_ms_of_camera_time_waits_for_no_more() -> None:
    """Four 1 ms packets, or one of 4 ms, are the gathering's 4 ms: taken at once, not waited on."""
    now = time.time_ns() + 10**10  # (a deadline far ahead whatever the load)

    def spanning(first_us: int, last_us: int) -> EventPacket:
        return EventPacket("cam0", 0, first_us, last_us, 1000, 640, 480, "evt3", now)

    ms = _Queue([spanning(k * 1000, k * 1000 + 999) for k in range(1, 5)])
    batch, _, _ = gather(spanning(0, 999), ms.recv, None, _cfg())
    assert len(batch) == 5 and [t > 0 for t in ms.timeouts] == [True, True, True, False, False]
    long = _Queue([spanning(4000, 7999)])
    batch, _, _ = gather(spanning(0, 3999), long.recv, None, _cfg())
    assert len(batch) == 2 and long.timeouts == [0.0, 0.0]  # (taken because it was queued: no wait)
