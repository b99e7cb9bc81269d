"""`flagtrack demo --quick --json`: the whole simulated rig, its JSON contract, onset and decay found, a plain
line per point on a pipe."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

KEYS = [
    "onset_mps_simulated",
    "decay_mps_simulated",
    "onset_mps_detected",
    "decay_mps_detected",
    "step_mps",
    "points",
    "summary_csv",
    "log",
    "rrd",
]


@pytest.mark.slow
def test_quick_demo_finds_onset_and_decay_within_one_step(tmp_path: Path) -> None:
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "flagtrack.daemon",
            "demo",
            "--quick",
            "--headless",
            "--json",
            "--out",
            str(tmp_path / "demo"),
        ],
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout.strip().splitlines()[-1])
    assert list(summary) == KEYS
    assert summary["points"] == 5 and summary["step_mps"] == 0.5
    step = summary["step_mps"]
    assert abs(summary["onset_mps_detected"] - summary["onset_mps_simulated"]) <= step
    assert abs(summary["decay_mps_detected"] - summary["decay_mps_simulated"]) <= step
    assert summary["onset_mps_detected"] > summary["decay_mps_detected"]  # hysteresis seen
    for key in ("summary_csv", "log", "rrd"):
        assert Path(summary[key]).is_absolute() and Path(summary[key]).stat().st_size > 0
    assert "onset  detected" in result.stderr
    # progress on a pipe: a plain line per point, no bar
    lines = [line for line in result.stderr.splitlines() if line.startswith("point ")]
    assert [line.split()[1] for line in lines] == ["1/5", "2/5", "3/5", "4/5", "5/5"] and "\r" not in result.stderr
