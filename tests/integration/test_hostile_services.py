"""No message kills a service: the supervisor's monitor, the recorder and the tracker take hostile and
unusable messages on their keys (counted, logged, skipped) and go on with the good ones after them."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from flagtrack.daemon.core.onset import OnsetParams
from flagtrack.daemon.core.tracker import Tracker
from flagtrack.daemon.schema import EventPacket, EventRate, RecorderCommand, RecorderStatus
from flagtrack.daemon.services.recorder import RecorderConfig, RecorderService
from flagtrack.daemon.services.supervisor.monitor import BusMonitor
from flagtrack.daemon.services.tracker import TrackerService, TrackerServiceConfig
from flagtrack.daemon.transport import QUEUE_BYTES, Bus, BusConfig
from flagtrack.drivers.formats import read_events
from tests.fakes.helpers import wait_until
from tests.integration.test_secure_bus import TRACKING, event_packets, forged_centrelines
from tests.unit.test_hostile_messages import RATE, wire


def rate(t_us: int, rate_hz: float) -> EventRate:
    return EventRate("cam0", t_us, 0.1, 0, rate_hz, 0.5)


def lines(t_s: list[float], n_s: int = 5, joints: int = 3):
    msg = forged_centrelines()
    n = len(t_s)
    one = np.zeros((n, n_s))
    return type(msg)(
        "tracker",
        0,
        "px",
        np.asarray(t_s, float),
        np.linspace(0, 1, n_s),
        one,
        one,
        np.zeros((n, joints)),
        np.zeros((n, joints)),
        np.zeros(n),
        np.zeros(n),
        np.zeros(n),
        np.ones(n, np.int64),
        np.ones(n, np.int64),
    )


def test_the_supervisors_monitor_skips_rates_and_centrelines_it_cannot_use() -> None:
    """Today's ValueError cases (a rate whose time goes back or that is negative, centrelines of another
    shape or out of time order) and a few more are counted and skipped; the good ones are taken."""
    with Bus(BusConfig(namespace="flagtrack/hostile")) as bus:
        monitor = BusMonitor(bus, "cam0", OnsetParams(learn_s=0.5), ())
        monitor.start_collecting()
        rates = bus.publisher(bus.keys.event_rate("cam0"))
        for t_us, value in [(100_000, 1e4), (50_000, 1e4), (200_000, -5.0), (300_000, math.inf), (400_000, 1e4)]:
            rates.put(rate(t_us, value))
        centrelines = bus.publisher(bus.keys.centrelines())
        for msg in [
            lines([1.0, 1.1]),
            lines([1.2], n_s=7),
            lines([0.5]),
            lines([1.3, 1.25]),
            lines([1e9]),
            lines([1.4], joints=4),
            lines([1.5]),
        ]:
            centrelines.put(msg)

        def taken() -> bool:
            monitor.pump()  # (never raises)
            collection = monitor.collection
            return collection is not None and len(collection.rates_hz) == 2 and len(collection.batches) == 2

        wait_until(taken, 10, "the good rates and centrelines")
        collection = monitor.stop_collecting()
    assert collection.rates_hz == [1e4, 1e4] and [list(b.t_s) for b in collection.batches] == [[1.0, 1.1], [1.5]]
    assert monitor.unusable == 3 + 5
    assert monitor.problems.totals == {
        "event rates that cannot be used": 3,
        "centreline messages that cannot be used": 5,
    }


def test_the_supervisors_queues_are_bounded_in_bytes() -> None:
    """100 000 rates of 1 MB each would be 100 GB: the queue keeps 16 MB and counts what it turns away."""
    with Bus(BusConfig(namespace="flagtrack/flood")) as bus:
        monitor = BusMonitor(bus, "cam0", OnsetParams(), ())
        publisher = bus.publisher(bus.keys.event_rate("cam0"))
        for k in range(40):
            publisher.put(EventRate("x" * (1 << 20), k, 0.1, 0, 1.0, 0.5))
        channel = monitor.rates.channel
        wait_until(lambda: len(channel) + channel.dropped == 40, 10, "the flood")
        assert channel.dropped >= 24 and channel.bytes <= 16 << 20
        assert monitor.recorder.channel._max_bytes is not None  # every queue of the monitor has a bound
        assert bus.subscribe(bus.keys.tunnel_state()).channel._max_bytes == QUEUE_BYTES  # and any without one


@contextmanager
def services(tmp_path: Path) -> Iterator[tuple[Bus, RecorderService, TrackerService]]:
    params = TRACKING.tracker_params()
    with Bus(BusConfig(namespace="flagtrack/hostile2")) as bus:
        recorder = RecorderService(bus, RecorderConfig(directory=tmp_path / "rec", path="run"))
        recorder.start()
        tracker = TrackerService(
            bus, TrackerServiceConfig(status_interval_s=0.2), lambda: Tracker(params, sensor_size=(640, 480))
        )
        tracker.start()
        tracker.warm_up()
        stop = threading.Event()
        threads = [threading.Thread(target=s.run, args=(stop,), daemon=True) for s in (recorder, tracker)]
        for thread in threads:
            thread.start()
        try:
            yield bus, recorder, tracker
        finally:
            stop.set()
            for thread in threads:
                thread.join(20)
            assert not any(thread.is_alive() for thread in threads), "a service did not stop"


def test_recorder_and_tracker_go_on_after_hostile_packets(tmp_path: Path) -> None:
    """On the event key: JSON nested 1000 deep, a bytes blob for an array, a packet whose time offset is
    decades away (its preamble would be 7 GB), one whose horizon jumps a day past the stream (the
    tracker would walk its windows for 19 s), one spanning decades; on the command key a start at
    '~nosuchuser/x' (RuntimeError from expanduser before). Both services count them and record and
    track the good packets sent after them, in bounded time."""
    good = event_packets(stream_id=1, n=40)
    decades = (30 * 365 * 86_400_000_000 >> 24) << 24
    day = 86_400_000_000
    first, rest = good[:20], good[20:]
    last = first[-1]
    hostile = [
        wire(1, "{" + RATE.replace("_blobs", "x") + ',"rate_hz":' + "[" * 1000 + "]" * 1000 + "}"),
        wire(
            1,
            '{"camera_id":"c","seq":0,"t_first_us":0,"t_last_us":0,"n_events":0,"width":1,"height":1,'
            '"encoding":"evt3","sent_ns":0,"_blobs":[["data","<u2",[2]]]}',
            bytes(4),
        ),
    ]
    forged = [
        EventPacket(
            "cam0",
            20,
            decades + 10,
            decades + 900,
            last.n_events,
            640,
            480,
            "evt3",
            1,
            decades,
            stream_id=1,
            data=last.data,
        ),
        EventPacket(
            "cam0",
            20,
            last.t_first_us,
            last.t_last_us + day,
            last.n_events,
            640,
            480,
            "evt3",
            1,
            last.t_offset_us,
            stream_id=1,
            data=last.data,
        ),
        EventPacket("cam0", 20, 0, 10**15, 0, 640, 480, "evt3", 1, 0, stream_id=1),  # no events, a horizon decades on
    ]
    with services(tmp_path) as (bus, recorder, tracker):
        statuses = bus.subscribe(bus.keys.recorder_status(), RecorderStatus)
        packets = bus.publisher(bus.keys.camera_events("cam0"))
        for packet in first:
            packets.put(packet)
        wait_until(
            lambda: tracker.packets == 20 and recorder.current is not None and recorder.current.packets == 20,
            20,
            "the first good packets",
        )
        for data in hostile:
            packets.put_bytes(data)
        for packet in forged:
            packets.put(packet)
        bus.publisher(bus.keys.recorder_command()).put(
            RecorderCommand("rotate", path="~nosuchuser/x", request_id="tilde")
        )
        started = time.monotonic()
        for packet in rest:
            packets.put(packet)
        wait_until(lambda: tracker.packets == 40 and recorder.current.packets == 40, 20, "the good packets after")
        assert time.monotonic() - started < 10
        refusal = wait_until(
            lambda: next(
                (s for s in iter(lambda: statuses.recv(timeout_s=0.05), None) if s.request_id == "tilde"), None
            ),
            10,
            "the refusal",
        )
    assert refusal.state == "error" and "'~' is not expanded" in refusal.message
    assert tracker.malformed_packets == 5 and tracker.restarts == 0 and tracker.missing_packets == 0
    assert recorder.malformed_packets == 5 and recorder.finished == [tmp_path / "rec" / "run.raw"]
    raw = tmp_path / "rec" / "run.raw"
    assert raw.stat().st_size < 1 << 20
    sent = np.concatenate([read_events_of(p) for p in good])
    np.testing.assert_array_equal(read_events(raw, strict=True).events, sent)
    assert not (tmp_path / "rec" / "x.json").exists() and sorted(p.name for p in (tmp_path / "rec").iterdir()) == [
        "run.json",
        "run.raw",
    ]


def read_events_of(packet: EventPacket) -> np.ndarray:
    from flagtrack.drivers.formats.packets import decode_packet

    return decode_packet(packet.encoding, packet.data, packet.t_offset_us)[0]
