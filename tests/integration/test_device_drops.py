"""What the camera itself drops reaches the recording's sidecar and makes it lossy (issue 30), on the real bus:
a simulated camera whose loop is held up longer than its ``max_lag_s`` (as by an overloaded host) skips ahead."""

from __future__ import annotations

import dataclasses
import json
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from flagtrack.daemon.schema import CameraStatus, RecorderCommand, RecorderStatus
from flagtrack.daemon.services.camera import CameraService, CameraStreamConfig
from flagtrack.daemon.services.recorder import RecorderConfig, RecorderService
from flagtrack.daemon.sweep.validity import recording_problem
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.camera.simulated import SKIP_REASON, SimulatedCamera, SimulatedCameraConfig
from flagtrack.drivers.formats import read_events
from tests.fakes.helpers import wait_subscribed, wait_until
from tests.integration.test_transport import free_port

TWIN = SimulatedCameraConfig(max_lag_s=0.05, events_per_px2=0.5, noise_rate_hz=5000)
HOLD_S = 0.2


class HeldUp:
    """The twin read by a loop that is held up for ``HOLD_S`` every ``every`` reads: each time, it is
    more than ``max_lag_s`` behind the wall clock, so it skips ahead (whatever the machine's speed)."""

    def __init__(self, camera: SimulatedCamera, every: int = 10) -> None:
        self.camera, self.every, self.reads = camera, every, 0

    def open(self) -> Any:
        return self.camera.open()

    def read(self, timeout_s: float) -> Any:
        self.reads += 1
        if self.reads % self.every == 0:
            time.sleep(HOLD_S)  # the fault injected: a host too busy to read the camera
        return self.camera.read(timeout_s)

    def close(self) -> None:
        self.camera.close()


def reply(statuses, request_id: str) -> RecorderStatus:
    """The recorder's answer to the command ``request_id``."""

    def answered() -> RecorderStatus | None:
        while (status := statuses.recv(timeout_s=0)) is not None:
            if status.request_id == request_id:
                return status
        return None

    return wait_until(answered, 20, f"the recorder's answer to {request_id}")


def test_a_camera_skipping_ahead_puts_its_drops_in_the_sidecar_and_the_point_is_lossy(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        Bus(BusConfig(namespace="flagtrack/drops", listen=(endpoint,))) as rec_bus,
        Bus(BusConfig(namespace="flagtrack/drops", connect=(endpoint,))) as cam_bus,
    ):
        recorder = RecorderService(rec_bus, RecorderConfig(directory=tmp_path))
        recorder.start()
        statuses = cam_bus.subscribe(cam_bus.keys.recorder_status(), RecorderStatus, capacity=100)
        camera_statuses = rec_bus.subscribe(rec_bus.keys.camera_status("cam0"), CameraStatus, capacity=100)
        stop, cam_stop = threading.Event(), threading.Event()
        rec_thread = threading.Thread(target=recorder.run, args=(stop,))
        rec_thread.start()
        wait_subscribed(cam_bus, cam_bus.keys.camera_events("cam0"), cam_bus.keys.recorder_command())
        wait_subscribed(rec_bus, rec_bus.keys.recorder_status())
        camera = CameraService(cam_bus, CameraStreamConfig(packet_us=4000), HeldUp(SimulatedCamera(TWIN)))
        camera.start()
        wait_subscribed(cam_bus, cam_bus.keys.camera_status("cam0"))
        cam_thread = threading.Thread(target=camera.run, args=(cam_stop,))
        cam_thread.start()
        commands = cam_bus.publisher(cam_bus.keys.recorder_command())
        try:
            commands.put(RecorderCommand("start", path="point", request_id="start"))
            started = reply(statuses, "start")
            wait_until(lambda: recorder.current is not None and recorder.current.device_drop_reports >= 3, 30)
            commands.put(RecorderCommand("stop", request_id="stop"))
            stopped = reply(statuses, "stop")
        finally:
            cam_stop.set()
            cam_thread.join(10)
            stop.set()
            rec_thread.join(10)
        seen = [camera_statuses.recv(timeout_s=0) for _ in range(100)]
    sidecar = json.loads((tmp_path / "point.json").read_text())
    drops = sidecar["device_drops"]
    assert sidecar["device_drop_reports"] == stopped.device_drops == sum(d["reports"] for d in drops) >= 3
    assert camera.device_drops >= stopped.device_drops  # some came before the recording began
    assert sidecar["sequence_gaps"] == [] and stopped.missing_packets == 0  # no packet lost on the bus
    # a hold skips the time held up, in whole slices, less the twin's lead on the clock (up to a slice) and the
    # rounding down; a loaded host may make the twin skip shorter spans besides
    assert max(d["count"] for d in drops) >= HOLD_S * 1e6 - 2 * TWIN.slice_us
    for drop in drops:
        assert (drop["reason"], drop["unit"]) == (SKIP_REASON, "us")
        assert drop["count"] > 0 and drop["count"] % TWIN.slice_us == 0
        assert drop["t_to_us"] - drop["t_from_us"] >= drop["count"]  # the span covers the skipped time
        assert drop["sent_to_ns"] >= drop["sent_from_ns"] > 0
    events = read_events(tmp_path / "point.raw").events["t"]
    for drop in drops:  # the recording holds no event in the time the camera skipped
        assert not ((events > drop["t_from_us"]) & (events < drop["t_to_us"])).any()
    reason = recording_problem(started, stopped)
    assert reason is not None and reason.startswith(f"the camera dropped data {stopped.device_drops} time(s)")
    assert SKIP_REASON in reason and stopped.device_drop_reason in reason
    said = [s for s in seen if s is not None and s.device_drops]
    assert said and SKIP_REASON in said[0].message and said[0].drop_reason == SKIP_REASON


@pytest.mark.slow
def test_a_sweep_point_the_camera_dropped_data_in_is_lossy_with_the_reason(tmp_path: Path) -> None:
    """A one-point sweep on the simulated rig: while the point records, the camera's loop is held up
    past the twin's max_lag_s once; the point is ``lossy`` with the twin's reason, measured again."""
    from flagtrack.daemon.sweep.runlog import read_run
    from tests.integration.test_supervisor import rig, run

    sweep = {"speeds": [4.0], "branches": ["up"], "settle_s": 0.5, "record_s": 3.0}  # (the hold ends within it)
    config = rig(tmp_path, sweep=sweep)
    twin = dataclasses.replace(config.camera.simulated, max_lag_s=1.0)  # (a busy CI host lags 0.3 s by itself)
    config = dataclasses.replace(config, camera=dataclasses.replace(config.camera, simulated=twin))
    point = "000-up-4.00"

    def hold_once(services: list, group: object) -> None:
        supervisor = services[0]
        camera = next(s for s in services if s.name.startswith("camera/")).camera
        wait_until(lambda: supervisor.recording_point == point, 60, "the point recording")
        read, held = camera.read, threading.Event()

        def held_up(timeout_s: float) -> Any:
            if not held.is_set():
                held.set()
                time.sleep(1.6)  # the fault injected: a host too busy to read the camera, past max_lag_s
            return read(timeout_s)

        camera.read = held_up

    run(config, during=hold_once)
    run_dir = tmp_path / "runs" / "run"
    attempts = [p for p in read_run(run_dir).points if p.point_id == point]
    assert [p.status for p in attempts] == ["lossy", "done"]
    assert attempts[0].reason.startswith("the camera dropped data 1 time(s) while recording: " + SKIP_REASON)
    sidecar = json.loads((run_dir / attempts[0].raw_file).with_suffix(".json").read_text())
    assert [d["reason"] for d in sidecar["device_drops"]] == [SKIP_REASON] and sidecar["device_drops"][0]["count"] > 0
