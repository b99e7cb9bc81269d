"""Every example config in deploy/ loads (keys, values, camera settings) and passes `flagtrack config
check` here, with the files it names in place: a user starts from these."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.cli import main
from flagtrack.daemon.core.events import EVENT_DTYPE
from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.rig.config import check_rig, load_rig
from flagtrack.daemon.rig.report import check_rig_file
from flagtrack.drivers.formats.files import write_events

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
RIGS = sorted(DEPLOY.glob("rig-*.yaml"))
CONFIGS = sorted(DEPLOY.glob("*.yaml"))

ANOTHER_HOST = {
    "rig-secure.yaml": "its certificates are systemd credentials, in /run/credentials/ only while each unit runs "
    "(test_config_check.py checks certificates made by flagtrack certs), its folders in /var/lib/flagtrack",
    "rig-tracker-host.yaml": "its recorder writes in /data/flagtrack, a folder of the analysis PC",
}
"""Configs whose files and folders are another host's: checked for what they say (--no-files)."""


def test_the_deploy_folder_has_the_example_rigs() -> None:
    names = {path.name for path in RIGS}
    assert {"rig-sim.yaml", "rig-replay.yaml", "rig-camera-host.yaml", "rig-tracker-host.yaml"} <= names


@pytest.mark.parametrize("path", RIGS, ids=lambda p: p.name)
def test_example_rig_loads_and_its_tracker_builds(path: Path) -> None:
    rig = load_rig(path, services=())  # files and folders of another machine are not checked here
    assert rig.services, "an example rig names the services it runs"
    if "tracker" in rig.services:
        params = rig.tracker.tracker_params(path=str(path))
        assert params.chain.length > 0 and params.chain.n_joints >= 1


def test_replay_rig_names_its_missing_recording_by_key() -> None:
    rig = load_rig(DEPLOY / "rig-replay.yaml", services=())
    if (DEPLOY / rig.camera.replay.path).exists() or Path(rig.camera.replay.path).exists():
        pytest.skip("the example recording exists here")
    with pytest.raises(ConfigError, match=r"camera\.replay\.path"):
        check_rig(rig, rig.services)


def put_in_place(folder: Path, path: Path) -> None:
    """Make in ``folder`` what the example names that a user makes: the recording rig-replay.yaml replays."""
    rig = load_rig(path, services=())
    if rig.camera.adapter == "replay" and rig.camera.replay is not None:
        recording = folder / rig.camera.replay.path
        recording.parent.mkdir(parents=True, exist_ok=True)
        events = np.zeros(100, EVENT_DTYPE)
        events["t"], events["x"], events["y"] = np.arange(100) * 10, 150, 240
        write_events(recording, events, width=640, height=480)


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_every_deploy_config_passes_config_check(
    path: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)  # relative folders and recordings are the working folder's
    put_in_place(tmp_path, path)
    options = ["--no-files"] if path.name in ANOTHER_HOST else []
    assert main(["config", "check", str(path), *options]) == 0, capsys.readouterr().err
    report = check_rig_file(path, files=not options)
    assert all(not note.text.startswith("no such") for note in report.notes)
    assert report.kind == ("rig" if path.name.startswith("rig-") else "part")


def test_the_examples_for_another_host_are_still_theirs() -> None:
    """Each entry of ANOTHER_HOST names an example that exists, and does fail here with its files."""
    for name in ANOTHER_HOST:
        assert (DEPLOY / name).is_file(), name
    with pytest.raises(ConfigError, match=r"key 'bus.security.tls.ca': identity '\w+': no such file: /run/credentials"):
        check_rig_file(DEPLOY / "rig-secure.yaml")
