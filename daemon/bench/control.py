"""``flagtrack bench control``: the control loop's latency and how well it holds the flag, on the
simulated rig.

Three processes joined by Zenoh on loopback, peer to peer: ``flagtrack camera`` (the digital twin at about
``--rate`` Mev/s while it flaps, its flag following the tunnel's speed from the bus), ``flagtrack
tracker``, and ``flagtrack control`` (the flag-state service and the supervisor with the simulated
tunnel on a pty) running a proportional law: each cycle the speed moves by ``--gain`` times the A/L
error, the set-point stepping from the first ``--targets`` value to the second ``--step-after`` s
into the loop. From the run's ``control.jsonl``:

- ``loop_latency_p50_ms`` / ``loop_latency_p99_ms``: for each step that wrote a speed, from the camera
  adapter's reception of the packet that completed the last window of the state the law used, to
  the speed command written to the tunnel's serial port (its reply read);
- ``to_state_p50_ms`` / ``..._p99_ms``: the part up to the flag state's publication (camera, tracker,
  flag-state service), and ``state_to_command_...`` the rest (one bus hop, the supervisor, the law,
  the write);
- ``amplitude_error_rms_over_l``: RMS of the cycles' A/L less the set-point, from ``--settle`` s
  after the step to the end (``..._before_step``: the same before the step).

The event rate the twin delivered, whether it kept up with real time, and the machine's load
average (1 minute, at the start and the end) come with the figures: the machine may be shared.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path
from typing import Any

COMMAND = "control"
HELP = "latency of the control loop (camera packet to tunnel command) and A/L held through a set-point step"
DESCRIPTION = """\
The simulated rig as three processes (twin camera at --rate Mev/s, tracker, control) with a law holding
A/L through a set-point step: the loop's latency p50/p99 (camera packet received to speed command
written) and the A/L error once settled, with the twin's rate and the machine's load. More: docs/control.md.
"""
EVENTS_PER_PX2_PER_MEV_S = 2.45
"""The twin's event density per Mev/s asked, at A/L 0.22-0.26 (measured: 11.0 px^-2 gave 4.48 Mev/s
while flapping, 12.5 gave 5.11)."""
LAW = '''
"""Hold A/L at a set-point that steps once: each cycle the speed moves by GAIN x the A/L error."""

TARGETS, STEP_AFTER_S, GAIN = {targets!r}, {step_after!r}, {gain!r}
setpoint = TARGETS[0]
t0_s, asked_mps = None, -1.0


def law(state):
    global setpoint, t0_s, asked_mps
    t0_s = state.t_s if t0_s is None else t0_s
    setpoint = TARGETS[0] if state.t_s - t0_s < STEP_AFTER_S else TARGETS[1]
    if not state.completes_cycle or state.amplitude_over_l < 0 or state.speed_mps < 0:
        return None
    asked_mps = state.speed_mps if asked_mps < 0 else asked_mps
    asked_mps += GAIN * (setpoint - state.amplitude_over_l)
    return asked_mps
'''


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the control benchmark."""
    parser.add_argument("--rate", type=float, default=5.0, help="the twin's event rate while it flaps, Mev/s")
    parser.add_argument("--targets", type=float, nargs=2, default=[0.22, 0.26], help="A/L before and after the step")
    parser.add_argument("--step-after", type=float, default=20.0, help="the set-point steps this long into the loop, s")
    parser.add_argument("--after", type=float, default=20.0, help="the loop goes on this long after the step, s")
    parser.add_argument("--settle", type=float, default=6.0, help="the error counts from this long after the step, s")
    parser.add_argument("--gain", type=float, default=1.0, help="speed change per cycle per unit of A/L error, m/s")
    parser.add_argument("--period", type=float, default=0.02, help="the law is called at most this often, s")
    parser.add_argument("--out", type=Path, help="keep the run folder and the processes' logs here")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")


def run(args: argparse.Namespace) -> int:
    """Run the loop through the step; print its figures."""
    if args.rate <= 0 or args.step_after <= 0 or args.after <= args.settle or args.period <= 0:
        raise SystemExit("flagtrack bench control: --rate, --step-after, --period positive and --after > --settle")
    load_start = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        folder = (args.out or Path(tmp)).expanduser().resolve()
        folder.mkdir(parents=True, exist_ok=True)
        outcome = _run_processes(args, folder)
        results = figures(folder / "run", args.targets, args.settle)
    results.update(outcome, load_average_start=load_start, load_average_end=os.getloadavg()[0], rate_asked=args.rate)
    if args.json:
        print(json.dumps(results))
    else:
        print(describe(results))
    return 0 if results["latency_steps"] else 1


def _configs(args: argparse.Namespace, folder: Path, ports: dict[str, int]) -> dict[str, Path]:
    """The three processes' rig files (one rig, each its own bus section: the camera and the tracker
    listen, each process connects to those before it) and the law's file."""
    from flagtrack.daemon.rig.twin import simulated_tunnel

    common = {
        "rig": f"benchctl{ports['camera']}",
        "camera": {
            "adapter": "simulated",
            "packet_us": 1000,
            "simulated": {
                "events_per_px2": EVENTS_PER_PX2_PER_MEV_S * args.rate,
                "noise_rate_hz": 20_000,
                "max_lag_s": 0.5,
                "flutter": {"onset_speed_mps": 4.9, "decay_speed_mps": 4.4, "tau_amp_s": 0.3},
            },
        },
        "tracker": {"root": [150, 240], "length": 300, "direction_deg": 0, "tau_s": 0.0005},
        "tracker_service": {"batch_updates": 64, "max_batch_delay_s": 0.002},
        "tunnel": simulated_tunnel(timeout_s=2.0),
        "services": [],
    }
    camera, tracker = (f"tcp/127.0.0.1:{ports[name]}" for name in ("camera", "tracker"))
    supervisor = {
        "runs_dir": str(folder),
        "onset": {"learn_s": 1.0},
        "required": ["camera", "tracker", "flagstate"],
        "startup_timeout_s": 120,
        "control": {
            "period_s": args.period,
            "duration_s": args.step_after + args.after,
            "start_speed_mps": 5.3,
            "settle_s": 3.0,
            "record": False,
        },
    }
    files = {
        "camera": {**common, "bus": {"listen": [camera]}},
        "tracker": {**common, "bus": {"listen": [tracker], "connect": [camera]}},
        "control": {**common, "bus": {"connect": [camera, tracker]}, "supervisor": supervisor},
    }
    paths = {name: folder / f"{name}.yaml" for name in files}
    for name, config in files.items():
        paths[name].write_text(json.dumps(config))
    paths["law"] = folder / "bench_law.py"
    paths["law"].write_text(
        textwrap.dedent(LAW).format(targets=tuple(args.targets), step_after=args.step_after, gain=args.gain)
    )
    return paths


def _run_processes(args: argparse.Namespace, folder: Path) -> dict[str, Any]:
    """Run camera, tracker and control until the loop ends; the camera's rate and whether it kept up."""
    from flagtrack.daemon.bench.live_run import free_port as _free_port

    ports = {"camera": _free_port(), "tracker": _free_port()}
    paths = _configs(args, folder, ports)
    flagtrack = [sys.executable, "-m", "flagtrack.daemon"]
    commands = {
        "camera": [*flagtrack, "camera", "-c", str(paths["camera"])],
        "tracker": [*flagtrack, "tracker", "-c", str(paths["tracker"])],
        "control": [*flagtrack, "control", "-c", str(paths["control"]), "--controller", f"{paths['law']}:law",
                    "--out", str(folder / "run")],
    }  # fmt: skip
    logs = {name: open(folder / f"{name}.log", "w") for name in commands}  # noqa: SIM115 - closed below
    procs: dict[str, subprocess.Popen] = {}
    try:
        for name, command in commands.items():  # each once those it connects to listen
            procs[name] = subprocess.Popen(command, stderr=logs[name])
            if name in ports:
                _wait_listening(ports[name], procs[name])
        rates = _gather_rates(f"benchctl{ports['camera']}", ports["camera"], procs["control"],
                              args.step_after + args.after + 300)  # fmt: skip
    finally:
        for proc in reversed(list(procs.values())):
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        for proc in procs.values():
            try:
                proc.wait(timeout=90)
            except subprocess.TimeoutExpired:
                proc.kill()
        for log in logs.values():
            log.close()
    flapping = [r for r in rates if r > 0.5 * max(rates, default=0.0)]
    return {
        "event_rate_mev_s": sum(flapping) / len(flapping) / 1e6 if flapping else None,
        "camera_kept_up": "cannot keep up" not in (folder / "camera.log").read_text(),
        "control_exit": procs["control"].returncode if "control" in procs else None,
    }


def _wait_listening(port: int, proc: subprocess.Popen, timeout_s: float = 120.0) -> None:
    """Wait until ``proc`` listens on ``port`` of loopback (it loads its kernels first)."""
    import socket

    deadline = time.monotonic() + timeout_s
    while proc.poll() is None and time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            return
        except OSError:
            time.sleep(0.1)  # (not listening yet: try again)
    raise SystemExit(f"flagtrack bench control: a process did not listen on port {port} (its log says why)")


def _gather_rates(rig: str, port: int, control: subprocess.Popen, timeout_s: float) -> list[float]:
    """The camera's event rates (events/s) heard until the control process ends."""
    from flagtrack.daemon.schema import EventRate
    from flagtrack.daemon.transport import Bus, BusConfig

    rates: list[float] = []
    deadline = time.monotonic() + timeout_s
    with Bus(BusConfig(namespace=f"flagtrack/{rig}", connect=(f"tcp/127.0.0.1:{port}",))) as bus:
        sub = bus.subscribe(bus.keys.event_rate("cam0"), EventRate, capacity=100_000)
        while control.poll() is None and time.monotonic() < deadline:
            rate = sub.recv(timeout_s=0.5)
            if rate is not None:
                rates.append(rate.rate_hz)
    return rates


def figures(run_dir: Path, targets: list[float], settle_s: float) -> dict[str, Any]:
    """The loop's figures from a run folder's ``control.jsonl`` (see the module)."""
    import numpy as np

    path = run_dir / "control.jsonl"
    records = [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []
    timed = [r for r in records if r.get("latency_ms") is not None]
    latencies = np.array([r["latency_ms"] for r in timed])
    to_state = np.array([(r["state"]["published_ns"] - r["state"]["source_ns"]) / 1e6 for r in timed])
    cycles = [r for r in records if r.get("state") and r["state"]["completes_cycle"]]
    after = [r for r in cycles if r.get("setpoint") == targets[1]]
    step_s = after[0]["t_s"] if after else math.inf
    settled = [r for r in after if r["t_s"] >= step_s + settle_s]
    before = [r for r in cycles if r.get("setpoint") == targets[0] and settle_s <= r["t_s"] < step_s]

    def rms(rows: list[dict[str, Any]]) -> float | None:
        errors = [r["state"]["amplitude_over_l"] - r["setpoint"] for r in rows if r["state"]["amplitude_over_l"] >= 0]
        return float(np.sqrt(np.mean(np.square(errors)))) if errors else None

    return {
        "loop_latency_p50_ms": float(np.percentile(latencies, 50)) if len(latencies) else None,
        "loop_latency_p99_ms": float(np.percentile(latencies, 99)) if len(latencies) else None,
        "latency_steps": len(latencies),
        "to_state_p50_ms": float(np.percentile(to_state, 50)) if len(timed) else None,
        "to_state_p99_ms": float(np.percentile(to_state, 99)) if len(timed) else None,
        "state_to_command_p50_ms": float(np.percentile(latencies - to_state, 50)) if len(timed) else None,
        "state_to_command_p99_ms": float(np.percentile(latencies - to_state, 99)) if len(timed) else None,
        "amplitude_error_rms_over_l": rms(settled),
        "amplitude_error_rms_over_l_before_step": rms(before),
        "settled_cycles": len(settled),
        "steps": len(records),
        "faults": sum(str(r.get("reason", "")).startswith("fault") for r in records),
        "targets": list(targets),
        "step_at_s": step_s if math.isfinite(step_s) else None,
    }


def describe(r: dict[str, Any]) -> str:
    """The figures as lines for a reader."""

    def num(value: Any, fmt: str) -> str:
        return "-" if value is None else format(value, fmt)

    return "\n".join(
        [
            f"control loop on the simulated rig (camera, tracker, control: three processes), twin at "
            f"{num(r['event_rate_mev_s'], '.2f')} Mev/s while flapping (asked {r['rate_asked']:g}; "
            f"{'kept up' if r['camera_kept_up'] else 'fell behind real time'})",
            f"  loop latency over {r['latency_steps']} steps: p50 {num(r['loop_latency_p50_ms'], '.1f')} ms, "
            f"p99 {num(r['loop_latency_p99_ms'], '.1f')} ms (camera packet received -> speed command written)",
            f"    of which camera packet -> flag state published p50 {num(r['to_state_p50_ms'], '.1f')} ms, p99 "
            f"{num(r['to_state_p99_ms'], '.1f')} ms (camera, tracker, flag state); state published -> command "
            f"written p50 {num(r['state_to_command_p50_ms'], '.1f')} ms, p99 {num(r['state_to_command_p99_ms'], '.1f')} ms",
            f"  A/L held at {r['targets'][1]:g} after the step from {r['targets'][0]:g}: error RMS "
            f"{num(r['amplitude_error_rms_over_l'], '.4f')} over {r['settled_cycles']} settled cycles "
            f"(before the step: {num(r['amplitude_error_rms_over_l_before_step'], '.4f')})",
            f"  load average (1 min) {r['load_average_start']:.1f} at the start, {r['load_average_end']:.1f} at the end",
        ]
    )
