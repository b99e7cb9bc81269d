"""The supervisor on the simulated rig (pty tunnel, twin camera, tracker, recorder, real Zenoh in one
process): a sweep records every point; every fault ends with the tunnel at zero, the finished points
intact and a resumable run."""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from flagtrack.daemon.rig.build import build_services
from flagtrack.daemon.rig.config import RigConfig
from flagtrack.daemon.services.runner import ServiceGroup
from flagtrack.daemon.services.supervisor.feedback import ControllerState, control_step
from flagtrack.daemon.services.supervisor.monitor import point_state
from flagtrack.daemon.services.supervisor.section import FeedbackConfig
from flagtrack.daemon.sweep.runlog import completed_points, read_run
from flagtrack.daemon.sweep.summary import SUMMARY_COLUMNS
from flagtrack.daemon.transport import Bus
from flagtrack.daemon.typed_yaml import from_mapping
from flagtrack.drivers.formats import read_events
from tests.fakes.helpers import wait_until
from tests.fakes.rig import simulated_rig

SPEEDS = [4.0, 5.5]  # the simulated rig's sweep


def rig(tmp_path: Path, **supervisor: Any) -> RigConfig:
    """The simulated rig sweeping SPEEDS up and the first down (``supervisor``: more keys of its section)."""
    return from_mapping(RigConfig, simulated_rig(tmp_path, f"sup{time.monotonic_ns() % 10**9}", supervisor=supervisor))


def run(config: RigConfig, during=None, resume_dir: Path | None = None, timeout_s: float = 90.0):
    """Run the rig until the supervisor ends; ``during(services, group)`` runs alongside (fault injection)."""
    with Bus(config.bus_config) as bus:
        services = build_services(config, bus, list(config.services), resume_dir=resume_dir)
        supervisor = services[0]
        group = ServiceGroup(services, stop_when_any_finishes=["supervisor"])
        group.start()
        if during is not None:
            threading.Thread(target=during, args=(services, group), daemon=True).start()
        group.wait(timeout_s)
        report = group.shutdown(30)
    simulator = supervisor.tunnel.simulator
    return supervisor, report, simulator


@pytest.mark.slow
def test_a_sweep_records_every_point_and_ends_at_zero(tmp_path: Path) -> None:
    supervisor, report, simulator = run(rig(tmp_path))
    assert supervisor.stop_reason == "finished" and not report.errors
    record = read_run(tmp_path / "runs" / "run")
    points = list(record.latest_points().values())
    assert [(p.branch, p.speed_mps) for p in points] == [("up", 4.0), ("up", 5.5), ("down", 4.0)]
    assert [p.state for p in points] == ["still", "flapping", "still"]
    flapping = points[1]
    assert 0.15 < flapping.amplitude_over_l < 0.4 and 8 < flapping.frequency_hz < 20 and 0 <= flapping.twi <= 1
    assert flapping.event_rate_mev_s > 5 * points[0].event_rate_mev_s
    assert flapping.chain_reach == pytest.approx(1.0, abs=0.02) and not flapping.suspect  # the chain is the flag's
    assert all(np.isnan(p.chain_reach) for p in (points[0], points[2]))  # still: not judged
    assert record.stop["reason"] == "finished"
    for p in points:
        raw = tmp_path / "runs" / "run" / p.raw_file
        assert raw.stat().st_size == p.raw_bytes and len(read_events(raw).events) > 0
    header = (tmp_path / "runs" / "run" / "summary.csv").read_text().splitlines()[0].split(",")
    assert (
        header[:9]
        == [
            "speed_mps",
            "branch",
            "state",
            "amplitude_over_l",
            "frequency_hz",
            "twi",
            "cloud_distance_mean_over_l",
            "event_rate_mev_s",
            "raw_bytes",
        ]
        == list(SUMMARY_COLUMNS[:9])
    )
    assert (tmp_path / "runs" / "run" / "amplitude.png").stat().st_size > 5000
    assert simulator.setpoint_mps == 0.0


def fault_after_first_point(action):
    def during(services: list, group: ServiceGroup) -> None:
        supervisor = services[0]
        simulator = supervisor.tunnel.simulator
        wait_until(
            lambda: supervisor.points_done and simulator.setpoint_mps > SPEEDS[0],
            60,
            "the first point done and the ramp to the second begun",
        )
        action(services, group)

    return during


@pytest.mark.slow
@pytest.mark.parametrize(
    ("fault", "words"),
    [
        ("mute", "no reply"),
        ("stall", "did not reach the set-point"),
        ("camera", "camera silent"),
        ("sigterm", "stopped by SIGTERM"),
    ],
)
def test_faults_end_at_zero_with_finished_points_kept_and_a_resumable_run(
    tmp_path: Path, fault: str, words: str
) -> None:
    def inject(services: list, group: ServiceGroup) -> None:
        simulator = services[0].tunnel.simulator
        if fault == "mute":
            simulator.inject(mute=True)
        elif fault == "stall":
            simulator.inject(stall_mps=4.2)
        elif fault == "camera":
            camera = next(s for s in services if s.name.startswith("camera"))
            camera.camera.read = lambda timeout_s: time.sleep(timeout_s)  # the device goes silent
        else:
            group.stop.request("stopped by SIGTERM")  # what the signal handler does

    config = rig(tmp_path)
    supervisor, _, simulator = run(config, during=fault_after_first_point(inject))
    record = read_run(tmp_path / "runs" / "run")
    assert words in (record.stop["reason"] + " " + str(record.stop.get("error"))), record.stop
    assert completed_points(tmp_path / "runs" / "run") >= {"000-up-4.00"}
    wait_until(lambda: simulator.speed_mps <= 0.2, 5, "the tunnel at zero (by its watchdog, if muted)")
    if fault == "sigterm":  # resume: the finished point is not redone, the others are done
        done_before = completed_points(tmp_path / "runs" / "run")
        supervisor, _, _ = run(rig(tmp_path), resume_dir=tmp_path / "runs" / "run")
        record = read_run(tmp_path / "runs" / "run")
        assert record.stop["reason"] == "finished"
        ids = [p.point_id for p in record.points]
        assert all(ids.count(pid) == 1 for pid in done_before)
        assert completed_points(tmp_path / "runs" / "run") == {"000-up-4.00", "001-up-5.50", "002-down-4.00"}


def test_point_state_uses_the_hysteresis_band() -> None:
    assert point_state([10.0, 12.0, 11.0], on_hz=40.0, off_hz=20.0, previous="still") == "still"
    assert point_state([50.0, 60.0], on_hz=40.0, off_hz=20.0, previous="still") == "flapping"
    assert point_state([30.0], on_hz=40.0, off_hz=20.0, previous="flapping") == "flapping"
    assert point_state([30.0], on_hz=40.0, off_hz=20.0, previous="still") == "still"
    assert point_state([], on_hz=40.0, off_hz=20.0, previous="still") == "unknown"


def test_feedback_controller_respects_rate_and_bounds() -> None:
    cfg = FeedbackConfig(target_amplitude_over_l=0.25, start_speed_mps=5.0, max_step_mps=0.2, max_speed_mps=6.0)
    state = ControllerState(0.0, 5.0)
    speeds = []
    for _ in range(20):  # flag still: amplitude 0 -> push the speed up, 0.2 m/s per step, up to the bound
        state = control_step(state, 0.0, 1.0, cfg)
        speeds.append(state.speed_mps)
    steps = np.diff([5.0, *speeds])
    assert np.all(steps <= 0.2 + 1e-12) and np.all(steps >= 0) and steps[0] == pytest.approx(0.2)
    assert speeds[-1] == 6.0 == max(speeds)  # rate-limited climb, stopped at the bound
    held = control_step(state, float("nan"), 1.0, cfg)
    assert held == state


@pytest.mark.slow
def test_feedback_holds_the_target_amplitude_on_the_simulated_rig(tmp_path: Path) -> None:
    # open loop, 5.2 m/s gives A/L ~ 0.25; the target needs ~4.65 m/s (on the flapping branch)
    config = rig(
        tmp_path,
        mode="feedback",
        sweep=None,
        feedback={
            "target_amplitude_over_l": 0.18,
            "start_speed_mps": 5.2,
            "kp_mps": 2.0,
            "ki_mps_per_s": 2.0,
            "period_s": 0.5,
            "window_s": 0.4,
            "max_step_mps": 0.2,
            "min_speed_mps": 4.5,
            "max_speed_mps": 7.0,
            "duration_s": 25.0,
        },
    )
    supervisor, report, simulator = run(config)
    assert supervisor.stop_reason == "finished" and not report.errors
    trace = np.array(supervisor.feedback_trace)
    assert trace[0, 1] > 0.22  # far from the target at first
    late = trace[-4:]
    assert abs(np.median(late[:, 1]) - 0.18) < 0.025  # then held at the target
    assert late[:, 2].mean() < 5.0  # by slowing the wind
    assert simulator.setpoint_mps == 0.0


@pytest.mark.slow
def test_point_actions_run_with_placeholders_and_a_required_failure_stops_at_zero(tmp_path: Path) -> None:
    write_raw_path = "import pathlib, sys; pathlib.Path(sys.argv[1]).write_text(sys.argv[2] + ' ' + sys.argv[3])"
    config = rig(
        tmp_path,
        sweep={
            "speeds": [4.0],
            "branches": ["up"],
            "settle_s": 0.3,
            "record_s": 0.5,
            "actions": [
                {"name": "pause", "when": "before_record", "params": {"seconds": 0.1}},
                {
                    "name": "command",
                    "params": {
                        "argv": [
                            sys.executable,
                            "-c",
                            write_raw_path,
                            "{point_dir}/{point_id}.seen",
                            "{raw}",
                            "{speed_mps}",
                        ]
                    },
                },
                {
                    "name": "command",
                    "params": {
                        "argv": [sys.executable, "-c", "print('bad data'); raise SystemExit(3)"],
                        "required": True,
                    },
                },
            ],
        },
    )
    supervisor, _, simulator = run(config)
    run_dir = tmp_path / "runs" / "run"
    (point,) = read_run(run_dir).latest_points().values()
    seen = (run_dir / "points" / f"{point.point_id}.seen").read_text().split()
    assert seen == [str((run_dir / point.raw_file).resolve()), "4"] and (run_dir / point.raw_file).stat().st_size > 0
    assert point.actions == "pause ok; command ok; command failed: exit code 3 (output: 000-up-4.00.action2.log)"
    assert "bad data" in (run_dir / "points" / "000-up-4.00.action2.log").read_text()
    assert point.status == "failed" and "required action" in supervisor.stop_reason
    assert completed_points(run_dir) == set() and simulator.setpoint_mps == 0.0
