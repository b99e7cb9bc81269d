"""The law of docs/control.md is examples/hold_amplitude.py, fits in 15 lines, and runs with
``flagtrack control`` on the simulated rig of deploy/rig-control-sim.yaml."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import yaml

from flagtrack.daemon.cli import main
from tests.conftest import REPO

EXAMPLE = REPO / "examples" / "hold_amplitude.py"


def documented_law() -> str:
    text = (REPO / "docs" / "control.md").read_text()
    section = text.split("## Writing a law", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_the_documented_law_is_the_example_and_fits_in_15_lines() -> None:
    assert documented_law() == EXAMPLE.read_text()
    assert len([line for line in EXAMPLE.read_text().splitlines() if line.strip()]) <= 15


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_the_documented_law_runs_on_the_simulated_rig(tmp_path: Path) -> None:
    rig = yaml.safe_load((REPO / "deploy" / "rig-control-sim.yaml").read_text())
    rig["rig"] = f"docs{tmp_path.name[-6:].replace('_', '')}"
    rig["recorder"]["directory"] = str(tmp_path / "recordings")
    (tmp_path / "recordings").mkdir()
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig))
    law = tmp_path / "hold_amplitude.py"
    law.write_text(documented_law())
    out = tmp_path / "hold1"
    assert main(["control", "-c", str(path), "--controller", f"{law}:law", "--duration", "8", "--out", str(out)]) == 0
    steps = [json.loads(line) for line in (out / "control.jsonl").read_text().splitlines()]
    asked = [r for r in steps if r["asked_mps"] is not None]
    assert len(asked) > 20 and not any("fault" in r.get("reason", "") for r in steps)
    assert all(r["setpoint"] == 0.22 and 0 < r["applied_mps"] <= 10 for r in asked)
    assert asked[-1]["applied_mps"] < 5.5  # the flag starts above 0.22 (at 5.5 m/s): the law slows the wind
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "finished" and run["law"] == f"{law}:law"
