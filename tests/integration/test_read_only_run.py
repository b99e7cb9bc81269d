"""A run folder that turns read-only mid-run (a disk remounted read-only after an error), in a private
mount namespace (`unshare -m`, skipped with a reason where it cannot be made), the folder bound
read-only over itself: `flagtrack sweep` after its first point, `flagtrack control` after a few
steps. Each stops safe with the tunnel at zero; the lines say which file could not be written (not a
temporary name, not "supervisor failed"); the end message does not list files that were not
written; what was recorded is kept, and the sweep resumes once the folder is writable again."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from flagtrack.daemon.schema import TunnelState
from flagtrack.daemon.sweep.runlog import read_run
from flagtrack.drivers.formats import read_events
from flagtrack.drivers.tunnel.simulated import SimulatedTunnel
from tests.fakes.helpers import wait_until
from tests.integration.test_control import law_file, watch_tunnel
from tests.integration.test_control import rig_file as control_rig
from tests.integration.test_full_disk import mount_namespace, sim_params  # noqa: F401 - fixtures (the sweep's tunnel)
from tests.integration.test_restart_resumes import FLAGTRACK, rig_file
from tests.integration.test_transport import free_port


@pytest.mark.slow
@pytest.mark.usefixtures("mount_namespace")
def test_a_run_folder_turning_read_only_stops_the_sweep_safe_and_says_what_was_not_written(
    sim: SimulatedTunnel, tmp_path: Path
) -> None:
    sweep = {"speeds": [5.5, 6.0], "branches": ["up"], "settle_s": 0.5, "record_s": 1.0}
    rig = rig_file(tmp_path, sim.port, sweep, {}, expected_rate_mev_s=0.0, free_space_margin_mb=0.0)
    runs, out, night = tmp_path / "runs", tmp_path / "copy", tmp_path / "runs" / "night"
    runs.mkdir()
    out.mkdir()
    flagtrack = " ".join(FLAGTRACK)
    first_point_logged = (  # polled with a bound of 90 s
        f'i=0; until grep -q \'"type": "point"\' {night}/run.jsonl 2>/dev/null || [ $i -gt 900 ]; '
        "do sleep 0.1; i=$((i+1)); done"
    )
    script = (
        f"mount -t tmpfs -o size=256m tmpfs {runs} || exit 99; "
        f"{flagtrack} sweep -c {rig} & pid=$!; {first_point_logged}; "
        f"mount --bind {night} {night} && mount -o remount,bind,ro {night} || exit 98; "
        f"wait $pid; rc=$?; cp -a {runs}/. {out}/; "
        f"echo RESUME >&2; mount -o remount,bind,rw {night} && {flagtrack} sweep --resume {night} >&2; "
        f"cp {night}/run.jsonl {out}/resumed.jsonl; exit $rc"
    )
    done = subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True, text=True, timeout=180)
    first, resumed = done.stderr.split("RESUME\n", 1)
    assert done.returncode == 1, done.stderr[-4000:]
    assert "Traceback" not in done.stderr
    # the second point's start failed on its own file (not a hidden temporary name); the run stopped there
    record = read_run(out / "night")
    done_point, failed = record.points
    assert done_point.status == "done" and failed.status == "failed", record.points
    assert "Read-only file system" in failed.reason and "points/001-up-6.00.json'" in failed.reason, failed.reason
    assert record.stop is not None and "001-up-6.00" in record.stop["reason"]
    assert len(read_events(out / "night" / done_point.raw_file).events) > 0
    # what could not be written is said once each, as what it is; the end does not claim it
    assert "could not write the stop record" not in first and "supervisor failed" not in first, first[-3000:]
    assert "summary failed" in first
    assert "not written: summary.csv, amplitude.png, README.txt (the lines above say why)" in first, first[-3000:]
    assert "  summary " not in first and "  log " in first
    assert sim.setpoint_mps == 0.0 and sim.watchdog_trips == 0
    # writable again: the same run resumes (the lock left behind does not hold it) and finishes
    lines = [json.loads(line) for line in (out / "resumed.jsonl").read_text().splitlines()]
    assert [r["type"] for r in lines][-4:] == ["stop", "resume", "point", "stop"], resumed[-3000:]
    assert lines[-2]["point_id"] == "001-up-6.00" and lines[-2]["status"] == "done"
    assert lines[-1]["reason"] == "finished", resumed[-3000:]


@pytest.mark.slow
@pytest.mark.timeout(240)
@pytest.mark.usefixtures("mount_namespace")
def test_a_control_run_whose_folder_turns_read_only_stops_safe_and_says_so(tmp_path: Path) -> None:
    port = free_port()
    runs, out, control = _control_run(tmp_path, port)
    states: list[TunnelState] = []
    done = watch_tunnel(port, f"flagtrack/ctl{port}", states)
    steps_logged = (  # polled with a bound of 90 s
        f"i=0; until [ $(cat {out}/control.jsonl 2>/dev/null | wc -l) -gt 3 ] || [ $i -gt 900 ]; "
        "do sleep 0.1; i=$((i+1)); done"
    )
    script = (
        f"mount -t tmpfs -o size=256m tmpfs {runs} || exit 99; "
        f"{control} & pid=$!; {steps_logged}; "
        f"mount --bind {out} {out} && mount -o remount,bind,ro {out} || exit 98; "
        f"wait $pid; rc=$?; cp -a {runs}/. {tmp_path / 'copy'}/; exit $rc"
    )
    try:
        ran = subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True, text=True, timeout=200)
        wait_until(lambda: states and states[-1].setpoint_mps == 0.0, 10, "the tunnel's last state (at zero)")
    finally:
        done.set()
    err = ran.stderr
    assert ran.returncode == 1, err[-4000:]  # stopped, not "finished" with half a recording
    assert "Traceback" not in err
    assert "flagtrack control: recorder: recording stopped: writing" in err, err[-4000:]
    assert "not written at the end: run.json, README.txt, control.png (the lines above say why)" in err
    assert f"Read-only file system: '{out / 'control.png'}'" in err  # the file meant, not its temporary name
    copy = tmp_path / "copy" / "exp"
    assert len((copy / "control.jsonl").read_text().splitlines()) > 3
    assert (copy / "recording.raw").stat().st_size > 0


@pytest.mark.slow
@pytest.mark.timeout(240)
@pytest.mark.usefixtures("mount_namespace")
def test_a_control_run_whose_recording_fails_at_once_does_not_run_without_it(tmp_path: Path) -> None:
    runs, _, control = _control_run(tmp_path, free_port())
    script = (  # a disk with room for the log, not for the recording's first write
        f"mount -t tmpfs -o size=1m tmpfs {runs} || exit 99; "
        f"{control}; rc=$?; "
        f"cp -a {runs}/. {tmp_path / 'copy'}/; exit $rc"
    )
    ran = subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True, text=True, timeout=200)
    assert ran.returncode == 1, ran.stderr[-4000:]
    assert "flagtrack control: recorder: recording stopped: writing" in ran.stderr, ran.stderr[-4000:]
    assert "No space left on device" in ran.stderr
    run = json.loads((tmp_path / "copy" / "exp" / "run.json").read_text())
    assert run["status"] == "stopped" and run["counts"]["steps"] == 0, run


def _control_run(tmp_path: Path, port: int) -> tuple[Path, Path, str]:
    """The runs folder (made), the run's folder in it, and the command line of a 30 s control run
    on the light simulated rig, its law asking 5 m/s."""
    runs = tmp_path / "runs"
    runs.mkdir()
    law = law_file(tmp_path, "def law(state):\n    return 5.0\n")
    out = runs / "exp"
    rig = control_rig(tmp_path, port, duration_s=30)
    return runs, out, f"{' '.join(FLAGTRACK)} control -c {rig} --controller {law}:law --out {out}"
