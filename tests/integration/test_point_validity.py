"""A point is good only if it was measured as planned (issue 20): on the simulated rig, a fan that
stalls or a tunnel that goes silent while a point records makes that point ``failed`` with the
reason, never ``done``; it is measured again (its first attempt's files kept) or the sweep stops
safe, as the plan's ``on_bad_point`` says."""

from __future__ import annotations

import csv
import dataclasses
import threading
import time
from pathlib import Path

import pytest

from flagtrack.daemon.services.runner import ServiceGroup
from flagtrack.daemon.sweep.runlog import read_run
from flagtrack.drivers.formats import read_events
from tests.fakes.helpers import wait_until
from tests.integration.test_supervisor import rig, run

FIRST = "000-up-4.00"
SECOND = "001-up-5.50"


def fault_while_recording(fault: str, clear: bool):
    """Inject ``fault`` into the simulated tunnel while the second point records; clear it once the
    point is recorded as failed (``clear``)."""

    def during(services: list, group: ServiceGroup) -> None:
        supervisor = services[0]
        simulator = supervisor.tunnel.simulator
        wait_until(lambda: supervisor.recording_point == SECOND, 60, "point 2 recording")
        simulator.inject(mute=True) if fault == "mute" else simulator.inject(stall_mps=4.2)
        wait_until(lambda: any(p.status == "failed" for p in supervisor.points_done), 30, "a failed point")
        if clear:
            simulator.clear_faults()

    return during


THIRD = "002-up-6.00"


@pytest.mark.slow
def test_a_stalled_fan_fails_the_point_the_retry_measures_it_and_a_hung_loop_lets_the_watchdog_stop_the_fan(
    tmp_path: Path,
) -> None:
    """One run: the recorder falls behind while point 1 records (its small queue drops packets: lossy,
    measured again: done); point 2 records while the fan stalls at 4.2 m/s (failed, measured again:
    done); point 3 records while the supervisor's own loop hangs (the controller's watchdog stops the fan)."""
    sweep = {"speeds": [4.0, 5.5, 6.0], "branches": ["up"], "settle_s": 0.5, "record_s": 2.0}
    config = rig(tmp_path, sweep=sweep, readback_grace_s=0.2)
    safety = dataclasses.replace(config.tunnel.safety, loop_timeout_s=2.0)
    recorder_cfg = dataclasses.replace(config.recorder, max_queue_packets=100)
    config = dataclasses.replace(config, recorder=recorder_cfg)
    config = dataclasses.replace(config, tunnel=dataclasses.replace(config.tunnel, safety=safety, timeout_s=1.0))
    seen: dict[str, float] = {}

    def faults(services: list, group: ServiceGroup) -> None:
        supervisor = services[0]
        recorder = next(s for s in services if s.name == "recorder")
        wait_until(lambda: supervisor.recording_point == FIRST, 60, "point 1 recording")
        take_lines = recorder._take_lines
        stalled = threading.Event()

        def slow_disk(now: float) -> None:  # the recorder's loop is held up once, as by a slow disk
            if not stalled.is_set():
                stalled.set()
                time.sleep(1.0)
                recorder._packets.channel._capacity = 1_000_000  # only the stall drops: a busy host lags too
            take_lines(now)

        recorder._take_lines = slow_disk
        fault_while_recording("stall", clear=True)(services, group)
        simulator = supervisor.tunnel.simulator
        wait_until(lambda: supervisor.recording_point == THIRD, 60, "point 3 recording")
        release = threading.Event()
        supervisor.add_observer(lambda state: release.wait())  # the supervisor's own loop hangs here
        hung_at = time.monotonic()
        wait_until(lambda: simulator.watchdog_trips >= 1, 10, "the tunnel's watchdog trip")
        seen["trip_after_s"] = time.monotonic() - hung_at
        wait_until(lambda: simulator.speed_mps < 0.2, 5, "the fan stopped")
        seen["setpoint"] = simulator.setpoint_mps
        release.set()
        group.stop.request("test over")

    _, _, simulator = run(config, during=faults)
    run_dir = tmp_path / "runs" / "run"
    record = read_run(run_dir)
    first = [p for p in record.points if p.point_id == FIRST]
    assert [p.status for p in first] == ["lossy", "done"]
    assert "of them dropped by the recorder's full queue" in first[0].reason and first[0].raw_file.endswith(".bad1.raw")
    second = [p for p in record.points if p.point_id == SECOND]
    assert [p.status for p in second] == ["failed", "done"]
    bad = second[0]
    assert "tunnel left its tolerance" in bad.reason and "set-point 5.50" in bad.reason
    assert bad.raw_file == f"points/{SECOND}.bad1.raw"  # the first attempt is kept beside the good one
    assert len(read_events(run_dir / bad.raw_file).events) > 0
    assert len(read_events(run_dir / second[1].raw_file).events) > 0 and second[1].raw_file == f"points/{SECOND}.raw"
    assert abs(second[1].speed_readback_mps - 5.5) < 0.15
    assert seen["setpoint"] == 0.0  # stopped by the controller while the supervisor hung
    assert seen["trip_after_s"] < 2.0 + 1.0 + 2.0  # loop_timeout_s + the controller's watchdog_s + slack
    assert simulator.setpoint_mps == 0.0


@pytest.mark.slow
def test_a_tunnel_going_silent_while_a_point_records_stops_the_sweep_as_the_plan_says(tmp_path: Path) -> None:
    sweep = {"speeds": [4.0, 5.5], "branches": ["up"], "settle_s": 0.5, "record_s": 2.0, "on_bad_point": "stop"}
    config = rig(tmp_path, sweep=sweep, readback_grace_s=0.2)
    _, _, simulator = run(config, during=fault_while_recording("mute", clear=False))
    run_dir = tmp_path / "runs" / "run"
    record = read_run(run_dir)
    assert f"point {SECOND} failed: tunnel silent" in record.stop["reason"], record.stop
    latest = record.latest_points()
    assert latest[SECOND].status == "failed" and "tunnel silent" in latest[SECOND].reason
    rows = {row["point_id"]: row for row in csv.DictReader((run_dir / "summary.csv").read_text().splitlines())}
    assert rows[SECOND]["status"] == "failed" and "tunnel silent" in rows[SECOND]["reason"]
    assert rows["000-up-4.00"]["status"] == "done"
    wait_until(lambda: simulator.speed_mps <= 0.2, 5, "the tunnel at zero by its own watchdog")
    assert simulator.watchdog_trips >= 1
