"""``flagtrack bench control``: three processes, a law through a set-point step, the figures the issue
names in its JSON (the numbers themselves are measured, not asserted: docs/control.md)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from flagtrack.daemon.bench.control import figures

KEYS = {"loop_latency_p50_ms", "loop_latency_p99_ms", "amplitude_error_rms_over_l", "load_average_start"}


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_bench_control_runs_the_loop_through_the_step(tmp_path: Path) -> None:
    run = subprocess.run(
        [sys.executable, "-m", "flagtrack.daemon", "bench", "control", "--rate", "0.5", "--step-after", "4",
         "--after", "5", "--settle", "2", "--json", "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=280,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    result = json.loads(run.stdout)
    assert set(result) >= KEYS and result["latency_steps"] > 10 and result["faults"] == 0
    assert 0 < result["loop_latency_p50_ms"] <= result["loop_latency_p99_ms"]
    assert result["settled_cycles"] > 10 and result["step_at_s"] == pytest.approx(4.0, abs=1.0)
    assert result["event_rate_mev_s"] > 0.1 and result["control_exit"] == 0
    for name in ("camera.log", "tracker.log", "control.log", "run/control.jsonl", "run/control.png"):
        assert (tmp_path / name).stat().st_size > 0, name


def test_the_figures_are_read_from_the_control_log(tmp_path: Path) -> None:
    def step(t_s: float, setpoint: float, amplitude: float, latency_ms: float | None) -> str:
        state = {"completes_cycle": True, "amplitude_over_l": amplitude, "source_ns": 1_000, "published_ns": 3_001_000}
        return json.dumps({"t_s": t_s, "setpoint": setpoint, "state": state, "latency_ms": latency_ms})

    rows = [step(t, 0.2, 0.25, 10.0) for t in (1.0, 7.0, 8.0)]  # before the step: only from 6 s on
    rows += [step(10.0, 0.3, 0.2, 30.0), step(17.0, 0.3, 0.28, None), step(18.0, 0.3, 0.34, 50.0)]
    (tmp_path / "control.jsonl").write_text("\n".join(rows) + "\n")
    found = figures(tmp_path, [0.2, 0.3], 6.0)
    assert found["step_at_s"] == 10.0 and found["settled_cycles"] == 2
    assert found["amplitude_error_rms_over_l"] == pytest.approx(math.sqrt((0.02**2 + 0.04**2) / 2))
    assert found["amplitude_error_rms_over_l_before_step"] == pytest.approx(0.05)
    assert found["latency_steps"] == 5 and found["loop_latency_p50_ms"] == 10.0
    assert found["to_state_p50_ms"] == 3.0 and found["state_to_command_p50_ms"] == 7.0
