"""``flagtrack bench kills``: a sweep on the simulated rig killed with SIGKILL at random moments and
resumed each time with ``flagtrack sweep --resume``; the run must end complete, with no point lost
or repeated in ``run.jsonl`` or ``summary.csv``, every ``.raw`` readable, and the simulated tunnel
(a controller on a real pseudo-terminal, in this process) stopped by its own watchdog after each
kill (docs/reliability.md)."""

from __future__ import annotations

import argparse
import csv
import json
import random
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

COMMAND = "kills"
HELP = "SIGKILL a simulated sweep at random moments, resume each time, check the run (about 8 s a kill)"
DESCRIPTION = __doc__
RUN_NAME = "kills"


@dataclass
class KillReport:
    """What a random-kill run did and found (``problems`` empty: every check held)."""

    kills: int = 0
    sessions: int = 0
    points: int = 0
    seconds: float = 0.0
    watchdog_trips: int = 0
    max_zero_after_kill_s: float = 0.0
    raw_files: int = 0
    problems: list[str] = field(default_factory=list)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack bench kills``."""
    parser.add_argument("--kills", type=int, default=20, help="how many SIGKILLs (default 20)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the kill moments")
    parser.add_argument("--dir", type=Path, help="work folder (default: a temporary one, removed)")
    parser.add_argument("--json", action="store_true", help="end with one JSON object of the figures")


def run(args: argparse.Namespace) -> int:
    """Run it and print the figures; exit 1 when a check failed."""
    with tempfile.TemporaryDirectory(prefix="flagtrack-kills-") as tmp:
        report = random_kills(args.dir or Path(tmp), args.kills, args.seed, log=print)
    for problem in report.problems:
        print(f"PROBLEM: {problem}")
    print(
        f"{report.kills} kills over {report.sessions} sessions, {report.points} points, {report.seconds:.0f} s; "
        f"watchdog trips {report.watchdog_trips}, tunnel at zero at most {report.max_zero_after_kill_s:.2f} s "
        f"after a kill; {report.raw_files} .raw files readable; {len(report.problems)} problems"
    )
    if args.json:
        print(json.dumps(asdict(report)))
    return 1 if report.problems else 0


def rig_config(workdir: Path, port: str, speeds: list[float], record_s: float) -> dict[str, Any]:
    """A light simulated rig in one process whose tunnel is the controller on ``port``."""
    return {
        "rig": f"kills{int(time.time() * 1000) % 10**9}",
        "camera": {"adapter": "simulated", "packet_us": 4000,
                   "simulated": {"events_per_px2": 0.5, "noise_rate_hz": 5000, "max_lag_s": 1.0}},
        "tracker": {"root": [150, 240], "length": 300, "tau_s": 0.002},
        "recorder": {"directory": str(workdir / "rec"), "allowed_dirs": [str(workdir / "runs")], "min_free_mb": 0},
        "tunnel": {"driver": "ascii", "port": port, "timeout_s": 0.3,
                   "safety": {"max_speed_mps": 8, "max_ramp_mps2": 4.0, "ramp_period_s": 0.05, "tolerance_mps": 0.15,
                              "settle_timeout_s": 3.0, "poll_period_s": 0.05, "keepalive_s": 0.25, "watchdog_s": 1.5}},
        "supervisor": {"mode": "sweep", "runs_dir": str(workdir / "runs"), "run_name": RUN_NAME,
                       "onset": {"learn_s": 1.0}, "silence_timeout_s": 3.0,
                       "sweep": {"speeds": speeds, "branches": ["up", "down"], "settle_s": 0.3, "record_s": record_s}},
        "services": ["camera", "tracker", "recorder", "supervisor"],
    }  # fmt: skip


def random_kills(
    workdir: Path,
    kills: int,
    seed: int = 0,
    speeds: tuple[float, ...] = (3.0, 4.0, 5.0, 5.5, 6.0),
    record_s: float = 1.0,
    log: Any = None,
) -> KillReport:
    """Run the sweep of :func:`rig_config`, SIGKILL it ``kills`` times at moments drawn uniformly
    over 0..2.5 s after its tunnel starts moving, resume it each time, let the last session finish,
    and check the run."""
    import yaml

    from flagtrack.drivers.tunnel.sim_model import SimParams
    from flagtrack.drivers.tunnel.simulated import SimulatedTunnel

    rng = random.Random(seed)
    report = KillReport()
    started = time.monotonic()
    run_dir = workdir / "runs" / RUN_NAME
    with SimulatedTunnel(SimParams(tau_s=0.1, ramp_mps2=6.0, watchdog_s=1.5)) as sim:
        config = workdir / "rig.yaml"
        workdir.mkdir(parents=True, exist_ok=True)
        config.write_text(yaml.safe_dump(rig_config(workdir, sim.port, list(speeds), record_s)))
        sweep = [sys.executable, "-m", "flagtrack.daemon", "sweep", "--quiet"]
        while True:
            resume = (run_dir / "run.jsonl").exists()
            command = [*sweep, "--resume", str(run_dir)] if resume else [*sweep, "-c", str(config)]
            proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
            report.sessions += 1
            if report.kills >= kills or not _kill_session(proc, sim, rng.uniform(0.0, 2.5), report):
                _finish(proc, report)
                break
            if log is not None:
                log(f"kill {report.kills}: after {time.monotonic() - started:.1f} s, tunnel at zero by its watchdog")
        report.watchdog_trips = sim.watchdog_trips
    report.seconds = time.monotonic() - started
    _check_run(run_dir, report)
    return report


def _kill_session(proc: subprocess.Popen[bytes], sim: Any, delay_s: float, report: KillReport) -> bool:
    """SIGKILL ``proc`` ``delay_s`` after the tunnel starts moving, then wait for the tunnel's own
    watchdog to bring it to zero; False when the sweep ended before the kill."""
    if not _wait(lambda: sim.setpoint_mps > 0 or proc.poll() is not None, 120):
        report.problems.append(f"session {report.sessions}: the tunnel never moved")
    time.sleep(delay_s)  # the random moment: settle, record, analysis or a log write
    if proc.poll() is not None:
        return False
    trips = sim.watchdog_trips
    proc.send_signal(signal.SIGKILL)
    killed_at = time.monotonic()
    proc.communicate(timeout=30)
    report.kills += 1
    if sim.setpoint_mps > 0 and not _wait(lambda: sim.watchdog_trips > trips and sim.speed_mps < 0.2, 10):
        report.problems.append(f"kill {report.kills}: the tunnel was not at zero within 10 s")
    report.max_zero_after_kill_s = max(report.max_zero_after_kill_s, time.monotonic() - killed_at)
    return True


def _finish(proc: subprocess.Popen[bytes], report: KillReport) -> None:
    _, err = proc.communicate(timeout=300)
    if proc.returncode != 0:
        said = [line for line in err.decode().splitlines() if line.startswith("flagtrack sweep:")]
        report.problems.append(f"the last session exited {proc.returncode}: {' '.join(said)[:500]}")


def _wait(predicate: Any, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def _check_run(run_dir: Path, report: KillReport) -> None:
    """The run is complete: every planned point done exactly once (log and summary), every .raw readable."""
    from flagtrack.daemon.errors import FlagtrackError
    from flagtrack.daemon.sweep.runlog import read_run
    from flagtrack.drivers.formats import read_events

    record = read_run(run_dir)
    planned = record.planned_ids
    report.points = len(planned)
    if record.stop is None or record.stop.get("reason") != "finished":
        report.problems.append(f"the run did not finish: {record.stop}")
    done = Counter(p.point_id for p in record.points if p.status == "done")
    lost = [pid for pid in planned if done[pid] == 0]
    repeated = [pid for pid, n in done.items() if n > 1]
    if lost or repeated:
        report.problems.append(f"run.jsonl: points lost {lost}, repeated {repeated}")
    rows = list(csv.DictReader((run_dir / "summary.csv").read_text().splitlines()))
    if sorted(r["point_id"] for r in rows) != sorted(planned) or any(r["status"] != "done" for r in rows):
        report.problems.append("summary.csv: not one done row per planned point")
    for raw in sorted((run_dir / "points").glob("*.raw")):
        try:
            if len(read_events(raw).events) == 0:
                report.problems.append(f"{raw.name}: no events")
        except FlagtrackError as exc:
            report.problems.append(f"{raw.name}: unreadable: {exc}")
        report.raw_files += 1
