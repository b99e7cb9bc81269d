"""What an operator sees of a sweep (the simulated rig: pty tunnel, twin camera, tracker, recorder, real Zenoh):
a line per finished point and a progress bar on a real terminal, plain lines on a pipe, nothing with --quiet, the
same per-point facts in the SupervisorState a remote subscriber receives, and a run folder that explains itself."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from flagtrack.daemon.rig.config import RigConfig
from flagtrack.daemon.rig.run import run_rig
from flagtrack.daemon.schema import SupervisorState
from flagtrack.daemon.sweep.runlog import read_run
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.daemon.typed_yaml import from_mapping
from tests.fakes.rig import rig_yaml, simulated_rig
from tests.fakes.terminal import run_on_a_terminal
from tests.integration.test_transport import free_port

pytestmark = pytest.mark.slow

POINTS = ["000-up-4.00", "001-up-5.50", "002-down-4.00"]


def rig_mapping(tmp_path: Path, bus: dict[str, Any] | None = None) -> dict[str, Any]:
    """A small sweep (4.0, 5.5 m/s up, 4.0 down) on the light twin: the rig shares 2 cores with the tests."""
    name = f"prog{time.monotonic_ns() % 10**9}"
    rig = simulated_rig(tmp_path, name)
    if bus:
        rig["bus"] = {"namespace": f"flagtrack/{name}", **bus}
    return rig


def rig_file(tmp_path: Path) -> Path:
    return rig_yaml(tmp_path, rig_mapping(tmp_path))


def flagtrack(*args: str) -> list[str]:
    return [sys.executable, "-m", "flagtrack.daemon", *args]


def point_lines(text: str) -> list[str]:
    """The per-point lines of a command's stderr (after the terminal's carriage returns)."""
    lines = [part for line in text.splitlines() for part in line.split("\r")]
    return [line.strip() for line in lines if re.match(r"\s*point\s+\d+/\d+\s", line)]


def test_sweep_on_a_terminal_shows_a_line_per_point_above_a_progress_bar(tmp_path: Path) -> None:
    shown = run_on_a_terminal(flagtrack("sweep", "-c", str(rig_file(tmp_path))), timeout_s=180.0)
    lines = point_lines(shown)
    assert [line.split()[1] for line in lines] == ["1/3", "2/3", "3/3"], shown
    assert [line.split()[4] for line in lines] == ["up", "up", "down"]
    assert [line.split()[5] for line in lines] == ["still", "flapping", "still"], lines
    assert "A/L 0.2" in lines[1] or "A/L 0.3" in lines[1], lines[1]
    assert all(re.search(r"lost (\d+\.\d %|-)", line) and "ETA" in line for line in lines)  # the tracker's /lost
    assert re.search(r"sweep [0-3]/3 \|[^|\n]*\| \d+:\d\d elapsed, ETA \d+:\d\d \| point \d", shown), shown  # live bar
    assert "sweep 3/3 |" in shown and "\r" in shown  # redrawn in place, ending full
    assert "flagtrack sweep: finished; run folder" in shown


def test_up_with_a_supervisor_prints_plain_lines_on_a_pipe(tmp_path: Path) -> None:
    result = subprocess.run(flagtrack("up", "-c", str(rig_file(tmp_path))), capture_output=True, text=True, timeout=180)
    assert result.returncode == 0, result.stderr
    lines = point_lines(result.stderr)
    assert [line.split()[1] for line in lines] == ["1/3", "2/3", "3/3"], result.stderr
    assert "sweep: 3 points, ETA" in result.stderr
    assert "\r" not in result.stderr and "|" not in result.stderr  # no bar drawn into a pipe


def test_quiet_sweep_prints_no_progress_only_the_result(tmp_path: Path) -> None:
    result = subprocess.run(
        flagtrack("sweep", "-c", str(rig_file(tmp_path)), "--quiet"), capture_output=True, text=True, timeout=180
    )
    assert result.returncode == 0, result.stderr
    assert not point_lines(result.stderr) and "sweep: 3 points" not in result.stderr and "ETA" not in result.stderr
    assert "flagtrack sweep: finished; run folder" in result.stderr  # the result still says where the run is
    assert read_run(tmp_path / "runs" / "run").stop["reason"] == "finished"
    run = json.loads((tmp_path / "runs" / "run" / "run.json").read_text())  # and what it found, as run.json says
    onset, decay = (f"{v:g} m/s" if v is not None else "not observed" for v in (run["onset_mps"], run["decay_mps"]))
    assert f"  found   onset {onset} going up, decay {decay} coming down; 3 of 3 points done\n" in result.stderr
    readme = (tmp_path / "runs" / "run" / "README.txt").read_text()  # run as python -m flagtrack.daemon
    assert f"Command    flagtrack sweep -c {tmp_path / 'rig.yaml'} --quiet\n" in readme, readme[:400]


def test_a_remote_subscriber_receives_the_facts_of_each_point(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    # the viewer listens, the rig connects: the link is up as the rig's bus opens (the other way round,
    # a viewer that came first waits for Zenoh's next connection retry, seconds later)
    config = from_mapping(RigConfig, rig_mapping(tmp_path, bus={"connect": [endpoint]}))
    local: list[SupervisorState] = []

    def broken_display(state: SupervisorState) -> None:
        local.append(state)
        if state.last_point:  # from the first finished point on, the command's display fails
            raise BrokenPipeError("stderr went away")

    with Bus(BusConfig(namespace=config.bus_config.namespace, listen=(endpoint,))) as viewer:
        states = viewer.subscribe(viewer.keys.supervisor_state(), SupervisorState, capacity=100_000)
        result = run_rig(config, list(config.services), quiet=True, on_supervisor_state=broken_display)
        assert result.code == 0  # the sweep went on: a display never stops it
        failures = [r for r in caplog.records if "progress observer failed" in r.getMessage()]
        assert len(failures) == 1 and "BrokenPipeError" in failures[0].getMessage()  # said once
        remote: list[SupervisorState] = []
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not (remote and remote[-1].mode == "safe"):  # the last state sent
            message = states.recv(timeout_s=0.1)
            if message is not None:
                remote.append(message)
    assert remote and remote[-1].mode == "safe", f"{len(remote)} states received"
    assert all(state in local for state in remote)  # what the command draws is what the bus carries
    record = read_run(tmp_path / "runs" / "run")
    points = {p.point_id: p for p in record.points}
    finished = {}
    for state in remote:
        if state.last_point:
            finished.setdefault(state.last_point, state)  # the first state after each point
    assert list(finished) == POINTS
    for position, (point_id, state) in enumerate(finished.items(), start=1):
        point = points[point_id]
        assert (state.last_index, state.points_done, state.points_total) == (position, position, 3)
        assert (state.last_speed_mps, state.last_branch, state.last_state) == (
            point.speed_mps,
            point.branch,
            point.state,
        )
        assert state.last_status == "done" and state.amplitude_over_l == point.amplitude_over_l
        expected_f = point.frequency_hz if point.state == "flapping" else -1.0  # still: no frequency, -1 on the wire
        assert state.frequency_hz == expected_f and state.lost_fraction == point.lost_fraction  # the tracker's /lost
        assert 0.0 <= point.lost_fraction <= 0.05 and not point.suspect
        assert state.sensor_error_rms_over_l == -1.0  # no sensor on this rig
    assert 8 < finished[POINTS[1]].frequency_hz < 20 and finished[POINTS[1]].amplitude_over_l > 0.1
    assert finished[POINTS[-1]].eta_s == 0.0 and finished[POINTS[0]].eta_s > 0
    assert {s.point_index for s in remote if s.point} == {1, 2, 3}  # the point being measured, while it is
    run = json.loads((tmp_path / "runs" / "run" / "run.json").read_text())
    assert [p["point_id"] for p in run["points"]] == POINTS and run["status"] == "finished"
    assert "Command" in (tmp_path / "runs" / "run" / "README.txt").read_text()
