"""A full disk (issue 20): `flagtrack sweep` whose run folder is a small tmpfs (mounted in a private
mount namespace: `unshare -m`, skipped with a reason where it cannot be made). The recording stops
with one clear error, its file reads back up to its last flush, the supervisor ends the sweep with
the reason and the tunnel (a simulated controller on a real pty, owned by the test) at zero; the run
log keeps its records. And a point the disk cannot hold is not started at all."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.sweep.runlog import read_run
from flagtrack.drivers.formats import read_events, write_events
from flagtrack.drivers.formats.centreline import read_centrelines
from flagtrack.drivers.reserve import RESERVE_BYTES
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events
from flagtrack.drivers.tunnel.sim_model import SimParams
from flagtrack.drivers.tunnel.simulated import SimulatedTunnel
from tests.fakes.tunnel import SWEEP_SIM
from tests.integration.test_restart_resumes import FLAGTRACK, rig_file


def _namespaces_work() -> str | None:
    """Why a private mount namespace with a tmpfs cannot be made here, or None."""
    if shutil.which("unshare") is None:
        return "no unshare(1)"
    probe = subprocess.run(
        ["unshare", "-rm", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"], capture_output=True, text=True
    )
    return None if probe.returncode == 0 else f"cannot mount a tmpfs in a mount namespace: {probe.stderr.strip()}"


@pytest.fixture
def mount_namespace() -> None:
    """Skip the test where a private mount namespace with a tmpfs cannot be made."""
    why = _namespaces_work()
    if why:
        pytest.skip(why)


@pytest.fixture
def sim_params() -> SimParams:
    return SWEEP_SIM


@pytest.mark.slow
@pytest.mark.usefixtures("mount_namespace")
def test_a_disk_filling_up_mid_point_ends_the_sweep_safe_with_the_file_readable(
    sim: SimulatedTunnel, tmp_path: Path
) -> None:
    sweep = {"speeds": [5.5, 6.0], "branches": ["up"], "settle_s": 0.5, "record_s": 8.0}
    recorder = {"min_free_mb": 0.0}
    rig = rig_file(tmp_path, sim.port, sweep, recorder, expected_rate_mev_s=0.0, free_space_margin_mb=0.0)
    runs, out = tmp_path / "runs", tmp_path / "copy"
    runs.mkdir()
    out.mkdir()
    flagtrack = " ".join(FLAGTRACK)
    script = (  # the sweep, then a resume on the disk still full, then a copy of the run out of the namespace
        f"mount -t tmpfs -o size=4m tmpfs {runs} && {flagtrack} sweep -c {rig}; rc=$?; cp -a {runs}/. {out}/; "
        f"echo RESUME >&2; {flagtrack} sweep --resume {runs}/night; cp {runs}/night/run.jsonl {out}/resumed.jsonl; "
        "exit $rc"
    )
    done = subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True, text=True, timeout=120)
    run_dir = out / "night"
    record = read_run(run_dir)
    assert done.returncode == 1, done.stderr[-3000:]
    assert "No space left on device" in record.stop["reason"], record.stop
    point = record.points[-1]
    assert point.status == "failed" and "recorder: recording stopped: writing" in point.reason
    errors = [line for line in done.stderr.splitlines() if line.startswith("ERROR flagtrack.daemon.services.recorder")]
    assert len(errors) == 1 and "No space left on device" in errors[0], done.stderr[-3000:]
    assert "Traceback" not in done.stderr
    raws = sorted(run_dir.glob("points/*.raw"))
    assert raws, list(run_dir.rglob("*"))
    events = read_events(raws[-1]).events  # whole up to its last flush
    assert len(events) > 0
    assert sim.setpoint_mps == 0.0 and sim.watchdog_trips == 0  # commanded to zero by the supervisor
    # resumed on the disk still full: the point is not started (the rate the failed attempt wrote at
    # says it cannot fit), the tunnel never ramped
    out_log = out / "resumed.jsonl"
    resumed = out_log.read_text().splitlines()
    stop = json.loads(resumed[-1])
    assert stop["type"] == "stop" and "000-up-5.50 not started: not enough free space on" in stop["reason"], stop
    assert not any(json.loads(line)["type"] == "point" for line in resumed[len(resumed) - 2 :])
    assert sim.watchdog_trips == 0


FILL = """
import json, sys, threading
from pathlib import Path
import numpy as np
from flagtrack.daemon.schema import RecorderStatus
from flagtrack.daemon.services.recorder import RecorderConfig, RecorderService
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.formats import read_events
from flagtrack.drivers.sim.quickline import WavyFlag, line_events
from tests.fakes.helpers import wait_subscribed, wait_until
from tests.integration.test_recorder import packets_of, publish
from tests.integration.test_transport import free_port

disk = Path(sys.argv[1])
events = np.concatenate(list(line_events(WavyFlag(), 0, 400_000, 640, 480)))
packets = packets_of(events, 400_000)
with Bus(BusConfig(namespace="flagtrack/disk", listen=(f"tcp/127.0.0.1:{free_port()}",))) as bus:
    cfg = RecorderConfig(directory=disk, path="full", min_free_mb=0.0, flush_interval_s=0.01)
    recorder = RecorderService(bus, cfg)
    recorder.start()
    statuses = bus.subscribe(bus.keys.recorder_status(), RecorderStatus)
    stop = threading.Event()
    thread = threading.Thread(target=recorder.run, args=(stop,), daemon=True)
    thread.start()
    wait_subscribed(bus, bus.keys.camera_events("cam0"))
    wait_until(lambda: recorder.current is not None, 10)
    pub = bus.publisher(bus.keys.camera_events("cam0"))
    for i in range(0, len(packets), 20):  # in steps, so that flushes happen between them
        publish(pub, packets[i : i + 20], first_seq=i)
        wait_until(lambda: recorder.current is None or recorder.current.packets >= min(i + 20, len(packets)), 10)
        if recorder.current is None:
            break
    errors = []
    wait_until(lambda: (s := statuses.recv(timeout_s=0.1)) and s.state == "error" and errors.append(s.message) is None, 10)
    stop.set()
    thread.join(10)
    got = read_events(disk / "full.raw", strict=True).events
    print(json.dumps({"error": errors[0], "alive": not thread.is_alive() and recorder.current is None,
                      "events": len(got), "prefix": bool(np.array_equal(got, events[: len(got)])),
                      "sent": len(events), "size": (disk / "full.raw").stat().st_size}))
"""


@pytest.mark.usefixtures("mount_namespace")
def test_the_recorder_on_a_full_disk_stops_cleanly_and_keeps_its_file_to_the_last_flush(tmp_path: Path) -> None:
    disk = tmp_path / "disk"
    disk.mkdir()
    script = f"mount -t tmpfs -o size=200k tmpfs {disk} && exec {sys.executable} -c '{FILL}' {disk}"
    done = subprocess.run(
        ["unshare", "-rm", "sh", "-c", script],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=Path(__file__).parents[2],
    )
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert "recording stopped: writing" in result["error"] and "No space left on device" in result["error"]
    assert result["alive"]  # the recorder went on (idle) and stopped when asked
    assert 0 < result["events"] < result["sent"] and result["prefix"]  # whole up to its last flush
    assert "Traceback" not in done.stderr


@pytest.mark.slow
@pytest.mark.usefixtures("mount_namespace")
def test_a_full_disk_under_the_centrelines_file_is_one_error_line_and_both_files_read_back(tmp_path: Path) -> None:
    flag = WavyFlag(length=200.0, root=(100.0, 240.0))
    events = np.concatenate(list(line_events(flag, 0, 1_500_000, 640, 480, QuickLineParams(noise_rate_hz=1e5))))
    recording = tmp_path / "flag.raw"
    write_events(recording, events, width=640, height=480, encoding="evt3")
    disk = tmp_path / "disk"
    disk.mkdir()
    rig = tmp_path / "rig.yaml"
    rig.write_text(
        f"rig: fullh5\ntracker: {{root: [100, 240], length: 200}}\n"
        f"recorder: {{directory: {disk}, path: {disk}/rec, centrelines: true, min_free_mb: 0, "
        "flush_interval_s: 0.05}\nservices: [camera, tracker, recorder]\n"
    )
    size_k = (RESERVE_BYTES + recording.stat().st_size // 2) // 1024  # half the recording fits
    flagtrack = " ".join(FLAGTRACK)
    up = f"{flagtrack} up -c {rig} --replay {recording} --speed 1 --exit-at-eof -q"
    script = f"mount -t tmpfs -o size={size_k}k tmpfs {disk} && {up}; rc=$?; cp -a {disk}/. {tmp_path}/out/; exit $rc"
    (tmp_path / "out").mkdir()
    done = subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True, text=True, timeout=180)
    errors = [line for line in done.stderr.splitlines() if line.startswith("ERROR flagtrack.daemon.services.recorder")]
    assert len(errors) == 1 and "No space left on device" in errors[0], done.stderr[-3000:]
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr, done.stderr[-3000:]
    assert done.returncode == 1 and "\nflagtrack up: recording stopped: writing " in done.stderr, done.stderr[-3000:]
    failed = errors[0].split("writing ", 1)[1].split(" failed", 1)[0]
    assert failed in (f"{disk}/rec.raw", f"{disk}/rec_centrelines.h5"), errors[0]
    got = read_events(tmp_path / "out" / "rec.raw", strict=True).events  # whole up to its last flush
    assert 0 < len(got) < len(events)
    lines, _ = read_centrelines(tmp_path / "out" / "rec_centrelines.h5")
    assert len(lines.t_s) > 0 and np.all(np.diff(lines.t_s) > 0)
