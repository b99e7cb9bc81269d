"""The live tracker's latency budget over a real bus: a backlog older than ``max_lag_ms`` is shed,
whole packets, as gaps that the next update reports (``shed``); below the budget nothing is shed and
the updates are those of the offline tracker."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.tracker import Tracker
from flagtrack.daemon.schema import CentrelineMessage, EventPacket, TrackerStatus
from flagtrack.daemon.services.tracker import SHED, TrackerService, TrackerServiceConfig
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.sim.quickline import line_events
from tests.fakes.helpers import wait_subscribed
from tests.integration.test_tracker_service import CONFIG, FLAG, packets_of
from tests.integration.test_transport import free_port, received_to_final, wait_for

BUDGET_MS = 1000.0  # far above any stall of a loaded test machine: only the packets sent long ago are late
N_PACKETS = 60


@contextmanager
def budgeted_tracker(namespace: str) -> Iterator[tuple[Bus, TrackerService]]:
    """A tracker service with a latency budget, running on its own bus and thread; yields a second bus."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    params = CONFIG.tracker_params()
    with (
        Bus(BusConfig(namespace=namespace, listen=(endpoint,))) as trk_bus,
        Bus(BusConfig(namespace=namespace, connect=(endpoint,))) as cam_bus,
    ):
        service = TrackerService(
            trk_bus,
            TrackerServiceConfig(status_interval_s=0.1),
            lambda: Tracker(params, sensor_size=(640, 480)),
            max_lag_ms=BUDGET_MS,
        )
        service.start()
        stop = threading.Event()
        thread = threading.Thread(target=service.run, args=(stop,))
        thread.start()
        try:
            watch = cam_bus.watch_liveliness()
            assert wait_for(lambda: watch.is_alive(cam_bus.keys.alive(service.name)), timeout_s=120)
            wait_subscribed(cam_bus, cam_bus.keys.camera_events("cam0"))
            yield cam_bus, service
        finally:
            stop.set()
            thread.join(10)


def _run(late: range) -> tuple[CentrelineBatch, list[TrackerStatus], TrackerService, list]:
    """60 packets of 1 ms through the tracker, those of ``late`` sent a minute ago (a backlog)."""
    events = np.concatenate(list(line_events(FLAG, 0, N_PACKETS * 1000, 640, 480)))
    packets = packets_of(events, N_PACKETS * 1000)[:N_PACKETS]
    with budgeted_tracker(f"flagtrack/shed{late.start}") as (cam_bus, service):
        lines = cam_bus.subscribe(cam_bus.keys.centrelines(), CentrelineMessage, capacity=100_000)
        status = cam_bus.subscribe(cam_bus.keys.tracker_status(), TrackerStatus, capacity=10_000)
        wait_subscribed(service.bus, cam_bus.keys.centrelines(), cam_bus.keys.tracker_status())
        pub = cam_bus.publisher(cam_bus.keys.camera_events("cam0"))
        budget = service.budget
        assert budget is not None
        # the late packets were "sent" once the tracker was ready, over two budgets ago (what queued
        # while it started is never shed): a backlog of its own making
        old_ns = budget.ready_ns + 1
        assert wait_for(lambda: time.time_ns() > old_ns + 2 * BUDGET_MS * 1e6, timeout_s=10)
        for seq, p in enumerate(packets):
            sent_ns = old_ns if seq in late else time.time_ns()
            pub.put(
                EventPacket(
                    "cam0",
                    seq,
                    p.t_first_us,
                    p.t_last_us,
                    p.n_events,
                    640,
                    480,
                    "evt3",
                    sent_ns,
                    p.t_offset_us,
                    end_of_stream=seq == N_PACKETS - 1,
                    data=p.data,
                )  # fmt: skip
            )
        assert wait_for(lambda: service.streams_ended == 1, timeout_s=60)
        messages = received_to_final(lines)
        assert wait_for(lambda: service.shed.packets == len(late), timeout_s=5)
        statuses: list[TrackerStatus] = []
        deadline = time.monotonic() + 10  # the statuses until one counts every packet
        while time.monotonic() < deadline and not (statuses and statuses[-1].packets == N_PACKETS):
            if (msg := status.recv(timeout_s=0.5)) is not None:
                statuses.append(msg)
    return CentrelineBatch.concatenate([m.batch() for m in messages]), statuses, service, packets


def _offline(packets: list) -> CentrelineBatch:
    from flagtrack.drivers.formats.packets import decode_packet

    tracker = Tracker(CONFIG.tracker_params(), sensor_size=(640, 480))
    out = [tracker.feed(decode_packet("evt3", p.data, p.t_offset_us)[0], p.t_last_us) for p in packets]
    return CentrelineBatch.concatenate([*out, tracker.finish()])


def test_a_backlog_older_than_the_budget_is_shed_as_a_gap_that_the_next_update_reports(
    caplog: pytest.LogCaptureFixture,
) -> None:
    late = range(20, 40)
    caplog.set_level(logging.WARNING)
    got, statuses, service, packets = _run(late)
    said = [r.getMessage() for r in caplog.records if "packets shed" in r.getMessage()]
    assert said and "not tracked, to stay within the latency budget" in said[0]  # on the console, not only the status
    assert service.problems.totals[SHED] == 20
    want = _offline(packets)
    assert service.shed.packets == 20 and service.missing_packets == 0  # skipped, not missing
    skip_lo_us, skip_hi_us = packets[late.start - 1].t_last_us + 1, packets[late.stop - 1].t_last_us + 1
    t_us = got.t_s * 1e6
    lo, hi = np.ceil(t_us - 125 - 1e-6), np.ceil(t_us + 125 - 1e-6)
    assert not np.any((lo < skip_hi_us) & (hi > skip_lo_us))  # no update made over the skipped time
    before = t_us < skip_lo_us
    assert before.sum() >= 70  # the 20 packets before the backlog: ~80 windows, as offline
    np.testing.assert_allclose(got.x[before], want.x[: before.sum()], rtol=0, atol=1e-9)
    assert not got.shed[before].any()
    after = np.flatnonzero(~before)
    assert len(after) >= 70
    assert 0.5 < got.shed[after[0]] <= 1.0  # the first update after the gap: most of its time was shed
    assert not got.shed[after[1:]].any()
    assert statuses[-1].shed_packets == 20 and statuses[-1].shed_events == sum(p.n_events for p in packets[20:40])
    assert max(s.shed_fraction for s in statuses) > 0


def test_below_the_budget_nothing_is_shed_and_the_updates_are_the_offline_ones() -> None:
    got, statuses, service, packets = _run(range(0))
    want = _offline(packets)
    assert service.shed.packets == 0
    np.testing.assert_array_equal(got.t_s, want.t_s)
    for name in ("x", "y", "joints_x", "joints_y", "delta_rms"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=0, atol=1e-9, err_msg=name)
    assert not got.shed.any()
    assert all(s.shed_fraction == 0 and s.shed_packets == 0 for s in statuses)


@pytest.mark.parametrize("budget", [None, 0.0, -1.0, float("inf")])
def test_the_budget_key_is_checked(budget: float | None) -> None:
    from flagtrack.daemon.errors import ConfigError

    config = CONFIG.with_overrides(max_lag_ms=budget)
    if budget is None:
        assert config.tracker_params() is not None and config.max_lag_ms == 50.0  # the default
        return
    with pytest.raises(ConfigError, match="tracker.max_lag_ms"):
        config.tracker_params()
