"""``flagtrack bench accuracy``: the paper's section 3 benchmark on flagtrack's simulator.

Simulates a family of flapping kinematics (clean), leak-rate and shot-noise sweeps and N_j / tau
sweeps, reconstructs each recording with the paper's method and the robust ones, and writes CSV
tables, figures in the manner of the paper's figures 4-6 and a markdown report (docs/benchmark.md).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from flagtrack.daemon.bench.accuracy_suite.runner import RunSettings

COMMAND = "accuracy"
HELP = "accuracy of the tracker on simulated recordings (paper section 3): tables, figures, report"
DESCRIPTION = """\
The paper's section 3 benchmark on flagtrack's simulator: a family of kinematics, noise sweeps and
N_j / tau sweeps, reconstructed with the paper's and the robust methods; writes tables, figures and
a report (--quick: a few minutes). More: docs/benchmark.md, docs/commands.md.
"""

METHOD_CHOICES = ("paper", "robust-classic", "robust")
PART_CHOICES = ("family", "leak", "shot", "params", "lost")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the accuracy benchmark."""
    parser.add_argument("-o", "--output", type=Path, default=Path("bench-accuracy"), help="results folder")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="small preset (24 kinematics, 2 sweep kinematics, 4 cycles, fewer levels): a few minutes",
    )
    parser.add_argument(
        "--n", type=int, default=None, help="kinematics of the family, part (a) (default 400; 24 with --quick)"
    )
    parser.add_argument("--sweep-kinematics", type=int, default=None, help="kinematics of the sweeps (b)-(d)")
    parser.add_argument("--cycles", type=float, default=None, help="periods of each sweep recording")
    parser.add_argument(
        "--method",
        action="append",
        choices=METHOD_CHOICES,
        default=None,
        help="tracking method (repeat for several; default: all three)",
    )
    parser.add_argument(
        "--parts",
        default=",".join(PART_CHOICES),
        help=f"comma-separated parts to run (default {','.join(PART_CHOICES)})",
    )
    parser.add_argument("--size", default=None, metavar="WxH", help="sensor size (default 640x480; the flag scales)")
    parser.add_argument("--seed", type=int, default=0, help="benchmark seed (every recording's seed derives from it)")
    parser.add_argument("--jobs", type=int, default=0, help="processes (0: all cores)")
    parser.add_argument("--keep-recordings", action="store_true", help="keep the simulated files in OUTPUT/recordings")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument(
        "--report-only",
        action="store_true",
        help="rewrite the figures and report.md of OUTPUT from its CSV tables and run.json",
    )


def settings_from_args(args: argparse.Namespace) -> RunSettings:
    """The :class:`~flagtrack.daemon.bench.accuracy_suite.runner.RunSettings` of the command line."""
    from dataclasses import replace

    from flagtrack.daemon.bench.accuracy_suite.plan import PRESETS
    from flagtrack.daemon.bench.accuracy_suite.runner import RunSettings
    from flagtrack.daemon.errors import ConfigError

    preset = PRESETS["quick" if args.quick else "full"]
    changes: dict[str, Any] = {}  # Preset fields from the command line
    if args.n is not None:
        changes["n_family"] = args.n
    if args.sweep_kinematics is not None:
        changes["n_sweep"] = args.sweep_kinematics
    if args.cycles is not None:
        changes["cycles"] = args.cycles
    if args.size:
        try:
            width, height = (int(v) for v in args.size.lower().split("x"))
        except ValueError:
            raise ConfigError(f"--size wants WxH, got {args.size!r}", key="size") from None
        changes.update(width=width, height=height)
    parts = tuple(p.strip() for p in args.parts.split(",") if p.strip())
    unknown = set(parts) - set(PART_CHOICES)
    if unknown or not parts:
        raise ConfigError(f"unknown parts {sorted(unknown)}; choose from {', '.join(PART_CHOICES)}", key="parts")
    for key in ("n_family", "n_sweep"):
        if int(changes.get(key, 1)) < 0:
            raise ConfigError(f"{key} must be >= 0", key=key)
    methods = tuple(dict.fromkeys(args.method)) if args.method else METHOD_CHOICES
    return RunSettings(
        preset=replace(preset, **changes),
        parts=parts,
        methods=methods,
        seed=args.seed,
        jobs=args.jobs if args.jobs > 0 else os.cpu_count() or 1,
        work_dir=args.output / "recordings",
        keep_recordings=args.keep_recordings,
        progress=not args.no_progress,
    )


def run(args: argparse.Namespace) -> int:
    """Run the benchmark and write the results folder."""
    from flagtrack.daemon.bench.accuracy_suite.report import write_results
    from flagtrack.daemon.bench.accuracy_suite.runner import run as run_benchmark

    settings = settings_from_args(args)
    if args.report_only:
        return _report_only(args.output, settings)
    command = (
        "flagtrack bench accuracy " + " ".join(sys.argv[3:])
        if sys.argv[1:3] == ["bench", "accuracy"]
        else "flagtrack bench accuracy"
    )
    started = time.perf_counter()
    result = run_benchmark(settings)
    headline = write_results(args.output, result, settings, command)
    if not settings.keep_recordings:
        try:
            settings.work_dir.rmdir()
        except OSError:
            pass
    for entry in headline["family"]:
        print(
            f"family {entry['method']:>15s}: delta_RMS/L median {100 * entry['delta_rms_over_l_median']:.2f} % "
            f"(range {100 * entry['delta_rms_over_l_min']:.2f}-{100 * entry['delta_rms_over_l_max']:.2f} %), "
            f"max eps_RMS/L {100 * entry['max_eps_rms_over_l_min']:.2f}-{100 * entry['max_eps_rms_over_l_max']:.2f} %"
        )
    print(
        f"{result.recordings} recordings, {result.events / 1e6:.0f} M events in {time.perf_counter() - started:.0f} s "
        f"-> {args.output / 'report.md'}"
    )
    return 0


def _report_only(out: Path, settings: RunSettings) -> int:
    """Rewrite the report of an earlier run (same command line recorded)."""
    from dataclasses import replace

    from flagtrack.daemon.bench.accuracy_suite.report import rows_from_folder, write_results
    from flagtrack.daemon.bench.accuracy_suite.tables import method_rank
    from flagtrack.daemon.errors import ConfigError

    if not (out / "run.json").is_file():
        raise ConfigError(f"no run.json in {out}: nothing to rewrite", key="output")
    result, run = rows_from_folder(out)
    methods = tuple(sorted(dict.fromkeys(r["method"] for r in result.rows), key=method_rank)) or settings.methods
    jobs = run.get("settings", {}).get("jobs", 0)
    write_results(out, result, replace(settings, methods=methods, jobs=jobs), run["command"])
    print(f"rewrote {out / 'report.md'} from {len(result.rows)} rows")
    return 0
