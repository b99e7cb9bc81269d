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
