"""``flagtrack control`` on the simulated rig (pty tunnel, twin camera, tracker, flag state, recorder,
supervisor, real Zenoh in one process): a law asking 99 m/s gets the tunnel's bound and the record
says why; a law that raises or returns nonsense holds the speed, is said once, and ends the run
safe; the readback never leaves the bounds; SIGTERM ends it safe too; the run folder has it all."""

from __future__ import annotations

import json
import logging
import signal
import textwrap
import threading
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from flagtrack.daemon.cli import main
from flagtrack.daemon.commands import _feedback_demo
from flagtrack.daemon.schema import TunnelState
from flagtrack.daemon.services.runner import SAME_SIGNAL_S
from flagtrack.daemon.services.supervisor.analysis import point_metrics
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.formats.centreline import read_centrelines
from tests.fakes.helpers import wait_until
from tests.integration.test_transport import free_port
from tests.integration.test_up import start

MAX_MPS, TOLERANCE_MPS = 8.0, 0.15


def rig_file(tmp_path: Path, port: int, **control: object) -> Path:
    """A light simulated rig connecting to 127.0.0.1:``port``, where a test may watch its bus (the
    watcher listens: the link is up as the rig's bus opens, not at Zenoh's next connection retry)."""
    settings = {"period_s": 0.05, "duration_s": 20, "start_speed_mps": 5.5, "settle_s": 1.0, "max_faults": 3}
    settings.update(control)
    body = f"""
    rig: ctl{port}
    bus: {{connect: ["tcp/127.0.0.1:{port}"]}}
    camera:
      adapter: simulated
      packet_us: 4000
      simulated: {{events_per_px2: 0.5, noise_rate_hz: 5000, max_lag_s: 1.0,
                  flutter: {{onset_speed_mps: 4.9, decay_speed_mps: 4.4, tau_amp_s: 0.15}}}}
    tracker: {{root: [150, 240], length: 300, tau_s: 0.002}}
    tracker_service: {{max_batch_delay_s: 0.005}}
    recorder: {{directory: {tmp_path / "rec"}}}
    tunnel:
      driver: simulated
      timeout_s: 2.0
      safety: {{max_speed_mps: {MAX_MPS}, max_ramp_mps2: 4.0, ramp_period_s: 0.05, tolerance_mps: {TOLERANCE_MPS},
               settle_timeout_s: 5.0, poll_period_s: 0.05, keepalive_s: 0.25, watchdog_s: 1.0}}
      sim: {{tau_s: 0.1, ramp_mps2: 6.0, watchdog_s: 1.0}}
    supervisor:
      runs_dir: {tmp_path / "runs"}
      onset: {{learn_s: 1.0}}
      silence_timeout_s: 3.0
      startup_timeout_s: 60
      control: {json.dumps(settings)}
    services: [camera, tracker]
    """
    path = tmp_path / "rig.yaml"
    path.write_text(textwrap.dedent(body))
    return path


def law_file(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "law.py"
    path.write_text(textwrap.dedent(text))
    return path


def watch_tunnel(port: int, namespace: str, states: list[TunnelState]) -> threading.Event:
    """Gather the tunnel states of a rig connecting to ``port`` (listened on here) until the returned
    event is set."""
    done = threading.Event()
    ready = threading.Event()

    def gather() -> None:
        with Bus(BusConfig(namespace=namespace, listen=(f"tcp/127.0.0.1:{port}",))) as bus:
            sub = bus.subscribe(bus.keys.tunnel_state(), TunnelState, capacity=100_000)
            ready.set()
            while not done.is_set():
                state = sub.recv(timeout_s=0.1)
                if state is not None:
                    states.append(state)

    threading.Thread(target=gather, daemon=True).start()
    ready.wait(10)
    return done


def records(run_dir: Path) -> list[dict]:
    return [json.loads(line) for line in (run_dir / "control.jsonl").read_text().splitlines()]


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_a_law_is_bounded_held_on_faults_and_stopped_safe(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    law = law_file(
        tmp_path,
        """
        calls = 0
        setpoint = 0.2

        def law(state):
            global calls
            calls += 1
            if calls <= 5:
                return 99.0  # far above the tunnel's bound
            if calls <= 8:
                return None  # hold
            if calls == 9:
                return "fast"  # not a speed
            raise ZeroDivisionError("gain over zero")
        """,
    )
    port = free_port()
    states: list[TunnelState] = []
    done = watch_tunnel(port, f"flagtrack/ctl{port}", states)
    out = tmp_path / "runs" / "exp1"
    caplog.set_level(logging.WARNING)
    code = main(["control", "-c", str(rig_file(tmp_path, port)), "--controller", f"{law}:law", "--out", str(out), "-q"])
    wait_until(lambda: states and states[-1].setpoint_mps == 0.0, 10, "the tunnel's last state (at zero) to arrive")
    done.set()
    assert code == 1  # stopped by the law's faults, not finished
    steps = records(out)
    laws = [r for r in steps if r["requester"] == "law"]
    asked_99 = [r for r in laws if r["asked_mps"] == 99.0]
    assert len(asked_99) == 5
    assert all(r["applied_mps"] == MAX_MPS and "tunnel.safety.max_speed_mps" in r["reason"] for r in asked_99)
    assert all(0 < r["setpoint_mps"] <= MAX_MPS for r in asked_99)  # the ramp's set-point, within the bounds
    bounded = [r.getMessage() for r in caplog.records if "tunnel.safety.max_speed_mps" in r.getMessage()]
    assert len(bounded) == 1 and f"{MAX_MPS:g} m/s applied (said once)" in bounded[0], bounded  # not 5 lines
    faults = [r for r in laws if r.get("reason", "").startswith("fault")]
    assert [("str" in r["reason"], "ZeroDivisionError" in r["reason"]) for r in faults] == [
        (True, False),
        (False, True),
        (False, True),
    ]
    assert all(r["applied_mps"] == MAX_MPS and r["asked_mps"] is None for r in faults)  # the speed held
    line = next(n for n, text in enumerate(law.read_text().splitlines(), 1) if "raise ZeroDivisionError" in text)
    assert [r.get("where") for r in faults] == [None, f"law.py:{line}", f"law.py:{line}"]  # the line to look at
    assert all(r["state"]["source"] == "cam0" and r["setpoint"] == 0.2 for r in laws)
    said = [r for r in caplog.records if r.levelno >= logging.ERROR and f"{law}:law" in r.getMessage()]
    assert len(said) == 1 and "held" in said[0].getMessage()  # said once, in one line
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "stopped" and "faulted 3 times in a row" in run["stop_reason"]
    assert run["counts"]["faults"] == 3 and run["loop_latency_ms"]["steps"] == 5
    for name in ("README.txt", "control.png", "recording.raw", "recording.json", "recording_centrelines.h5"):
        assert (out / name).stat().st_size > 0, name
    with h5py.File(out / "recording_centrelines.h5") as f:
        assert len(f["t"]) > 100
    readbacks = [s.speed_mps for s in states if s.speed_mps >= 0]
    assert readbacks and max(readbacks) <= MAX_MPS + TOLERANCE_MPS  # (and it ended at zero: waited for above)


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_a_law_that_never_returns_stops_the_run_safe_within_its_timeouts(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    law = law_file(
        tmp_path,
        """
        import threading
        import time

        calls = 0

        def law(state):
            global calls
            calls += 1
            if calls == 1:
                time.sleep(0.2)  # slower than its period: said once
                return 6.0
            if calls == 2:
                raise SystemExit("leaving")  # not the supervisor's exit: a fault
            threading.Event().wait()  # never returns
        """,
    )
    port = free_port()
    states: list[TunnelState] = []
    done = watch_tunnel(port, f"flagtrack/ctl{port}", states)
    out = tmp_path / "runs" / "exp3"
    caplog.set_level(logging.WARNING)
    rig = rig_file(tmp_path, port, duration_s=0, law_timeout_s=0.5)  # until stopped: only the faults end it
    code = main(["control", "-c", str(rig), "--controller", f"{law}:law", "--out", str(out), "-q"])
    wait_until(lambda: states and states[-1].setpoint_mps == 0.0, 10, "the tunnel's last state (at zero) to arrive")
    done.set()
    assert code == 1
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "stopped" and "faulted 3 times in a row" in run["stop_reason"], run["stop_reason"]
    assert "has not returned for" in run["stop_reason"]
    reasons = [r.get("reason", "") for r in records(out) if r["requester"] == "law"]
    assert reasons[0] == "" and [r.split(";")[0] for r in reasons[1:]] == [
        "fault: raised SystemExit: leaving",
        "fault: did not return within 0.5 s",
        reasons[3].split(";")[0],
    ]
    assert "has not returned for" in reasons[3]
    slow = [r.getMessage() for r in caplog.records if "longer than supervisor.control.period_s" in r.getMessage()]
    assert len(slow) == 1, slow


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_sigterm_stops_the_loop_safe_and_the_record_says_so(tmp_path: Path) -> None:
    law = law_file(tmp_path, "def law(state):\n    return 5.0\n")
    port = free_port()
    states: list[TunnelState] = []
    done = watch_tunnel(port, f"flagtrack/ctl{port}", states)
    out = tmp_path / "runs" / "exp2"
    rig = rig_file(tmp_path, port, duration_s=0)  # until stopped
    proc = start("control", "-c", str(rig), "--controller", f"{law}:law", "--out", str(out), "-q")
    try:
        wait_until(lambda: (out / "control.jsonl").exists() and len(records(out)) >= 3, 150, "three control steps")
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=90)
        wait_until(lambda: states and states[-1].setpoint_mps == 0.0, 10, "the tunnel's last state (at zero) to arrive")
    finally:
        proc.kill()
        done.set()
    assert proc.returncode != 0, err
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "stopped" and "SIGTERM" in run["stop_reason"].upper(), run["stop_reason"]
    assert all(r["asked_mps"] == 5.0 and r["applied_mps"] == 5.0 for r in records(out))  # (ended at zero: above)


def test_a_missing_law_is_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rig = rig_file(tmp_path, free_port())
    assert main(["control", "-c", str(rig), "--controller", "nowhere.py:law"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["flagtrack control: error: --controller: no such file: nowhere.py"]
    assert main(["control", "-c", str(rig), "--controller", "law.txt"]) == 2
    assert "give the law as FILE.py:FUNCTION, or pi (or none: speed requests only)" in capsys.readouterr().err
    # a syntax error or a name the file lacks: before the rig starts (it was found once all was up)
    (tmp_path / "typo.py").write_text("def law(state):\n    return 5.0 +\n")
    assert main(["control", "-c", str(rig), "--controller", f"{tmp_path / 'typo.py'}:law"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--controller" in err[0] and "typo.py, line 2: invalid syntax" in err[0], err
    assert main(["control", "-c", str(rig), "--controller", f"{tmp_path / 'typo.py'}:lawww"]) == 2
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_the_feedback_demo_holds_the_flag_through_the_step(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(_feedback_demo, "STEP_AFTER_S", 12.0)  # (25 s each in the demo: the same law, shorter)
    monkeypatch.setattr(_feedback_demo, "AFTER_S", 14.0)
    assert main(["demo", "--feedback", "--out", str(tmp_path), "--json", "-q"]) == 0
    found = json.loads(capsys.readouterr().out)
    assert found["amplitude_error_rms_over_l"] < 0.02 and found["amplitude_error_rms_over_l_before_step"] < 0.02
    assert found["settled_cycles"] > 50 and found["faults"] == 0 and found["latency_steps"] > 100
    assert (tmp_path / "control" / "control.png").stat().st_size > 0
    assert (tmp_path / "law.py").read_text().count("\n") < 25  # the law the user can read and change
    live_and_offline_agree(tmp_path / "control")


def live_and_offline_agree(run_dir: Path) -> None:
    """Each cycle's state as the law saw it live has the A/L the sweep's per-point figure gives offline
    for that cycle's recorded centrelines, and over ten whole cycles at a steady speed the cycles per
    second are the per-point frequency within 1 %."""
    batch, _ = read_centrelines(run_dir / "recording_centrelines.h5")
    cycles = [r["state"] for r in records(run_dir) if r["state"] and r["state"]["completes_cycle"]]
    cycles = list({s["seq"]: s for s in cycles}.values())
    assert len(cycles) > 100
    for state in cycles:
        rows = (batch.t_s >= state["cycle_start_s"]) & (batch.t_s <= state["cycle_end_s"])
        offline = point_metrics([batch.select(rows)], 300.0, (150.0, 240.0), 0.0)
        assert state["amplitude_over_l"] == pytest.approx(offline.amplitude_over_l, rel=1e-9)
        assert state["updates"] == int(rows.sum())
    stretches, run = [], [cycles[0]]
    for state in cycles[1:]:
        if state["cycle_start_s"] == run[-1]["cycle_end_s"]:
            run.append(state)
        else:
            stretches.append(run)
            run = [state]
    chunks = [r[k : k + 10] for r in [*stretches, run] for k in range(0, len(r) - 9, 10)]
    steady = [c for c in chunks if np.ptp([s["frequency_hz"] for s in c]) < 0.02 * c[0]["frequency_hz"]]
    assert len(steady) >= 3  # (while the speed moves, f does: the FFT's peak and the mean rate differ)
    for run in steady:
        rows = (batch.t_s >= run[0]["cycle_start_s"]) & (batch.t_s <= run[-1]["cycle_end_s"])
        offline = point_metrics([batch.select(rows)], 300.0, (150.0, 240.0), 0.0)
        per_s = len(run) / (run[-1]["cycle_end_s"] - run[0]["cycle_start_s"])
        assert per_s == pytest.approx(offline.frequency_hz, rel=0.01)


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_a_forced_exit_says_the_tunnel_was_left_to_its_watchdog(tmp_path: Path) -> None:
    law = law_file(tmp_path, "def law(state):\n    return 5.0\n")
    port = free_port()
    out = tmp_path / "runs" / "exp4"
    proc = start("control", "-c", str(rig_file(tmp_path, port, duration_s=0)), "--controller", f"{law}:law",
                 "--out", str(out), "-q")  # fmt: skip
    try:
        wait_until(lambda: (out / "control.jsonl").exists() and len(records(out)) >= 3, 150, "three control steps")
        lines: list[str] = []
        reader = threading.Thread(target=lambda: lines.extend(iter(proc.stderr.readline, "")), daemon=True)
        reader.start()
        proc.send_signal(signal.SIGINT)
        wait_until(lambda: any("SIGINT received" in line for line in lines), 30, "the first SIGINT to be taken")
        time.sleep(SAME_SIGNAL_S)  # (a person's second press: the same signal at once is the first again)
        proc.send_signal(signal.SIGINT)  # while the tunnel ramps down from 5 m/s (over a second)
        proc.wait(timeout=60)
    finally:
        proc.kill()
    reader.join(10)  # (the pipe closed with the process)
    proc.stdout.close()
    proc.stderr.close()
    err = "".join(lines)
    assert proc.returncode == 130, err
    assert "second SIGINT, forcing exit" in err
    assert "the tunnel was not ramped down (last set-point" in err and "watchdog (1 s) must stop the fan" in err


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_a_law_that_faults_into_the_safe_speed_is_recorded_there_and_not_called_finished(tmp_path: Path) -> None:
    law = law_file(tmp_path, "def law(state):\n    raise RuntimeError('no gain')\n")
    port = free_port()
    out = tmp_path / "runs" / "exp5"
    rig = rig_file(tmp_path, port, duration_s=2.0, max_faults=2, safe_speed_mps=4.5)
    code = main(["control", "-c", str(rig), "--controller", f"{law}:law", "--out", str(out), "-q"])
    assert code == 1
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "stopped", run
    assert (
        "faulted 2 times in a row" in run["stop_reason"]
        and "held the safe speed 4.5 m/s to the end" in run["stop_reason"]
    )
    safe = [r for r in records(out) if r.get("reason") == "safe speed after the law's faults"]
    assert len(safe) >= 5 and all(r["applied_mps"] == 4.5 and r["state"]["source"] == "cam0" for r in safe)
    assert run["counts"]["faults"] == 2
