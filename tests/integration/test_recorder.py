"""Recorder: loss-free .raw files that decode to exactly what the camera sent, rotation, crash safety."""

from __future__ import annotations

import json
import logging
import shutil
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.schema import CentrelineMessage, EventPacket, RecorderCommand, RecorderStatus
from flagtrack.daemon.services.camera import CameraService, CameraStreamConfig
from flagtrack.daemon.services.recorder import RecorderConfig, RecorderService
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.camera.replay import ReplayCamera, ReplayConfig
from flagtrack.drivers.formats import read_events, write_events
from flagtrack.drivers.formats.centreline import read_centrelines
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events
from tests.fakes.helpers import wait_subscribed
from tests.integration.test_transport import free_port, wait_for


def make_recording(tmp_path: Path, t0_us: int, t1_us: int) -> tuple[Path, np.ndarray]:
    events = np.concatenate(list(line_events(WavyFlag(), t0_us, t1_us, 640, 480)))
    path = tmp_path / "source.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    return path, events


def data_bytes(path: Path) -> int:
    """Bytes of a RAW file past its header (0 while there are none, or no file)."""
    data = path.read_bytes() if path.exists() else b""
    end = 0
    while data.startswith(b"%", end):
        if (end := data.find(b"\n", end) + 1) == 0:
            return 0
    return len(data) - end


def run_rig(source: Path, rec_cfg: RecorderConfig, speed: float, during=None, replay=None) -> RecorderService:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        Bus(BusConfig(namespace="flagtrack/rec", listen=(endpoint,))) as rec_bus,
        Bus(BusConfig(namespace="flagtrack/rec", connect=(endpoint,))) as cam_bus,
    ):
        recorder = RecorderService(rec_bus, rec_cfg, {"test": True})
        recorder.start()
        stop = threading.Event()
        thread = threading.Thread(target=recorder.run, args=(stop,))
        thread.start()
        wait_subscribed(cam_bus, cam_bus.keys.camera_events("cam0"), cam_bus.keys.recorder_command())
        replay_cfg = ReplayConfig(source, speed=speed, **(replay or {}))
        camera = CameraService(cam_bus, CameraStreamConfig(), ReplayCamera(replay_cfg))
        camera.start()
        cam_thread = threading.Thread(target=camera.run, args=(threading.Event(),))
        cam_thread.start()
        if during is not None:
            during(cam_bus, recorder)
        cam_thread.join(30)
        if rec_cfg.path:  # recording from launch: every packet the camera sent is in the one file
            assert wait_for(lambda: recorder.current is not None and recorder.current.packets == camera.packets)
        else:  # recording on command: the last part has the end of stream (the last packets were in flight)
            assert wait_for(lambda: recorder.current is None or recorder.current.ended)
        stop.set()
        thread.join(10)
        assert not thread.is_alive()
    return recorder


def test_recording_decodes_to_exactly_the_source_across_time_wrap(tmp_path: Path) -> None:
    source, events = make_recording(tmp_path, 33_500_000, 33_700_000)  # 2 EVT 3.0 loops in, crossing none
    recorder = run_rig(source, RecorderConfig(directory=tmp_path / "out", path="run1"), speed=0.0)
    raw = tmp_path / "out" / "run1.raw"
    assert recorder.finished == [raw]
    got = read_events(raw, strict=True)
    np.testing.assert_array_equal(got.events, events)
    assert (got.info.width, got.info.height, got.info.encoding) == (640, 480, "evt3")
    sidecar = json.loads((tmp_path / "out" / "run1.json").read_text())
    assert sidecar["stopped"] and sidecar["sequence_gaps"] == [] and sidecar["events"] == len(events)
    assert sidecar["config"] == {"test": True}


def test_rotate_on_command_splits_without_losing_events(tmp_path: Path) -> None:
    source, events = make_recording(tmp_path, 0, 600_000)
    statuses: list[RecorderStatus] = []

    def rotate(bus: Bus, recorder: RecorderService) -> None:
        status = bus.subscribe(bus.keys.recorder_status(), RecorderStatus)
        commands = bus.publisher(bus.keys.recorder_command())
        commands.put(RecorderCommand("start", path="a", request_id="1"))
        assert wait_for(lambda: recorder.current is not None and recorder.current.packets > 0)  # a.raw has some
        commands.put(RecorderCommand("rotate", path="b", request_id="2"))
        # (a rotation closes and syncs a file before its statuses: slow on a busy disk)
        while len(statuses) < 3 and (msg := status.recv(timeout_s=10.0)) is not None:
            statuses.append(msg)

    run_rig(source, RecorderConfig(directory=tmp_path / "out"), speed=0.25, during=rotate)  # 2.4 s: room to rotate
    a = read_events(tmp_path / "out" / "a.raw", strict=True).events
    b = read_events(tmp_path / "out" / "b.raw", strict=True).events
    assert len(a) > 0 and len(b) > 0
    joined = np.concatenate([a, b])
    # recording started after the first packets: what was recorded is one contiguous run, ending at the end
    np.testing.assert_array_equal(joined, events[len(events) - len(joined) :])
    assert [s.request_id for s in statuses[:3]] == ["1", "2", "2"]
    assert [s.state for s in statuses[:3]] == ["recording", "idle", "recording"]


def test_a_recording_cut_mid_write_is_readable_up_to_its_last_flush(tmp_path: Path) -> None:
    source, events = make_recording(tmp_path, 0, 600_000)
    copies: list[Path] = []

    def snapshot(bus: Bus, recorder: RecorderService) -> None:
        # mid-recording (after its first flush of events): copy the file as a power cut would leave it
        assert wait_for(lambda: data_bytes(tmp_path / "out" / "live.raw") > 0)
        copy = tmp_path / "cut.raw"
        shutil.copyfile(tmp_path / "out" / "live.raw", copy)
        with open(copy, "ab") as f:
            f.write(b"\x01")  # a torn last word
        copies.append(copy)

    cfg = RecorderConfig(directory=tmp_path / "out", path="live", flush_interval_s=0.05)
    run_rig(source, cfg, 0.25, snapshot)  # 2.4 s: the copy is taken mid-recording on a busy host too
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cut = read_events(copies[0]).events
    assert 0 < len(cut) < len(events)
    np.testing.assert_array_equal(cut, events[: len(cut)])
    assert any("cut.raw" in str(w.message) for w in caught)


def test_malformed_packets_are_counted_not_written(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with Bus(BusConfig(namespace="flagtrack/rec", listen=(endpoint,))) as bus:
        recorder = RecorderService(bus, RecorderConfig(directory=tmp_path, path="m"))
        recorder.start()
        stop = threading.Event()
        thread = threading.Thread(target=recorder.run, args=(stop,))
        thread.start()
        wait_subscribed(bus, bus.keys.camera_events("cam0"))
        pub = bus.publisher(bus.keys.camera_events("cam0"))
        pub.put_bytes(b"FT\x01\x01garbage")
        pub.put(EventPacket("cam0", 0, 0, 999, 0, 640, 480, "evt3", 0, data=b""))
        assert wait_for(lambda: recorder.current is not None and recorder.current.packets == 1)
        assert recorder.current.malformed == 1
        stop.set()
        thread.join(10)


def packets_of(events: np.ndarray, t_until_us: int) -> list:
    from flagtrack.drivers.formats.packets import Packetizer, PacketParams

    packetizer = Packetizer("evt3", 640, 480, PacketParams(packet_us=1000))
    return packetizer.push(events, None, t_until_us=t_until_us) + packetizer.flush()


def publish(pub, packets: list, first_seq: int = 0, end: bool = False, **fields) -> None:
    for i, packet in enumerate(packets):
        pub.put(
            EventPacket(
                fields.get("camera_id", "cam0"),
                first_seq + i,
                packet.t_first_us,
                packet.t_last_us,
                packet.n_events,
                640,
                480,
                "evt3",
                time.time_ns(),
                fields.get("t_offset_us", packet.t_offset_us),
                end_of_stream=end and i == len(packets) - 1,
                data=packet.data,
            )
        )


def recorder_lines(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [
        r.getMessage()
        for r in caplog.records
        if r.name == "flagtrack.daemon.services.recorder" and r.levelno >= logging.WARNING
    ]


def test_packets_and_commands_that_cannot_be_carried_out_stop_nothing(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A first packet whose time offset is not a whole loop (stream_preamble refused it, uncaught), one
    whose camera id cannot go in a RAW header, 50 undecodable messages and a start command to a path
    that cannot be written: each counted and logged in a few lines; the recording goes on, exact."""
    events = np.concatenate(list(line_events(WavyFlag(), 0, 20_000, 640, 480)))
    packets = packets_of(events, 20_000)
    blocked = tmp_path / "a-file"
    blocked.write_text("not a folder")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        caplog.at_level(logging.WARNING, logger="flagtrack.daemon.services.recorder"),
        Bus(BusConfig(namespace="flagtrack/rec", listen=(endpoint,))) as bus,
    ):
        recorder = RecorderService(bus, RecorderConfig(directory=tmp_path, path="m"))
        recorder.start()
        statuses = bus.subscribe(bus.keys.recorder_status(), RecorderStatus)
        stop = threading.Event()
        thread = threading.Thread(target=recorder.run, args=(stop,))
        thread.start()
        try:
            wait_subscribed(bus, bus.keys.camera_events("cam0"), bus.keys.recorder_command())
            pub = bus.publisher(bus.keys.camera_events("cam0"))
            publish(pub, packets[:1], t_offset_us=123)
            publish(pub, packets[:1], camera_id="cam\n0")
            for _ in range(50):
                pub.put_bytes(b"FT\x01\x01garbage")
            publish(pub, packets)
            assert wait_for(lambda: recorder.current is not None and recorder.current.packets == len(packets))
            bus.publisher(bus.keys.recorder_command()).put(
                RecorderCommand("start", path=str(blocked / "x"), request_id="bad")
            )
            replies = []
            while len(replies) < 2 and (msg := statuses.recv(timeout_s=5.0)) is not None:
                replies += [msg] if msg.request_id == "bad" else []
            assert [r.state for r in replies] == ["idle", "error"] and "a-file" in replies[1].message
            assert thread.is_alive()
        finally:
            stop.set()
            thread.join(10)
    assert not thread.is_alive() and recorder.malformed_packets == 52
    np.testing.assert_array_equal(read_events(tmp_path / "m.raw", strict=True).events, events)
    sidecar = json.loads((tmp_path / "m.json").read_text())
    assert sidecar["malformed_packets"] == 52 and sidecar["sequence_gaps"] == [] and sidecar["stopped"]
    lines = recorder_lines(caplog)
    assert 2 <= len(lines) <= 5, lines  # first malformed packet, its summary, the failed command
    assert any("time offset 123" in line for line in lines) and any("(52 in all)" in line for line in lines)


def offline(path: Path, config) -> CentrelineBatch:
    from tests.integration.test_tracker_service import offline as reconstruct

    return reconstruct(path, config)


def test_a_restarted_camera_goes_to_a_new_file_and_the_last_centrelines_are_kept(tmp_path: Path) -> None:  # noqa: PLR0915 - one scenario, in the order it happens
    """The camera restarts mid-recording (its packets number from 0 again, its times too): the first
    stream stays in run.raw, the second goes to run_stream2.raw, each exactly as sent, with clean
    sidecars linked to each other; each stream's centrelines go to its own file, and the recorder,
    exiting at the end of stream, waits for the tracker's last ones: the second file holds every
    update of the offline reconstruction."""
    from flagtrack.daemon.core.tracker import Tracker
    from flagtrack.daemon.services.tracker import TrackerService, TrackerServiceConfig
    from tests.integration.test_tracker_service import CONFIG, FLAG

    first = np.concatenate(list(line_events(FLAG, 0, 30_000, 640, 480)))
    second = np.concatenate(list(line_events(FLAG, 0, 80_000, 640, 480, QuickLineParams(noise_rate_hz=1e5))))
    first_packets, second_packets = packets_of(first, 30_000)[:25], packets_of(second, 80_000)
    source = tmp_path / "second.raw"
    write_events(source, second, width=640, height=480, encoding="evt3")
    want = offline(source, CONFIG)
    params = CONFIG.tracker_params()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        Bus(BusConfig(namespace="flagtrack/rs", listen=(endpoint,))) as svc_bus,
        Bus(BusConfig(namespace="flagtrack/rs", connect=(endpoint,))) as cam_bus,
    ):
        tracker = TrackerService(svc_bus, TrackerServiceConfig(), lambda: Tracker(params, sensor_size=(640, 480)))
        tracker.start()
        recorder = RecorderService(
            svc_bus,
            RecorderConfig(directory=tmp_path / "out", path="run", centrelines=True),
            exit_at_end_of_stream=True,
        )
        recorder.start()
        lines = cam_bus.subscribe(cam_bus.keys.centrelines(), CentrelineMessage, capacity=100_000)
        stop = threading.Event()
        threads = [threading.Thread(target=s.run, args=(stop,)) for s in (tracker, recorder)]
        for thread in threads:
            thread.start()
        try:
            watch = cam_bus.watch_liveliness()  # the tracker is alive once its kernels are warm
            assert wait_for(lambda: watch.is_alive(cam_bus.keys.alive(tracker.name)), timeout_s=120)
            wait_subscribed(cam_bus, cam_bus.keys.camera_events("cam0"))
            pub = cam_bus.publisher(cam_bus.keys.camera_events("cam0"))
            publish(pub, first_packets)  # then the camera dies: no end of stream
            assert wait_for(lambda: recorder.current is not None and recorder.current.packets == 25, timeout_s=20)
            publish(pub, second_packets, end=True)
            threads[1].join(30)  # the recorder ends by itself
            assert not threads[1].is_alive()
        finally:
            stop.set()
            for thread in threads:
                thread.join(10)
        old_updates = 0
        while (msg := lines.recv(timeout_s=0.5)) is not None:
            old_updates += len(msg.t_s) if msg.stream == 0 else 0
    out = tmp_path / "out"
    n_first = int(sum(p.n_events for p in first_packets))
    np.testing.assert_array_equal(read_events(out / "run.raw", strict=True).events, first[:n_first])
    np.testing.assert_array_equal(read_events(out / "run_stream2.raw", strict=True).events, second)
    one, two = (json.loads((out / name).read_text()) for name in ("run.json", "run_stream2.json"))
    assert one["continued_in"] == "run_stream2.raw" and two["continues"] == "run.raw" and two["part"] == 2
    for sidecar, n in ((one, 25), (two, len(second_packets))):
        assert sidecar["stopped"] and sidecar["packets"] == n
        assert sidecar["sequence_gaps"] == [] and sidecar["missing_packets"] == 0
    assert recorder.restarts == 1 and tracker.restarts == 1
    got, _ = read_centrelines(out / "run_stream2_centrelines.h5")
    assert len(got) == len(want) > 300
    for name in ("t_s", "x", "y", "joints_x", "joints_y", "delta_rms", "n_events"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=0, atol=1e-9, err_msg=name)
    old, _ = read_centrelines(out / "run_centrelines.h5")
    assert len(old) == old_updates > 80 and old.t_s.max() < 0.025


@pytest.mark.timeout(400)  # its `up` child has its own 300 s timeout
def test_up_replay_exit_at_eof_records_every_centreline(tmp_path: Path) -> None:
    """``flagtrack up --replay F --speed 0 --exit-at-eof --centrelines OUT.h5 --record BASE`` with the
    recorder taking centrelines: the file as fast as possible, so the tracker's last centrelines come
    well after the camera's end of stream; the recorder waits for them (it stopped at the end packet
    before), and its file holds exactly what the centreline file (and reconstruct) has."""
    import subprocess
    import sys

    from tests.integration.test_tracker_service import CONFIG, FLAG

    events = np.concatenate(list(line_events(FLAG, 0, 200_000, 640, 480, QuickLineParams(noise_rate_hz=1e5))))
    source = tmp_path / "flag.raw"
    write_events(source, events, width=640, height=480, encoding="evt3")
    rig = tmp_path / "rig.yaml"
    rig.write_text("rig: drain\nservices: [camera, tracker, recorder]\nrecorder: {centrelines: true}\n")
    live, base = tmp_path / "live.h5", tmp_path / "rec" / "run"
    up = subprocess.run(
        [
            sys.executable,
            "-m",
            "flagtrack.daemon",
            "up",
            "-c",
            str(rig),
            "--replay",
            str(source),
            "--speed",
            "0",
            "--exit-at-eof",
            "--centrelines",
            str(live),
            "--record",
            str(base),
            "--root",
            "100",
            "240",
            "--length",
            "200",
            "--tau",
            "0.00025",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert up.returncode == 0, up.stderr
    want, _ = read_centrelines(live)
    got, attrs = read_centrelines(tmp_path / "rec" / "run_centrelines.h5")
    assert len(want) > 700 and len(got) == len(want)
    for name in ("t_s", "x", "y", "joints_x", "joints_y", "delta_rms", "n_events"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
    np.testing.assert_allclose(got.x, offline(source, CONFIG).x, rtol=0, atol=1e-9)
    sidecar = json.loads((tmp_path / "rec" / "run.json").read_text())
    assert (
        sidecar["stopped"] and sidecar["events"] == len(events) and sidecar["centrelines_file"] == "run_centrelines.h5"
    )


def test_centrelines_of_another_tracker_setup_are_refused_not_mixed_in(tmp_path: Path) -> None:
    """The centreline file takes the samples and joints of its first message; a message with
    others raises a SchemaError (counted by the service) and the file keeps the rest."""
    from flagtrack.daemon.errors import SchemaError
    from flagtrack.daemon.services.recorder import RecordingPart as Recording
    from tests.integration.test_centreline_file_service import message

    recording = Recording(base=tmp_path / "r", config={}, want_centrelines=True)
    recording.write_centrelines(message(0, 4, 51))
    with pytest.raises(SchemaError, match="7 samples and 11 joints, the file 51 and 11"):
        recording.write_centrelines(message(1, 5, 7))
    recording.write_centrelines(message(2, 3, 51))
    recording.close()
    got, _ = read_centrelines(tmp_path / "r_centrelines.h5")
    np.testing.assert_array_equal(got.t_s, np.r_[np.arange(4) * 1e-3, 2 + np.arange(3) * 1e-3])


def test_packets_a_full_queue_drops_are_in_the_sidecar_and_logged(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """60 packets come while the recorder's loop is not reading and its queue holds 10: the newest 10
    are recorded, the 50 dropped are in the sidecar (dropped_packets) and in one warning."""
    events = np.concatenate(list(line_events(WavyFlag(), 0, 60_000, 640, 480)))
    packets = packets_of(events, 60_000)[:60]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        caplog.at_level(logging.WARNING, logger="flagtrack.daemon.services.recorder"),
        Bus(BusConfig(namespace="flagtrack/rfull", listen=(endpoint,))) as bus,
    ):
        recorder = RecorderService(bus, RecorderConfig(directory=tmp_path, max_queue_packets=10))
        recorder.start()
        recorder.start_recording("q", centrelines=False)
        wait_subscribed(bus, bus.keys.camera_events("cam0"))
        publish(bus.publisher(bus.keys.camera_events("cam0")), packets)
        assert wait_for(lambda: recorder._packets.channel.dropped == 50)
        stop = threading.Event()
        thread = threading.Thread(target=recorder.run, args=(stop,))
        thread.start()
        try:
            assert wait_for(lambda: recorder.current is not None and recorder.current.packets == 10)
            assert wait_for(lambda: recorder.current.dropped == 50)
        finally:
            stop.set()
            thread.join(10)
    sidecar = json.loads((tmp_path / "q.json").read_text())
    assert sidecar["dropped_packets"] == 50 and sidecar["packets"] == 10 and sidecar["stopped"]
    n_kept = sum(p.n_events for p in packets[-10:])  # the queue keeps the newest
    np.testing.assert_array_equal(read_events(tmp_path / "q.raw", strict=True).events, events[len(events) - n_kept :])
    assert [line for line in recorder_lines(caplog) if "dropped by the full queue" in line] == [
        "recorder: the queue dropped 50 packet(s) in all (the disk falls behind) [packets dropped by the full queue: 50]"
    ]


def test_the_recorder_queue_is_bounded_by_bytes(tmp_path: Path) -> None:
    """A queue of 100 KB under 60 packets of ~3 KB while the loop is not reading: the newest that
    fit are recorded, exactly, and the dropped ones are counted in the sidecar."""
    from flagtrack.daemon.schema import encode

    events = np.concatenate(list(line_events(WavyFlag(), 0, 60_000, 640, 480)))
    packets = packets_of(events, 60_000)[:60]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with Bus(BusConfig(namespace="flagtrack/rbytes", listen=(endpoint,))) as bus:
        recorder = RecorderService(bus, RecorderConfig(directory=tmp_path, max_queue_bytes=100_000))
        recorder.start()
        recorder.start_recording("b", centrelines=False)
        wait_subscribed(bus, bus.keys.camera_events("cam0"))
        pub = bus.publisher(bus.keys.camera_events("cam0"))
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
                data=p.data,
            )
            sizes.append(len(encode(message)))
            pub.put(message)
        kept = int(np.searchsorted(np.cumsum(sizes[::-1]), 100_000, side="right"))
        assert 10 < kept < 50 and wait_for(lambda: recorder._packets.channel.dropped == 60 - kept)
        stop = threading.Event()
        thread = threading.Thread(target=recorder.run, args=(stop,))
        thread.start()
        try:
            assert wait_for(lambda: recorder.current is not None and recorder.current.packets == kept)
            assert wait_for(lambda: recorder.current.dropped == 60 - kept)
        finally:
            stop.set()
            thread.join(10)
    sidecar = json.loads((tmp_path / "b.json").read_text())
    assert sidecar["dropped_packets"] == 60 - kept and sidecar["packets"] == kept
    from flagtrack.drivers.formats.packets import decode_packet

    want = np.concatenate([decode_packet("evt3", p.data, p.t_offset_us)[0] for p in packets[-kept:]])
    np.testing.assert_array_equal(read_events(tmp_path / "b.raw", strict=True).events, want)


def test_a_duplicated_packet_is_dropped_and_the_file_stays_one_stream(tmp_path: Path) -> None:
    """Packet 30 comes twice (after 31): the recorder keeps one file, exactly the events sent once,
    and counts the duplicate as late; a packet of another stream id then starts the next part."""
    events = np.concatenate(list(line_events(WavyFlag(), 0, 60_000, 640, 480)))
    packets = packets_of(events, 60_000)[:50]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with Bus(BusConfig(namespace="flagtrack/rdup", listen=(endpoint,))) as bus:
        recorder = RecorderService(bus, RecorderConfig(directory=tmp_path, path="d"))
        recorder.start()
        stop = threading.Event()
        thread = threading.Thread(target=recorder.run, args=(stop,))
        thread.start()
        try:
            wait_subscribed(bus, bus.keys.camera_events("cam0"))
            pub = bus.publisher(bus.keys.camera_events("cam0"))
            for seq in [*range(32), 30, *range(32, 50)]:
                p = packets[seq]
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
                        time.time_ns(),
                        p.t_offset_us,
                        stream_id=42,
                        data=p.data,
                    )
                )
            assert wait_for(lambda: recorder.late_packets == 1 and recorder.current.packets == 50)
            p = packets[0]
            pub.put(
                EventPacket(
                    "cam0",
                    3,
                    p.t_first_us,
                    p.t_last_us,
                    p.n_events,
                    640,
                    480,
                    "evt3",
                    time.time_ns(),
                    p.t_offset_us,
                    stream_id=43,
                    data=p.data,
                )
            )
            assert wait_for(lambda: recorder.current.part == 2)
        finally:
            stop.set()
            thread.join(10)
    sidecar = json.loads((tmp_path / "d.json").read_text())
    assert sidecar["packets"] == 50 and sidecar["late_packets"] == 1 and sidecar["sequence_gaps"] == []
    assert sidecar["continued_in"]
    sent = events[events["t"] <= packets[49].t_last_us]
    np.testing.assert_array_equal(read_events(tmp_path / "d.raw", strict=True).events, sent)
