"""Restart means resume (issue 20): a real ``flagtrack up`` process with the supervisor sweeping,
killed by SIGKILL mid-sweep (a second one started meanwhile on the same tunnel is refused, naming
the first) and started again with the same command line (what systemd's
``Restart=on-failure`` does), resumes the interrupted run: no new sweep, no point lost or repeated,
the tunnel (a simulated controller on a real pty, outside the killed process) stopped by its own
watchdog meanwhile. Started once more, the finished run is held: tunnel at zero, nothing new."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from flagtrack.daemon.errors import FormatError
from flagtrack.daemon.sweep.plan import SweepConfig, plan_points
from flagtrack.daemon.sweep.restart import start_decision
from flagtrack.daemon.sweep.runlog import RunLog, read_run
from flagtrack.drivers.tunnel.sim_model import SimParams
from flagtrack.drivers.tunnel.simulated import SimulatedTunnel
from tests.fakes.helpers import wait_until
from tests.fakes.rig import rig_yaml, simulated_rig
from tests.fakes.tunnel import SWEEP_SIM

FLAGTRACK = [sys.executable, "-m", "flagtrack.daemon"]


def rig_file(
    tmp_path: Path, port: str, sweep: dict[str, Any], recorder: dict[str, Any] | None = None, **supervisor: Any
) -> Path:
    """A whole simulated rig in one process, its tunnel a controller on ``port`` (``recorder``,
    ``supervisor``: more keys of their sections)."""
    name = f"restart{tmp_path.name[-12:]}".replace("-", "").replace("_", "").lower()
    rig = simulated_rig(
        tmp_path,
        name,
        sweep,
        flutter=False,
        tunnel_port=port,
        recorder={"allowed_dirs": [str(tmp_path / "runs")], **(recorder or {})},
        supervisor={"run_name": "night", "silence_timeout_s": 3.0, **supervisor},
    )
    return rig_yaml(tmp_path, rig)


def so_far(run_dir: Path) -> Any:
    """The run log as written so far (empty before its start record is complete)."""
    try:
        return read_run(run_dir)
    except FormatError:  # not there yet, or the start record half-written
        return SimpleNamespace(points=(), resumes=())


@pytest.fixture
def sim_params() -> SimParams:
    return SWEEP_SIM


@pytest.mark.slow
def test_a_supervisor_killed_and_started_again_resumes_its_run(sim: SimulatedTunnel, tmp_path: Path) -> None:
    # points of 3 s: the resumed run is still at work when the second supervisor, slow to start on a
    # busy machine, asks for the tunnel (with 1 s points it sometimes found the run finished)
    sweep = {"speeds": [3.0, 4.0, 5.0], "branches": ["up"], "settle_s": 0.5, "record_s": 3.0}
    command = [*FLAGTRACK, "up", "-c", str(rig_file(tmp_path, sim.port, sweep))]
    run_dir = tmp_path / "runs" / "night"
    first = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        wait_until(lambda: so_far(run_dir).points, 90, "a point recorded")
        wait_until(lambda: sim.setpoint_mps >= 3.9, 30, "the ramp to the second point")
    finally:
        first.send_signal(signal.SIGKILL)
        first.communicate(timeout=10)
    wait_until(lambda: sim.watchdog_trips >= 1 and sim.speed_mps < 0.2, 10, "the tunnel stopped by its watchdog")
    assert read_run(run_dir).stop is None  # killed: no stop record

    again_proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        wait_until(lambda: so_far(run_dir).resumes, 90, "the run resumed")
        # meanwhile a second supervisor on the same tunnel is refused, naming the first
        second = subprocess.run(command, capture_output=True, text=True, timeout=60)
        _, err = again_proc.communicate(timeout=120)
    finally:
        again_proc.kill()
    again = subprocess.CompletedProcess(command, again_proc.returncode, "", err)
    assert second.returncode != 0
    refusal = [line for line in second.stderr.splitlines() if "port in use" in line]
    assert len(refusal) == 1 and f"held by pid {again_proc.pid} (" in refusal[0], second.stderr[-2000:]
    assert "Traceback" not in second.stderr
    assert again.returncode == 0, again.stderr[-2000:]
    assert "resuming the interrupted run" in again.stderr
    record = read_run(run_dir)
    assert len(record.resumes) == 1 and record.stop["reason"] == "finished"
    ids = [p.point_id for p in record.points if p.status == "done"]
    assert sorted(ids) == ["000-up-3.00", "001-up-4.00", "002-up-5.00"]  # each once: none lost, none repeated
    assert [p.name for p in (tmp_path / "runs").iterdir()] == ["night"]  # no new run
    assert sim.setpoint_mps == 0.0

    size = (run_dir / "run.jsonl").stat().st_size
    trips = sim.watchdog_trips
    held = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert held.returncode == 0 and "is finished; nothing to do" in held.stderr, held.stderr[-2000:]
    assert (run_dir / "run.jsonl").stat().st_size == size  # the run is untouched
    assert sim.setpoint_mps == 0.0 and sim.watchdog_trips == trips  # never ramped up


def test_the_start_decision_follows_how_the_last_run_ended(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    assert start_decision(runs, "a").action == "new"
    sweep = SweepConfig(speeds=(3.0,))
    log = RunLog.create(runs / "a", run_id="a", config={}, plan=plan_points(sweep))
    assert start_decision(runs, "a").action == "resume"
    assert start_decision(runs, None).action == "resume"  # the newest run, without a name
    log.stop("error", error="DriverError: /dev/ttyUSB0: no reply within 0.5 s")
    log.close()
    held = start_decision(runs, "a")
    assert held.action == "hold" and "stopped (error: DriverError: /dev/ttyUSB0: no reply" in held.why
    assert f"flagtrack sweep --resume {runs / 'a'}" in held.why
    assert start_decision(runs, None).action == "hold"
    (runs / "a" / "run.jsonl").write_text('{"type": "stop"}\n{"broken\n')
    assert start_decision(runs, "a").action == "hold"
    finished = RunLog.create(runs / "b", run_id="b", config={}, plan=plan_points(sweep))
    finished.stop("finished")
    finished.close()
    assert start_decision(runs, "b").action == "hold"
    assert start_decision(runs, None).action == "new"  # unnamed runs: a finished one leaves room for the next
