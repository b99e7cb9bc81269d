"""One owner per tunnel and per run (issue 20): real processes, a real pseudo-terminal, real locks.

A second program on a held tunnel port (`flagtrack tunnel set`, a supervisor) is refused with one
line naming the holder and sends nothing; a second supervisor on a run folder in use is refused
naming the holder; a killed holder frees both at once.
"""

from __future__ import annotations

import fcntl
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.sweep.runlock import LOCK_FILE, RunLock, held_by
from flagtrack.drivers.tunnel.simulated import SimulatedTunnel
from tests.integration.test_tunnel_cli import FLAGTRACK, rig_config, start_set


def test_a_second_tunnel_set_on_a_held_port_is_refused_naming_the_holder(sim: SimulatedTunnel, tmp_path: Path) -> None:
    config = rig_config(tmp_path, sim.port)
    holder = start_set(config, "3")
    try:
        commands_before = sim.valid_commands
        second = subprocess.run(
            [*FLAGTRACK, "tunnel", "set", "6", "-c", str(config)], capture_output=True, text=True, timeout=30
        )
        assert second.returncode != 0
        lines = second.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in second.stderr, second.stderr
        assert f"{sim.port}: port in use, held by pid {holder.pid} (" in lines[0]
        assert "tunnel set 3" in lines[0]
        assert sim.setpoint_mps == 3.0  # the second one sent nothing
        assert sim.valid_commands >= commands_before  # (the holder's keep-alives went on)
        stop = subprocess.run(
            [*FLAGTRACK, "tunnel", "stop", "-c", str(config)], capture_output=True, text=True, timeout=30
        )
        assert stop.returncode != 0 and len(stop.stderr.strip().splitlines()) == 1, stop.stderr
        assert f"held by pid {holder.pid}" in stop.stderr and "stop its owner (SIGTERM" in stop.stderr
    finally:
        holder.send_signal(signal.SIGTERM)
        holder.communicate(timeout=10)
    assert sim.setpoint_mps == 0.0
    freed = subprocess.run([*FLAGTRACK, "tunnel", "get", "-c", str(config)], capture_output=True, text=True, timeout=30)
    assert freed.returncode == 0, freed.stderr  # the port is free again


HOLD = """
import sys
from flagtrack.daemon.sweep.runlock import RunLock
lock = RunLock.acquire(sys.argv[1], "flagtrack supervisor -c rig.yaml")
print("locked", flush=True)
sys.stdin.read()
"""


def hold(run_dir: Path) -> subprocess.Popen:
    """Another process holding ``run_dir``'s lock (until it is killed)."""
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(run_dir)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert holder.stdout is not None and holder.stdout.readline() == "locked\n"
    return holder


def test_a_run_folder_in_use_is_refused_naming_the_holder_and_freed_by_its_death(tmp_path: Path) -> None:
    run_dir = tmp_path / "runs" / "run"
    holder = hold(run_dir)
    try:
        with pytest.raises(ConfigError) as refused:
            RunLock.acquire(run_dir, "flagtrack sweep --resume runs/run")
        text = str(refused.value)
        assert f"the run is in use by pid {holder.pid} on host " in text
        assert "(flagtrack supervisor -c rig.yaml) since " in text and "not started" in text
    finally:
        holder.kill()  # SIGKILL: no clean-up, the kernel drops the lock with the process
        holder.communicate(timeout=10)
    assert (run_dir / LOCK_FILE).exists()  # the killed holder's file stays, locking nothing
    with RunLock.acquire(run_dir, "flagtrack sweep --resume runs/run"):
        assert "flagtrack sweep --resume runs/run" in (run_dir / LOCK_FILE).read_text()
    assert not (run_dir / LOCK_FILE).exists()  # an orderly release leaves no lock file


def test_a_finished_run_leaves_no_lock_file_and_a_removed_one_is_not_locked(tmp_path: Path) -> None:
    """An orderly release removes ``.lock``; a process that opened the file just before it went (and
    locks the removed file) is not an owner: it starts again on the path, and only one owner holds it."""
    run_dir = tmp_path / "run"
    first = RunLock.acquire(run_dir, "flagtrack sweep -c rig.yaml")
    with open(run_dir / LOCK_FILE, encoding="utf-8") as late:  # opened before the release removes the file
        first.release()
        assert not (run_dir / LOCK_FILE).exists()
        fcntl.flock(late.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)  # the removed file: locked, but nobody's lock
        with RunLock.acquire(run_dir, "flagtrack sweep --resume run"):  # a new file, locked for real
            with pytest.raises(ConfigError, match="in use by pid"):
                RunLock.acquire(run_dir, "flagtrack sweep --resume run")
    assert not (run_dir / LOCK_FILE).exists()


def test_resuming_a_run_in_use_is_refused_before_the_rig_starts(tmp_path: Path) -> None:
    run_dir = tmp_path / "runs" / "run"
    holder = hold(run_dir)
    try:
        assert held_by(run_dir) is not None and held_by(tmp_path) is None
        resume = subprocess.run(
            [*FLAGTRACK, "sweep", "--resume", str(run_dir)], capture_output=True, text=True, timeout=60
        )
    finally:
        holder.kill()
        holder.communicate(timeout=10)
    lines = resume.stderr.strip().splitlines()
    assert resume.returncode == 2 and len(lines) == 1, resume.stderr  # before reading the run or opening the rig
    assert f"the run is in use by pid {holder.pid} on host " in lines[0] and str(run_dir) in lines[0]
    assert held_by(run_dir) is None  # the killed holder's file locks nothing
