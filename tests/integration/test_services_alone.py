"""Each service as its own process (`flagtrack camera|tracker|recorder|viewer -c rig.yaml`), joined by a
router: the recorder keeps every event and centreline, the viewer writes its .rrd, the tracker's status
reports its rates, lag and packet counts."""

from __future__ import annotations

import json
import signal
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from flagtrack.daemon.schema import TrackerStatus
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.formats import read_events
from tests.fakes.helpers import wait_subscribed, wait_until
from tests.integration.test_transport import free_port
from tests.integration.test_up import TRACKER_ARGS, flagtrack, start

TAU_S = 0.0003
SPEED = 0.1  # the 0.2 s recording replayed over 2 s: the tracker's 1 s status windows see it flow


def _wait_alive(bus: Bus, services: list[str], timeout_s: float) -> bool:
    watch = bus.watch_liveliness()
    return wait_until(
        lambda: all(watch.is_alive(bus.keys.alive(name)) for name in services),
        timeout_s,
        f"{', '.join(services)} alive",
        poll_s=0.1,
    )


@pytest.mark.slow
def test_each_service_alone_through_a_router(recording: Path, tmp_path: Path) -> None:
    port = free_port()
    rig = tmp_path / "rig.yaml"
    rig.write_text(f"""
rig: alone
bus: {{mode: client, connect: ["tcp/127.0.0.1:{port}"]}}
camera: {{adapter: replay, replay: {{path: {recording}, speed: {SPEED}}}}}
tracker: {{root: [100, 240], length: 200, tau_s: {TAU_S}, max_lag_ms: null}}
recorder: {{directory: {tmp_path / "rec"}, path: run, centrelines: true}}
viewer: {{sink: rrd, rrd_path: {tmp_path / "view.rrd"}}}
""")
    router = start("router", "--listen", f"tcp/127.0.0.1:{port}")
    services, camera = [], None
    statuses: list[TrackerStatus] = []
    try:
        assert "listening" in router.stderr.readline()
        services = [start(name, "-c", str(rig)) for name in ("tracker", "recorder", "viewer")]
        with Bus(BusConfig(namespace="flagtrack/alone", mode="client", connect=(f"tcp/127.0.0.1:{port}",))) as bus:
            status = bus.subscribe(bus.keys.tracker_status(), TrackerStatus)
            assert _wait_alive(bus, ["tracker", "recorder", "viewer"], 90), "services did not come up"
            wait_subscribed(bus, bus.keys.camera_events("cam0"), bus.keys.centrelines())  # theirs reached the router
            camera = start("camera", "-c", str(rig))
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and (
                camera.poll() is None or len(statuses) < 3 or statuses[-1].events_per_s > 0
            ):
                msg = status.recv(timeout_s=0.5)  # until the camera is done and a status saw no events
                if msg is not None:
                    statuses.append(msg)
            _, camera_err = camera.communicate(timeout=10)  # (closes its pipes)
            assert camera.returncode == 0, camera_err
    finally:
        for proc in [*services, router]:
            proc.send_signal(signal.SIGINT)
        outs = [proc.communicate(timeout=60) for proc in [*services, router]]
    assert [p.returncode for p in services] == [130, 130, 130], [err for _, err in outs]

    offline = tmp_path / "offline.h5"
    assert flagtrack("reconstruct", str(recording), "-o", str(offline), *TRACKER_ARGS, "--no-progress").returncode == 0
    with h5py.File(offline) as f:
        t_offline = f["t"][()]

    # the recorder: every event of the file, and every centreline of the tracker
    raw = tmp_path / "rec" / "run.raw"
    np.testing.assert_array_equal(read_events(raw).events, read_events(recording).events)
    sidecar = json.loads((tmp_path / "rec" / "run.json").read_text())
    assert sidecar["sequence_gaps"] == [] and sidecar["missing_packets"] == 0 and sidecar["stopped"]
    assert abs(sidecar["started_unix_s"] - time.time()) < 300
    with h5py.File(tmp_path / "rec" / "run_centrelines.h5") as f:
        np.testing.assert_allclose(f["t"][()], t_offline, atol=1e-9)

    # the viewer wrote its file; the tracker's status counted every packet and its rates
    assert (tmp_path / "view.rrd").stat().st_size > 10_000
    tracking = [s for s in statuses if s.state == "tracking" and s.updates_per_s > 0]
    assert tracking, statuses
    # each status counts over about 1 s (status_interval_s): summed, the rates give back what flowed, however
    # a stall and its catch-up moved it between windows (one update per tau of camera time, every event);
    # a window a loaded host stretched past 1 s divides by its length: less, never more
    updates, events = len(t_offline), len(read_events(recording).events)
    assert 0.6 * updates <= sum(s.updates_per_s for s in statuses) <= 1.2 * updates
    assert 0.6 * events <= sum(s.events_per_s for s in statuses) <= 1.2 * events
    assert statuses[-1].missing_packets == 0 and statuses[-1].malformed_packets == 0
    assert 0.0 <= min(s.lag_s for s in tracking) < 0.5
