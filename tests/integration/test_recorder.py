"""Recorder: loss-free .raw files that decode to exactly what the camera sent, rotation, crash safety."""

from __future__ import annotations

import json
import shutil
import threading
import time
import warnings
from pathlib import Path

import numpy as np

from flagtrack.daemon.schema import EventPacket, RecorderCommand, RecorderStatus
from flagtrack.daemon.services.camera import CameraService, CameraStreamConfig
from flagtrack.daemon.services.recorder import RecorderConfig, RecorderService
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.camera.replay import ReplayCamera, ReplayConfig
from flagtrack.drivers.formats import read_events, write_events
from flagtrack.drivers.sim.quickline import WavyFlag, line_events
from tests.integration.test_transport import free_port, wait_for


def make_recording(tmp_path: Path, t0_us: int, t1_us: int) -> tuple[Path, np.ndarray]:
    events = np.concatenate(list(line_events(WavyFlag(), t0_us, t1_us, 640, 480)))
    path = tmp_path / "source.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    return path, events


def run_rig(source: Path, rec_cfg: RecorderConfig, speed: float, during=None) -> RecorderService:  # noqa: ANN001
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with Bus(BusConfig(namespace="flagtrack/rec", listen=(endpoint,))) as rec_bus, \
            Bus(BusConfig(namespace="flagtrack/rec", connect=(endpoint,))) as cam_bus:
        recorder = RecorderService(rec_bus, rec_cfg, {"test": True})
        stop = threading.Event()
        thread = threading.Thread(target=recorder.run, args=(stop,))
        thread.start()
        time.sleep(0.4)
        camera = CameraService(cam_bus, CameraStreamConfig(), ReplayCamera(ReplayConfig(source, speed=speed)))
        cam_thread = threading.Thread(target=camera.run, args=(threading.Event(),))
        cam_thread.start()
        if during is not None:
            during(cam_bus, recorder)
        cam_thread.join(30)
        recorded = lambda: recorder.current is not None and recorder.current.packets == camera.packets  # noqa: E731
        assert wait_for(recorded if rec_cfg.path else lambda: True)
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
        time.sleep(0.3)
        commands.put(RecorderCommand("rotate", path="b", request_id="2"))
        while (msg := status.recv(timeout_s=2.0)) is not None and len(statuses) < 3:
            statuses.append(msg)

    run_rig(source, RecorderConfig(directory=tmp_path / "out"), speed=1.0, during=rotate)
    a = read_events(tmp_path / "out" / "a.raw", strict=True).events
    b = read_events(tmp_path / "out" / "b.raw", strict=True).events
    assert len(a) > 0 and len(b) > 0
    joined = np.concatenate([a, b])
    # recording started after the first packets: what was recorded is one contiguous run, ending at the end
    np.testing.assert_array_equal(joined, events[len(events) - len(joined):])
    assert [s.request_id for s in statuses[:3]] == ["1", "2", "2"]
    assert [s.state for s in statuses[:3]] == ["recording", "idle", "recording"]


def test_a_recording_cut_mid_write_is_readable_up_to_its_last_flush(tmp_path: Path) -> None:
    source, events = make_recording(tmp_path, 0, 600_000)
    copies: list[Path] = []

    def snapshot(bus: Bus, recorder: RecorderService) -> None:
        time.sleep(0.35)  # mid-recording: copy the file as a power cut would leave it
        copy = tmp_path / "cut.raw"
        shutil.copyfile(tmp_path / "out" / "live.raw", copy)
        with open(copy, "ab") as f:
            f.write(b"\x01")  # a torn last word
        copies.append(copy)

    run_rig(source, RecorderConfig(directory=tmp_path / "out", path="live", flush_interval_s=0.05), 1.0, snapshot)
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
        stop = threading.Event()
        thread = threading.Thread(target=recorder.run, args=(stop,))
        thread.start()
        time.sleep(0.3)
        pub = bus.publisher(bus.keys.camera_events("cam0"))
        pub.put_bytes(b"FT\x01\x01garbage")
        pub.put(EventPacket("cam0", 0, 0, 999, 0, 640, 480, "evt3", 0, data=b""))
        assert wait_for(lambda: recorder.current is not None and recorder.current.packets == 1)
        assert recorder.current.malformed == 1
        stop.set()
        thread.join(10)
