"""`flagtrack sweep -c rig.yaml --runs-dir DIR`: the flag replaces the rig's runs_dir before it is checked, and a
rig without a sweep plan is one clear line (it was a ValueError traceback)."""

from __future__ import annotations

from pathlib import Path

import pytest

from flagtrack.daemon.cli import main


def test_runs_dir_flag_is_checked_instead_of_the_rigs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("a file where the rig says its runs go")
    rig = tmp_path / "rig.yaml"
    rig.write_text(
        f"rig: s\ntunnel: {{driver: simulated}}\nsupervisor: {{runs_dir: {blocker / 'runs'}}}\nservices: [supervisor]\n"
    )
    assert main(["sweep", "-c", str(rig), "--runs-dir", str(tmp_path / "runs")]) == 2
    err = capsys.readouterr().err
    assert "needs a 'sweep:' plan" in err and "key 'supervisor.runs_dir'" not in err  # past the rig's runs_dir


def test_a_sweep_that_never_began_is_not_exit_0(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Services that do not appear in time: the run never starts; an unattended script must see it
    (it printed one warning and exited 0)."""
    import yaml

    rig = yaml.safe_load((Path(__file__).resolve().parents[2] / "deploy" / "rig-sensor-sim.yaml").read_text())
    rig["supervisor"].update(startup_timeout_s=0.001, runs_dir=str(tmp_path / "runs"))
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig))
    assert main(["sweep", "-c", str(path), "-q"]) == 1
    err = capsys.readouterr().err
    assert err.strip().splitlines()[-1] == "flagtrack sweep: no run was started (the lines above say why)"
