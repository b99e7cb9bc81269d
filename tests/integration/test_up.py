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
from flagtrack.daemon.services.runner import SAME_SIGNAL_S
from flagtrack.daemon.transport import Bus, BusConfig
from tests.fakes.helpers import wait_until
from tests.integration.test_transport import free_port

TRACKER_ARGS = ["--root", "100", "240", "--length", "200", "--tau", "0.0003"]


def flagtrack(*args: str, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "flagtrack.daemon", *args], capture_output=True, text=True, timeout=120, **kwargs
    )


def start(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "flagtrack.daemon", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def test_up_replay_gives_exactly_the_reconstruct_centrelines(recording: Path, tmp_path: Path) -> None:
    live, offline, rrd = tmp_path / "live.h5", tmp_path / "offline.h5", tmp_path / "view.rrd"
    up = flagtrack(
        "up",
        "--replay",
        str(recording),
        "--speed",
        "0",
        "--exit-at-eof",
        "--centrelines",
        str(live),
        "--rrd",
        str(rrd),
        *TRACKER_ARGS,
    )
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
        (
            "camera: {adapter: replay, replay: {path: x.raw, encoding: evt21}}\ntracker: {root: [1, 2], length: 100}\n",
            "'camera.replay': encoding must be evt2 or evt3",
        ),
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
viewer: {{sink: rrd, rrd_path: {tmp_path / "live.rrd"}}}
recorder: {{directory: {tmp_path / "rec"}, path: run}}
{extra}""")
    return config


def size(path: Path) -> int:
    return path.stat().st_size if path.exists() else 0


def test_sigint_stops_every_service_cleanly(tmp_path: Path) -> None:
    stderr = tmp_path / "stderr.txt"
    with stderr.open("w") as err_file:
        proc = subprocess.Popen(
            [sys.executable, "-m", "flagtrack.daemon", "up", "-c", str(sim_rig(tmp_path))], stderr=err_file
        )
    recorded, rrd = tmp_path / "rec" / "run.raw", tmp_path / "live.rrd"
    wait_until(
        lambda: size(recorded) > 10_000 and size(rrd) > 1000, 60, "the recorder and the viewer writing", poll_s=0.2
    )
    wait_until(lambda: "flagtrack up: recording " in stderr.read_text(), 30, "the recording's line", poll_s=0.2)
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=30)
    err = stderr.read_text()
    assert proc.returncode == 130, err
    assert "stopping" in err and "did not stop" not in err
    info = flagtrack("events", "info", str(recorded), "--json")
    assert info.returncode == 0 and '"events"' in info.stdout
    assert rrd.stat().st_size > 1000
    # where the events went, while and after (not a terminal: a line as it begins, one at the end)
    assert f"flagtrack up: recording {recorded}  0:0" in err, err
    ended = [line for line in err.splitlines() if line.startswith(f"flagtrack up: recorded {recorded}: ")]
    assert len(ended) == 1 and f"{recorded.stat().st_size / 1e6:.1f} MB, 0:" in ended[0], err
    assert "of camera time" in ended[0] and "lost" not in ended[0]
    assert f"flagtrack up: Rerun view saved in {rrd.resolve()} (open it with: rerun " in err, err


STUBBORN = """
import threading, time
from flagtrack.daemon.services.runner import run_services

class Stubborn:
    name = "stubborn"
    def start(self):
        pass
    def run(self, stop):
        print("ready", flush=True)  # the signal handlers are installed
        stop.wait()
        print("asked to stop", flush=True)
        time.sleep(60)  # ignores the request to stop for a minute

run_services([Stubborn()], shutdown_timeout_s=120)
"""


def test_second_signal_forces_exit() -> None:
    proc = subprocess.Popen([sys.executable, "-c", STUBBORN], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "ready"
    started = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    assert proc.stdout.readline().strip() == "asked to stop"  # handled: a second signal is not merged into it
    time.sleep(SAME_SIGNAL_S)  # (a person's second press: the same signal at once is the first one again)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130 and "stopping (again to force)" in err and "forcing exit" in err
    assert time.monotonic() - started < 10


SLOW_TO_STOP = STUBBORN.replace("time.sleep(60)  # ignores the request to stop for a minute", "time.sleep(0.5)")
"""A service that takes half a second to stop, as a tunnel ramping to zero."""


def test_the_same_signal_twice_at_once_is_one_request_not_a_forced_exit() -> None:
    """GNU `timeout -s INT` signals the process and then its group: two SIGINTs, counted as two presses
    when the first was handled in between (in 2 sweeps of 3 on a loaded host the exit was forced and
    the tunnel left at 4.5 m/s). Here the second comes once the first was handled, within SAME_SIGNAL_S."""
    for _ in range(5):  # (a host that stalls this test past SAME_SIGNAL_S between the two: try again)
        proc = subprocess.Popen([sys.executable, "-c", SLOW_TO_STOP], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True)  # fmt: skip
        assert proc.stdout.readline().strip() == "ready"
        sent_s = time.monotonic()
        os.kill(proc.pid, signal.SIGINT)
        handled = proc.stderr.readline()  # written by the handler: the first was taken
        os.kill(proc.pid, signal.SIGINT)  # (timeout's second kill, to the group)
        apart_s = time.monotonic() - sent_s
        _, err = proc.communicate(timeout=30)
        if apart_s < SAME_SIGNAL_S:
            break
    assert "SIGINT received, stopping (again to force)" in handled
    assert apart_s < SAME_SIGNAL_S and "forcing exit" not in err and proc.returncode == 0, (apart_s, err)


@pytest.mark.slow
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
        assert "listening" in router.stderr.readline()
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


@pytest.mark.timeout(400)  # its child may compile for up to its own 300 s timeout
def test_the_rig_does_its_slow_one_off_work_before_its_services_start() -> None:
    """A first run after installing compiles for tens of seconds: that must happen before the services
    start (else a supervisor in the same process gives up waiting for the tracker), so after the
    preparation the tracker's, the packets' and the twin's kernels are all compiled or loaded; and
    matplotlib is imported (else the summary figure stalls the twin camera at the end of a sweep)."""
    code = """
import sys
from flagtrack.daemon.rig.run import prepare_services
from flagtrack.daemon.typed_yaml import from_mapping
from flagtrack.daemon.rig.config import RigConfig
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
    from flagtrack.daemon.errors import FlagtrackError
    from flagtrack.daemon.rig.config import RigConfig
    from flagtrack.daemon.rig.run import prepare_services
    from flagtrack.daemon.sweep import figures

    def broken() -> None:
        raise ImportError("No module named 'matplotlib'")

    monkeypatch.setattr(figures, "load_figure_modules", broken)
    with pytest.raises(FlagtrackError, match="preparing the services failed .*ImportError.*matplotlib"):
        prepare_services(RigConfig(), ["supervisor"])


TRACKER = "tracker: {root: [100, 240], length: 200}\n"
TRACKER_FORMAT = TRACKER.replace("{", "{{").replace("}", "}}")
# (command, rig text with {tmp} for the test's folder, the key the error must name, words it must say)
BAD_FILES = [
    (
        "up",
        "camera: {{adapter: replay, replay: {{path: {tmp}/nope.raw}}}}\n"
        + TRACKER_FORMAT
        + "viewer: {{sink: rrd, rrd_path: {tmp}/out/live.rrd}}\nservices: [viewer, camera, tracker]\n",
        "camera.replay.path",
        "no such file",
    ),
    ("camera", "camera: {{adapter: replay, replay: {{path: {tmp}/nope.raw}}}}\n", "camera.replay.path", "no such file"),
    (
        "up",
        "camera: {{adapter: simulated}}\ntracker: {{root: [100, 240], length: 200, calibration: cal/none.yaml}}\n"
        "services: [camera, tracker]\n",
        "tracker.calibration",
        "no such file",
    ),
    (
        "tracker",
        "tracker: {{root: [100, 240], length: 200, calibration: {tmp}}}\n",
        "tracker.calibration",
        "is a folder",
    ),
    ("up", "recorder: {{directory: {tmp}/blocker/rec}}\nservices: [recorder]\n", "recorder.directory", "is a file"),
    ("recorder", "recorder: {{directory: {tmp}, path: blocker/run}}\n", "recorder.path", "is a file"),
    ("up", "viewer: {{sink: rrd, rrd_path: {tmp}}}\nservices: [viewer]\n", "viewer.rrd_path", "is a folder"),
    ("viewer", "viewer: {{sink: rrd, rrd_path: {tmp}/blocker/live.rrd}}\n", "viewer.rrd_path", "is a file"),
    (
        "up",
        "tunnel: {{driver: simulated}}\nsupervisor: {{runs_dir: {tmp}/blocker/runs}}\nservices: [supervisor]\n",
        "supervisor.runs_dir",
        "is a file",
    ),
    (
        "up",
        "camera: {{adapter: prophesee, hardware: {{biases: {{dif_on: 3}}}}}}\nservices: [camera]\n",
        "camera.hardware.biases.dif_on",
        "no Prophesee-sensor camera has a bias",
    ),
    (
        "camera",
        "camera: {{adapter: metavision, hardware: {{biases: {{bias_fu: 3}}}}}}\n",
        "camera.hardware.biases.bias_fu",
        "not a HAL bias name",
    ),
    (
        "camera",
        "camera: {{adapter: inivation, hardware: {{davis_biases: {{On: [9, 2]}}}}}}\n",
        "camera.hardware.davis_biases.On",
        "must be in [0..7, 0..255]",
    ),
    (
        "up",
        "camera: {{adapter: prophesee, hardware: {{roi: {{x: -1, y: 0, width: 10, height: 10}}}}}}\n"
        "services: [camera]\n",
        "camera.hardware.roi",
        "must be >= 0",
    ),
]


@pytest.mark.parametrize(("command", "yaml_text", "key", "words"), BAD_FILES)
def test_bad_paths_and_camera_settings_are_one_line_before_anything_opens(
    tmp_path: Path, command: str, yaml_text: str, key: str, words: str
) -> None:
    (tmp_path / "blocker").write_text("a file where a folder should be")
    config = tmp_path / "rig.yaml"
    config.write_text(yaml_text.format(tmp=tmp_path))
    before = sorted(tmp_path.rglob("*"))
    result = flagtrack(command, "-c", str(config), cwd=tmp_path)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert lines[0].startswith(f"flagtrack {command}: error: file {config}, key '{key}': ") and words in lines[0]
    assert sorted(tmp_path.rglob("*")) == before  # no .rrd, no folder: nothing was opened or made


def test_files_are_checked_for_the_services_that_run_only(tmp_path: Path) -> None:
    """A tracker host's copy of the rig does not need the camera host's recording."""
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.rig.config import load_rig

    config = tmp_path / "rig.yaml"
    config.write_text(
        f"camera: {{adapter: replay, replay: {{path: {tmp_path}/nope.raw}}}}\n{TRACKER}services: [camera, tracker]\n"
    )
    assert load_rig(config, services=["tracker"]).camera.replay.path == tmp_path / "nope.raw"
    with pytest.raises(ConfigError, match="no such file") as info:
        load_rig(config)
    assert info.value.key == "camera.replay.path" and info.value.path == str(config)


def test_up_checks_its_centrelines_output_before_anything_opens(recording: Path, tmp_path: Path) -> None:
    (tmp_path / "blocker").write_text("")
    result = flagtrack(
        "up",
        "--replay",
        str(recording),
        "--exit-at-eof",
        "--centrelines",
        str(tmp_path / "blocker" / "c.h5"),
        "--rrd",
        str(tmp_path / "v.rrd"),
        *TRACKER_ARGS,
    )
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and "--centrelines" in lines[0], result.stderr
    assert not (tmp_path / "v.rrd").exists()


def hardware_rig(tmp_path: Path, hardware: str, services: str) -> Path:
    config = tmp_path / "rig.yaml"
    config.write_text(f"""
rig: hw{os.getpid()}
bus: {{listen: ["tcp/127.0.0.1:{free_port()}"]}}
camera: {{id: cam0, adapter: prophesee, hardware: {hardware}}}
viewer: {{sink: rrd, rrd_path: {tmp_path / "live.rrd"}}}
recorder: {{directory: {tmp_path / "rec"}, path: run}}
services: {services}
""")
    return config


@pytest.mark.parametrize(
    ("plugged", "hardware", "words"),
    [
        (
            True,
            '{serial: "V1", roi: {x: 600, y: 0, width: 100, height: 10}}',
            "key 'camera.hardware.roi': region {'x': 600, 'y': 0, 'width': 100, 'height': 10} does not fit the 640x480",
        ),
        (
            True,
            '{serial: "V1", biases: {inv: 3}}',
            "key 'camera.hardware.biases.inv': CenturyArks VGA has no bias 'inv'",
        ),
        (False, '{serial: "V1"}', "camera 'V1': no such Prophesee-sensor camera found"),
    ],
)
def test_what_only_the_device_can_refuse_stops_up_before_the_rest_opens(
    fake_nd, tmp_path: Path, capsys: pytest.CaptureFixture, plugged: bool, hardware: str, words: str
) -> None:
    """The hardware camera opens before the bus and the other services: one line, exit 2, no .rrd."""
    from flagtrack.daemon.cli import main

    cam = fake_nd._fake.plug(fake_nd.FakeCamera(name=fake_nd.Name.CENTURYARKS_VGA, serial="V1")) if plugged else None
    config = hardware_rig(tmp_path, hardware, "[camera, recorder, viewer]")
    assert main(["up", "-c", str(config)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("flagtrack up: error: ") and words in lines[0], lines
    if plugged:
        assert f"file {config}" in lines[0] and cam.opened == cam.closed == 1  # released
    assert not (tmp_path / "live.rrd").exists() and not (tmp_path / "rec").exists()


def test_a_root_off_the_opened_cameras_sensor_stops_up_before_the_rest_opens(
    fake_nd, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """Only the device says its sensor's size: a tracker root off it is one line, exit 2, the camera
    released (a sweep would otherwise run to its end on nothing)."""
    from flagtrack.daemon.cli import main

    cam = fake_nd._fake.plug(fake_nd.FakeCamera(name=fake_nd.Name.CENTURYARKS_VGA, serial="V1"))
    config = hardware_rig(tmp_path, '{serial: "V1"}', "[camera, recorder, viewer]")
    config.write_text(config.read_text() + "tracker: {root: [700, 240], length: 300}\n")
    assert main(["up", "-c", str(config)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and f"file {config}, key 'tracker.root': (700, 240) is off the 640 x 480" in lines[0], lines
    assert cam.opened == cam.closed == 1
    assert not (tmp_path / "live.rrd").exists() and not (tmp_path / "rec").exists()


def test_the_camera_opened_first_is_the_one_the_service_streams(
    fake_nd, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """`up` hands the device it opened to the camera service: every event the sensor produced up to
    the last packet is recorded, then the stall ends the rig (exit 1) and the device is closed once."""
    from flagtrack.daemon.cli import main
    from flagtrack.drivers.formats import read_events

    cam = fake_nd._fake.plug(fake_nd.FakeCamera(serial="E1", duration_us=150_000, seed=3))
    hardware = '{serial: "E1", biases: {diff_off: 30}, stall_timeout_s: 0.5}'
    config = hardware_rig(tmp_path, hardware, "[camera, recorder]")
    assert main(["up", "-c", str(config)]) == 1
    err = capsys.readouterr().err
    assert "camera/cam0 failed: camera 'E1': camera stopped delivering data" in err
    assert cam.opened == cam.closed == 1 and cam.applied.biases.diff_off == 30
    recorded, sent = read_events(tmp_path / "rec" / "run.raw").events, cam.sent_events
    assert len(recorded) > 0.9 * len(sent)
    np.testing.assert_array_equal(recorded, sent[: len(recorded)])


def test_up_withdraws_a_services_liveliness_when_it_ends(recording: Path, tmp_path: Path) -> None:
    """In `up`, the replay camera reaches the end of its file: a watcher in another process sees it gone
    while the tracker of the same process (and session) is still alive; the stop then takes the tracker."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    config = tmp_path / "rig.yaml"
    config.write_text(f"""
rig: alive{os.getpid()}
bus: {{connect: ["{endpoint}"]}}
camera: {{adapter: replay, replay: {{path: {recording}, speed: 1.0}}}}
tracker: {{root: [100, 240], length: 200, tau_s: 0.0003}}
services: [camera, tracker]
""")
    with Bus(BusConfig(namespace=f"flagtrack/alive{os.getpid()}", listen=(endpoint,))) as bus:
        watch = bus.watch_liveliness()
        camera, tracker = bus.keys.alive("camera/cam0"), bus.keys.alive("tracker")
        proc = start("up", "-c", str(config))
        try:
            wait_until(lambda: camera in watch.gone or proc.poll() is not None, 60, "the camera gone", poll_s=0.02)
            assert camera in watch.gone and not watch.is_alive(camera)
            time.sleep(0.5)  # a window to see what must not happen: nothing to wait for
            assert watch.is_alive(tracker) and proc.poll() is None  # the tracker runs on, its token stays
        finally:
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=30)
        assert proc.returncode == 130, err
        wait_until(lambda: tracker in watch.gone, 10, "the tracker gone")
        assert watch.gone == [camera, tracker]


def test_router_stops_on_the_first_signal_and_is_forced_by_a_second(tmp_path: Path) -> None:
    """`flagtrack router` as the other services: one signal closes it (exit 0), a second one while it
    closes forces it out (exit 130)."""
    for signals, code, words in (
        ((signal.SIGTERM,), 0, "flagtrack router: stopped"),
        ((signal.SIGTERM, signal.SIGINT), 130, "forcing exit"),
    ):
        port = free_port()
        router = start("router", "--listen", f"tcp/127.0.0.1:{port}")
        try:
            assert "listening" in router.stderr.readline()
            with Bus(BusConfig(namespace="flagtrack/r", mode="client", connect=(f"tcp/127.0.0.1:{port}",))):
                pass  # the router serves
            for sig in signals:  # two different signals: the second is not merged into the first
                router.send_signal(sig)
            _, err = router.communicate(timeout=30)
        finally:
            if router.poll() is None:
                router.kill()
        assert router.returncode == code and "stopping (again to force)" in err and words in err, err
