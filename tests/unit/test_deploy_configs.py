"""Every example rig config in deploy/ loads (keys, values, camera settings): a user starts from these."""

from __future__ import annotations

from pathlib import Path

import pytest

from flagtrack.daemon.rig.config import check_rig, load_rig

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
RIGS = sorted(DEPLOY.glob("rig-*.yaml"))


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
    from flagtrack.daemon.errors import ConfigError

    with pytest.raises(ConfigError, match=r"camera\.replay\.path"):
        check_rig(rig, rig.services)
