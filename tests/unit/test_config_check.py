"""``flagtrack config check``: a whole rig checked without opening anything, what would run, and one
line naming the key and the file for what is wrong; what the host lacks is a note, an error when strict."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from flagtrack.daemon.cli import main
from flagtrack.daemon.core.events import EVENT_DTYPE
from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.rig.config import load_rig
from flagtrack.daemon.rig.describe import DESCRIPTIONS
from flagtrack.daemon.rig.report import READING_ORDER, check_rig_file
from flagtrack.daemon.rig.table import SERVICE_NAMES
from flagtrack.drivers.formats.files import write_events

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
SIM_TUNNEL = {"driver": "simulated", "safety": {"max_speed_mps": 10, "max_ramp_mps2": 2.0}}
SWEEP = {"range": {"start": 3.0, "stop": 6.0, "step": 1.0}, "branches": ["up", "down"], "settle_s": 2, "record_s": 3}


def rig_file(folder: Path, **sections: object) -> Path:
    body = {
        "rig": "t",
        "camera": {"adapter": "simulated"},
        "tracker": {"root": [150, 240], "length": 300},
        "recorder": {"directory": str(folder / "recordings")},
        "viewer": {"sink": "none"},
        "tunnel": SIM_TUNNEL,
        "supervisor": {"runs_dir": str(folder / "runs"), "sweep": SWEEP},
        "services": ["camera", "tracker", "recorder", "viewer"],
    }
    body.update(sections)
    path = folder / "rig.yaml"
    path.write_text(yaml.safe_dump({k: v for k, v in body.items() if v is not None}))
    return path


def test_every_service_has_a_line_in_reading_order() -> None:
    assert set(DESCRIPTIONS) == set(SERVICE_NAMES) == set(READING_ORDER)


def test_the_single_pc_rig_says_what_would_run() -> None:
    report = check_rig_file(DEPLOY / "rig-single-pc.yaml")
    assert report.kind == "rig"
    assert set(report.services) == {"camera", "tracker", "recorder", "viewer", "supervisor"}  # sweep -c adds it
    assert report.runs[0].endswith("camera, tracker, recorder, viewer") and "flagtrack sweep -c" in report.runs[1]
    plan = report.plan
    assert plan is not None and plan.points == 45 and (plan.lowest_mps, plan.highest_mps) == (3.0, 8.5)
    assert plan.disk_bytes == pytest.approx(45 * 6 * 10e6 * 2)  # record_s x expected rate x bytes per event
    ramps_s = 2 * (8.5 - 3.0) / 0.5 + 3.0 / 0.5 + 0.25 / 0.5  # up, down, from and to zero, the turn
    assert plan.duration_s == pytest.approx(45 * (10 + 6) + ramps_s, rel=0.05)
    lines = dict(report.lines)
    assert "prophesee" in lines["camera"] and "/dev/flagtrack-tunnel" in lines["tunnel"]
    if not Path("/dev/flagtrack-tunnel").exists():
        assert any(n.key == "tunnel.port" and n.pending for n in report.notes)


def test_the_cli_prints_the_summary_and_exits_0(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["config", "check", str(rig_file(tmp_path))]) == 0
    out = capsys.readouterr().out
    assert "a rig, checked without opening any device" in out and "sweep: 7 points, 3.00 to 6.00 m/s" in out
    assert main(["config", "check", str(rig_file(tmp_path)), "--json"]) == 0
    found = json.loads(capsys.readouterr().out)
    assert found["plan"]["points"] == 7 and found["notes"] == [] and found["files_checked"] is True


@pytest.mark.parametrize(
    ("sections", "key", "words"),
    [
        ({"tracker": {"root": [150, 240], "length": 300, "alfa": 1}}, "tracker.alfa", "unknown key"),
        ({"tracker": {"root": [150, 240]}}, "tracker.length", "required"),
        ({"supervisor": {"sweep": {**SWEEP, "range": {"start": 3, "stop": 13, "step": 1}}}}, "supervisor.sweep.range",
         "11 m/s is above tunnel.safety.max_speed_mps (10 m/s)"),
        ({"supervisor": {"sweep": {"speeds": [0.5, 4.0], "settle_s": 1, "record_s": 1}},
          "tunnel": {**SIM_TUNNEL, "safety": {"min_speed_mps": 1.0, "max_speed_mps": 10}}},
         "supervisor.sweep.speeds", "0.5 m/s is below tunnel.safety.min_speed_mps"),
        ({"tunnel": {"driver": "simulated", "sim": {"protocol": "modbus"},
                     "modbus": {"mps_per_hz": 0.05, "max_hz": 100}}}, "supervisor.sweep.range", "outside the drive's"),
        ({"tunnel": {"driver": "simulated", "safety": {"max_speed_mps": 30}, "sim": {"max_speed_mps": 5}}},
         "supervisor.sweep.range", "simulated fan"),
        ({"supervisor": {"mode": "feedback", "feedback": {"max_speed_mps": 11}}, "services": ["camera", "supervisor"]},
         "supervisor.feedback.max_speed_mps", "above tunnel.safety.max_speed_mps"),
        ({"supervisor": {"sweep": SWEEP, "required": ["camera", "trakcer"]}}, "supervisor.required", "'trakcer'"),
        ({"supervisor": {"sweep": SWEEP, "required": ["sensor"]}}, "supervisor.required", "'sensor'"),  # no token it waits for
        ({"supervisor": {"sweep": {**SWEEP, "record_s": 0}}}, "supervisor.sweep", "record_s > 0"),
        ({"supervisor": {"sweep": {**SWEEP, "record_s": float("nan")}}}, "supervisor.sweep.record_s",
         "must be a finite number, got nan"),  # (passed every range check)
        ({"tunnel": {**SIM_TUNNEL, "safety": {"max_speed_mps": 10, "max_ramp_mps2": float("inf")}}},
         "tunnel.safety.max_ramp_mps2", "must be a finite number, got inf"),  # (no ramp limit at all)
        ({"supervisor": {"sweep": {**SWEEP, "settle_s": 1e9}}}, "supervisor.sweep", "at most 86400 s"),
        ({"supervisor": {"sweep": {**SWEEP, "range": {"start": 3, "stop": 6, "step": 1e-12}}}}, "supervisor.sweep.range",
         "more than 10000 speeds"),
        ({"supervisor": {"sweep": {**SWEEP, "range": {"start": 3, "stop": float("inf"), "step": 1}}}},
         "supervisor.sweep.range.stop", "finite"),
        ({"camera": {"adapter": "prophesee", "hardware": {"biases": {"dif_on": 3}}}}, "camera.hardware.biases.dif_on",
         "no Prophesee-sensor camera has a bias"),
        ({"camera": {"adapter": "replay", "replay": {"path": "nowhere.raw"}}}, "camera.replay.path", "no such file"),
        ({"camera": {"min_packet_events": -1}}, "camera", "min_packet_events must be 0 or more"),
        ({"camera": {"max_packet_us": 0}}, "camera", "max_packet_us"),
        ({"tracker_service": {"reserve_mev_s": -1}}, "tracker_service", "reserve_mev_s must be from 0 to 1000"),
        ({"tunnel": {**SIM_TUNNEL, "baudrate": -9600}}, "tunnel", "baudrate must be 50 to 4000000"),
        ({"camera": {"adapter": "prophesee", "hardware": {"roi": {"x": 0, "y": 0, "width": 10**9, "height": 10}}}},
         "camera.hardware.roi", "reaches past any event sensor"),
        ({"viewer": {"sink": "none", "web_port": 10**9}}, "viewer.web_port", "must be a port"),
        ({"camera": {"adapter": "simulated", "simulated": {"width": 10**12}}}, "camera.simulated", "16 to 8192"),
        ({"camera": {"adapter": "simulated", "simulated": {"speed_mps": -6}}}, "camera.simulated", "speed_mps"),
        ({"supervisor": {"sweep": SWEEP, "expected_rate_mev_s": float("nan")}}, "supervisor.expected_rate_mev_s",
         "finite"),
    ],
)  # fmt: skip
def test_a_mistake_is_one_line_naming_the_key_and_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], sections: dict, key: str, words: str
) -> None:
    path = rig_file(tmp_path, **sections)
    assert main(["config", "check", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"file {path}" in err and f"key '{key}'" in err and words in err, err


def test_a_plan_in_bounds_passes_and_the_same_bound_refuses_it_in_up(tmp_path: Path) -> None:
    """The supervisor's check is the table's: `flagtrack sweep` and `up` refuse the plan before the tunnel opens."""
    path = rig_file(tmp_path, supervisor={"sweep": {**SWEEP, "range": {"start": 3, "stop": 10, "step": 1}}})
    assert check_rig_file(path).plan is not None
    path = rig_file(tmp_path, supervisor={"sweep": {**SWEEP, "range": {"start": 3, "stop": 11, "step": 1}}})
    assert main(["sweep", "-c", str(path)]) == 2


def test_sweep_without_a_tunnel_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """It was an AssertionError traceback: `flagtrack sweep -c` adds the supervisor to a rig without a tunnel."""
    path = rig_file(tmp_path, tunnel=None)
    assert main(["sweep", "-c", str(path)]) == 2
    assert "needs a 'tunnel:' section" in capsys.readouterr().err


def test_a_calibration_not_made_yet_is_a_note_and_an_error_for_the_rig(tmp_path: Path) -> None:
    tracker = {"root": [0, 0], "length": 0.18, "calibration": "cal.yaml"}
    path = rig_file(tmp_path, tracker=tracker)
    report = check_rig_file(path)
    (note,) = [n for n in report.notes if n.key == "tracker.calibration"]
    assert note.pending and "not made yet: flagtrack calibrate" in note.text and str(tmp_path / "cal.yaml") in note.text
    with pytest.raises(ConfigError, match=r"key 'tracker.calibration': .*not made yet.*\(--strict\)"):
        check_rig_file(path, strict=True)
    with pytest.raises(ConfigError, match=r"key 'tracker.calibration': no such file"):
        load_rig(path)  # what up, sweep and each service check
    (tmp_path / "cal.yaml").write_text("format: something-else\n")
    with pytest.raises(ConfigError, match=r"key 'tracker.calibration'"):
        check_rig_file(path)  # there, but not a calibration


def test_a_disk_too_small_for_one_point_is_a_note_and_for_the_run_a_warning(tmp_path: Path) -> None:
    free = shutil.disk_usage(tmp_path).free
    rate = free / (3 * 1e6 * 2)  # one point of record_s 3 s fills the disk
    report = check_rig_file(rig_file(tmp_path, supervisor={"sweep": SWEEP, "expected_rate_mev_s": rate * 1.5}))
    assert any(n.key == "supervisor.runs_dir" and n.pending and "no point could start" in n.text for n in report.notes)
    report = check_rig_file(rig_file(tmp_path, supervisor={"sweep": SWEEP, "expected_rate_mev_s": rate / 3}))
    (note,) = [n for n in report.notes if n.key == "supervisor.runs_dir"]
    assert not note.pending and "would stop safe after about 2 of 7 points" in note.text
    check_rig_file(rig_file(tmp_path, supervisor={"sweep": SWEEP, "expected_rate_mev_s": rate / 3}), strict=True)


def test_a_replay_recording_is_checked_readable(tmp_path: Path) -> None:
    recording = tmp_path / "run.raw"
    events = np.zeros(3, EVENT_DTYPE)
    events["t"], events["x"] = [10, 20, 30], [1, 2, 3]
    write_events(recording, events, width=640, height=480)
    path = rig_file(tmp_path, camera={"adapter": "replay", "replay": {"path": str(recording)}})
    assert "replay of" in dict(check_rig_file(path).lines)["camera"]
    (tmp_path / "junk.raw").write_bytes(b"\x00not an event file" * 10)
    path = rig_file(tmp_path, camera={"adapter": "replay", "replay": {"path": str(tmp_path / "junk.raw")}})
    with pytest.raises(ConfigError, match=r"key 'camera.replay.path'"):
        check_rig_file(path)


def test_a_root_off_a_known_sensor_is_refused_by_the_check_and_the_rig(tmp_path: Path) -> None:
    """A root off the sensor tracked nothing: a whole sweep ran to "finished" on 100 % stale updates.
    The simulated camera's and a replay's sensor are known before anything opens."""
    path = rig_file(tmp_path, tracker={"root": [1500, 240], "length": 300})
    with pytest.raises(
        ConfigError, match=r"key 'tracker.root': \(1500, 240\) is off the 640 x 480 sensor of the simulated"
    ):
        check_rig_file(path)
    with pytest.raises(ConfigError, match=r"key 'tracker.root'"):
        load_rig(path)  # what up, sweep and each service check
    recording = tmp_path / "run.raw"
    write_events(recording, np.zeros(0, EVENT_DTYPE), width=320, height=240)
    replay = {"adapter": "replay", "replay": {"path": str(recording)}}
    with pytest.raises(ConfigError, match=r"off the 320 x 240 sensor of the recording"):
        check_rig_file(rig_file(tmp_path, camera=replay, tracker={"root": [400, 100], "length": 300}))
    check_rig_file(rig_file(tmp_path, camera=replay, tracker={"root": [300, 100], "length": 300}))


@pytest.mark.parametrize("text", ["", "# only a comment\n", "{}\n"])
def test_a_file_without_sections_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str) -> None:
    """It passed as "a part of a rig", --strict too."""
    (tmp_path / "rig.yaml").write_text(text)
    assert main(["config", "check", str(tmp_path / "rig.yaml"), "--strict"]) == 2
    assert "holds no sections: nothing to check" in capsys.readouterr().err


def test_a_part_of_a_rig_is_checked_as_its_sections() -> None:
    report = check_rig_file(DEPLOY / "tunnel-modbus.yaml")
    assert report.kind == "part" and report.services == () and report.plan is None
    assert [name for name, _ in report.lines] == ["tunnel"] and "flagtrack tunnel" in report.runs[0]


def test_services_and_no_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = rig_file(tmp_path, tracker={"root": [0, 0], "length": 0.2, "calibration": "missing.yaml"})
    report = check_rig_file(path, services=["camera"])
    assert report.services == ("camera",) and report.notes == ()  # the camera needs no calibration
    assert check_rig_file(path, files=False).notes == ()  # nothing of this host looked at
    assert main(["config", "check", str(path), "--services", "camera,teleporter"]) == 2
    assert "--services: unknown service 'teleporter'" in capsys.readouterr().err


@pytest.mark.parametrize("path", sorted(DEPLOY.glob("*.yaml")), ids=lambda p: p.name)
def test_the_deploy_configs_pass_the_cli(path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The quick form of tests/unit/test_deploy_configs.py: what each example says, through the command."""
    assert main(["config", "check", str(path), "--no-files"]) == 0, capsys.readouterr().err
    assert "this host's files, folders, ports and SDKs not looked at" in capsys.readouterr().out


def secured_rig(folder: Path, certs_dir: Path) -> Path:
    tls = {
        "ca": str(certs_dir / "ca.pem"),
        "cert": f"{certs_dir}/{{identity}}.pem",
        "key": f"{certs_dir}/{{identity}}.key",
    }
    bus = {"listen": ["tls/127.0.0.1:7447"], "security": {"tls": tls, "acl": True}}
    return rig_file(folder, bus=bus, services=["camera", "tracker"], supervisor=None, tunnel=None)


def test_a_secured_rigs_certificates_are_checked_for_each_identity(tmp_path: Path) -> None:
    import datetime as dt
    import os

    from flagtrack.daemon.security import certs

    good, other = tmp_path / "certs", tmp_path / "other"
    certs.init(good, ["camera", "tracker"])
    path = secured_rig(tmp_path, good)
    report = check_rig_file(path)
    assert "each service alone" in report.runs[0] and report.notes == ()

    def fails_with(words: str) -> None:
        with pytest.raises(
            ConfigError, match=rf"file {path}, key 'bus.security.tls.\w+': identity 'tracker': .*{words}"
        ):
            check_rig_file(path)

    os.replace(good / "tracker.pem", tmp_path / "tracker.pem")
    fails_with("no such file")
    shutil.copy(good / "camera.pem", good / "tracker.pem")
    fails_with("is the certificate of 'camera'")
    certs.init(other, ["tracker"])
    for suffix in (".pem", ".key"):
        shutil.copy(other / f"tracker{suffix}", good / f"tracker{suffix}")
    fails_with("was not issued by the CA")
    past = dt.datetime.now(dt.UTC) - dt.timedelta(days=20)
    certs.issue(good, "tracker", days=10, now=past, replace=True)
    fails_with("expired on")
    certs.issue(good, "tracker", days=10, replace=True)
    (note,) = check_rig_file(path).notes
    assert not note.pending and "(tracker) expires in" in note.text and "flagtrack certs issue" in note.text
    assert check_rig_file(path, files=False).notes == ()


def test_a_device_not_plugged_in_is_a_note_left_to_the_rig_when_strict(tmp_path: Path) -> None:
    port = str(tmp_path / "ttyUSB9")  # a device path that is not there
    tunnel = {"driver": "ascii", "port": port}
    sensor = {"id": "om70", "driver": "ascii", "port": port}
    path = rig_file(tmp_path, tunnel=tunnel, sensor=sensor, services=["camera", "sensor"])
    notes = {n.key: n for n in check_rig_file(path).notes}
    assert set(notes) == {"tunnel.port", "sensor.port"} and all(n.pending for n in notes.values())
    assert f"{port} is not there now" in notes["tunnel.port"].text
    with pytest.raises(
        ConfigError, match=r"key '(tunnel|sensor).port'.*\(--strict; 1 more to do: (sensor|tunnel).port\)"
    ):
        check_rig_file(path, strict=True)  # one line, naming what else is left
    load_rig(path)  # the rig's own commands say so when they open it


def test_a_placeholder_host_is_a_to_do_and_an_error_for_the_rig(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """deploy/'s two-host examples connect to ROUTER_HOST: config check passed them silently, and `up`
    failed in Zenoh's words (naming a source file of Zenoh's)."""
    path = rig_file(tmp_path, bus={"connect": ["tcp/127.0.0.1:7447", "tcp/ROUTER_HOST:7447"]})
    report = check_rig_file(path)
    assert [(n.key, n.pending) for n in report.notes] == [("bus.connect[1]", True)]
    assert "ROUTER_HOST is a placeholder; put the host's name or address there" in report.notes[0].text
    assert main(["up", "-c", str(path), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "key 'bus.connect[1]': tcp/ROUTER_HOST:7447: ROUTER_HOST is a placeholder" in err[0], err
    for host in ("router-1.lab", "LAB_PC1", "[::1]"):  # (a host in capitals is a host)
        assert check_rig_file(rig_file(tmp_path, bus={"connect": [f"tcp/{host}:7447"]})).notes == ()
    iface = check_rig_file(rig_file(tmp_path, bus={"connect": ["tcp/CAMERA_HOST:7447#iface=en:0"]}))
    assert [n.key for n in iface.notes] == ["bus.connect[0]"]
    # a command that opens no bus (aim -c: the camera alone) reads the file as it is
    assert load_rig(rig_file(tmp_path, bus={"connect": ["tcp/ROUTER_HOST:7447"]}), services=("camera",))
