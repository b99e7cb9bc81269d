"""``flagtrack tunnel``: real processes, real pseudo-terminals, real signals.

The supervisor's safe state at process level: SIGTERM ramps the tunnel to zero through the driver;
a process killed outright (SIGKILL) leaves it to the tunnel's own watchdog.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest

from flagtrack.drivers.tunnel.ascii import AsciiTunnel
from flagtrack.drivers.tunnel.simulated import SimulatedTunnel
from tests.fakes.helpers import wait_until
from tests.fakes.tunnel import RIG_SIM

FLAGTRACK = [sys.executable, "-m", "flagtrack.daemon"]


def rig_config(tmp_path: Path, port: str) -> Path:
    path = tmp_path / "rig.yaml"
    path.write_text(
        "tunnel:\n"
        "  driver: ascii\n"
        f"  port: {port}\n"
        "  timeout_s: 0.3\n"
        "  safety: {max_speed_mps: 8, max_ramp_mps2: 10, ramp_period_s: 0.05, tolerance_mps: 0.1,\n"
        "           settle_timeout_s: 2, poll_period_s: 0.05, keepalive_s: 0.2, watchdog_s: 1.0}\n"
    )
    return path


def start_set(config: Path, speed: str) -> subprocess.Popen[str]:
    proc = subprocess.Popen([*FLAGTRACK, "tunnel", "set", speed, "-c", str(config)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    line = proc.stdout.readline() if proc.stdout else ""
    assert "holding" in line, (line, proc.stderr.read() if proc.stderr else "")
    return proc


def test_sigterm_ramps_to_zero_through_the_driver(sim: SimulatedTunnel, tmp_path: Path) -> None:
    proc = start_set(rig_config(tmp_path, sim.port), "3")
    try:
        assert sim.speed_mps == pytest.approx(3.0, abs=0.15)
        time.sleep(1.5)  # longer than the watchdog: the keep-alive holds the speed
        assert sim.watchdog_trips == 0 and sim.setpoint_mps == 3.0
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=10)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "ramped to zero" in out
    assert sim.setpoint_mps == 0.0 and sim.watchdog_trips == 0
    assert wait_until(lambda: sim.speed_mps < 0.05)


def test_sigkill_leaves_it_to_the_tunnel_watchdog(sim: SimulatedTunnel, tmp_path: Path) -> None:
    proc = start_set(rig_config(tmp_path, sim.port), "4")
    proc.kill()
    proc.communicate(timeout=5)  # (and close its pipes)
    assert sim.setpoint_mps == 4.0  # nobody told it to stop ...
    assert wait_until(lambda: sim.watchdog_trips == 1)  # ... its own watchdog did
    assert wait_until(lambda: sim.speed_mps < 0.05)


def test_set_ends_with_one_line_when_the_controller_goes(sim: SimulatedTunnel, tmp_path: Path) -> None:
    """The controller's end of the link closes (a USB adapter pulled): the keep-alive thread died of
    termios' EIO with a traceback and the command went on saying it held the speed until Ctrl-C."""
    proc = start_set(rig_config(tmp_path, sim.port), "3")
    try:
        sim.close()
        out, err = proc.communicate(timeout=30)  # the watchdog (1 s) and the next check (1 s) later
    finally:
        proc.kill()
    assert proc.returncode == 2, err  # a device's error, as everywhere
    assert "Traceback" not in err and "ramped to zero" not in out
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"flagtrack tunnel: error: {sim.port}: the controller has not answered for "), err
    assert "its watchdog (1 s) stops the fan" in err


def test_a_closed_pty_is_a_driver_error_naming_the_port() -> None:
    import os
    import pty

    from flagtrack.daemon.errors import DriverError
    from flagtrack.drivers.serial.adapter import SerialAdapter

    master, slave = pty.openpty()
    port = os.ttyname(slave)
    adapter = SerialAdapter(port, timeout_s=0.2)
    os.close(master)
    os.close(slave)
    try:
        with pytest.raises(DriverError, match=f"^{port}: write failed: "):  # not termios.error
            adapter.write_line("V?")
    finally:
        adapter.close()


def test_set_beyond_bounds_is_one_line_error(sim: SimulatedTunnel, tmp_path: Path) -> None:
    result = subprocess.run([*FLAGTRACK, "tunnel", "set", "9", "-c", str(rig_config(tmp_path, sim.port))],
                            capture_output=True, text=True, timeout=20)  # fmt: skip
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        f"flagtrack tunnel: error: {sim.port}: set-point 9 m/s outside the bounds [0, 8] m/s (tunnel.safety); nothing sent"
    ]
    assert sim.valid_commands == 0  # refused before anything was sent


# the controller's watchdog waits out the seconds a loaded machine takes to start `flagtrack tunnel get`
@pytest.mark.parametrize("sim_params", [replace(RIG_SIM, watchdog_s=30.0)], ids=["watchdog 30 s"])
def test_get_and_stop(sim: SimulatedTunnel, tmp_path: Path) -> None:
    link = AsciiTunnel.open(sim.port, timeout_s=0.3)
    link.write_setpoint_mps(2.0)
    link.close()
    assert wait_until(lambda: abs(sim.speed_mps - 2.0) < 0.01)
    config = str(rig_config(tmp_path, sim.port))
    got = subprocess.run([*FLAGTRACK, "tunnel", "get", "-c", config], capture_output=True, text=True, timeout=20)
    assert got.returncode == 0 and f"{sim.port}: speed 2.00 m/s, fault none" in got.stdout
    stopped = subprocess.run([*FLAGTRACK, "tunnel", "stop", "-c", config], capture_output=True, text=True, timeout=20)
    assert stopped.returncode == 0, stopped.stderr
    assert sim.setpoint_mps == 0.0 and sim.speed_mps < 0.15


def test_get_from_a_controller_that_does_not_answer_is_an_error_line(tmp_path: Path) -> None:
    """A real pseudo-terminal nobody answers on: it printed "speed nan m/s, fault no reply" on stdout,
    as if it were a reading (exit 2)."""
    import os
    import pty

    master, slave = pty.openpty()
    try:
        port = os.ttyname(slave)
        config = str(rig_config(tmp_path, port))
        got = subprocess.run([*FLAGTRACK, "tunnel", "get", "-c", config], capture_output=True, text=True, timeout=30)
    finally:
        os.close(master)
        os.close(slave)
    assert got.returncode == 2 and got.stdout == "", got
    lines = got.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"flagtrack tunnel: error: {port}: ") and "no reply" in lines[0], (
        lines
    )


def test_sim_command_prints_a_pty_the_driver_can_use() -> None:
    proc = subprocess.Popen([*FLAGTRACK, "tunnel", "sim", "--tau-s", "0.02"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        port = proc.stdout.readline().strip() if proc.stdout else ""
        assert port.startswith("/dev/")
        link = AsciiTunnel.open(port, timeout_s=0.5)
        try:
            link.write_setpoint_mps(1.5)
            assert wait_until(lambda: abs(link.read_speed_mps() - 1.5) < 0.01)
            link.stop()
        finally:
            link.close()
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=5)
    finally:
        proc.kill()
        proc.communicate(timeout=5)  # close its pipes
    assert proc.returncode == 0


def test_a_typo_anywhere_in_the_rig_file_is_named_before_the_port_opens(tmp_path: Path) -> None:
    """`tunnel get -c rig.yaml` read only the tunnel section: a misspelt key elsewhere passed unseen,
    where every other command refuses the file."""
    config = rig_config(tmp_path, "/dev/flagtrack-no-such-port")
    config.write_text(config.read_text() + "tracker: {root: [100, 240], lenght: 200}\n")
    got = subprocess.run([*FLAGTRACK, "tunnel", "get", "-c", str(config)], capture_output=True, text=True, timeout=30)
    assert got.returncode == 2 and got.stdout == "", got
    lines = got.stderr.strip().splitlines()
    assert len(lines) == 1 and "tracker.lenght" in lines[0] and "unknown key" in lines[0], lines


@pytest.mark.parametrize("sim_params", [replace(RIG_SIM, watchdog_s=30.0)], ids=["watchdog 30 s"])
def test_stop_is_never_held_up_by_a_key_outside_the_tunnel_section(sim: SimulatedTunnel, tmp_path: Path) -> None:
    link = AsciiTunnel.open(sim.port, timeout_s=0.3)
    link.write_setpoint_mps(2.0)
    link.close()
    config = rig_config(tmp_path, sim.port)
    config.write_text(config.read_text() + "tracker: {root: [100, 240], lenght: 200}\n")
    stopped = subprocess.run(
        [*FLAGTRACK, "tunnel", "stop", "-c", str(config)], capture_output=True, text=True, timeout=20
    )
    assert stopped.returncode == 0, stopped.stderr
    assert sim.setpoint_mps == 0.0
