"""The camera's own bytes through: a replayed RAW file -> camera service -> Zenoh -> recorder gives
back the file's words byte for byte (header aside); files without a native encoding are re-encoded."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.schema import EventPacket
from flagtrack.daemon.services.camera import CameraService, CameraStreamConfig
from flagtrack.daemon.services.recorder import RecorderConfig
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.camera.replay import ReplayCamera, ReplayConfig
from flagtrack.drivers.formats import parse_raw_header, read_events
from flagtrack.drivers.formats.packets import decode_packet
from tests.fakes.helpers import wait_until
from tests.integration.test_recorder import run_rig
from tests.integration.test_transport import free_port

RAW_FILES = [
    "expelliarmus_evt2_sample.raw",
    "expelliarmus_evt2_test_sparklers.raw",
    "expelliarmus_evt3_sample.raw",
    "expelliarmus_evt3_test_pedestrians.raw",
]


def body(path: Path) -> bytes:
    data = path.read_bytes()
    return data[parse_raw_header(data[: 1 << 20])[1] :]


@pytest.mark.shared_data
@pytest.mark.parametrize("name", RAW_FILES)
def test_every_real_raw_recording_is_recorded_byte_for_byte(shared_real, tmp_path, name) -> None:
    source = shared_real / name
    speed = 1.0 if name == "expelliarmus_evt3_sample.raw" else 0.0  # one paced (9 ms of data), the rest at once
    recorder = run_rig(source, RecorderConfig(directory=tmp_path, path="rec"), speed=speed)
    recorded = tmp_path / "rec.raw"
    assert recorder.finished == [recorded]
    assert body(recorded) == body(source)  # the camera's words, as it sent them
    got, expected = read_events(recorded, strict=True), read_events(source)
    np.testing.assert_array_equal(got.events, expected.events)
    assert recorder.current is None or recorder.current.events == len(expected.events)


@pytest.mark.shared_data
@pytest.mark.parametrize("name", ["expelliarmus_dat_test_NCARS.dat", "tonic_sample_ncars.dat"])
# the AEDAT4 recordings are not here: their times are Unix-epoch us, and the recorder refuses a packet
# time offset of more than a year of camera time (packets.MAX_OFFSET_US), re-encoded or not
def test_real_recordings_without_a_native_encoding_are_re_encoded_and_recorded_unchanged(
    shared_real, tmp_path, name
) -> None:
    source = shared_real / name
    config = RecorderConfig(directory=tmp_path, path="rec")
    recorder = run_rig(source, config, speed=0.0, replay={"width": 346, "height": 260})  # .dat: no size in header
    got, expected = read_events(tmp_path / "rec.raw", strict=True), read_events(source)
    assert recorder.finished == [tmp_path / "rec.raw"]
    np.testing.assert_array_equal(got.events, expected.events)


def test_packets_say_native_and_a_non_raw_source_is_re_encoded(tmp_path, shared_real_or_synthetic) -> None:
    """Native packets carry their preamble size; a .npy replay (no native encoding) is re-encoded."""
    for source, native in shared_real_or_synthetic:
        packets = _publish_all(source)
        assert packets and all(p.native is native for p in packets)
        assert all(p.preamble_bytes == 0 for p in packets) if not native else any(p.preamble_bytes for p in packets)
        events = np.concatenate([decode_packet(p.encoding, p.data, p.t_offset_us)[0] for p in packets])
        np.testing.assert_array_equal(events, read_events(source).events)
        assert sum(p.n_events for p in packets) == len(events)  # the counts the rate statistics use


@pytest.fixture
def shared_real_or_synthetic(tmp_path) -> list[tuple[Path, bool]]:
    from flagtrack.drivers.formats import write_events
    from flagtrack.drivers.sim.quickline import WavyFlag, line_events

    events = np.concatenate(list(line_events(WavyFlag(), 0, 20_000, 640, 480)))
    raw, npy = tmp_path / "s.raw", tmp_path / "s.npy"
    write_events(raw, events, width=640, height=480, encoding="evt3")
    write_events(npy, events, width=640, height=480)
    return [(raw, True), (npy, False)]


def _publish_all(source: Path, speed: float = 0.0, slice_us: int = 1000) -> list[EventPacket]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        Bus(BusConfig(namespace="flagtrack/native", listen=(endpoint,))) as sub_bus,
        Bus(BusConfig(namespace="flagtrack/native", connect=(endpoint,))) as cam_bus,
    ):
        sub = sub_bus.subscribe(sub_bus.keys.camera_events("cam0"), EventPacket, capacity=100_000)
        from tests.fakes.helpers import wait_subscribed

        wait_subscribed(cam_bus, cam_bus.keys.camera_events("cam0"))
        config = ReplayConfig(source, speed=speed, width=640, height=480, slice_us=slice_us)
        camera = CameraService(cam_bus, CameraStreamConfig(), ReplayCamera(config))
        camera.start()
        camera.run(threading.Event())
        packets: list[EventPacket] = []

        def all_came() -> bool:
            while (packet := sub.recv(timeout_s=0)) is not None:
                packets.append(packet)
            return bool(packets) and packets[-1].end_of_stream

        wait_until(all_came, timeout_s=20, what="the end of the stream")
    return packets


@pytest.mark.parametrize("slice_us", [1000, 4000], ids=["slices of a packet", "longer slices"])
def test_a_paced_replay_hands_over_its_packets_and_the_bytes_are_scanned_once(
    tmp_path, monkeypatch, slice_us: int
) -> None:
    """A paced replay cuts the file per slice to pace itself; slices no longer than a packet go out as
    cut (no second scan in the service, no wait for the next slice to close one); longer ones are
    cut again. Either way the packets decode alone and carry the file's words."""
    from flagtrack.daemon.services import camera as camera_service

    scans: list[int] = []
    cutter_class = camera_service.NativeCutter

    class CountingCutter(cutter_class):  # type: ignore[misc,valid-type]
        def push(self, data: bytes | bytearray | memoryview) -> list:
            scans.append(len(data))
            return super().push(data)

    monkeypatch.setattr(camera_service, "NativeCutter", CountingCutter)
    source = tmp_path / "s.raw"
    from flagtrack.drivers.formats import write_events
    from flagtrack.drivers.sim.quickline import WavyFlag, line_events

    events = np.concatenate(list(line_events(WavyFlag(), 0, 30_000, 640, 480)))
    write_events(source, events, width=640, height=480, encoding="evt3")
    packets = _publish_all(source, speed=20.0, slice_us=slice_us)
    scanned = sum(n for n in scans if n > 8)  # (8 bytes: the service's warm-up)
    assert scanned == (0 if slice_us == 1000 else len(body(source)))
    joined_us = CameraStreamConfig().max_packet_us  # the service's packet size either way (joined at this rate)
    assert all(p.t_last_us - p.t_first_us < joined_us for p in packets)
    assert all(p.native for p in packets)  # the end of stream too
    decoded = np.concatenate([decode_packet(p.encoding, p.data, p.t_offset_us)[0] for p in packets])
    np.testing.assert_array_equal(decoded, events)
    assert b"".join(p.data[p.preamble_bytes :] for p in packets) == body(source)
