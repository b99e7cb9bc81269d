"""``flagtrack control``: a feedback-control experiment with your own law, on the rig of -c rig.yaml."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from flagtrack.daemon.commands._numbers import positive_seconds, seconds

COMMAND = "control"
HELP = "run your control law FUNCTION(state) -> speed_mps | None on the rig of -c rig.yaml, safely, recorded"
DESCRIPTION = """\
Run a control law on the rig of -c rig.yaml: FUNCTION(state) gets the flag's newest state (A/L, f,
phase, ... per cycle) and returns a wind speed in m/s (None: hold). The supervisor applies it inside
the sweep's safety wrapper (tunnel.safety bounds and ramp); a law that raises or returns nonsense
holds the speed, and supervisor.control.max_faults in a row stop the run with the tunnel at zero, as
Ctrl-C does. Everything goes to the run folder (--out): control.jsonl, the recording, a figure.
Example: flagtrack control -c rig.yaml --controller examples/hold_amplitude.py:law --duration 60. More: docs/control.md.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack control``."""
    parser.add_argument("-c", "--config", type=Path, required=True, help="rig config with a tunnel: section")
    parser.add_argument(
        "--controller",
        metavar="FILE.py:FUNCTION",
        help="the law (or 'pi': the built-in PI of the supervisor's feedback: section; 'none': no law, "
        "speed requests from the bus only); default supervisor.control.controller",
    )
    parser.add_argument("--duration", type=seconds, metavar="S", help="run this long, s (0: until Ctrl-C)")
    parser.add_argument("--period", type=float, metavar="S", help="call the law at most this often, s")
    parser.add_argument(
        "--out", type=Path, metavar="DIR", help="the run folder (default: supervisor.runs_dir/control-<time>)"
    )
    parser.add_argument(
        "--shutdown-timeout", type=positive_seconds, default=90.0, help="seconds to wait for services to stop"
    )
    parser.add_argument("-q", "--quiet", action="store_true", help="only the result")


def run(args: argparse.Namespace) -> int:
    """Run the law on the rig; say where the run folder is and how the loop did."""
    from flagtrack.daemon.rig.config import load_rig
    from flagtrack.daemon.rig.control import control_rig
    from flagtrack.daemon.rig.run import run_rig

    if args.out is not None:  # (found only once the rig was up, blamed on supervisor.runs_dir)
        from flagtrack.daemon.errors import ConfigError
        from flagtrack.daemon.typed_yaml import require_folder

        if args.out.exists() and not args.out.is_dir():
            raise ConfigError(f"{args.out} is a file: give the run folder to make", key="--out")
        require_folder(args.out, key="--out", path=None)
    rig = load_rig(args.config, services=())
    rig, names = control_rig(rig, args.controller, duration_s=args.duration, period_s=args.period, out=args.out)
    result = run_rig(rig, names, shutdown_timeout_s=args.shutdown_timeout, quiet=args.quiet, command="control")
    supervisor = result.service("supervisor")
    run_dir = None if supervisor is None else supervisor.run_dir
    if run_dir is None or not (run_dir / "run.json").exists():
        print(f"flagtrack control: {getattr(supervisor, 'stop_reason', '') or 'not run'}", file=sys.stderr)
        return result.code or 1
    print(summary_text(run_dir, supervisor.stop_reason), file=sys.stderr)
    return result.code or (0 if supervisor.stop_reason == "finished" else 1)


def summary_text(run_dir: Path, stop_reason: str) -> str:
    """How the run ended and where its files are, from its ``run.json`` (or, where that could not be
    written at the end, from ``stop_reason`` and the files there)."""
    import json

    run = json.loads((run_dir / "run.json").read_text())
    if run["status"] == "running":  # the one written at the start: the end could not be written
        unwritten = ["run.json", "README.txt"] + ([] if (run_dir / "control.png").exists() else ["control.png"])
        return "\n".join(
            [
                f"flagtrack control: {stop_reason or 'stopped'}; run folder {run_dir}",
                f"  log     {run_dir / 'control.jsonl'} (one record per step)",
                f"  not written at the end: {', '.join(unwritten)} (the lines above say why)",
            ]
        )
    latency = run["loop_latency_ms"]
    p50, p99 = (f"{latency[p]:.1f} ms" if latency[p] is not None else "-" for p in ("p50", "p99"))
    counts = run["counts"]
    return "\n".join(
        [
            f"flagtrack control: {run['stop_reason'] or run['status']}; run folder {run_dir}",
            f"  steps   {counts['steps']} ({counts['faults']} faults, {counts['requests']} requests); "
            f"loop latency p50 {p50}, p99 {p99}",
            f"  log     {run_dir / 'control.jsonl'} (one record per step)",
            f"  figure  {run_dir / 'control.png'} (A/L, f and speed against time)",
            f"  about   {run_dir / 'README.txt'} (what each file is; run.json for programs)",
        ]
    )
