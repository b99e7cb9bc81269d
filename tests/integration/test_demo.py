"""`flagtrack demo --quick --json`: the whole simulated rig, its JSON contract, onset and decay found, the point
sensor's check of every point (the paper's validation), a plain line per point on a pipe, a self-describing run."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from flagtrack.daemon.sweep.runlog import read_run
from tests.results_agree import check_demo_report, check_files, check_terminal

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
    "sensor_error_rms_over_l_max",
    "sensor_figure",
    "run_json",
]


@pytest.mark.slow
def test_quick_demo_finds_onset_and_decay_within_one_step(quick_demo: subprocess.CompletedProcess[str]) -> None:
    result = quick_demo
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout.strip().splitlines()[-1])
    assert list(summary) == KEYS
    assert summary["points"] == 5 and summary["step_mps"] == 0.5
    step = summary["step_mps"]
    assert abs(summary["onset_mps_detected"] - summary["onset_mps_simulated"]) <= step
    assert abs(summary["decay_mps_detected"] - summary["decay_mps_simulated"]) <= step
    assert summary["onset_mps_detected"] > summary["decay_mps_detected"]  # hysteresis seen
    for key in ("summary_csv", "log", "rrd", "sensor_figure", "run_json"):
        assert Path(summary[key]).is_absolute() and Path(summary[key]).stat().st_size > 0
    assert f"onset  detected {summary['onset_mps_detected']:g} m/s (points 0.5 m/s apart; simulated " in result.stderr
    # the paper's validation: a laser distance sensor, trigger-synchronised, within the paper's 1.5 % of L
    assert 0 < summary["sensor_error_rms_over_l_max"] < 0.015
    assert Path(summary["sensor_figure"]).name.endswith("_sensor.png") and summary["sensor_figure"] in result.stderr
    run = json.loads(Path(summary["run_json"]).read_text())
    flapping = [p for p in run["points"] if p["state"] == "flapping"]
    assert flapping and max(p["sensor_error_rms_over_l"] for p in flapping) == summary["sensor_error_rms_over_l_max"]
    assert {p["sensor_sync"] for p in run["points"]} == {"trigger"}
    assert f"worst e/L RMS {100 * summary['sensor_error_rms_over_l_max']:.2f} % of L" in result.stderr
    # progress on a pipe: a plain line per point, no bar
    # (a point the loaded machine recorded lossy is redone: a LOSSY line, then the redo's own line)
    lines = [line for line in result.stderr.splitlines() if line.startswith("point ")]
    measured = [line for line in lines if "LOSSY" not in line]
    assert [line.split()[1] for line in measured] == ["1/5", "2/5", "3/5", "4/5", "5/5"] and "\r" not in result.stderr
    assert all("e/L RMS" in line for line in measured)
    lossy = sum(p.status == "lossy" for p in read_run(Path(summary["run_json"]).parent).points)
    assert len(lines) == len(measured) + lossy, (lines, lossy)
    # every number reads the same on the terminal, in the files and in the report (issue 32)
    run = check_files(Path(summary["run_json"]).parent)
    assert check_terminal(lines, run) == 5
    check_demo_report(result.stderr, summary, run)
    assert not (Path(summary["run_json"]).parent / ".lock").exists()
