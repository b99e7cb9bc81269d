"""``flagtrack runs list RUNS_DIR``: the sweep runs of a folder, with their date, points, onset, decay, status."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

COMMAND = "runs"
HELP = "list the sweep runs of a folder: date, points, onset and decay, status"
DESCRIPTION = """\
List the sweep runs of RUNS_DIR: when each started, its points done, the onset and decay found and
how it ended (an incomplete one resumes with `flagtrack sweep --resume RUN_DIR`).
More: docs/commands.md.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``list`` action and its arguments."""
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    listing = actions.add_parser(
        "list",
        help="list the runs of a folder",
        description="List the sweep and control runs of a folder, one line each: when it started, its points, "
        "the onset and decay speeds found, its status; a run whose log is damaged says so (docs/commands.md).",
    )
    listing.add_argument("runs_dir", type=Path, metavar="RUNS_DIR", help="a folder of sweep run folders")
    listing.add_argument("--json", action="store_true", help="print one JSON array instead of a table")


def run(args: argparse.Namespace) -> int:
    """List the runs."""
    from flagtrack.daemon.errors import ConfigError

    runs_dir: Path = args.runs_dir
    if not runs_dir.is_dir():
        what = "no such folder" if not runs_dir.exists() else "not a folder"
        raise ConfigError(f"{what}: {runs_dir}")
    from flagtrack.daemon.sweep.runlog import RUN_LOG

    # RUNS_DIR may be one run's folder itself
    folders = [runs_dir] if (runs_dir / RUN_LOG).exists() else sorted(p for p in runs_dir.iterdir() if p.is_dir())
    rows = [run_overview(folder) for folder in folders]
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    if not rows:
        print(f"flagtrack runs: no run folders in {runs_dir}", file=sys.stderr)
        return 0
    print(_table(rows))
    return 0


def run_overview(folder: Path) -> dict[str, Any]:
    """What ``runs list`` shows of one folder (``status`` ``not a run`` or ``unreadable`` with a
    ``reason`` when it is not a readable run)."""
    from flagtrack.daemon.errors import FormatError
    from flagtrack.daemon.sweep.runfiles import run_status
    from flagtrack.daemon.sweep.runlog import RUN_LOG, read_run
    from flagtrack.daemon.sweep.summary import summary_points, transition_speeds

    row: dict[str, Any] = {
        "run": folder.name,
        "path": str(folder.resolve()),
        "started": None,
        "started_unix": None,
        "points_done": None,
        "points_planned": None,
        "onset_mps": None,
        "decay_mps": None,
        "status": None,
        "reason": None,
        "kind": None,  # "sweep" (run.jsonl) or "control" (flagtrack control's run.json)
    }
    if not (folder / RUN_LOG).is_file():
        control = _control_run(folder)
        return {**row, **control} if control else {**row, "status": "not a run", "reason": f"no {RUN_LOG}"}
    try:
        record = read_run(folder)
        points = summary_points(record)
        onset, decay = transition_speeds(points)
        status, detail = run_status(record)
    except (FormatError, ValueError, TypeError, KeyError, AttributeError) as exc:  # a log another program wrote
        return {**row, "status": "unreadable", "reason": str(exc)}
    started = record.start.get("t_unix")
    shown = _local_time(started)
    known_start = shown is not None
    return {
        **row,
        "started": shown,
        "started_unix": started if known_start else None,
        "points_done": sum(p.status == "done" for p in points),
        "points_planned": len(record.planned_ids),
        "onset_mps": onset,
        "decay_mps": decay,
        "status": status,
        "reason": detail or None,
        "kind": "sweep",
    }


def _local_time(t_unix: object) -> str | None:
    """``t_unix`` as local date and minute, or None where it is no time (a log another program wrote:
    1e300 or NaN; the other runs are still listed)."""
    if not isinstance(t_unix, int | float):
        return None
    try:
        return time.strftime("%Y-%m-%d %H:%M", time.localtime(t_unix))
    except (OverflowError, ValueError, OSError):
        return None


def _control_run(folder: Path) -> dict[str, Any] | None:
    """The row fields of a feedback-control run (``flagtrack control``: its ``run.json``), or None."""
    try:
        description = json.loads((folder / "run.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(description, dict) or description.get("format") != "flagtrack-control-run":
        return None
    started = description.get("started_unix")
    shown = _local_time(started)
    status = description.get("status")
    reason = description.get("error") or description.get("stop_reason")
    return {
        "started": shown,
        "started_unix": started if shown else None,
        "kind": "control",
        "status": status if isinstance(status, str) else "unreadable",
        "reason": str(reason) if reason and reason != status else None,
    }


def _table(rows: list[dict[str, Any]]) -> str:
    """The rows as an aligned text table."""

    def cell(value: Any) -> str:
        return "-" if value is None else f"{value:g}" if isinstance(value, float) else str(value)

    header = ("run", "started", "points", "onset m/s", "decay m/s", "status")
    body = [
        (
            row["run"],
            cell(row["started"]),
            "-" if row["points_planned"] is None else f"{row['points_done']}/{row['points_planned']}",
            cell(row["onset_mps"]),
            cell(row["decay_mps"]),
            ("control run, " if row.get("kind") == "control" else "")
            + row["status"]
            + (f": {row['reason']}" if row["reason"] else ""),
        )
        for row in rows
    ]
    widths = [max(len(line[i]) for line in [header, *body]) for i in range(len(header) - 1)]
    return "\n".join(
        "  ".join([*(text.ljust(width) for text, width in zip(line[:-1], widths)), line[-1]]).rstrip()
        for line in [header, *body]
    )
