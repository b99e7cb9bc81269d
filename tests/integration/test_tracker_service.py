"""A replayed file through camera -> Zenoh -> tracker gives the same centrelines as offline reconstruct."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.tracker import PreparedChunk, Tracker
from flagtrack.daemon.schema import CentrelineMessage, EventPacket, TrackerStatus
from flagtrack.daemon.services.camera import CameraService, CameraStreamConfig
from flagtrack.daemon.services.tracker import TrackerService, TrackerServiceConfig
from flagtrack.daemon.tracking.section import TrackingConfig
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.camera.replay import ReplayCamera, ReplayConfig
from flagtrack.drivers.formats import open_events, write_events
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events
from tests.fakes.helpers import wait_subscribed
from tests.integration.test_transport import free_port, received, received_to_final, wait_for

FLAG = WavyFlag(length=200.0, root=(100.0, 240.0), frequency_hz=20.0)
CONFIG = TrackingConfig(root=FLAG.root, length=FLAG.length, tau_s=2.5e-4)


def offline(path: Path, config: TrackingConfig) -> CentrelineBatch:
    tracker = Tracker(config.tracker_params(), sensor_size=(640, 480))
    with open_events(path) as reader:
        batches = [tracker.feed(chunk.events) for chunk in reader]
    return CentrelineBatch.concatenate([*batches, tracker.finish()])


@contextmanager
def running_tracker(config: TrackingConfig, namespace: str) -> Iterator[tuple[Bus, TrackerService, Callable[[], None]]]:
    """A tracker service on its own bus and thread, running (its kernels warm, its packet subscription
    known to the second bus); yields (a second bus joined to it, the service, a function that stops
    the service and waits for it). Callers subscribe, then wait for their subscriptions to reach the
    tracker's session (``wait_subscribed(service.bus, ...)``) before publishing."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    params = config.tracker_params()
    with (
        Bus(BusConfig(namespace=namespace, listen=(endpoint,))) as trk_bus,
        Bus(BusConfig(namespace=namespace, connect=(endpoint,))) as cam_bus,
    ):
        service = TrackerService(
            trk_bus, TrackerServiceConfig(status_interval_s=0.2), lambda: Tracker(params, sensor_size=(640, 480))
        )
        service.start()
        stop = threading.Event()
        thread = threading.Thread(target=service.run, args=(stop,))
        thread.start()
        watch = cam_bus.watch_liveliness()
        assert wait_for(lambda: watch.is_alive(cam_bus.keys.alive(service.name)), timeout_s=120)  # a first run compiles
        wait_subscribed(cam_bus, cam_bus.keys.camera_events("cam0"))

        def stop_service() -> None:
            stop.set()
            thread.join(10)

        try:
            yield cam_bus, service, stop_service
        finally:
            stop_service()


def live(path: Path, config: TrackingConfig, speed: float = 0.0) -> tuple[CentrelineBatch, list, TrackerService]:
    with running_tracker(config, "flagtrack/trk") as (cam_bus, service, stop_service):
        lines = cam_bus.subscribe(cam_bus.keys.centrelines(), CentrelineMessage, capacity=1_000_000)
        status = cam_bus.subscribe(cam_bus.keys.tracker_status(), TrackerStatus)
        wait_subscribed(service.bus, cam_bus.keys.centrelines(), cam_bus.keys.tracker_status())
        camera = CameraService(cam_bus, CameraStreamConfig(), ReplayCamera(ReplayConfig(path, speed=speed)))
        camera.start()
        camera.run(threading.Event())
        assert wait_for(lambda: service.streams_ended == 1, timeout_s=30)
        messages = received_to_final(lines)
        stop_service()
        statuses = received(status, timeout_s=0.5)
    assert [m.seq for m in messages] == list(range(len(messages)))
    # stamped at publication, after the packets they used reached the camera adapter (same host clock)
    assert all(m.published_ns >= m.source_ns.max() for m in messages if len(m.source_ns))
    return CentrelineBatch.concatenate([m.batch() for m in messages]), statuses, service


@pytest.mark.parametrize("method", ["robust", "paper"])
def test_replay_through_the_bus_equals_offline_reconstruct(tmp_path: Path, method: str) -> None:
    events = np.concatenate(list(line_events(FLAG, 0, 150_000, 640, 480, QuickLineParams(noise_rate_hz=2e5))))
    path = tmp_path / "flag.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    config = CONFIG.with_overrides(
        method=__import__("flagtrack.daemon.tracking.section", fromlist=["Method"]).Method(method)
    )
    want = offline(path, config)
    got, statuses, service = live(path, config)
    assert len(want) > 500 and len(got) == len(want)
    for name in ("t_s", "x", "y", "joints_x", "joints_y", "delta_rms", "n_events", "lost", "stale"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=0, atol=1e-9, err_msg=name)
    assert service.missing_packets == 0 and service.malformed_packets == 0
    assert statuses[-1].state == "stopped" and statuses[-1].packets == service.packets


def test_bad_packets_and_gaps_are_counted_and_tracking_goes_on(tmp_path: Path) -> None:
    """A message that is not a packet, a packet whose EVT bytes are corrupt and a lost packet are
    counted, and the packets around them are still tracked."""
    from flagtrack.daemon.schema import EventPacket
    from flagtrack.drivers.formats.packets import Packetizer, PacketParams

    events = np.concatenate(list(line_events(FLAG, 0, 40_000, 640, 480)))
    packets = Packetizer("evt3", 640, 480, PacketParams(packet_us=1000)).push(events, None, t_until_us=40_000)
    with running_tracker(CONFIG, "flagtrack/bad") as (cam_bus, service, _):
        lines = cam_bus.subscribe(cam_bus.keys.centrelines(), CentrelineMessage, capacity=100_000)
        pub = cam_bus.publisher(cam_bus.keys.camera_events("cam0"))
        wait_subscribed(service.bus, cam_bus.keys.centrelines())
        corrupt = np.full(8, 0x9000, dtype="<u2").tobytes()  # a reserved EVT 3.0 word type
        for seq, packet in enumerate(packets):
            if seq == 10:
                pub.put_bytes(b"not a packet")
            data = corrupt if seq == 20 else packet.data
            if seq != 30:  # lost on the way
                pub.put(
                    EventPacket(
                        "cam0",
                        seq,
                        packet.t_first_us,
                        packet.t_last_us,
                        packet.n_events,
                        640,
                        480,
                        "evt3",
                        time.time_ns(),
                        packet.t_offset_us,
                        data=data,
                    )
                )
        assert wait_for(lambda: service.packets == len(packets) - 1, timeout_s=20)
        updates, timeout_s = 0, 10.0  # (the first message may still be in the making: tracking follows counting)
        while (msg := lines.recv(timeout_s=timeout_s)) is not None:
            updates += len(msg.t_s)
            timeout_s = 1.0
    assert service.missing_packets == 1 and service.malformed_packets == 2
    assert updates > 120  # 4 updates per 1 ms packet, a few lost around the gaps


def test_each_update_counts_its_latency_from_the_packet_of_its_newest_events() -> None:
    """Packets that queued up are tracked together; each update still names the packet that held
    its window's last µs (not the last packet of the call), and windows past every horizon the last."""
    from flagtrack.daemon.services.tracker_outbox import newest_packet_ns

    horizons = np.array([999, 1999, 2999])
    sent = np.array([10, 20, 30])
    ends = np.array([250, 1000, 1001, 1750, 2000, 3000, 3250])  # exclusive: 1000 ends in packet 0
    np.testing.assert_array_equal(newest_packet_ns(ends, horizons, sent), [10, 10, 20, 20, 20, 30, 30])


def test_the_window_ending_with_a_packet_is_published_with_that_packet() -> None:
    """The packet's horizon completes the window that ends where the packet ends: its centreline
    does not wait for the next packet (a millisecond later, live)."""
    from flagtrack.daemon.schema import EventPacket
    from flagtrack.drivers.formats.packets import Packetizer, PacketParams

    events = np.concatenate(list(line_events(FLAG, 0, 6_000, 640, 480)))
    events["t"] -= events["t"][0]  # windows of 250 µs from t = 0: every fourth ends with a 1 ms packet
    packets = Packetizer("evt3", 640, 480, PacketParams(packet_us=1000)).push(events, None, t_until_us=6_000)
    with running_tracker(CONFIG, "flagtrack/horizon") as (cam_bus, service, _):
        lines = cam_bus.subscribe(cam_bus.keys.centrelines(), CentrelineMessage, capacity=100_000)
        pub = cam_bus.publisher(cam_bus.keys.camera_events("cam0"))
        wait_subscribed(service.bus, cam_bus.keys.centrelines())
        for seq, packet in enumerate(packets[:5]):
            pub.put(
                EventPacket(
                    "cam0",
                    seq,
                    packet.t_first_us,
                    packet.t_last_us,
                    packet.n_events,
                    640,
                    480,
                    "evt3",
                    time.time_ns(),
                    packet.t_offset_us,
                    data=packet.data,
                )
            )
            assert wait_for(lambda seq=seq: service.packets == seq + 1, timeout_s=10)
            t_s: list[float] = []
            deadline = time.monotonic() + 10
            while len(t_s) < 4 and time.monotonic() < deadline:  # this packet's four windows
                if (msg := lines.recv(timeout_s=0.5)) is not None:
                    t_s.extend(msg.t_s)
            while (msg := lines.recv(timeout_s=0.3)) is not None:  # and no more before the next packet
                t_s.extend(msg.t_s)
            assert packet.t_last_us == 1000 * seq + 999
            assert len(t_s) == 4 and t_s[-1] * 1e6 == pytest.approx(packet.t_last_us + 1 - 125)


def publish(
    pub, packets: list, seqs: list[int] | None = None, end: bool = False, data: dict | None = None, stream_id: int = 0
) -> None:
    """Publish packetizer packets as camera cam0 would (``seqs``: their numbers; ``end``: the last ends
    the stream; ``data``: replaced EVT bytes by index; ``stream_id`` 0: as an older peer, without)."""
    from flagtrack.daemon.schema import EventPacket

    for i, packet in enumerate(packets):
        pub.put(
            EventPacket(
                "cam0",
                i if seqs is None else seqs[i],
                packet.t_first_us,
                packet.t_last_us,
                packet.n_events,
                640,
                480,
                "evt3",
                time.time_ns(),
                packet.t_offset_us,
                end_of_stream=end and i == len(packets) - 1,
                stream_id=stream_id,
                data=(data or {}).get(i, packet.data),
            )
        )


def packets_of(events: np.ndarray, t_until_us: int) -> list:
    from flagtrack.drivers.formats.packets import Packetizer, PacketParams

    packetizer = Packetizer("evt3", 640, 480, PacketParams(packet_us=1000))
    return packetizer.push(events, None, t_until_us=t_until_us) + packetizer.flush()


def test_a_restarted_camera_is_tracked_afresh(tmp_path: Path) -> None:
    """The camera restarts while the tracker runs (its packets number from 0 again, its times start
    again): the tracker starts a fresh core tracker, and the new stream gives exactly the offline
    centrelines; the restart is counted in the status and the messages say which stream they are of."""
    first = np.concatenate(list(line_events(FLAG, 0, 30_000, 640, 480)))
    second = np.concatenate(list(line_events(FLAG, 0, 60_000, 640, 480, QuickLineParams(noise_rate_hz=1e5))))
    path = tmp_path / "second.raw"
    write_events(path, second, width=640, height=480, encoding="evt3")
    want = offline(path, CONFIG)
    with running_tracker(CONFIG, "flagtrack/restart") as (cam_bus, service, stop_service):
        lines = cam_bus.subscribe(cam_bus.keys.centrelines(), CentrelineMessage, capacity=100_000)
        status = cam_bus.subscribe(cam_bus.keys.tracker_status(), TrackerStatus, capacity=1000)
        pub = cam_bus.publisher(cam_bus.keys.camera_events("cam0"))
        wait_subscribed(service.bus, cam_bus.keys.centrelines(), cam_bus.keys.tracker_status())
        publish(pub, packets_of(first, 30_000)[:25])  # then the camera dies: no end of stream
        assert wait_for(lambda: service.packets == 25, timeout_s=20)
        memory = service.tracker._buffer.t  # (preallocated at start-up: written once)
        publish(pub, packets_of(second, 60_000), end=True)
        assert wait_for(lambda: service.streams_ended == 1, timeout_s=30)
        messages = received_to_final(lines)
        stop_service()
        statuses = received(status, timeout_s=0.5)
    assert service.tracker._buffer.t is memory  # the fresh trackers of the restart and the end reuse it
    assert service.restarts == 1 and service.missing_packets == 0
    assert statuses[-1].restarts == 1 and statuses[-1].missing_packets == 0
    old = [m for m in messages if m.stream == 0 and len(m.t_s)]
    new = CentrelineBatch.concatenate([m.batch() for m in messages if m.stream == 1])
    assert sum(len(m.t_s) for m in old) > 80 and all(m.t_s[-1] < 0.025 for m in old)
    assert [m.stream for m in messages] == sorted(m.stream for m in messages)  # the old stream's first
    assert messages[-1].final and messages[-1].stream == 1
    assert len(new) == len(want) > 200
    for name in ("t_s", "x", "y", "joints_x", "joints_y", "delta_rms", "n_events"):
        np.testing.assert_allclose(getattr(new, name), getattr(want, name), rtol=0, atol=1e-9, err_msg=name)


def test_gaps_and_undecodable_packets_are_logged_as_counted_summaries(caplog: pytest.LogCaptureFixture) -> None:
    """20 gaps and 10 corrupt packets: counted one by one, but logged in a few lines, not 30."""
    events = np.concatenate(list(line_events(FLAG, 0, 60_000, 640, 480)))
    packets = packets_of(events, 60_000)[:60]
    corrupt = np.full(8, 0x9000, dtype="<u2").tobytes()  # a reserved EVT 3.0 word type
    kept = [k for k in range(60) if k % 3 != 1]  # 20 lost on the way
    with (
        caplog.at_level(logging.WARNING, logger="flagtrack.daemon.services.tracker"),
        running_tracker(CONFIG, "flagtrack/quiet") as (cam_bus, service, stop_service),
    ):
        pub = cam_bus.publisher(cam_bus.keys.camera_events("cam0"))
        publish(pub, [packets[k] for k in kept], seqs=kept, data={i: corrupt for i in range(0, 40, 4)})
        assert wait_for(lambda: service.packets == 40, timeout_s=20)
        stop_service()
    assert service.missing_packets == 20 and service.malformed_packets == 10
    lines = [r.getMessage() for r in caplog.records if r.name == "flagtrack.daemon.services.tracker"]
    assert 2 <= len(lines) <= 4, lines  # the first of each kind, and a summary of each at the stop
    assert any("more packets missing" in line and "(20 in all)" in line for line in lines), lines


def test_packets_a_full_queue_drops_are_counted_reported_and_logged(caplog: pytest.LogCaptureFixture) -> None:
    """60 packets come while the tracker is not reading yet and its queue holds 10: the 50 it turns
    away are in the status (dropped_packets) and in one warning, and the 10 it kept are tracked."""
    events = np.concatenate(list(line_events(FLAG, 0, 60_000, 640, 480)))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    params = CONFIG.tracker_params()
    with (
        caplog.at_level(logging.WARNING, logger="flagtrack.daemon.services.tracker"),
        Bus(BusConfig(namespace="flagtrack/full", listen=(endpoint,))) as trk_bus,
        Bus(BusConfig(namespace="flagtrack/full", connect=(endpoint,))) as cam_bus,
    ):
        service = TrackerService(
            trk_bus,
            TrackerServiceConfig(status_interval_s=0.2, queue_packets=10),
            lambda: Tracker(params, sensor_size=(640, 480)),
        )
        service.start()
        status = cam_bus.subscribe(cam_bus.keys.tracker_status(), TrackerStatus, capacity=1000)
        wait_subscribed(cam_bus, cam_bus.keys.camera_events("cam0"))
        wait_subscribed(trk_bus, cam_bus.keys.tracker_status())
        publish(cam_bus.publisher(cam_bus.keys.camera_events("cam0")), packets_of(events, 60_000)[:60])
        assert wait_for(lambda: service.dropped_packets == 50)
        stop = threading.Event()
        thread = threading.Thread(target=service.run, args=(stop,))
        thread.start()
        try:
            assert wait_for(lambda: service.packets == 10, timeout_s=20)
            reported = None
            while reported is None and (msg := status.recv(timeout_s=2.0)) is not None:
                reported = msg if msg.dropped_packets else None
        finally:
            stop.set()
            thread.join(10)
    assert reported is not None and reported.dropped_packets == 50 and reported.packets == 10
    lines = [r.getMessage() for r in caplog.records if "dropped by the full queue" in r.getMessage()]
    assert len(lines) == 1 and "50 packet(s)" in lines[0], lines


def test_the_tracker_queue_is_bounded_by_bytes_and_keeps_the_newest() -> None:
    """A queue of 100 KB under 60 packets of ~3 KB that come while the tracker is not reading: it
    keeps the newest that fit (the end of stream among them, so the stream still ends), drops and
    counts the others."""
    from flagtrack.daemon.schema import EventPacket, encode

    events = np.concatenate(list(line_events(FLAG, 0, 60_000, 640, 480)))
    packets = packets_of(events, 60_000)[:60]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    params = CONFIG.tracker_params()
    with (
        Bus(BusConfig(namespace="flagtrack/bytes", listen=(endpoint,))) as trk_bus,
        Bus(BusConfig(namespace="flagtrack/bytes", connect=(endpoint,))) as cam_bus,
    ):
        service = TrackerService(
            trk_bus, TrackerServiceConfig(queue_bytes=100_000), lambda: Tracker(params, sensor_size=(640, 480))
        )
        service.start()
        wait_subscribed(cam_bus, cam_bus.keys.camera_events("cam0"))
        pub = cam_bus.publisher(cam_bus.keys.camera_events("cam0"))
        sizes = []
        for seq, p in enumerate(packets):
            message = EventPacket(
                "cam0",
                seq,
                p.t_first_us,
                p.t_last_us,
                p.n_events,
                640,
                480,
                "evt3",
                time.time_ns(),
                p.t_offset_us,
                end_of_stream=seq == 59,
                data=p.data,
            )
            sizes.append(len(encode(message)))
            pub.put(message)
        kept = int(np.searchsorted(np.cumsum(sizes[::-1]), 100_000, side="right"))
        assert 10 < kept < 50
        assert wait_for(lambda: service.dropped_packets == 60 - kept)
        assert service.packets_sub.channel.bytes == sum(sizes[-kept:]) <= 100_000
        stop = threading.Event()
        thread = threading.Thread(target=service.run, args=(stop,))
        thread.start()
        try:
            assert wait_for(lambda: service.streams_ended == 1, timeout_s=20)
        finally:
            stop.set()
            thread.join(10)
    assert service.packets == kept and service.dropped_packets == 60 - kept


@pytest.mark.parametrize("stream_id", [0, 7_000_001], ids=["no stream id", "stream id"])
def test_a_duplicated_or_late_packet_is_dropped_not_taken_for_a_restart(tmp_path: Path, stream_id: int) -> None:
    """Zenoh may deliver a packet twice (overlapping routers): packet 30 comes again after 31, and 45
    and 46 come swapped. The duplicate is dropped (the centrelines equal the clean run's up to the
    swap), the late 45 is dropped and counted as missing, and the chain is never restarted."""
    events = np.concatenate(list(line_events(FLAG, 0, 60_000, 640, 480)))
    path = tmp_path / "clean.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    packets = packets_of(events, 60_000)
    order = [*range(32), 30, *range(32, 45), 46, 45, *range(47, len(packets))]
    with running_tracker(CONFIG, f"flagtrack/dup{stream_id}") as (cam_bus, service, stop_service):
        lines = cam_bus.subscribe(cam_bus.keys.centrelines(), CentrelineMessage, capacity=100_000)
        pub = cam_bus.publisher(cam_bus.keys.camera_events("cam0"))
        wait_subscribed(service.bus, cam_bus.keys.centrelines())
        publish(pub, [packets[k] for k in order], seqs=order, end=True, stream_id=stream_id)
        assert wait_for(lambda: service.streams_ended == 1, timeout_s=30)
        messages = received_to_final(lines)
        stop_service()
    assert service.restarts == 0 and service.late_packets == 2 and service.missing_packets == 1
    got = CentrelineBatch.concatenate([m.batch() for m in messages])
    want = offline(path, CONFIG)
    assert {m.stream for m in messages} == {0}
    before_swap = want.t_s < packets[45].t_first_us * 1e-6 - CONFIG.tau_s  # windows the lost packet 45 cannot reach
    assert before_swap.sum() > 150
    np.testing.assert_allclose(got.x[: before_swap.sum()], want.x[before_swap], rtol=0, atol=1e-9)
    assert abs(len(got) - len(want)) <= 8  # the lost millisecond's windows may differ, the rest goes on


def test_a_restarted_camera_with_a_new_stream_id_is_a_new_stream_whatever_its_numbers(tmp_path: Path) -> None:
    """The tracker misses the first 40 packets of a restarted camera: the packets it gets number 40
    on, below where the old stream stopped (80), yet their stream id says they are a new stream."""
    first = np.concatenate(list(line_events(FLAG, 0, 90_000, 640, 480)))
    second = np.concatenate(list(line_events(FLAG, 0, 60_000, 640, 480)))
    with running_tracker(CONFIG, "flagtrack/newid") as (cam_bus, service, stop_service):
        pub = cam_bus.publisher(cam_bus.keys.camera_events("cam0"))
        publish(pub, packets_of(first, 90_000)[:80], stream_id=111)
        assert wait_for(lambda: service.packets == 80, timeout_s=20)
        late_start = list(range(40, 60))
        publish(pub, packets_of(second, 60_000)[40:60], seqs=late_start, stream_id=222)
        assert wait_for(lambda: service.packets == 100, timeout_s=20)
        stop_service()
    assert service.restarts == 1 and service.late_packets == 0 and service.stream == 1


def test_a_packet_whose_time_offset_is_loops_off_is_dropped_not_tracked(tmp_path: Path) -> None:
    """Packet 30 claims a time offset 1000 EVT 3.0 loops (4.7 hours) off: it is counted as malformed
    and left out; the chain is not thrown hours ahead (before: 4124 updates instead of 240)."""
    import dataclasses

    events = np.concatenate(list(line_events(FLAG, 0, 60_000, 640, 480)))
    path = tmp_path / "clean.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    packets = packets_of(events, 60_000)
    bad = dataclasses.replace(packets[30], t_offset_us=packets[30].t_offset_us + 1000 * (1 << 24))
    with running_tracker(CONFIG, "flagtrack/offset") as (cam_bus, service, stop_service):
        lines = cam_bus.subscribe(cam_bus.keys.centrelines(), CentrelineMessage, capacity=100_000)
        pub = cam_bus.publisher(cam_bus.keys.camera_events("cam0"))
        wait_subscribed(service.bus, cam_bus.keys.centrelines())
        publish(pub, [*packets[:30], bad, *packets[31:]], end=True)
        assert wait_for(lambda: service.streams_ended == 1, timeout_s=30)
        messages = received_to_final(lines)
        stop_service()
    assert service.malformed_packets == 1 and service.restarts == 0
    got = CentrelineBatch.concatenate([m.batch() for m in messages])
    want = offline(path, CONFIG)
    assert abs(len(got) - len(want)) <= 4 and got.t_s.max() < 0.061


def native_packets(tmp_path: Path) -> tuple[Path, np.ndarray, list[EventPacket]]:
    """A 60 ms recording of the flag, its events, and its bytes cut into native packets, as a camera sends them."""
    from flagtrack.drivers.formats import parse_raw_header
    from flagtrack.drivers.formats.native import NativeCutter

    events = np.concatenate(list(line_events(FLAG, 0, 60_000, 640, 480, QuickLineParams(), seed=2)))
    path = tmp_path / "run.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    data = path.read_bytes()
    cutter = NativeCutter("evt3")
    cut = cutter.push(data[parse_raw_header(data)[1] :]) + cutter.flush()
    packets = [
        EventPacket(
            "cam0",
            i,
            p.t_first_us,
            p.t_last_us,
            p.n_events,
            640,
            480,
            "evt3",
            i,
            p.t_offset_us,
            end_of_stream=i == len(cut) - 1,
            stream_id=1,
            preamble_bytes=p.preamble_bytes,
            native=True,
            data=p.data,
        )  # fmt: skip
        for i, p in enumerate(cut)
    ]
    return path, events, packets


def test_a_run_of_queued_packets_on_two_threads_gives_the_updates_of_one(tmp_path: Path, monkeypatch) -> None:
    """Under load (packets queued up) the service decodes and prepares on its thread while a worker
    updates the chain; the updates are exactly those of tracking the run on one thread."""
    from flagtrack.daemon.services import tracker as tracker_service

    path, events, packets = native_packets(tmp_path)
    params = CONFIG.tracker_params()

    def tracked(min_packets: int) -> CentrelineBatch:
        monkeypatch.setattr(tracker_service, "PIPELINE_MIN_PACKETS", min_packets)
        with Bus(BusConfig(namespace="flagtrack/two")) as bus:
            config = TrackerServiceConfig(batch_updates=1 << 30)
            service = TrackerService(bus, config, lambda: Tracker(params, sensor_size=(640, 480)))
            service.start()
            service._lines_pub = bus.publisher(bus.keys.centrelines())
            added: list[CentrelineBatch] = []
            queue_updates = service._add
            monkeypatch.setattr(service, "_add", lambda batch, ns: [added.append(batch), queue_updates(batch, ns)])
            for start in range(0, len(packets), 32):  # as the service takes them: up to max_coalesce at once
                service.handle(packets[start : start + 32])
            assert service.events == len(events) and service.undecodable_packets == 0
            return CentrelineBatch.concatenate(added)

    two_threads, one_thread = tracked(8), tracked(1 << 30)
    assert len(two_threads) == len(one_thread) > 100
    for name in ("t_s", "x", "y", "joints_x", "joints_y", "delta_rms", "n_events"):
        np.testing.assert_array_equal(getattr(two_threads, name), getattr(one_thread, name), err_msg=name)
    np.testing.assert_allclose(two_threads.x, offline(path, CONFIG).x, atol=1e-9)


class _FailingTracker(Tracker):
    """A core tracker whose chain update fails on the chunk holding ``fail_at_us`` (data it cannot take)."""

    fail_at_us = 30_000

    def feed(self, events: np.ndarray, complete_through_us: int | None = None) -> CentrelineBatch:
        self._check(events["t"])
        return super().feed(events, complete_through_us)

    def advance(self, chunk: PreparedChunk, complete_through_us: int | None = None) -> CentrelineBatch:
        self._check(chunk.t)
        return super().advance(chunk, complete_through_us)

    def _check(self, t: np.ndarray) -> None:
        if len(t) and t[0] <= self.fail_at_us <= t[-1]:
            raise ValueError("the chain cannot take this chunk")


@pytest.mark.parametrize("min_packets", [1 << 30, 8], ids=["one thread", "two threads"])
def test_a_chunk_the_core_cannot_track_is_counted_and_a_fresh_tracker_goes_on(
    tmp_path: Path, monkeypatch, min_packets: int
) -> None:
    """Whichever thread updates the chain, a failure drops the packets it held (counted, logged as a
    summary) and the packets after them are tracked by a fresh core tracker."""
    from flagtrack.daemon.services import tracker as tracker_service

    monkeypatch.setattr(tracker_service, "PIPELINE_MIN_PACKETS", min_packets)
    _, _, packets = native_packets(tmp_path)
    params = CONFIG.tracker_params()
    with Bus(BusConfig(namespace="flagtrack/fail")) as bus:
        service = TrackerService(
            bus, TrackerServiceConfig(batch_updates=1 << 30), lambda: _FailingTracker(params, sensor_size=(640, 480))
        )
        service.start()
        service._lines_pub = bus.publisher(bus.keys.centrelines())
        added: list[CentrelineBatch] = []
        queue_updates = service._add
        monkeypatch.setattr(service, "_add", lambda batch, ns: [added.append(batch), queue_updates(batch, ns)])
        for start in range(0, len(packets), 16):
            service.handle(packets[start : start + 16])
        failed = service.undecodable_packets
        assert 1 <= failed <= 16  # the packets tracked with the failing chunk, no more
        assert service.problems.totals.get("packets that failed to track") == failed
        t_s = CentrelineBatch.concatenate(added).t_s
        assert t_s.max() > 0.05  # tracking went on after the failure (at 30 ms) to the end (60 ms)
        assert not np.any((t_s > 0.0305) & (t_s < 0.0315))  # the failed chunk's updates are dropped


@pytest.mark.parametrize(("length", "warned"), [(200.0, False), (230.0, True)])
def test_a_live_chain_longer_than_the_flag_is_said_in_the_log(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture, length: float, warned: bool
) -> None:
    """Every update finds the flag with a chain 15 % too long; the live tracker says, once a span
    (here 0.1 s of camera time, 10 s by default), how long the flag looks from its events."""
    import functools

    import flagtrack.daemon.services.tracker as tracker_module
    from flagtrack.daemon.tracking.reach import LiveReach

    monkeypatch.setattr(tracker_module, "LiveReach", functools.partial(LiveReach, every_us=10_000, span_us=100_000))
    events = np.concatenate(list(line_events(FLAG, 0, 400_000, 640, 480, QuickLineParams(noise_rate_hz=2e5))))
    path = tmp_path / "flag.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    with caplog.at_level(logging.WARNING, logger="flagtrack.daemon.services.tracker"):
        got, statuses, _ = live(path, CONFIG.with_overrides(length=length))
    assert np.mean(got.lost | got.stale) < 0.05  # found, whatever the length
    assert statuses[-1].chain_reach == pytest.approx(200.0 / length, abs=0.02)  # a program reads it too
    said = [r.getMessage() for r in caplog.records if "check tracker.length" in r.getMessage()]
    assert bool(said) is warned, said
    if warned:
        assert said[0].startswith("tracker: over the last 0.1 s, the chain's last 13 % had no events: from this root")
        assert "looks about 200 px long, not 230" in said[0]
