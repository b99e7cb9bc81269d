"""`flagtrack up` and the one-service commands as real processes: same results as reconstruct,
clear config errors before anything opens, graceful and forced stops, two hosts through a router."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from flagtrack.daemon.schema import CentrelineMessage
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.formats import write_events
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events
from tests.integration.test_transport import free_port

FLAG = WavyFlag(length=200.0, root=(100.0, 240.0))
TRACKER_ARGS = ["--root", "100", "240", "--length", "200", "--tau", "0.0003"]


def flagtrack(*args: str, **kwargs) -> subprocess.CompletedProcess:  # noqa: ANN003
    return subprocess.run([sys.executable, "-m", "flagtrack.daemon", *args], capture_output=True, text=True,
                          timeout=120, **kwargs)


def start(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "flagtrack.daemon", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("up") / "flag.raw"
    events = np.concatenate(list(line_events(FLAG, 0, 200_000, 640, 480, QuickLineParams(noise_rate_hz=1e5))))
    write_events(path, events, width=640, height=480, encoding="evt3")
    return path


def test_up_replay_gives_exactly_the_reconstruct_centrelines(recording: Path, tmp_path: Path) -> None:
    live, offline, rrd = tmp_path / "live.h5", tmp_path / "offline.h5", tmp_path / "view.rrd"
    up = flagtrack("up", "--replay", str(recording), "--speed", "0", "--exit-at-eof", "--centrelines", str(live),
                   "--rrd", str(rrd), *TRACKER_ARGS)
    assert up.returncode == 0, up.stderr
    rec = flagtrack("reconstruct", str(recording), "-o", str(offline), *TRACKER_ARGS)
    assert rec.returncode == 0, rec.stderr
    with h5py.File(live) as a, h5py.File(offline) as b:
        assert a["x"].shape == b["x"].shape and a["x"].shape[0] > 500
        for name in ("t", "x", "y", "joints/x", "joints/y", "delta_rms", "n_events"):
            np.testing.assert_allclose(a[name][()], b[name][()], rtol=0, atol=1e-9, err_msg=name)
        assert a.attrs["units"] == "px" and a.attrs["length"] == 200.0
    assert rrd.stat().st_size > 10_000


@pytest.mark.parametrize(
    ("yaml_text", "words"),
    [
        ("tracker: {root: [1, 2]}\n", "'tracker.length'"),
        ("tracker: {root: [1, 2], length: 100, alpha: two}\n", "'tracker.alpha'"),
        ("camera: {adapter: webcam}\n", "'camera.adapter'"),
        ("camra: {}\n", "'camra'"),
        ("services: [camera, teleporter]\ntracker: {root: [1, 2], length: 100}\n", "teleporter"),
        ("camera: {adapter: replay}\ntracker: {root: [1, 2], length: 100}\n", "replay"),
        ("camera: {adapter: replay, replay: {path: x.raw, encoding: evt21}}\ntracker: {root: [1, 2], length: 100}\n",
         "'camera.replay': encoding must be evt2 or evt3"),
    ],
)
def test_bad_rig_config_is_one_clear_line(tmp_path: Path, yaml_text: str, words: str) -> None:
    config = tmp_path / "rig.yaml"
    config.write_text(yaml_text)
    result = flagtrack("up", "-c", str(config))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and str(config) in lines[0] and words in lines[0], result.stderr


def sim_rig(tmp_path: Path, extra: str = "") -> Path:
    config = tmp_path / "rig.yaml"
    config.write_text(f"""
rig: t{os.getpid()}
bus: {{listen: ["tcp/127.0.0.1:{free_port()}"]}}
camera: {{adapter: simulated, simulated: {{speed_mps: 6.0}}}}
tracker: {{root: [150, 240], length: 300, tau_s: 0.0005}}
viewer: {{sink: rrd, rrd_path: {tmp_path / 'live.rrd'}}}
recorder: {{directory: {tmp_path / 'rec'}, path: run}}
{extra}""")
    return config


def test_sigint_stops_every_service_cleanly(tmp_path: Path) -> None:
    proc = start("up", "-c", str(sim_rig(tmp_path)))
    recorded = tmp_path / "rec" / "run.raw"
    deadline = time.monotonic() + 60
    while not (recorded.exists() and recorded.stat().st_size > 10_000) and time.monotonic() < deadline:
        time.sleep(0.2)
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert "stopping" in err and "did not stop" not in err
    info = flagtrack("events", "info", str(recorded), "--json")
    assert info.returncode == 0 and '"events"' in info.stdout
    assert (tmp_path / "live.rrd").stat().st_size > 1000


STUBBORN = """
import threading, time
from flagtrack.daemon.services.runner import run_services

class Stubborn:
    name = "stubborn"
    def run(self, stop):
        stop.wait()
        time.sleep(60)  # ignores the request to stop for a minute

print("ready", flush=True)
run_services([Stubborn()], shutdown_timeout_s=120)
"""


def test_second_signal_forces_exit() -> None:
    proc = subprocess.Popen([sys.executable, "-c", STUBBORN], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "ready"
    time.sleep(0.3)
    started = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130 and "stopping (again to force)" in err and "forcing exit" in err
    assert time.monotonic() - started < 10


def test_camera_and_tracker_on_two_hosts_through_a_router(recording: Path, tmp_path: Path) -> None:
    port = free_port()
    host_cfg = tmp_path / "host.yaml"
    host_cfg.write_text(f"""
rig: tworouter
bus: {{mode: client, connect: ["tcp/127.0.0.1:{port}"]}}
camera: {{adapter: replay, replay: {{path: {recording}, speed: 1.0, loop: true}}}}
tracker: {{root: [100, 240], length: 200, tau_s: 0.0003}}
""")
    router = start("router", "--listen", f"tcp/127.0.0.1:{port}")
    procs = []
    try:
        time.sleep(2.0)
        procs = [start("tracker", "-c", str(host_cfg)), start("camera", "-c", str(host_cfg))]
        with Bus(BusConfig(namespace="flagtrack/tworouter", mode="client", connect=(f"tcp/127.0.0.1:{port}",))) as bus:
            sub = bus.subscribe(bus.keys.centrelines(), CentrelineMessage)
            updates = 0
            deadline = time.monotonic() + 40
            while updates < 300 and time.monotonic() < deadline:
                msg = sub.recv(timeout_s=1.0)
                updates += 0 if msg is None else len(msg.t_s)
        assert updates >= 300
    finally:
        for proc in [*procs, router]:
            proc.send_signal(signal.SIGINT)
        for proc in [*procs, router]:
            proc.communicate(timeout=30)
    assert [p.returncode for p in procs] == [130, 130]


def test_the_rig_does_its_slow_one_off_work_before_its_services_start() -> None:
    """A first run after installing compiles for tens of seconds: that must happen before the services
    start (else a supervisor in the same process gives up waiting for the tracker), so after the
    preparation the tracker's, the packets' and the twin's kernels are all compiled or loaded; and
    matplotlib is imported (else the summary figure stalls the twin camera at the end of a sweep)."""
    code = """
import sys
from flagtrack.daemon.commands.up import prepare_services
from flagtrack.daemon.config import from_mapping
from flagtrack.daemon.rig import RigConfig
from flagtrack.daemon.core.kernels import run_updates
from flagtrack.drivers.formats._packet_kernels import encode_packets
from flagtrack.drivers.sim.quickline import _fill_events
rig = from_mapping(RigConfig, {"camera": {"adapter": "simulated"}, "tracker": {"root": [100, 240], "length": 200}},
                   key="test")
assert not run_updates.signatures and not encode_packets.signatures and not _fill_events.signatures
assert "matplotlib.figure" not in sys.modules
prepare_services(rig, ["camera", "tracker", "supervisor"])
print(len(run_updates.signatures), len(encode_packets.signatures), len(_fill_events.signatures),
      int("matplotlib.figure" in sys.modules))
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert all(int(n) >= 1 for n in done.stdout.split()), done.stdout


def test_a_failing_preparation_is_one_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    """A broken install (here: matplotlib cannot be imported) stops the rig before anything opens,
    with one line for the user instead of a traceback."""
    from flagtrack.daemon.commands.up import prepare_services
    from flagtrack.daemon.errors import FlagtrackError
    from flagtrack.daemon.rig import RigConfig
    from flagtrack.daemon.sweep import summary

    def broken() -> None:
        raise ImportError("No module named 'matplotlib'")

    monkeypatch.setattr(summary, "load_figure_modules", broken)
    with pytest.raises(FlagtrackError, match="preparing the services failed .*ImportError.*matplotlib"):
        prepare_services(RigConfig(), ["supervisor"])
