"""Replay camera -> Zenoh -> subscriber: every event arrives exactly, in order, in numbered packets."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.core.events import empty_events
from flagtrack.daemon.schema import CameraStatus, EventPacket, EventRate
from flagtrack.daemon.services.camera import CameraService, CameraStreamConfig
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.camera.base import EndOfStream
from flagtrack.drivers.camera.replay import ReplayCamera, ReplayConfig
from flagtrack.drivers.formats import make_decoder, read_events, write_events
from flagtrack.drivers.formats.packets import Packetizer, PacketParams, decode_packet
from flagtrack.drivers.sim.quickline import WavyFlag, line_events
from tests.fakes.helpers import wait_subscribed
from tests.integration.test_transport import free_port


def replay_over_bus(path: Path, speed: float = 0.0) -> tuple[list[EventPacket], list[EventRate], list[CameraStatus]]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        Bus(BusConfig(namespace="flagtrack/replay", listen=(endpoint,))) as cam_bus,
        Bus(BusConfig(namespace="flagtrack/replay", connect=(endpoint,))) as sub_bus,
    ):
        keys = sub_bus.keys
        packets_sub = sub_bus.subscribe(keys.camera_events("cam0"), EventPacket, capacity=1_000_000)
        rate_sub = sub_bus.subscribe(keys.event_rate("cam0"), EventRate)
        status_sub = sub_bus.subscribe(keys.camera_status("cam0"), CameraStatus)
        wait_subscribed(cam_bus, keys.camera_events("cam0"), keys.event_rate("cam0"), keys.camera_status("cam0"))
        service = CameraService(cam_bus, CameraStreamConfig(), ReplayCamera(ReplayConfig(path, speed=speed)))
        service.start()
        service.run(threading.Event())
        packets, statuses = [], []
        while (status := status_sub.recv(timeout_s=5.0)) is not None:
            statuses.append(status)
            if status.state == "eof":
                break
        while len(packets) < service.packets and (msg := packets_sub.recv(timeout_s=5.0)) is not None:
            packets.append(msg)
        rates = []
        while (rate := rate_sub.recv(timeout_s=0.2)) is not None:
            rates.append(rate)
        return packets, rates, statuses


def decoded(packets: list[EventPacket]) -> np.ndarray:
    return np.concatenate([decode_packet(p.encoding, p.data, p.t_offset_us)[0] for p in packets])


@pytest.mark.parametrize("name", ["expelliarmus_evt3_sample.raw", "expelliarmus_evt2_test_sparklers.raw"])
def test_real_recording_arrives_exactly(shared_real: Path, name: str) -> None:
    path = shared_real / name
    want = read_events(path).events
    packets, rates, statuses = replay_over_bus(path)
    assert [p.seq for p in packets] == list(range(len(packets)))
    np.testing.assert_array_equal(decoded(packets), want)
    assert sum(p.n_events for p in packets) == len(want)
    assert statuses[0].state == "streaming" and statuses[-1].state == "eof" and statuses[-1].events == len(want)
    spans = [p.t_last_us - p.t_first_us for p in packets if p.n_events]
    assert max(spans) < 4000  # 1 ms packets, joined up to 4 ms while they hold under 4 000 events
    assert sum(r.events for r in rates) <= len(want)  # only whole 0.1 s intervals are reported


def test_packets_concatenate_into_one_valid_stream_across_time_wrap(tmp_path: Path) -> None:
    events = np.concatenate(list(line_events(WavyFlag(), 16_600_000, 17_000_000, 640, 480)))
    path = tmp_path / "wrap.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    packets, rates, _ = replay_over_bus(path)
    np.testing.assert_array_equal(decoded(packets), events)
    assert [r.t_us for r in rates] == [16_700_000, 16_800_000, 16_900_000]  # the last, open interval is not
    inside = (events["t"] >= 16_700_000) & (events["t"] < 16_800_000)
    assert abs(rates[1].events - np.count_nonzero(inside)) < 0.02 * rates[1].events
    assert rates[1].rate_hz == pytest.approx(rates[1].events / 0.1)
    stream = make_decoder("evt3", t_offset_us=packets[0].t_offset_us).decode(b"".join(p.data for p in packets))[0]
    np.testing.assert_array_equal(stream, events)


def test_packetizer_carries_time_forward_without_events() -> None:
    packetizer = Packetizer("evt3", 640, 480, PacketParams(packet_us=1000))
    empty = empty_events()
    first = packetizer.push(empty, None, t_until_us=5_500)
    assert [(p.n_events, p.t_last_us, p.data) for p in first] == [(0, 4_999, b"")]
    assert packetizer.push(empty, None, t_until_us=5_900) == []
    assert [p.t_last_us for p in packetizer.push(empty, None, t_until_us=7_000)] == [6_999]


def test_replay_paces_at_real_time(tmp_path: Path) -> None:
    events = np.concatenate(list(line_events(WavyFlag(), 0, 300_000, 640, 480)))
    path = tmp_path / "paced.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    camera = ReplayCamera(ReplayConfig(path, speed=2.0, native=False))  # decoded slices
    camera.open()
    start = time.monotonic()
    n = 0
    while True:
        try:
            data = camera.read(0.05)
        except EndOfStream:
            break
        n += 0 if data is None else len(data.events)
    elapsed = time.monotonic() - start
    assert n == len(events)
    assert 0.12 < elapsed < 2.0  # 0.3 s of camera time at speed 2 (the upper bound: a stalled CI machine)
