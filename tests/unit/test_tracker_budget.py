"""The latency budget's decisions and the shed fraction each update carries (no timing: fixed clocks)."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.daemon.core.windows import WindowSchedule
from flagtrack.daemon.schema import EventPacket
from flagtrack.daemon.services.tracker_budget import LatencyBudget, ShedSpans

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
    # a call of many packets: as many as can still be published within the budget of the oldest
    assert budget.room(now - 10_000_000, 900_000, now)  # 10 ms late + 36 ms of work
    assert not budget.room(now - 10_000_000, 1_100_000, now)  # 10 + 44 ms


def test_the_cost_model_learns_from_the_calls() -> None:
    budget = LatencyBudget(50.0, ns_per_event=40.0, ns_per_call=200_000.0)
    for _ in range(50):
        budget.measured(100_000, 200_000 + 100_000 * 80)  # 80 ns per event
    assert budget.ns_per_event == pytest.approx(80.0, rel=1e-3)
    for _ in range(50):
        budget.measured(0, 500_000)  # empty calls measure the fixed cost
    assert budget.ns_per_call == pytest.approx(500_000.0, rel=1e-3)


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
