"""The legitimate rig, secured: router, camera, tracker, recorder and supervisor, each its own process
with its own certificate, over mutual TLS with the rig's access control; a one-point sweep records
through the supervisor's command, and the replay still equals `flagtrack reconstruct` to 1e-9."""

from __future__ import annotations

import json
import signal
import subprocess
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.rig.config import load_rig
from flagtrack.daemon.schema import CentrelineMessage
from flagtrack.daemon.sweep.runlog import read_run
from flagtrack.daemon.transport import Bus
from flagtrack.drivers.formats import read_events, write_events
from flagtrack.drivers.formats.centreline import read_centrelines
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events
from tests.fakes.helpers import wait_until
from tests.fakes.secure import load, make_pki, rig_text
from tests.integration.test_transport import free_port
from tests.integration.test_up import flagtrack, start

FLAG = WavyFlag(length=200.0, root=(100.0, 240.0))
TRACKER_ARGS = ["--root", "100", "240", "--length", "200", "--tau", "0.0003"]
SPEED = 0.1  # 0.8 s of camera time over 8 s: the sweep's point fits inside it


def rig_body(tmp_path: Path, recording: Path) -> str:
    return f"""
camera: {{id: cam0, adapter: replay, rate_interval_s: 0.02, replay: {{path: {recording}, speed: {SPEED}}}}}
tracker: {{root: [100, 240], length: 200, tau_s: 0.0003, max_lag_ms: null}}
recorder: {{directory: {tmp_path / "rec"}}}
tunnel:
  driver: simulated
  safety: {{max_speed_mps: 8, max_ramp_mps2: 4.0, ramp_period_s: 0.05, tolerance_mps: 0.15, settle_timeout_s: 3.0,
           poll_period_s: 0.05, keepalive_s: 0.25, watchdog_s: 1.0}}
  sim: {{tau_s: 0.1, ramp_mps2: 6.0, watchdog_s: 1.0}}
supervisor:
  mode: sweep
  runs_dir: {tmp_path / "runs"}
  run_name: run
  onset: {{learn_s: 0.2, window_s: 0.1}}  # in camera time: a baseline within the first 0.3 s (3 s here)
  silence_timeout_s: 3.0
  startup_timeout_s: 60
  sweep: {{speeds: [2.0], branches: [up], settle_s: 0.2, record_s: 1.5}}
services: [camera, tracker, recorder, supervisor]
"""


def run_processes(path: Path) -> tuple[list[CentrelineMessage], dict[str, tuple[str, str]], dict[str, int]]:
    """Router, tracker and recorder, then supervisor and camera, each `flagtrack SERVICE -c path` (its
    own identity); this process watches as the operator. Returns the centreline messages it heard,
    each process's (stdout, stderr) and exit code."""
    rig = load_rig(path, services=())
    router = start("router", "-c", str(path))  # listens where the rig's clients connect, as `router`
    procs: dict[str, subprocess.Popen] = {"router": router}
    messages: list[CentrelineMessage] = []
    try:
        assert "mutual TLS, access control" in router.stderr.readline()
        procs.update((name, start(name, "-c", str(path))) for name in ("tracker", "recorder"))
        with Bus(rig.bus_config_for(["operator"])) as bus:
            lines = bus.subscribe(bus.keys.centrelines(), CentrelineMessage, capacity=1_000_000)
            alive = bus.watch_liveliness()
            names = ("tracker", "recorder")
            wait_until(lambda: all(alive.is_alive(bus.keys.alive(n)) for n in names), 90, "tracker and recorder")
            procs["supervisor"] = start("supervisor", "-c", str(path))  # it waits for the camera and a baseline
            procs["camera"] = start("camera", "-c", str(path))
            deadline = time.monotonic() + 90
            while time.monotonic() < deadline and not (messages and messages[-1].final):
                msg = lines.recv(timeout_s=0.5)
                messages += [msg] if msg is not None else []
            for name in ("camera", "supervisor"):  # both end by themselves
                try:
                    procs[name].wait(timeout=30)
                except subprocess.TimeoutExpired:
                    pass
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        outs = {name: proc.communicate(timeout=60) for name, proc in procs.items()}
    return messages, outs, {name: proc.returncode for name, proc in procs.items()}


@pytest.mark.slow
@pytest.mark.timeout(180)
def test_the_secured_rig_runs_end_to_end_each_service_with_its_identity(tmp_path: Path) -> None:
    recording = tmp_path / "flag.raw"
    events = np.concatenate(list(line_events(FLAG, 0, 800_000, 640, 480, QuickLineParams(noise_rate_hz=1e5))))
    write_events(recording, events, width=640, height=480, encoding="evt3")
    pki = make_pki(tmp_path / "pki")
    path = tmp_path / "rig.yaml"
    load(path, rig_text(free_port(), pki, body=rig_body(tmp_path, recording)))
    messages, outs, codes = run_processes(path)
    assert codes == {"router": 0, "tracker": 130, "recorder": 130, "supervisor": 0, "camera": 0}, outs

    # the tracker's centrelines, over TLS through the router, equal the offline reconstruction (its latency
    # budget is off, max_lag_ms: null: on a machine busy with other tests it would shed, as it should)
    offline = tmp_path / "offline.h5"
    assert flagtrack("reconstruct", str(recording), "-o", str(offline), *TRACKER_ARGS, "--no-progress").returncode == 0
    live = CentrelineBatch.concatenate([m.batch() for m in messages if len(m.t_s)])
    with h5py.File(offline) as f:
        want = {name: f[name][()] for name in ("t", "x", "y", "joints/x", "joints/y", "delta_rms", "n_events")}
    assert len(live) == len(want["t"]) > 1000
    for name, got in (
        ("t", live.t_s),
        ("x", live.x),
        ("y", live.y),
        ("joints/x", live.joints_x),
        ("joints/y", live.joints_y),
        ("delta_rms", live.delta_rms),
        ("n_events", live.n_events),
    ):
        np.testing.assert_allclose(got, want[name], rtol=0, atol=1e-9, err_msg=name)

    # the supervisor heard the camera's rates and the tracker's centrelines, and its command made the
    # recorder record the point: a contiguous run of the source's events, and its centrelines
    record = read_run(tmp_path / "runs" / "run")
    (point,) = record.latest_points().values()
    assert record.stop["reason"] == "finished" and point.status == "done"
    assert point.event_rate_mev_s > 0 and point.raw_bytes > 0 and point.centreline_file
    raw = read_events(tmp_path / "runs" / "run" / point.raw_file, strict=True).events
    first = int(np.searchsorted(events["t"], raw["t"][0]))
    assert len(raw) > 1000
    np.testing.assert_array_equal(raw, events[first : first + len(raw)])
    point_lines, _ = read_centrelines(tmp_path / "runs" / "run" / point.centreline_file)
    assert len(point_lines) > 100
    at = np.searchsorted(want["t"], point_lines.t_s)
    np.testing.assert_allclose(point_lines.x, want["x"][at], rtol=0, atol=1e-9)
    sidecar = json.loads((tmp_path / "runs" / "run" / point.raw_file).with_suffix(".json").read_text())
    assert sidecar["config"]["bus"]["security"]["acl"] is True  # the rig as it ran, beside the recording
