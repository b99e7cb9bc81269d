"""``flagtrack bench verdicts``: does the tracker say lost or stale when it is off the flag, and found
when it is on it? (issue 30's targets, on recordings of two independent generators)."""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

COMMAND = "verdicts"
HELP = "found / lost / stale of the tracker against the truth: acquisition, noise, weak signal, still flag"
DESCRIPTION = """\
Generates flapping-flag recordings (the event-camera simulator and a slow-photoreceptor sensor),
tracks them from good and bad starts, with noise and with few events, and prints the share of
updates more than 5 % of L off the flag that say found (target <= 10 %), the share lost or stale on
clean flapping (<= 2 %) and the demo twin's still flag after flapping. More: docs/commands.md.
"""

CASES = ("clean", "acq", "noise", "weak", "still")
"""``clean``: flapping, started on the flag (robust and paper); ``acq``: started 90 degrees off;
``noise``: shot noise at the paper's f_snr/f = 30; ``weak``: 5 % of the events kept, and the slow
photoreceptor; ``still``: the demo's twin, still after flapping."""
FOUND_WHILE_OFF_MAX = 0.10
CLEAN_LOST_OR_STALE_MAX = 0.02
GROUP_LABELS = {
    "clean": "clean",
    "clean_paper": "clean (paper)",
    "acq": "acquisition, 90 deg off",
    "noise": "noise f_snr/f = 30",
    "weak_thinned": "weak: 5 % of events",
    "weak_slow": "weak: slow photoreceptor",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the verdicts benchmark."""
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    parser.add_argument("--cases", default=",".join(CASES), help=f"comma-separated (default {','.join(CASES)})")
    parser.add_argument("--seeds", type=int, default=None, help="kinematics per case (default 6; 1 with --quick)")
    parser.add_argument("--periods", type=float, default=None, help="flapping periods per recording (default 5)")
    parser.add_argument("--cache", type=Path, default=None, help="keep the recordings here (default: made anew)")
    parser.add_argument("--jobs", type=int, default=0, help="processes (0: all cores)")
    parser.add_argument("--quick", action="store_true", help="1 kinematics, 2 periods, a short twin: for tests")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (none without a terminal)")


def settings_from_args(args: argparse.Namespace, folder: Path) -> Any:
    """The run's :class:`~flagtrack.daemon.bench.verdict_schedule.Settings`; a bad option is a ConfigError."""
    from flagtrack.daemon.bench.verdict_runs import kinematics_seeds
    from flagtrack.daemon.bench.verdict_schedule import Settings, default_jobs
    from flagtrack.daemon.errors import ConfigError

    cases = tuple(dict.fromkeys(c.strip() for c in args.cases.split(",") if c.strip()))
    unknown = [c for c in cases if c not in CASES]
    if unknown or not cases:
        raise ConfigError(f"unknown cases {unknown}; choose from {', '.join(CASES)}", key="cases")
    n_seeds = args.seeds if args.seeds is not None else (1 if args.quick else 6)
    if not 1 <= n_seeds <= 1000:
        raise ConfigError(f"--seeds must be within 1-1000, got {n_seeds}", key="seeds")
    periods = args.periods if args.periods is not None else (2.0 if args.quick else 5.0)
    if not (math.isfinite(periods) and 0.5 <= periods <= 100):
        raise ConfigError(f"--periods must be within 0.5-100, got {periods}", key="periods")
    if args.jobs < 0:
        raise ConfigError(f"--jobs must be >= 0, got {args.jobs}", key="jobs")
    return Settings(
        cases=cases,
        seeds=kinematics_seeds(n_seeds),
        periods=periods,
        still_profile="quick" if args.quick else "full",
        folder=folder,
        jobs=args.jobs or default_jobs(),
        progress=not args.no_progress and sys.stderr.isatty(),
    )


def run(args: argparse.Namespace) -> int:
    """Run the benchmark; print its figures (text or JSON)."""
    from flagtrack.daemon.bench.verdict_schedule import run_all
    from flagtrack.daemon.errors import ConfigError

    if args.cache is not None and args.cache.exists() and not args.cache.is_dir():
        raise ConfigError(f"{args.cache} is not a directory", key="cache")
    load_start = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="flagtrack-verdicts-") as tmp:
        settings = settings_from_args(args, args.cache or Path(tmp))
        outcome = run_all(settings)
    figures = report(settings, outcome, load_start)
    print(json.dumps(figures, indent=1) if args.json else "\n".join(text_lines(figures)))
    return 0


def report(settings: Any, outcome: Any, load_start: tuple[float, float, float]) -> dict[str, Any]:
    """The figures as one JSON-ready mapping."""
    from flagtrack.daemon.bench.verdict_runs import OFF_OVER_L, POOLED_CASES, summarise

    rows = outcome.rows
    groups = {g: summarise(rows, "group", (g,)) for g in GROUP_LABELS if any(r["group"] == g for r in rows)}
    pooled_groups = tuple(g for g in groups if g not in ("clean", "clean_paper"))
    pooled = summarise(rows, "group", pooled_groups) if pooled_groups else None
    if pooled is not None:
        share = pooled["found_while_off"]
        pooled |= {"cases": [c for c in POOLED_CASES if c in settings.cases], "target": FOUND_WHILE_OFF_MAX}
        pooled["within_target"] = share is None or share <= FOUND_WHILE_OFF_MAX
    clean = groups.get("clean")
    if clean is not None:
        clean = {**clean, "target": CLEAN_LOST_OR_STALE_MAX}
        clean["within_target"] = (clean["lost_or_stale_share"] or 0.0) <= CLEAN_LOST_OR_STALE_MAX
    return {
        "settings": {
            "cases": list(settings.cases),
            "seeds": list(settings.seeds),
            "periods": settings.periods,
            "still_profile": settings.still_profile if "still" in settings.cases else None,
            "jobs": settings.jobs,
            "off_over_l": OFF_OVER_L,
        },
        "groups": groups,
        "pooled": pooled,
        "clean": clean,
        "still": outcome.still,
        "runs": rows,
        "wall_s": outcome.wall_s,
        "load_average": {"start": list(load_start), "end": list(os.getloadavg())},
    }


def _pct(value: float | None, digits: int = 1) -> str:
    return "-" if value is None else f"{100 * value:.{digits}f} %"


def _range(pair: list[float] | None, digits: int = 1) -> str:
    return "" if not pair else f" ({100 * pair[0]:.{digits}f}-{100 * pair[1]:.{digits}f} %)"


def _verdict(within: bool) -> str:
    return "within target" if within else "OVER TARGET"


def text_lines(figures: dict[str, Any]) -> list[str]:
    """The figures for a person."""
    s = figures["settings"]
    lines = [
        f"bench verdicts: seeds {', '.join(map(str, s['seeds']))}, {s['periods']:g} periods each; "
        f"robust method unless said; off = eps_RMS > {100 * s['off_over_l']:g} % L",
        f"  {'case':26s} {'runs':>4s} {'updates':>8s} {'off':>6s}  found while off (per run)   lost or stale",
    ]
    for group, g in figures["groups"].items():
        lines.append(
            f"  {GROUP_LABELS[group]:26s} {g['runs']:4d} {g['updates']:8d} {g['off']:6d}  "
            f"{_pct(g['found_while_off']) + _range(g['found_while_off_range']):26s}  "
            f"{_pct(g['lost_or_stale_share'], 2)}{_range(g['lost_or_stale_range'], 2)}"
        )
    pooled, clean, still = figures["pooled"], figures["clean"], figures["still"]
    if pooled:
        lines.append(
            f"pooled {' + '.join(pooled['cases'])}: found while > 5 % L off {_pct(pooled['found_while_off'])} "
            f"of {pooled['off']} (target <= {_pct(pooled['target'], 0)}): {_verdict(pooled['within_target'])}"
        )
    if clean:
        lines.append(
            f"clean flapping: lost or stale {_pct(clean['lost_or_stale_share'], 2)} of {clean['updates']} "
            f"(target <= {_pct(clean['target'], 0)}): {_verdict(clean['within_target'])}"
        )
    if still:
        points = ", ".join(f"{p['point']} {_pct(p['e_over_l_rms'], 3)}" for p in still["points"])
        gap = still["gap_over_l"]
        lines += [
            f"still flag (twin): e/L RMS going up {_pct(still['still_up_e_over_l_rms'], 3)}, coming down "
            f"{_pct(still['still_down_e_over_l_rms'], 3)} (gap {'-' if gap is None else f'{100 * gap:+.3f} % L'}, "
            f"target 0.05 %): {_verdict(still['within_target'])}",
            f"  per point: {points}",
        ]
    load = figures["load_average"]
    lines.append(f"{figures['wall_s']:.0f} s, load average {load['start'][0]:.1f} -> {load['end'][0]:.1f}")
    return lines
